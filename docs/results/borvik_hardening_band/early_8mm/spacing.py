"""The 8 mm plate without hardening in its first 10 µs: the speed against the spacing, and what
moves one level.

    python3 spacing.py

Prints the projectile's speed at 6–10 µs of the runs stored beside this script (how they were
run: ../README.md, "The early phase at more spacings"): the five levels and three more spacings
(0.889, 0.533 and 0.5 mm), then, at 0.667 mm, the projectile's radius moved by a quarter and a
half of a spacing (where its edge falls on the plate's lattice) and, at 0.8 / 0.667 / 0.571 mm,
the contact four times as stiff.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, os.path.join(HERE, "..", "full"))
from levels import speed  # noqa: E402  (the same reader as levels.py)

TIMES_US = (6, 7, 8, 9, 10)
GROUPS = [
    (
        "spacing (the projectile's radius R = 10 mm)",
        [
            ("1.333 mm", "no_hardening_1333um"),
            ("1 mm", "no_hardening_1mm"),
            ("0.889 mm, coarse 2.667 mm", "no_hardening_889um_coarse_2667um_to_10us"),
            ("0.8 mm", "no_hardening_800um"),
            ("0.667 mm", "no_hardening_667um"),
            ("0.571 mm", "no_hardening_571um_to_12us"),
            ("0.533 mm, coarse 2.667 mm", "no_hardening_533um_coarse_2667um_to_10us"),
            ("0.5 mm", "no_hardening_500um_to_10us"),
        ],
    ),
    (
        "0.667 mm: the projectile's radius (R/Δx)",
        [
            ("R = 9.667 mm (14.5)", "no_hardening_667um_radius_9667um_to_10us"),
            ("R = 9.833 mm (14.75)", "no_hardening_667um_radius_9833um_to_10us"),
            ("R = 10 mm (15)", "no_hardening_667um"),
            ("R = 10.167 mm (15.25)", "no_hardening_667um_radius_10167um_to_10us"),
            ("R = 10.167 mm, on the plate's lattice", "no_hardening_667um_radius_10167um_on_the_plate_lattice_to_10us"),
            ("R = 10.333 mm (15.5)", "no_hardening_667um_radius_10333um_to_10us"),
        ],
    ),
    (
        "contact four times as stiff (contact_stiffness = 4)",
        [
            ("0.8 mm", "no_hardening_contact_stiffness_4_800um_to_10us"),
            ("0.667 mm", "no_hardening_contact_stiffness_4_667um_to_10us"),
            ("0.571 mm", "no_hardening_contact_stiffness_4_571um_to_10us"),
        ],
    ),
]


def main():
    for title, runs in GROUPS:
        print(f"{title:45s}" + "".join(f"{x:>7g} us" for x in TIMES_US))
        for name, folder in runs:
            print(f"  {name:43s}" + "".join(f"{speed(os.path.join(HERE, folder), x):10.3f}" for x in TIMES_US))


if __name__ == "__main__":
    main()
