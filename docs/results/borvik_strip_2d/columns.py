#!/usr/bin/python3
"""The plug's columns in a strip run's VTK output at one time (µs): the mean jump of the deviatoric
stress (s_xx, s_xy, s_yy, MPa) and of v_x (m/s) from each column to the next, over the intact plate
particles that started within 6 mm of the axis; and the axis column (the first, x0 = Δx/2): its
largest ε_p and its widest gap to the next column, in spacings. The spacing is read from the run
folder's name as failed.py reads it. Usage: python3 columns.py T RUN…"""
import os
import re
import sys

import numpy as np

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "borvik_rings"))
from band import outputs, read  # noqa: E402


def main(t_us, run):
    dx = float(re.search(r"(\d+)(um)?/?$", run.rstrip("/")).group(1)) / 1000.0
    dx = {0.667: 2 / 3, 0.333: 1 / 3}.get(dx, dx)
    frames = outputs(run)
    first = read(frames[0][1])
    o0 = np.argsort(first["id"])
    x0, plate = first["Points"][o0] * 1e3, first["body"][o0] == 1
    t, path = min(frames, key=lambda f: abs(f[0] * 1e6 - t_us))
    d = read(path)
    o = np.argsort(d["id"])
    s, v, x, eps, damage = d["s"][o] / 1e6, d["v"][o], d["Points"][o] * 1e3, d["eps_p"][o], d["D"][o]
    # Each particle by its lattice cell (column, row), so that a column's neighbour is one index on.
    cell = {tuple(np.round(x0[k, :2] / dx - 0.5).astype(int)): k for k in np.where(plate)[0]}
    jumps_s, jumps_v, gaps = [], [], []
    for (col, row), k in cell.items():
        n = cell.get((col + 1, row))
        if n is None:
            continue
        if 0 <= x0[k, 0] < 6 and x0[n, 0] < 6 and damage[k] < 1 and damage[n] < 1:
            jumps_s.append(np.abs(s[n] - s[k]))
            jumps_v.append(abs(v[n, 0] - v[k, 0]))
        if col == 0:
            gaps.append((x[n, 0] - x[k, 0]) / dx)
    axis = plate & (np.abs(x0[:, 0] - dx / 2) < 1e-3)
    print(f"{run} {t * 1e6:4.0f} us  column jumps: s {np.round(np.mean(jumps_s, axis=0)).astype(int)} MPa, "
          f"v_x {np.mean(jumps_v):.2f} m/s; axis column: largest eps_p {eps[axis].max():.2f}, "
          f"widest gap {max(gaps):.2f} dx")


if __name__ == "__main__":
    for run in sys.argv[2:]:
        main(float(sys.argv[1]), run)
