#!/usr/bin/env python3
"""The Børvik plates about their axis over the lattice, pair forces that conserve momentum (stops
119–120): each level's residual speed averaged over five places of the projectile's edge
(edge_phase -0.4 … +0.4; phase 0 is ../c{8,12}_0_k*), with its standard error, the arguments of
`pairsum uncertainty`, and a weighted least-squares fit f = a + b ln(1 mm / Δx) with its χ².
Run from anywhere: python3 docs/results/borvik_axisymmetric/lattice_conserving/lattice.py
(edge_hardening/lattice.py reads another series through `report`; when.py and
edge_hardening/series.py read the projectile's speed at given times through `speeds_at`, and when.py
and edge_hardening/lattice.py its mean over the edge places through `mean_speeds_at`)."""
import bisect
import csv
import math
import os
import statistics as st

HERE = os.path.dirname(os.path.abspath(__file__))
PHASES = ["m04", "m02", "0", "p02", "p04"]


def folder(plate, phase, k):
    """This study's run of a plate at an edge place and coarse factor."""
    return os.path.join(HERE, "..", f"c{plate}_0_k{k}") if phase == "0" else os.path.join(HERE, f"c{plate}_{phase}_k{k}")


def speeds_at(path, times_us):
    """The projectile's speed (m/s, towards the plate) at each time (µs) from a run's histories.csv:
    the first row at or after it, or the last row. Rows where the speed was not sampled (a probe
    sampled at other steps, as the case's work probes since stop 125) are skipped."""
    rows = [r for r in list(csv.reader(open(os.path.join(path, "histories.csv"))))[1:] if r[1] != ""]
    t = [float(r[0]) * 1e6 for r in rows]
    v = [-float(r[1]) for r in rows]
    return [v[min(bisect.bisect_left(t, x), len(t) - 1)] for x in times_us]


def mean_speeds_at(plate, k, times_us, folder=folder, phases=PHASES):
    """The projectile's speed at each time, the mean over the edge places of a plate's level."""
    return [st.mean(c) for c in zip(*(speeds_at(folder(plate, p, k), times_us) for p in phases))]


def residual(plate, phase, k, folder=folder):
    try:
        for line in open(os.path.join(folder(plate, phase, k), "report.md")):
            if line.startswith("| projectile_residual_velocity"):
                return float(line.split("|")[4])
    except FileNotFoundError:
        return None


def chi2_sf(x, dof):
    """P(χ² > x) for an odd or even number of degrees of freedom."""
    if dof % 2 == 0:
        return math.exp(-x / 2) * sum((x / 2) ** i / math.factorial(i) for i in range(dof // 2))
    term, total = math.sqrt(2 * x / math.pi) * math.exp(-x / 2), math.erfc(math.sqrt(x / 2))
    for i in range(1, (dof + 1) // 2):
        total += term
        term *= x / (2 * i + 1)
    return total


def log_fit(levels):
    w = [1 / s**2 for _, _, s in levels]
    x = [math.log(1 / h) for h, _, _ in levels]
    y = [v for _, v, _ in levels]
    sw, sx, sy = sum(w), sum(a * b for a, b in zip(w, x)), sum(a * b for a, b in zip(w, y))
    sxx, sxy = sum(a * b * b for a, b in zip(w, x)), sum(a * b * c for a, b, c in zip(w, x, y))
    b = (sw * sxy - sx * sy) / (sw * sxx - sx * sx)
    a = (sy - b * sx) / sw
    chi = sum(wi * (yi - a - b * xi) ** 2 for wi, xi, yi in zip(w, x, y))
    return a, b, chi, len(levels) - 2


def report(folder=folder, plates=(12, 8), phases=PHASES):
    """Print each plate's lattice means over the edge places `phases`, the `pairsum uncertainty`
    arguments and the log fit (over the levels run at every place)."""
    for plate in plates:
        print(f"== {plate} mm plate")
        levels = []
        for k in (6, 8, 10, 12, 16, 20):
            values = [residual(plate, p, k, folder) for p in phases]
            got = [v for v in values if v is not None]
            if not got:
                continue
            mean = st.mean(got)
            se = st.stdev(got) / math.sqrt(len(got)) if len(got) > 1 else float("nan")
            shown = " / ".join("—" if v is None else f"{v:.2f}" for v in values)
            print(f"Δx {4 / k:.3f} mm: {shown}   mean {mean:.2f} ± {se:.2f} (n = {len(got)})")
            if len(got) == len(phases):
                levels.append((4 / k, mean, se))
        print("pairsum uncertainty " + " ".join(f"{h:.6f}={v:.3f}±{s:.3f}" for h, v, s in levels))
        if len(levels) >= 3:
            a, b, chi, dof = log_fit(levels)
            print(f"f = {a:.2f} + {b:.2f} ln(1 mm / Δx) m/s: χ² {chi:.2f} on {dof}, probability {chi2_sf(chi, dof):.2f}")
            for h, v, s in levels:
                print(f"  Δx {h:.3f}: {v:.2f}, fit {a + b * math.log(1 / h):.2f}, ({(v - a - b * math.log(1 / h)) / s:+.2f} σ)")


if __name__ == "__main__":
    report()
