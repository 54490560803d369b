"""The 8 mm plate with both bodies in rings, beside the lattice-filled levels averaged over where
the projectile's edge falls.

    python3 rings.py

Reads `histories.csv` of the ring-filled runs stored here (`8mm_1333um/`, `8mm_1mm/`, ...; how
they were run: README.md) and prints every 10 µs the projectile's speed at each level, the steps
between levels, and the order and Richardson value through each three consecutive levels (as
../borvik_hardening_band/full/levels.py: `none` where the steps differ in sign). Beside them, the
lattice-filled (`fill = "cells"`) levels averaged over five projectile radii, the least-squares
line in R at R = 10 mm (../borvik_hardening_band/full/radius.py), with their order the same way.
Then, for each ring-filled run, when the plug first passes the projectile from 50 µs on, when it
last lags it, and the speed the projectile loses from 80 to 100 µs (../borvik_hardening_band/full/plug.py's reading: a
plug slower than the projectile pushing it is still held by the plate).
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
FULL = os.path.join(HERE, "..", "borvik_hardening_band", "full")
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, FULL)
from levels import history, order, speed  # noqa: E402
from radius import line, runs  # noqa: E402

LEVELS = [(4 / 3, "1333um"), (1.0, "1mm"), (0.8, "800um"), (2 / 3, "667um")]
TIMES = range(10, 110, 10)


def averaged(h, tag, t):
    """The lattice-filled level's speed at t averaged over the projectile's radii (the line at R = 10 mm)."""
    found = runs(h, f"8mm_{tag}")
    if len(found) < 3:
        return np.nan
    radii = np.array([r for r, _ in found])
    return line(radii, np.array([speed(f, t) for _, f in found]))[1]


def orders(hs, f):
    """The order and Richardson value through each three consecutive levels, as text."""
    out = []
    for k in range(len(f) - 2):
        p, f0 = order(hs[k : k + 3], f[k : k + 3]) if np.all(np.isfinite(f[k : k + 3])) else (None, None)
        out.append("none" if p is None else f"p={p:.2f} R={f0:.2f}")
    return "; ".join(out)


def main():
    stored = [(h, tag) for h, tag in LEVELS if os.path.isdir(os.path.join(HERE, f"8mm_{tag}"))]
    hs = [h for h, _ in stored]
    tags = " / ".join(tag for _, tag in stored)
    print(f"rings: {tags}; steps; order and Richardson value through each three; lattice averaged over R, the same")
    for t in TIMES:
        rings = np.array([speed(os.path.join(HERE, f"8mm_{tag}"), t) for _, tag in stored])
        cells = np.array([averaged(h, tag, t) for h, tag in stored])
        print(
            f"{t:4d} us  rings " + " / ".join(f"{x:.2f}" for x in rings)
            + "  steps " + ", ".join(f"{x:+.2f}" for x in np.diff(rings)) + f"  {orders(hs, rings)}"
            + "\n         cells " + " / ".join(f"{x:.2f}" for x in cells)
            + "  steps " + ", ".join(f"{x:+.2f}" for x in np.diff(cells)) + f"  {orders(hs, cells)}"
        )
    print(f"\n{'run':12s} {'plug passes first (us)':>23s} {'lags last (us)':>15s} {'lost 80-100 us':>15s} {'v(100 us)':>10s}")
    for _, tag in stored:
        t, v, plug = history(os.path.join(HERE, f"8mm_{tag}"))
        if t[-1] < 100:
            continue
        window = (t > 50) & (t <= 100)
        passes, lags = np.where(window & (plug > v))[0], np.where(window & (plug < v))[0]
        first = t[passes[0]] if len(passes) else np.nan
        last = t[lags[-1]] if len(lags) else np.nan
        lost = np.interp(80, t, v) - np.interp(100, t, v)
        print(f"8mm_{tag:8s} {first:23.1f} {last:15.1f} {lost:15.2f} {np.interp(100, t, v):10.2f}")


if __name__ == "__main__":
    main()
