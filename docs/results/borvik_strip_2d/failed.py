#!/usr/bin/python3
"""The strip's plate at each VTK output of a run: its failed area (D = 1), damaged area (D > 0.5),
the failed particles' span in reference |x| (mm), and its largest ε_p. The spacing is read from
the run folder's name (…_<Δx in µm>um or …_l<Δx in µm>). Usage: python3 failed.py RUN…"""
import os
import re
import sys

import numpy as np

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "borvik_rings"))
from band import outputs, read  # noqa: E402


def main(run):
    dx = float(re.search(r"(\d+)(um)?/?$", run.rstrip("/")).group(1)) / 1000.0
    frames = outputs(run)
    first = read(frames[0][1])
    o0 = np.argsort(first["id"])
    body, x0 = first["body"][o0], first["Points"][o0] * 1e3
    plate = body == 1
    for t, path in frames[1:]:
        d = read(path)
        o = np.argsort(d["id"])
        damage, eps = d["D"][o], d["eps_p"][o]
        failed, damaged = plate & (damage >= 0.999), plate & (damage > 0.5)
        span = np.abs(x0[failed, 0])
        where = f"{span.min():.2f}-{span.max():.2f}" if len(span) else "-"
        print(f"{run} {t * 1e6:5.0f} us  failed {failed.sum() * dx * dx:6.2f} mm2 (|x0| {where} mm), "
              f"D > 0.5 {damaged.sum() * dx * dx:6.2f} mm2, largest eps_p {eps[plate].max():.2f}")


if __name__ == "__main__":
    for run in sys.argv[1:]:
        main(run)
