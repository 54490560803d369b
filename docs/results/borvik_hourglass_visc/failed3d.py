#!/usr/bin/python3
"""The 3D plate at each VTK output of a run: its failed particles (D = 1) by the ring of the
quarter plate they started in (their distance r0 from the axis: within 6 mm, each millimetre from
6 to 11 mm, beyond; the projectile's radius is 10 mm), as volumes (count × Δx³, mm³: the failed
particles lie in the fine zone), their total, the plug's speed (the mean downward speed of the
plate's particles that started within 6 mm of the axis) and the largest ε_p. The spacing is read from the run folder's name (…_<Δx in µm>um or
…_<Δx in mm>mm). The runs' VTK output is not kept here; rerun a level to read it.
Usage: python3 failed3d.py RUN…"""
import os
import re
import sys

import numpy as np

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "borvik_rings"))
from band import outputs, read  # noqa: E402


def spacing_mm(run):
    m = re.search(r"_(\d+)(um|mm)/?$", run.rstrip("/"))
    return float(m.group(1)) / (1000.0 if m.group(2) == "um" else 1.0)


def main(run):
    dx = spacing_mm(run)
    frames = outputs(run)
    first = read(frames[0][1])
    o0 = np.argsort(first["id"])
    plate, x0 = first["body"][o0] == 1, first["Points"][o0] * 1e3
    r0 = np.hypot(x0[:, 0], x0[:, 1])
    edges = [0, 6, 7, 8, 9, 10, 11, np.inf]
    rings = [(r0 >= a) & (r0 < b) for a, b in zip(edges, edges[1:])]
    for t, path in frames[1:]:
        d = read(path)
        o = np.argsort(d["id"])
        failed, eps, vz = plate & (d["D"][o] >= 0.999), d["eps_p"][o], d["v"][o][:, 2]
        volumes = [(failed & ring).sum() * dx**3 for ring in rings]
        plug = -vz[plate & (r0 < 6)].mean()
        print(f"{run} {t * 1e6:5.0f} us  failed mm3 by r0 (<6, 6-7, …, 10-11, >11 mm): "
              f"{' '.join(f'{v:5.1f}' for v in volumes)}, {sum(volumes):5.1f} in all  plug {plug:6.1f} m/s  "
              f"largest eps_p {eps[plate].max():.2f}")


if __name__ == "__main__":
    for run in sys.argv[1:]:
        main(run)
