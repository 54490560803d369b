"""The 12 mm plate at 1.333, 1 and 0.8 mm with the projectile's radius up to a quarter spacing either way.

    python3 radius.py

For each of those levels, prints every 10 µs the projectile's speed of the runs at R = 10 mm
(`12mm_1333um/`, `12mm_1mm/`, `12mm_800um/`) and of those of `12mm_*_radius_*um/` that are stored
(R moved by an eighth and a quarter of the level's spacing either way; at 0.8 mm by a quarter
only; how they were run: ../README.md, "full/"), then the straight line in R through them all
(least squares), its slope and each run's miss of it.

Over a few per cent of R the projectile's own change is close to linear; what misses the line is
where its edge falls on the plate's lattice. The line's value at R = 10 mm is the level's speed
averaged over where the edge falls (the level's phase average). The next table sets those
averages beside the R = 10 mm runs alone, with the order and Richardson value through the three
levels; the last adds the finer levels' R = 10 mm runs (`12mm_667um/`, `12mm_571um/`) and fits
f0 + C Δx^p through the four and the five levels by least squares (`levels.py`).
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, HERE)
from levels import least_squares, order, speed  # noqa: E402

LEVELS = [(4 / 3, "12mm_1333um"), (1.0, "12mm_1mm"), (0.8, "12mm_800um")]
FINER = [(2 / 3, "12mm_667um"), (4 / 7, "12mm_571um")]  # at R = 10 mm only
SHIFTS = [-0.25, -0.125, 0.0, 0.125, 0.25]  # of the level's spacing
TIMES = range(10, 90, 10)


def runs(h, level):
    """(R, folder) of a level's stored runs: R = 10 mm is the level's own run."""
    name = lambda r: level if r == 10.0 else f"{level}_radius_{round(r * 1000)}um"
    found = [(r, os.path.join(HERE, name(r))) for r in (10.0 + s * h for s in SHIFTS)]
    return [(r, f) for r, f in found if os.path.isdir(f)]


def line(radii, v):
    """Slope, value at R = 10 mm and misses of the least-squares line in R."""
    slope, icept = np.polyfit(radii, v, 1)
    return slope, icept + 10.0 * slope, v - (icept + slope * radii)


def main():
    averaged = {}
    for h, level in LEVELS:
        found = runs(h, level)
        radii = np.array([r for r, _ in found])
        print(f"\n{level}: R = " + ", ".join(f"{r:.3f}" for r in radii) + " mm")
        print(f"{'t (us)':>7}" + "".join(f"{'R = %.3f' % r:>11}" for r in radii) + "   line: slope (m/s per mm), at R = 10, misses")
        for t in TIMES:
            v = np.array([speed(f, t) for _, f in found])
            slope, at10, miss = line(radii, v)
            averaged[(h, t)] = (v[list(radii).index(10.0)], at10, np.sqrt(np.mean(miss**2)))
            print(f"{t:7d}" + "".join(f"{x:11.2f}" for x in v) + f"   {slope:6.2f}, {at10:7.2f}," + "".join(f"{m:+7.2f}" for m in miss))
    fmt = lambda x: "none" if x is None else f"{x:.2f}"
    hs = [h for h, _ in LEVELS]
    print("\nThe levels at R = 10 mm alone and averaged over the edge's place (the line at R = 10 mm, its rms miss)")
    for t in TIMES:
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
    print("\nThe averaged levels with the finer ones at R = 10 mm alone: the least-squares f0 + C dx^p through four and five")
    for t in TIMES:
        f = [averaged[(h, t)][1] for h in hs] + [speed(os.path.join(HERE, level), t) for _, level in FINER]
        h = hs + [x for x, _ in FINER]
        fits = [(n, *least_squares(h[:n], f[:n])) for n in (4, 5)]
        print(f"{t:4d} us  " + " / ".join(f"{x:.2f}" for x in f) + "".join(
            f"   {n} levels: p={p:.2f} f0={f0:.2f} rms={rms:.2f}" for n, p, f0, rms in fits))


if __name__ == "__main__":
    main()
