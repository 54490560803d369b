"""The 12 mm plate's first 11.5 µs: the six levels beside the runs that perturb one level.

    python3 jump.py

Prints the projectile's speed at 4–11.5 µs of the full runs at each level (`../full/12mm_*/`),
of a sixth level (0.5 mm) run to 12 µs, and of the runs stored beside this script (how they were
run: ../README.md, "early_12mm/"), so that the step from 0.667 to 0.571 mm stands beside the
next one and beside what the projectile's fill, its start and the time step change at one
level. A run whose projectile started `gap` farther is read that much later (gap / 399.6 m/s),
when it has flown as far as the others.

Then each level averaged over where the projectile's edge falls on the plate's lattice: the
straight line in R through its runs with the radius moved (the coarser three's are
`../full/12mm_*_radius_*um/`, to 82 µs; the finer ones', a quarter spacing either way, are stored
here, to 12 µs) at R = 10 mm, and the R = 10 mm run's miss of that line (`../full/radius.py`).
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
FULL = os.path.join(HERE, "..", "full")
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, FULL)
from levels import speed  # noqa: E402  (the same reader as levels.py)
from radius import LEVELS, line, runs  # noqa: E402  (the line in R that averages a level)

V0 = 399.6
RUNS = [
    ("1.333 mm", os.path.join(FULL, "12mm_1333um"), 0.0),
    ("1 mm", os.path.join(FULL, "12mm_1mm"), 0.0),
    ("0.8 mm", os.path.join(FULL, "12mm_800um"), 0.0),
    ("0.667 mm", os.path.join(FULL, "12mm_667um"), 0.0),
    ("0.571 mm", os.path.join(FULL, "12mm_571um"), 0.0),
    ("0.5 mm (to 12 us)", os.path.join(HERE, "nonlocal_hardening_500um_to_12us"), 0.0),
    ("0.667 mm, gap 2 mm", os.path.join(HERE, "nonlocal_hardening_667um_gap_2mm"), 0.5e-3),
    ("0.667 mm, cfl 0.24", os.path.join(HERE, "nonlocal_hardening_667um_cfl_0.24"), 0.0),
    ("0.571 mm, gap 2 mm", os.path.join(HERE, "nonlocal_hardening_571um_gap_2mm"), 0.5e-3),
    ("0.571 mm, projectile on the plate's lattice", os.path.join(HERE, "nonlocal_hardening_571um_projectile_on_the_plate_lattice"), 0.0),
]
TIMES_US = (4, 6, 8, 10, 11.5)
# The finer levels' runs with the projectile's radius a quarter spacing either way (here), beside
# their R = 10 mm run; the coarser three are radius.py's.
FINER = [
    (2 / 3, os.path.join(FULL, "12mm_667um"), "nonlocal_hardening_667um_radius_{}um"),
    (4 / 7, os.path.join(FULL, "12mm_571um"), "nonlocal_hardening_571um_radius_{}um"),
    (0.5, os.path.join(HERE, "nonlocal_hardening_500um_to_12us"), "nonlocal_hardening_500um_radius_{}um"),
]


def radius_runs():
    """(Δx, [(R, run), ...]) of every level with runs at more than one radius."""
    levels = [(h, runs(h, f"12mm_{tag}")) for h, tag in LEVELS]
    for h, at10, name in FINER:
        found = [(r, os.path.join(HERE, name.format(round(r * 1000)))) for r in (10 - h / 4, 10 + h / 4)]
        found = [(r, f) for r, f in found if os.path.isdir(f)]
        levels.append((h, sorted(found + [(10.0, at10)])))
    return [(h, found) for h, found in levels if len(found) > 1]


def speeds(run, shift_m):
    """The projectile's speed (m/s) at TIMES_US, each read shift_m / V0 later."""
    return [speed(run, x + shift_m / V0 * 1e6) for x in TIMES_US]


def main():
    print(f"{'run':45s}" + "".join(f"{x:>9g} us" for x in TIMES_US))
    for name, run, shift in RUNS:
        print(f"{name:45s}" + "".join(f"{x:12.3f}" for x in speeds(run, shift)))
    print("\nEach level averaged over where the projectile's edge falls: its line in R at R = 10 mm, and")
    print("the R = 10 mm run's miss of that line")
    for h, found in radius_runs():
        radii = np.array([r for r, _ in found])
        v = np.array([speeds(f, 0.0) for _, f in found])
        fits = [line(radii, v[:, k]) for k in range(len(TIMES_US))]
        at10 = list(radii).index(10.0)
        print(f"{'%.3f mm, %d radii' % (h, len(radii)):45s}" + "".join(f"{f[1]:12.3f}" for f in fits))
        print(f"{'  R = 10 mm: miss':45s}" + "".join(f"{f[2][at10]:+12.3f}" for f in fits))


if __name__ == "__main__":
    main()
