"""The 12 mm plate at 1 mm with the projectile's radius up to a quarter of a spacing either way.

    python3 radius.py

Prints, every 10 µs, the projectile's speed of `12mm_1mm/` (R = 10 mm, R/Δx = 10) and of
`12mm_1mm_radius_*um/` (R = 9.75, 9.875, 10.125, 10.25 mm; how they were run: ../README.md,
"full/"), then the straight line in R through them all (least squares) and each run's miss of it.
Over ±2.5 % of R the projectile's own change is close to linear; what misses the line is where its
edge falls on the plate's lattice: how much that moves a level, beside the steps between levels.
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, HERE)
from levels import speed  # noqa: E402

RUNS = [
    (9.75, "12mm_1mm_radius_9750um"),
    (9.875, "12mm_1mm_radius_9875um"),
    (10.0, "12mm_1mm"),
    (10.125, "12mm_1mm_radius_10125um"),
    (10.25, "12mm_1mm_radius_10250um"),
]


def main():
    runs = [(r, os.path.join(HERE, f)) for r, f in RUNS]
    radii = np.array([r for r, _ in runs])
    print(f"{'t (us)':>7}" + "".join(f"{'R = %g' % r:>11}" for r in radii) + "   line: slope (m/s per mm), misses")
    for t in range(10, 90, 10):
        v = np.array([speed(f, t) for _, f in runs])
        slope, icept = np.polyfit(radii, v, 1)
        miss = v - (icept + slope * radii)
        print(f"{t:7d}" + "".join(f"{x:11.2f}" for x in v) + f"   {slope:6.2f}," + "".join(f"{m:+7.2f}" for m in miss))


if __name__ == "__main__":
    main()
