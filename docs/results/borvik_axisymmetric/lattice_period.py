"""The part of the projectile's speed that repeats with the lattice (stop 112).

For each run (a folder named *_k<k>, the spacing 4 mm / k, histories sampled every step), the
speed between 12 and 40 us less a quartic in the projectile's travel d since contact, and the
amplitude of that remainder's Fourier component of period dx / f in d, for f = 0.5 … 2: if the
plug's slip past the lattice drove the speed, f = 1 would stand out.
    python3 lattice_period.py uf8_k10 uf8_k11 uf8_k12 uf8_k13
"""
import sys

import numpy as np

from history_diff import load

GAP = 1.5e-3  # m: the projectile's start above the plate (the case's `gap`)

for run in sys.argv[1:]:
    dx = 4e-3 / int(run.split("_k")[1])
    t, v = load(run)
    travel = np.concatenate([[0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))]) - GAP
    window = (t > 12e-6) & (t < 40e-6)
    d, speed = travel[window], v[window]
    rest = speed - np.polyval(np.polyfit(d, speed, 4), d)
    amplitudes = []
    for f in [0.5, 0.73, 1.0, 1.37, 2.0]:
        c = np.trapezoid(rest * np.exp(2j * np.pi * d * f / dx), d) / (d[-1] - d[0]) * 2
        amplitudes.append(f"{f}:{abs(c):.3f}")
    print(run, f"rms {rest.std():.3f}", " ".join(amplitudes),
          f"d(40us)={travel[-1] * 1e3:.3f}mm d/dx={travel[-1] / dx:.2f}")
