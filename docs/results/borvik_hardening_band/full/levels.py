"""The projectile's speed at each level through the run, its steps, order and Richardson value.

    python3 levels.py [8mm|12mm]

Reads `histories.csv` of the runs stored beside this script (`8mm_1333um/`, `8mm_1mm/`, ...;
how they were run: ../README.md, "full/") and prints, every 10 µs, the projectile's speed at each
level, the steps between levels, the observed order p and Richardson value through each three
consecutive levels (f = f0 + C Δx^p solved exactly through three levels of any spacings; `none`
where the two steps differ in sign or no p in 0.05–12 fits), and, where four levels or more reach
the time, the p, f0 and rms miss of the f0 + C Δx^p that fits them all best in the least-squares
sense (`all:`; p searched over 0.25–6, `p=6 (bound)` where the best lies at the bound: the levels
then follow no power of Δx, f0 is the finest levels' mean).
"""
import functools
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
LEVELS = [("1333um", 4 / 3), ("1mm", 1.0), ("800um", 0.8), ("667um", 2 / 3), ("571um", 4 / 7)]
END = {"8mm": 150, "12mm": 100}


@functools.lru_cache(maxsize=None)
def history(run):
    """Time (µs), the projectile's speed and the plug's (m/s) from a run's histories.csv, read once."""
    d = np.genfromtxt(os.path.join(run, "histories.csv"), delimiter=",", names=True)
    t, projectile, plug = (d[name] for name in d.dtype.names[:3])
    return t * 1e6, -projectile, plug


def speed(run, t_us):
    """The projectile's speed (m/s) at t_us, NaN past the run's last output."""
    t, v, _ = history(run)
    return np.interp(t_us, t, v) if t[-1] >= t_us - 1 else np.nan


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


def least_squares(h, f):
    """p, f0 and the rms miss of the f = f0 + C h^p that fits all levels best (p in 0.25–6)."""
    h, f = np.asarray(h), np.asarray(f)
    best = None
    for p in np.arange(0.25, 6.0001, 0.01):
        a = np.c_[np.ones_like(h), h**p]
        c = np.linalg.lstsq(a, f, rcond=None)[0]
        rms = np.sqrt(np.mean((f - a @ c) ** 2))
        if best is None or rms < best[2]:
            best = (p, c[0], rms)
    return best


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
        if len(f) > 3 and not np.isnan(f).any():
            p, f0, rms = least_squares(h, f)
            shown = f"{p:.2f}" if p < 5.995 else "6 (bound)"
            line += f"  all: p={shown} f0={f0:.2f} rms={rms:.2f}"
        print(line)


if __name__ == "__main__":
    for plate in sys.argv[1:] or ["8mm", "12mm"]:
        main(plate)
