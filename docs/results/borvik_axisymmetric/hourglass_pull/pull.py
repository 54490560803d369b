#!/usr/bin/env python3
"""The shaped plate's hourglass pull on the Børvik plates about their axis (stops 124–125).

    python3 docs/results/borvik_axisymmetric/hourglass_pull/pull.py

Runs of pull_case.sh's case (the case with the pull's and the contact's power as probes), gradient
hardening m = -3 (`--set nonlocal_hardening=-3`), 8 mm at 298 m/s unless named _12_:
  pwm3_<plate>_k<k>        the case's pull, α = 0.01
  pwa005m3_<plate>_k<k>    α = 0.005 (`--set hourglass_alpha=0.005`)
  pwa0m3<place>_<plate>_k<k>  no pull (`--set hourglass_alpha=0`), at edge places m04 / 0 / p04
Δx = 4 mm / k. For each run, at 65, 100 and 150 µs: the projectile's speed, the work the pull has
done on the bodies (the time integral of Σ m v · a_hourglass over the rings), the contact's, and
the energy the balance misses (the projectile's kinetic energy at impact less Σ m (e + ½ |v|²)).
Last, the no-pull series over the lattice, through ../lattice_conserving/lattice.py's report, and
the runs of the case itself (no power probes) with the pull weakened by the damage
(damage_weakened_pull.diff, applied to a copy of the stdlib run with PAIRSUM_STDLIB, stop 125):
  dw<place>_<plate>_k<k>      the case's hardening (m = 1)
  dwm3<place>_<plate>_k<k>    m = -3
and, since stop 126, with the committed stdlib's switch (`--set hourglass_damage=1`, the same
figures bit for bit; their histories.csv kept every 20 steps, where every probe is sampled):
  dwm3<place>_12_k16          m = -3 at 0.25 mm on 12 mm
  dwm1<place>_8_k<k>          m = -1 on 8 mm
and, since stop 127, m = -3 at two more edge places, m02 and p02 (-0.2, +0.2), on both plates:
  dwm3<place>_<plate>_k<k>    five places a level, with the speeds at 40, 65, 100 and 150 µs"""
import csv
import os
import statistics as st
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "lattice_conserving"))
import lattice  # noqa: E402

TIMES = [65, 100, 150]  # µs
STAGES = [40, 65, 100, 150]  # µs, the five-place means
SERIES = [("pwm3", "α = 0.01 (the case)"), ("pwa005m3", "α = 0.005"), ("pwa0m3", "α = 0, no pull")]


def histories(run):
    rows = list(csv.reader(open(os.path.join(run, "histories.csv"))))
    column = {h.split(" [")[0]: i for i, h in enumerate(rows[0])}
    return column, rows[1:]


def sampled(column, rows, name):
    """(t, value) where the probe has a value."""
    return [(float(r[0]), float(r[column[name]])) for r in rows if r[column[name]] != ""]


def integral(points):
    """The running trapezoidal integral of (t, value) points."""
    out = [(points[0][0], 0.0)]
    for (a, pa), (b, pb) in zip(points, points[1:]):
        out.append((b, out[-1][1] + 0.5 * (pa + pb) * (b - a)))
    return out


def at(points, t_us):
    return min(points, key=lambda p: abs(p[0] - t_us * 1e-6))[1]


def energies(run):
    """Per time: the projectile's speed, the pull's work, the contact's work, the energy missed."""
    column, rows = histories(run)
    v = sampled(column, rows, "projectile_velocity")
    total = sampled(column, rows, "total_energy")
    pull = integral(sampled(column, rows, "hourglass_power"))
    contact = integral(sampled(column, rows, "contact_power"))
    start = total[0][1]
    return [(-at(v, t), at(pull, t), at(contact, t), start - at(total, t)) for t in TIMES]


def folder(series, plate, place, k):
    return os.path.join(HERE, f"{series}{'' if place == '0' else place}_{plate}_k{k}")


if __name__ == "__main__":
    for plate in (8, 12):
        for series, what in SERIES:
            runs = [(k, folder(series, plate, "0", k)) for k in (6, 8, 10, 12, 16, 20)]
            runs = [(k, r) for k, r in runs if os.path.exists(os.path.join(r, "histories.csv"))]
            if not runs:
                continue
            print(f"== {plate} mm, {what}, edge place 0: at " + " / ".join(f"{t} µs" for t in TIMES))
            print("Δx (mm)  residual | speed m/s | pull's work J | contact's work J | energy missed J")
            for k, run in runs:
                rows = energies(run)
                cells = [" / ".join(f"{row[i]:.{2 if i == 0 else 1}f}" for row in rows) for i in range(4)]
                print(f"{4 / k:<8.3f} {lattice.residual(plate, '0', k, lambda p, ph, kk: run):8.2f} | " + " | ".join(cells))
    print("== no pull over the lattice (edge places -0.4, 0, +0.4)")
    lattice.report(lambda plate, place, k: folder("pwa0m3", plate, place, k), plates=(8, 12), phases=["m04", "0", "p04"])
    for series, what in (("dw", "the case's hardening (m = 1)"), ("dwm1", "m = -1"), ("dwm3", "m = -3")):
        print(f"== the pull weakened by the damage, {what}, over the lattice")
        lattice.report(lambda plate, place, k: folder(series, plate, place, k), plates=(8, 12), phases=["m04", "0", "p04"])
    print("== the pull weakened by the damage, m = -3, over five edge places (-0.4, -0.2, 0, +0.2, +0.4; stop 127)")
    lattice.report(lambda plate, place, k: folder("dwm3", plate, place, k), plates=(8, 12))
    print("mean speed (m/s) over the five edge places ± standard error, and what is lost after 100 µs")
    for plate in (8, 12):
        for k in (6, 8, 10, 12, 16):
            runs = [folder("dwm3", plate, place, k) for place in lattice.PHASES]
            if not all(os.path.exists(os.path.join(r, "report.md")) for r in runs):
                continue
            speeds = list(zip(*(lattice.speeds_at(r, STAGES) for r in runs)))
            cells = [f"{st.mean(s):.2f} ± {st.stdev(s) / len(s) ** 0.5:.2f}" for s in speeds]
            lost = [a - b for a, b in zip(speeds[2], speeds[3])]
            print(f"{plate} mm, Δx {4 / k:.3f} mm: at " + " / ".join(f"{t} µs {c}" for t, c in zip(STAGES, cells))
                  + f"; lost after 100 µs {st.mean(lost):.2f} ± {st.stdev(lost) / len(lost) ** 0.5:.2f}")
