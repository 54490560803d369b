#!/usr/bin/env python3
"""Stop 121's single-place series (edge_phase 0) beside the case's (../c{8,12}_0_k*): the
projectile's speed at given times, the residual speed, its steps, and an unweighted line in
ln(1 mm / Δx) through the residuals. Series: r20 (the edge rounded to 2 mm, ../edge_case.py 2),
nhm1 (`--set nonlocal_hardening=-1`), nh0 (`--set nonlocal_hardening=0`), nhm3 (`-3`, stop 122,
to 0.2 mm at stop 123), c (the case). Stop 123's probes of the tearing, on 8 mm with m = -3:
ef1m3 (a fixed failure strain: `--set D1=1 --set D2=0 --set D3=0 --set D4=0`), nsef1m3 (the same
without the spall: `--set p_spall=1e20`), av05ef1m3 (ef1m3 with `--set visc_a=0.5`), sk1m3
(failed neighbours left out of ε̄_p: the case with `nonlocal_skips_failed = 1` under
[materials.weldox]), r20m3 (m = -3 with the edge rounded to 2 mm, ../edge_case.py 2) and c4m3
(m = -3 with the contact four times stiffer: `contact_stiffness = 4` under both [materials]).
Stop 124's, on 8 mm with m = -3: ncm3 (a failed particle carries no stress at all, its compression
too: failed_free.diff applied to a copy of the stdlib, run with PAIRSUM_STDLIB), dc0m3 (no
weakening by the damage before failure: `--set damage_coupling=0`) and l4m3 (ℓ = 4 mm: `--set
damage_length=4`).
Run from anywhere: python3 docs/results/borvik_axisymmetric/edge_hardening/series.py"""
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "lattice_conserving"))
from lattice import speeds_at  # noqa: E402

TIMES = [20, 40, 56, 65, 100, 120, 150]  # µs
SERIES = {"c": "the case (edge_phase 0)", "r20": "edge rounded to 2 mm",
          "nhm1": "nonlocal_hardening = -1", "nh0": "nonlocal_hardening = 0",
          "nhm3": "nonlocal_hardening = -3",
          "ef1m3": "m = -3, a fixed failure strain 1", "nsef1m3": "m = -3, failure strain 1, no spall",
          "av05ef1m3": "m = -3, failure strain 1, visc_a 0.5", "sk1m3": "m = -3, failed neighbours left out",
          "r20m3": "m = -3, edge rounded to 2 mm",
          "c4m3": "m = -3, contact four times stiffer",
          "ncm3": "m = -3, failed particles carry nothing", "dc0m3": "m = -3, no weakening before failure",
          "l4m3": "m = -3, ℓ = 4 mm"}


def folder(series, plate, k):
    if series == "c":
        return os.path.join(HERE, "..", f"c{plate}_0_k{k}")
    return os.path.join(HERE, f"{series}_{plate}_k{k}")


def line(points):
    n = len(points)
    mx = sum(x for x, _ in points) / n
    my = sum(y for _, y in points) / n
    b = sum((x - mx) * (y - my) for x, y in points) / sum((x - mx) ** 2 for x, _ in points)
    rms = math.sqrt(sum((y - my - b * (x - mx)) ** 2 for x, y in points) / n)
    return my - b * mx, b, rms


for plate in (12, 8):
    for series, what in SERIES.items():
        rows = [(k, speeds_at(folder(series, plate, k), TIMES)) for k in (6, 8, 10, 12, 16, 20)
                if os.path.exists(os.path.join(folder(series, plate, k), "histories.csv"))]
        if not rows:
            continue
        print(f"== {plate} mm, {what}: the projectile's speed (m/s) at t (µs)")
        print("Δx (mm)".ljust(8), " ".join(f"{t:>7}" for t in TIMES), "   step")
        for i, (k, v) in enumerate(rows):
            step = f"{v[-1] - rows[i - 1][1][-1]:+7.2f}" if i else ""
            print(f"{4 / k:<8.3f}", " ".join(f"{x:7.2f}" for x in v), step)
        if len(rows) >= 3:
            a, b, rms = line([(math.log(k / 4), v[-1]) for k, v in rows])
            print(f"  residual ≈ {a:.2f} + {b:.2f} ln(1 mm / Δx) m/s, rms {rms:.2f} m/s")
