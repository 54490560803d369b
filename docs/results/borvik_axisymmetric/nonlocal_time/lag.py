#!/usr/bin/env python3
"""The nonlocal strain's lag and a relaxation time of its own (stop 129).

    python3 docs/results/borvik_axisymmetric/nonlocal_time/lag.py

The closest setting (`--set hourglass_damage=1 --set nonlocal_hardening=-3`) with ε̄_p relaxing over
a fixed time τ (`--set nonlocal_time=τ` in µs; damage/nonlocal_strain.sph), against the same
setting with one Jacobi step a correction (stops 125–128, ../hourglass_pull/dwm3*). Prints, per
plate, the projectile's speed (m/s) at 20, 40, 65 and 100 µs and its residual at 150 µs for each
level; the residual against τ at 0.5 mm on 12 mm; and both plates' levels over the edge places run
at τ = 4 µs."""
import csv
import os
import statistics as st

HERE = os.path.dirname(os.path.abspath(__file__))
PULL = os.path.join(HERE, "..", "hourglass_pull")
KS = (6, 8, 10, 12, 16)
DX = {6: 0.667, 8: 0.5, 10: 0.4, 12: 0.333, 16: 0.25}
TIMES = (20e-6, 40e-6, 65e-6, 100e-6, 150e-6)


def speeds(path):
    """The projectile's speed at TIMES from a run's histories.csv, or None if the run is missing."""
    if not os.path.exists(path):
        return None
    with open(path) as f:
        rows = list(csv.reader(f))
    column = rows[0].index("projectile_velocity [m/s]")
    rows = [r for r in rows[1:] if r[column] != ""]
    return [-float(min(rows, key=lambda r: abs(float(r[0]) - t))[column]) for t in TIMES]


def run(folder):
    return speeds(os.path.join(folder, "histories.csv"))


def ladder(plate):
    print(f"\n{plate} mm, edge place 0: projectile speed at 20 / 40 / 65 / 100 µs and the residual (150 µs)")
    print("| Δx (mm) | one Jacobi step a correction | τ = 4 µs |")
    print("| --- | --- | --- |")
    for k in KS:
        committed = run(os.path.join(PULL, f"dwm3_{plate}_k{k}"))
        fixed = run(os.path.join(HERE, f"t4_{plate}_k{k}"))
        cells = [" / ".join(f"{v:.2f}" for v in s) if s else "—" for s in (committed, fixed)]
        print(f"| {DX[k]} | {cells[0]} | {cells[1]} |")


def sensitivity():
    print("\n12 mm at 0.5 mm, edge place 0: residual (m/s) against τ")
    natural = run(os.path.join(PULL, "dwm3_12_k8"))
    print(f"  one Jacobi step a correction: {natural[-1]:.2f}")
    for tau, name in ((1, "c1_12_k8"), (2, "t2_12_k8"), (4, "t4_12_k8"), (8, "t8_12_k8"), (1, "t1first_12_k8")):
        s = run(os.path.join(HERE, name))
        if s:
            print(f"  τ = {tau} µs ({name}): {s[-1]:.2f} (at 20 / 40 µs {s[0]:.2f} / {s[1]:.2f}; natural {natural[0]:.2f} / {natural[1]:.2f})")


def places(plate):
    print(f"\n{plate} mm at τ = 4 µs at the edge places −0.4 / 0 / +0.4: residual (m/s), and the mean of those run")
    for k in KS:
        values = [run(os.path.join(HERE, f"t4{p}_{plate}_k{k}")) for p in ("m04", "", "p04")]
        run_ = [v[-1] for v in values if v]
        mean = f"  → {st.mean(run_):.2f}" if len(run_) > 1 else ""
        print(f"  {DX[k]} mm: " + " / ".join(f"{v[-1]:.2f}" if v else "—" for v in values) + mean)


if __name__ == "__main__":
    ladder(12)
    ladder(8)
    sensitivity()
    places(12)
    places(8)
