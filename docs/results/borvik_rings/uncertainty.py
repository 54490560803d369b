"""The Børvik plates' residual speed at every level, with the numerical uncertainty of the finest
from power laws fitted through all of them (`pairsum uncertainty`, after Eça & Hoekstra 2014).

    python3 uncertainty.py [8mm|12mm]     (both when none is given; PAIRSUM names the binary,
                                          target/release/pairsum by default)

The levels are the lattice-filled runs of ../borvik_hardening_band/full/ (how they were run: that
folder's README): a level's speed is its runs' least-squares line in the projectile's radius at
R = 10 mm where three radii or more were run (rings.py's `averaged`), else its one run at R = 10 mm.
Every 10 µs it prints the speed at each level and what `pairsum uncertainty` makes of them: the
observed order over every level (and with five levels or more, its least and greatest value leaving
out one level at a time), the law the error is estimated with, f0, the fits' scatter σ and
U, the finest level's uncertainty. Where the coarsest level is out of the asymptotic range (the
8 mm plate's 1.333 mm level, whose plug the plate held to 81–85 µs), the same without it.
"""
import json
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, HERE)
from rings import FULL, averaged  # noqa: E402
from levels import speed  # noqa: E402

LEVELS = [(4 / 3, "1333um"), (1.0, "1mm"), (0.8, "800um"), (2 / 3, "667um"), (4 / 7, "571um"), (0.5, "500um")]
TIMES = {"8mm": range(40, 110, 10), "12mm": range(20, 90, 10)}
PAIRSUM = os.environ.get("PAIRSUM", os.path.join(HERE, "..", "..", "..", "target", "release", "pairsum"))


def level(plate, h, tag, t):
    """A level's speed at t: averaged over radii where three or more were run, else its R = 10 mm run."""
    v = averaged(plate, h, tag, t)
    if np.isnan(v):
        run = os.path.join(FULL, f"{plate}_{tag}")
        v = speed(run, t) if os.path.isdir(run) else np.nan
    return v


def uncertainty(hs, v):
    """`pairsum uncertainty --json`'s answer for these levels, on one line."""
    args = [f"{float(h)!r}={float(x)!r}" for h, x in zip(hs, v)]
    out = subprocess.run([PAIRSUM, "uncertainty", "--json", *args], capture_output=True, text=True)
    if out.returncode != 0:
        return out.stderr.strip()
    u = json.loads(out.stdout)
    text = f"p {u['order_text']}, {u['law']}: f0 {u['f0']:.2f}, σ {u['sigma']:.2f}, U {u['u']:.2f}"
    if u["order_without_one_text"]:
        text += f" (p leaving out one level: {u['order_without_one_text']})"
    return text


def main(plate):
    found = [(h, tag) for h, tag in LEVELS if not np.isnan(level(plate, h, tag, 10))]
    print(f"\n== {plate}: " + " / ".join(tag for _, tag in found))
    for t in TIMES[plate]:
        hs = [h for h, _ in found]
        v = [level(plate, h, tag, t) for h, tag in found]
        keep = [k for k, x in enumerate(v) if np.isfinite(x)]
        hs, v = [hs[k] for k in keep], [v[k] for k in keep]
        missing = "" if len(v) == len(found) else "  (" + ", ".join(tag for k, (_, tag) in enumerate(found) if k not in keep) + " not run so far)"
        print(f"{t:4d} us  " + " / ".join(f"{x:.2f}" for x in v) + missing)
        print("        all levels:     " + uncertainty(hs, v))
        if len(v) >= 5:
            print("        without 1.333:  " + uncertainty(hs[1:], v[1:]))


if __name__ == "__main__":
    for plate in sys.argv[1:] or ["8mm", "12mm"]:
        main(plate)
