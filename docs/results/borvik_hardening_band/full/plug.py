"""When the 8 mm plate's plug comes free of its projectile, and what the projectile loses after.

    python3 plug.py

For every 8 mm run stored here (`8mm_*/`; how they were run: ../README.md, "full/"), reads
`histories.csv` and prints the first and the last time from 50 µs to 100 µs at which the plug's
mean speed lies above and below the projectile's, the plug's lowest speed over 65–95 µs, and the
projectile's speed lost from 80 to 100 µs and left at 100 µs. A plug that slows below the
projectile pushing it can only be held by the plate it has not torn from. At 1.333 mm it is held
until 81–85 µs at every radius, and the projectile loses 6.9–7.5 m/s from 80 to 100 µs; a plug
clear by 78 µs leaves it 0.4–1.6 m/s (../README.md, "full/", stop 85).
"""
import os
import sys
from glob import glob

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, HERE)
from levels import history  # noqa: E402  (the same reader as levels.py)


def main():
    print(f"{'run':30s} {'passes first (us)':>17s} {'lags last (us)':>14s} {'plug lowest (m/s)':>18s} {'lost 80-100 us':>15s} {'v(100 us)':>10s}")
    for run in sorted(os.path.dirname(f) for f in glob(os.path.join(HERE, "8mm_*", "histories.csv"))):
        t, v, plug = history(run)
        window = (t > 50) & (t <= 100)
        passes, lags = np.where(window & (plug > v))[0], np.where(window & (plug < v))[0]
        first = t[passes[0]] if len(passes) else np.nan
        last = t[lags[-1]] if len(lags) else np.nan
        lowest = plug[(t > 65) & (t < 95)].min()
        lost = np.interp(80, t, v) - np.interp(100, t, v)
        print(f"{os.path.basename(run):30s} {first:17.1f} {last:14.1f} {lowest:18.1f} {lost:15.2f} {np.interp(100, t, v):10.2f}")


if __name__ == "__main__":
    main()
