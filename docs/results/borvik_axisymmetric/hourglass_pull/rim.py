#!/usr/bin/env python3
"""How the 8 mm plug comes off (stop 124): from a run of ../reach.py's kind (the case written every
5 µs with "kernel_metric"; `sed` line under "Commands" in ../README.md), at one output time, for
each 1 mm slice of the plate's depth (y0 from the top face): over the particles that started 8–12
mm from the axis, the largest D, the largest ε_p and where it started, how many have failed; the
mean axial speed of the plug (r0 < 7 mm) and of the plate beyond it (12 < r0 < 14 mm), and how far
the plug has moved along the axis past that plate since impact (mm).

    python3 rim.py RUN T_US
"""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from reach import by_id, outputs, read_vtu  # noqa: E402


def mean(values):
    return sum(values) / len(values) if values else math.nan


def rim(run, t_us):
    series = outputs(run)
    start = by_id(read_vtu(series[0][1]))["Points"]
    t, path = min(series, key=lambda s: abs(s[0] * 1e6 - t_us))
    d = by_id(read_vtu(path))
    x, D, eps, v, body = d["Points"], d["D"], d["eps_p"], d["v"], d["body"]
    print(f"{run} at {t * 1e6:.1f} µs: slice | largest D | largest ε_p (r0 mm) | failed | plug, plate m/s | plug's lead mm")
    for s in range(8):
        ks = [k for k in range(len(body)) if body[k] == 1 and -s - 1 < start[k][1] * 1e3 <= -s]
        ring = [k for k in ks if 8 <= start[k][0] * 1e3 <= 12]
        plug = [k for k in ks if start[k][0] * 1e3 < 7]
        plate = [k for k in ks if 12 < start[k][0] * 1e3 < 14]
        top = max(ring, key=lambda k: eps[k])
        lead = mean([x[k][1] - start[k][1] for k in plate]) - mean([x[k][1] - start[k][1] for k in plug])
        print(f"{s} | {max(D[k] for k in ring):.2f} | {eps[top]:.2f} ({start[top][0] * 1e3:.2f}) | "
              f"{sum(1 for k in ring if D[k] >= 1)} | {mean([-v[k][1] for k in plug]):.1f}, "
              f"{mean([-v[k][1] for k in plate]):.1f} | {lead * 1e3:.2f}")


if __name__ == "__main__":
    rim(sys.argv[1], float(sys.argv[2]))
