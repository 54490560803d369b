"""The 12 mm plate's first 11.5 µs: the six levels beside the runs that perturb one level.

    python3 jump.py

Prints the projectile's speed at 4–11.5 µs of the full runs at each level (`../full/12mm_*/`),
of a sixth level (0.5 mm) run to 12 µs, and of the runs stored beside this script (how they were
run: ../README.md, "early_12mm/"), so that the step from 0.667 to 0.571 mm stands beside the
next one and beside what the projectile's fill, its start and the time step change at one
level. A run whose projectile started `gap` farther is read that much later (gap / 399.6 m/s),
when it has flown as far as the others.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
FULL = os.path.join(HERE, "..", "full")
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, FULL)
from levels import speed  # noqa: E402  (the same reader as levels.py)

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


def speeds(run, shift_m):
    """The projectile's speed (m/s) at TIMES_US, each read shift_m / V0 later."""
    return [speed(run, x + shift_m / V0 * 1e6) for x in TIMES_US]


def main():
    print(f"{'run':45s}" + "".join(f"{x:>9g} us" for x in TIMES_US))
    for name, run, shift in RUNS:
        print(f"{name:45s}" + "".join(f"{x:12.3f}" for x in speeds(run, shift)))


if __name__ == "__main__":
    main()
