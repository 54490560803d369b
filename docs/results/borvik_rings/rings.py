"""The 8 mm plate with both bodies in rings, beside the lattice-filled levels averaged over where
the projectile's edge falls.

    python3 rings.py [8mm|12mm]     (both when none is given)

Reads `histories.csv` of the ring-filled runs stored here (`8mm_1333um/`, `8mm_1mm/`, ...,
`12mm_…`; how they were run: README.md) and prints every 10 µs the projectile's speed at each level, the steps
between levels, and the order and Richardson value through each three consecutive levels (as
../borvik_hardening_band/full/levels.py: `none` where the steps differ in sign). Beside them, the
lattice-filled (`fill = "cells"`) levels averaged over five projectile radii, the least-squares
line in R at R = 10 mm (../borvik_hardening_band/full/radius.py), with their order the same way.
Then the ring-filled runs with the projectile's radius moved (`8mm_1mm_radius_*um/`, both bodies'
rings fitted to it), with the least-squares line in R through them and each run's miss of it,
beside the lattice's runs at the same radii. Then, for each ring-filled run, when the plug first passes the projectile from 50 µs on, when it
last lags it, and the speed the projectile loses from 80 to 100 µs (../borvik_hardening_band/full/plug.py's reading: a
plug slower than the projectile pushing it is still held by the plate). Last, the ring-filled levels run with
the over-nonlocal damage driver (`--set nonlocal_weight=2`, `8mm_<level>_m2/`) beside the same levels with m = 1,
and the 0.667 mm level on the lattice at three radii beside the ring-filled one.
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
TIMES = {"8mm": range(10, 110, 10), "12mm": range(10, 90, 10)}


def averaged(plate, h, tag, t):
    """The lattice-filled level's speed at t averaged over the projectile's radii (the line at R = 10 mm)."""
    found = runs(h, f"{plate}_{tag}")
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


def series(hs, v):
    """A level series as text: its values, the steps between them, and orders()."""
    return " / ".join(f"{x:.2f}" for x in v) + "  steps " + ", ".join(f"{x:+.2f}" for x in np.diff(v)) + f"  {orders(hs, v)}"


def main(plate):
    print(f"\n== {plate}")
    stored = [(h, tag) for h, tag in LEVELS if os.path.isdir(os.path.join(HERE, f"{plate}_{tag}"))]
    hs = [h for h, _ in stored]
    tags = " / ".join(tag for _, tag in stored)
    print(f"rings: {tags}; steps; order and Richardson value through each three; lattice averaged over R, the same")
    for t in TIMES[plate]:
        rings = np.array([speed(os.path.join(HERE, f"{plate}_{tag}"), t) for _, tag in stored])
        cells = np.array([averaged(plate, h, tag, t) for h, tag in stored])
        print(f"{t:4d} us  rings {series(hs, rings)}\n         cells {series(hs, cells)}")
    for h, tag in stored:
        moved = [(r, os.path.join(HERE, os.path.basename(f))) for r, f in runs(h, f"{plate}_{tag}")]
        moved = [(r, f) for r, f in moved if os.path.isdir(f)]
        if len(moved) < 3:
            continue
        radii = np.array([r for r, _ in moved])
        cells = [(r, f) for r, f in runs(h, f"{plate}_{tag}") if r in radii]
        print(f"\n{plate}_{tag}, R = " + ", ".join(f"{r:.3f}" for r in radii) + " mm: speeds; the line's slope (m/s per mm) and misses")
        for t in TIMES[plate]:
            both = []
            for name, found in (("rings", moved), ("cells", cells)):
                v = np.array([speed(f, t) for _, f in found])
                slope, _, miss = line(radii, v)
                both.append(f"{name} " + " / ".join(f"{x:.2f}" for x in v) + f"  {slope:6.2f}," + "".join(f"{m:+6.2f}" for m in miss))
            print(f"{t:4d} us  " + "   ".join(both))
    ended = [tag for _, tag in stored if history(os.path.join(HERE, f"{plate}_{tag}"))[0][-1] >= 100]
    if ended:
        print(f"\n{'run':22s} {'plug passes first (us)':>23s} {'lags last (us)':>15s} {'lost 80-100 us':>15s} {'v(100 us)':>10s}")
    for tag in ended:
        t, v, plug = history(os.path.join(HERE, f"{plate}_{tag}"))
        window = (t > 50) & (t <= 100)
        passes, lags = np.where(window & (plug > v))[0], np.where(window & (plug < v))[0]
        first = t[passes[0]] if len(passes) else np.nan
        last = t[lags[-1]] if len(lags) else np.nan
        lost = np.interp(80, t, v) - np.interp(100, t, v)
        print(f"{plate}_{tag:16s} {first:23.1f} {last:15.1f} {lost:15.2f} {np.interp(100, t, v):10.2f}")


def over_nonlocal(plate):
    """The ring-filled levels with the over-nonlocal damage driver (`--set nonlocal_weight=2`,
    `<plate>_<level>_m2/`) beside the same levels with m = 1, every 10 µs, with their steps and
    orders; then when each m = 2 run's plug first passes the projectile, as above."""
    stored = [(h, tag) for h, tag in LEVELS if os.path.isdir(os.path.join(HERE, f"{plate}_{tag}_m2"))]
    if not stored:
        return
    hs = [h for h, _ in stored]
    print(f"\n== {plate}, nonlocal_weight m = 2 beside m = 1 (rings, " + " / ".join(tag for _, tag in stored) + ")")
    for t in TIMES[plate]:
        rows = []
        for name, suffix in (("m=1", ""), ("m=2", "_m2")):
            v = np.array([speed(os.path.join(HERE, f"{plate}_{tag}{suffix}"), t) for _, tag in stored])
            rows.append(f"{name} {series(hs, v)}")
        print(f"{t:4d} us  " + "\n         ".join(rows))
    for _, tag in stored:
        t, v, plug = history(os.path.join(HERE, f"{plate}_{tag}_m2"))
        passes = np.where((t > 50) & (t <= 100) & (plug > v))[0]
        first = f"{t[passes[0]]:.1f} us" if len(passes) else "not by the run's end"
        print(f"{plate}_{tag}_m2: the plug first passes the projectile {first}; v({t[-1]:.0f} us) = {v[-1]:.2f} m/s")


def lattice_667um():
    """The 8 mm plate's 0.667 mm level on the lattice at R = 10 mm (../borvik_hardening_band/full/8mm_667um/),
    9.917 mm (stop 87) and 10.083 mm (stop 88; `8mm_667um_radius_<R>um/` there), their least-squares line in R
    at R = 10 mm (`averaged`), beside the ring-filled level with m = 1 and the lattice's 0.8 mm level averaged
    the same way, every 10 µs."""
    found = runs(2 / 3, "8mm_667um")
    if len(found) < 2:
        return
    columns = [(f"cells R={r:.3f}", lambda t, f=f: speed(f, t)) for r, f in found]
    columns.append(("their line at R=10", lambda t: averaged("8mm", 2 / 3, "667um", t)))
    columns.append(("rings", lambda t: speed(os.path.join(HERE, "8mm_667um"), t)))
    columns.append(("cells 0.8 mm averaged", lambda t: averaged("8mm", 0.8, "800um", t)))
    print("\n== 8mm at 0.667 mm: " + " / ".join(name for name, _ in columns))
    for t in TIMES["8mm"]:
        print(f"{t:4d} us  " + " / ".join(f"{value(t):.2f}" for _, value in columns))


if __name__ == "__main__":
    for plate in sys.argv[1:] or ["8mm", "12mm"]:
        main(plate)
        over_nonlocal(plate)
        if plate == "8mm":
            lattice_667um()
