"""The 12 mm plate at 1 mm with the projectile's radius a quarter of a spacing shorter and longer.

    python3 radius.py

Prints, every 10 µs, the projectile's speed of `12mm_1mm/` (R = 10 mm, R/Δx = 10) and of
`12mm_1mm_radius_9750um/` and `12mm_1mm_radius_10250um/` (R/Δx 9.75 and 10.25; how they were run:
../README.md, "full/"), the mean of the two, which is R = 10 mm up to the curvature in R, with its
projectile's edge elsewhere on the plate's lattice, and that mean less the level's speed: how much
where the edge falls moves the level, beside the steps between levels.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, HERE)
from levels import speed  # noqa: E402

RUNS = ["12mm_1mm", "12mm_1mm_radius_9750um", "12mm_1mm_radius_10250um"]


def main():
    print(f"{'t (us)':>7}" + "".join(f"{r:>26}" for r in RUNS) + f"{'mean of the two':>17}{'less R = 10':>13}")
    for t in range(10, 90, 10):
        v = [speed(os.path.join(HERE, r), t) for r in RUNS]
        mean = 0.5 * (v[1] + v[2])
        print(f"{t:7d}" + "".join(f"{x:26.2f}" for x in v) + f"{mean:17.2f}{mean - v[0]:+13.2f}")


if __name__ == "__main__":
    main()
