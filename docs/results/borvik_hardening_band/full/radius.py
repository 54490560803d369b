"""A plate at 1.333, 1 and 0.8 mm with the projectile's radius up to a quarter spacing either way.

    python3 radius.py [12mm|8mm]     (both when none is given)

For each of those levels, prints every 10 µs the projectile's speed of the runs at R = 10 mm
(`12mm_1333um/`, `12mm_1mm/`, `12mm_800um/`, or `8mm_…`) and of those of `12mm_*_radius_*um/` (or
`8mm_…`) that are stored (R moved by an eighth and a quarter of the level's spacing either way; on
12 mm at 0.8 mm by a quarter only; how they were run: ../README.md, "full/"), then the straight
line in R through them all (least squares), its slope and each run's miss of it.

Over a few per cent of R the projectile's own change is close to linear; what misses the line is
where its edge falls on the plate's lattice. The line's value at R = 10 mm is the level's speed
averaged over where the edge falls (the level's phase average). The next table sets those
averages beside the R = 10 mm runs alone, with the order and Richardson value through the three
levels; the next gives each averaged level's standard error (from the line's misses) and the
order and Richardson value of 10,000 draws of the three levels within those errors; the last adds
the finer levels' R = 10 mm runs (`12mm_667um/`, `12mm_571um/`; on 8 mm `8mm_667um/`) and fits
f0 + C Δx^p through four levels and, on 12 mm, five by least squares (`levels.py`).
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, HERE)
from levels import least_squares, order, speed  # noqa: E402

LEVELS = [(4 / 3, "1333um"), (1.0, "1mm"), (0.8, "800um")]
FINER = [(2 / 3, "667um"), (4 / 7, "571um")]  # at R = 10 mm only, where stored
SHIFTS = [-0.25, -0.125, 0.0, 0.125, 0.25]  # of the level's spacing
TIMES = {"12mm": range(10, 90, 10), "8mm": range(10, 110, 10)}  # the 8 mm radius runs end at 102 µs


def runs(h, level):
    """(R, folder) of a level's stored runs: R = 10 mm is the level's own run."""
    name = lambda r: level if r == 10.0 else f"{level}_radius_{round(r * 1000)}um"
    found = [(r, os.path.join(HERE, name(r))) for r in (10.0 + s * h for s in SHIFTS)]
    return [(r, f) for r, f in found if os.path.isdir(f)]


def line(radii, v):
    """Slope, value at R = 10 mm and misses of the least-squares line in R (one run: itself)."""
    if len(radii) < 2:
        return np.nan, v[0], v - v[0]
    slope, icept = np.polyfit(radii, v, 1)
    return slope, icept + 10.0 * slope, v - (icept + slope * radii)


def standard_error(radii, miss):
    """The standard error of the line's value at R = 10 mm, from its misses (NaN under three runs)."""
    n = len(radii)
    if n < 3:
        return np.nan
    sigma = np.sqrt(np.sum(miss**2) / (n - 2))
    return sigma * np.sqrt(1 / n + (10.0 - radii.mean()) ** 2 / np.sum((radii - radii.mean()) ** 2))


def order_spread(hs, f, se, draws=10000):
    """Share of draws within each level's standard error that have an order, and the 16th–84th
    percentiles of p and of the Richardson value among them (a fixed seed: the same each run)."""
    rng = np.random.default_rng(85)
    found = [order(hs, f + se * rng.standard_normal(len(f))) for _ in range(draws)]
    found = np.array([x for x in found if x[0] is not None])
    if len(found) == 0:
        return 0.0, None, None
    return len(found) / draws, np.percentile(found[:, 0], [16, 84]), np.percentile(found[:, 1], [16, 84])


def main(plate):
    print(f"\n== {plate}")
    levels = [(h, f"{plate}_{tag}") for h, tag in LEVELS]
    finer = [(h, f"{plate}_{tag}") for h, tag in FINER if os.path.isdir(os.path.join(HERE, f"{plate}_{tag}"))]
    averaged = {}
    for h, level in levels:
        found = runs(h, level)
        radii = np.array([r for r, _ in found])
        print(f"\n{level}: R = " + ", ".join(f"{r:.3f}" for r in radii) + " mm")
        print(f"{'t (us)':>7}" + "".join(f"{'R = %.3f' % r:>11}" for r in radii) + "   line: slope (m/s per mm), at R = 10, misses")
        for t in TIMES[plate]:
            v = np.array([speed(f, t) for _, f in found])
            slope, at10, miss = line(radii, v)
            averaged[(h, t)] = (v[list(radii).index(10.0)], at10, np.sqrt(np.mean(miss**2)), standard_error(radii, miss))
            print(f"{t:7d}" + "".join(f"{x:11.2f}" for x in v) + f"   {slope:6.2f}, {at10:7.2f}," + "".join(f"{m:+7.2f}" for m in miss))
    fmt = lambda x: "none" if x is None else f"{x:.2f}"
    hs = [h for h, _ in levels]
    print("\nThe levels at R = 10 mm alone and averaged over the edge's place (the line at R = 10 mm, its rms miss)")
    for t in TIMES[plate]:
        alone = [averaged[(h, t)][0] for h in hs]
        phase = [averaged[(h, t)][1] for h in hs]
        rms = [averaged[(h, t)][2] for h in hs]
        p1, r1 = order(hs, alone)
        p2, r2 = order(hs, phase)
        print(
            f"{t:4d} us  alone " + " / ".join(f"{x:.2f}" for x in alone) + f"  p={fmt(p1)} R={fmt(r1)}"
            "   averaged " + " / ".join(f"{x:.2f} ({e:.2f})" for x, e in zip(phase, rms))
            + "  steps " + ", ".join(f"{x:+.2f}" for x in np.diff(phase)) + f"  p={fmt(p2)} R={fmt(r2)}"
        )
    print("\nThe averaged levels with their standard errors, and the order and Richardson value of draws within them")
    print("(the share of draws with an order; p and Richardson value: 16th–84th percentiles of those)")
    for t in TIMES[plate]:
        phase = np.array([averaged[(h, t)][1] for h in hs])
        se = np.array([averaged[(h, t)][3] for h in hs])
        share, p, r = order_spread(hs, phase, se)
        spread = "" if p is None else f"  p {p[0]:.2f}–{p[1]:.2f}  R {r[0]:.2f}–{r[1]:.2f}"
        print(f"{t:4d} us  " + " / ".join(f"{x:.2f} ± {e:.2f}" for x, e in zip(phase, se)) + f"  with an order {share:.0%}" + spread)
    counts = range(4, 4 + len(finer))
    print("\nThe averaged levels with the finer ones at R = 10 mm alone: the least-squares f0 + C dx^p through " + " and ".join(map(str, counts)))
    for t in TIMES[plate]:
        f = [averaged[(h, t)][1] for h in hs] + [speed(os.path.join(HERE, level), t) for _, level in finer]
        h = hs + [x for x, _ in finer]
        fits = [(n, *least_squares(h[:n], f[:n])) for n in counts]
        print(f"{t:4d} us  " + " / ".join(f"{x:.2f}" for x in f) + "".join(
            f"   {n} levels: p={p:.2f} f0={f0:.2f} rms={rms:.2f}" for n, p, f0, rms in fits))


if __name__ == "__main__":
    for plate in sys.argv[1:] or ["12mm", "8mm"]:
        main(plate)
