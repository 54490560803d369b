"""The projectile's speed at each level through the run, its steps, order and Richardson value.

    python3 levels.py [8mm|12mm]

Reads `histories.csv` of the runs stored beside this script (`8mm_1333um/`, `8mm_1mm/`, ...;
how they were run: ../README.md, "full/") and prints, every 10 µs, the projectile's speed at each
level, the steps between levels, and the observed order p and Richardson value through the
three coarser levels and through the three finer ones (f = f0 + C Δx^p solved exactly through
three levels of any spacings; `none` where the two steps differ in sign or no p in 0.05–12 fits).
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
LEVELS = [("1333um", 4 / 3), ("1mm", 1.0), ("800um", 0.8), ("667um", 2 / 3)]
END = {"8mm": 150, "12mm": 100}


def speed(run, t_us):
    """The projectile's speed (m/s) at t_us, NaN past the run's last output."""
    d = np.genfromtxt(os.path.join(run, "histories.csv"), delimiter=",", names=True)
    t, v = d[d.dtype.names[0]], -d[d.dtype.names[1]]
    return np.interp(t_us * 1e-6, t, v) if t[-1] >= (t_us - 1) * 1e-6 else np.nan


def order(h, f):
    """p and f0 with f = f0 + C h^p through three levels, or (None, None)."""
    d1, d2 = f[1] - f[0], f[2] - f[1]
    if not d1 * d2 > 0:
        return None, None
    g = lambda p: (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - d1 / d2
    lo, hi = 0.05, 12.0
    if g(lo) * g(hi) > 0:
        return None, None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(lo) * g(mid) <= 0:
            hi = mid
        else:
            lo = mid
    p = 0.5 * (lo + hi)
    return p, f[2] - d2 / (h[2] ** p - h[1] ** p) * h[2] ** p


def main(plate):
    runs = [(os.path.join(HERE, f"{plate}_{tag}"), h) for tag, h in LEVELS]
    runs = [(r, h) for r, h in runs if os.path.isdir(r)]
    h = [x for _, x in runs]
    print(f"{plate}: levels " + " / ".join(f"{x:.3f}" for x in h) + " mm")
    fmt = lambda x: "none" if x is None else f"{x:.2f}"
    for t in range(10, END[plate] + 1, 10):
        f = [speed(r, t) for r, _ in runs]
        line = f"{t:4d} us  " + " / ".join(f"{x:.2f}" for x in f)
        line += "  steps " + ", ".join(f"{x:+.2f}" for x in np.diff(f))
        for k in range(len(f) - 2):
            p, r = order(h[k : k + 3], f[k : k + 3])
            line += f"  p{k + 1}={fmt(p)} R{k + 1}={fmt(r)}"
        print(line)


if __name__ == "__main__":
    for plate in sys.argv[1:] or ["8mm", "12mm"]:
        main(plate)
