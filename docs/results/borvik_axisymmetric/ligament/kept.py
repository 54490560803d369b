#!/usr/bin/env python3
"""How much of its strength the plug's rim keeps, from a dense run (stop 123).

    python3 kept.py RUN [RUN …]

RUN as for ligament.py (dense_case.sh's case). For each output from 55 µs: the projectile's speed,
and over the plate's particles that started 8–11 mm from the axis, in eight slices of the 8 mm
plate's depth (1 mm each, y0 from the top face), the largest damage D in each slice; last, the
rim's weakest-section kept share, the mean over the slices of 1 − max D: the share of its stress
that the weakest particle of each slice still carries (damage/failed_stress.sph: (1 − D) with
damage_coupling 1), 0 once a failed particle lies in every slice.
"""
import sys

from ligament import EVERY_US, outputs, projectile_speed, shear_band

SLICES = 8


def kept(run):
    files, start = outputs(run)
    print(f"== {run}: t µs, projectile m/s | largest D in each 1 mm slice from the top face | kept share")
    for n, path in enumerate(files):
        t = n * EVERY_US
        if t < 55:
            continue
        a = shear_band.read_vtu(path)
        most = [0.0] * SLICES
        for i, d in zip(a["id"], a["D"]):
            r0, y0, body = start[int(i)]
            if body == 1 and 8 <= r0 <= 11 and -SLICES < y0 <= 0:
                k = min(int(-y0), SLICES - 1)
                most[k] = max(most[k], d)
        share = sum(1 - d for d in most) / SLICES
        print(f"{t:6.1f} {projectile_speed(a, start):6.1f} | {' '.join(f'{d:4.2f}' for d in most)} | {share:.3f}")


if __name__ == "__main__":
    for run in sys.argv[1:]:
        kept(run)
