#!/usr/bin/env python3
"""A hardening series over the lattice: each level's residual speed averaged over places of the
projectile's edge, as ../lattice_conserving/lattice.py does for the case.
    python3 docs/results/borvik_axisymmetric/edge_hardening/lattice.py          # nh0, 12 mm
    python3 docs/results/borvik_axisymmetric/edge_hardening/lattice.py nhm3     # nhm3, 8 mm
nh0 (stop 122): local hardening (`--set nonlocal_hardening=0`) on the 12 mm plate at five places
(edge_phase -0.4 … +0.4); runs nh0_12_k<k> (phase 0, stop 121) and nh0<phase>_12_k<k>.
nhm3 (stops 123–124): gradient hardening (`--set nonlocal_hardening=-3`) on the 8 mm plate (stop 123)
and the 12 mm plate (stop 124) at three places (-0.4, 0, +0.4); runs nhm3_<plate>_k<k> (phase 0,
stop 122) and nhm3<phase>_<plate>_k<k>.
Last, the mean over the places of the projectile's speed at given times, for the levels run at
every place: where the levels part."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "lattice_conserving"))
import lattice  # noqa: E402

TIMES = [40, 65, 100, 120, 150]  # µs
SERIES = {"nh0": ((12,), lattice.PHASES), "nhm3": ((8, 12), ["m04", "0", "p04"])}

if __name__ == "__main__":
    series = sys.argv[1] if len(sys.argv) > 1 else "nh0"
    if series not in SERIES:
        sys.exit(f"lattice.py: no series {series!r}; the series are {', '.join(SERIES)}")
    plates, phases = SERIES[series]

    def folder(plate, phase, k):
        return os.path.join(HERE, f"{series}{'' if phase == '0' else phase}_{plate}_k{k}")

    lattice.report(folder, plates=plates, phases=phases)
    for plate in plates:
        print(f"== {plate} mm: the projectile's speed (m/s) at t (µs), the mean over {len(phases)} places")
        print("Δx (mm)".ljust(8), " ".join(f"{t:>7}" for t in TIMES))
        for k in (6, 8, 10, 12, 16, 20):
            if all(os.path.exists(os.path.join(folder(plate, p, k), "histories.csv")) for p in phases):
                mean = lattice.mean_speeds_at(plate, k, TIMES, folder, phases)
                print(f"{4 / k:<8.3f}", " ".join(f"{v:7.2f}" for v in mean))
