"""When the 8 mm plate's plug last lags its projectile, and what the projectile loses after.

    python3 plug.py

For every 8 mm run stored here (`8mm_*/`; how they were run: ../README.md, "full/"), reads
`histories.csv` and prints the last time from 50 µs to 100 µs at which the plug's mean speed lies
below the projectile's, the plug's lowest speed over 65–95 µs (a plug that passed its projectile
at about 63 µs and then slows below it can only be held by the plate it has not torn from), and
the projectile's speed lost from 80 to 100 µs and left at 100 µs. A plug that lags until 81–85 µs
costs the projectile 5–7.5 m/s more than one that clears it by 78 µs (../README.md, "full/", stop
85).
"""
import glob
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    print(f"{'run':30s} {'lags last (us)':>14s} {'plug lowest (m/s)':>18s} {'lost 80-100 us':>15s} {'v(100 us)':>10s}")
    for run in sorted(glob.glob(os.path.join(HERE, "8mm_*", "histories.csv"))):
        d = np.genfromtxt(run, delimiter=",", names=True)
        t, v, plug = d[d.dtype.names[0]] * 1e6, -d[d.dtype.names[1]], d[d.dtype.names[2]]
        lags = np.where((t > 50) & (t <= 100) & (plug < v))[0]
        held = (t > 65) & (t < 95)
        lost = np.interp(80, t, v) - np.interp(100, t, v)
        last = t[lags[-1]] if len(lags) else np.nan
        name = os.path.basename(os.path.dirname(run))
        print(f"{name:30s} {last:14.1f} {plug[held].min():18.1f} {lost:15.2f} {np.interp(100, t, v):10.2f}")


if __name__ == "__main__":
    main()
