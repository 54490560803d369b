"""The projectile's and the plug's speeds (m/s) at fixed times, from runs' histories (stop 113).
    python3 plug_rebound.py nh8_l1000 nh8_k5 nh8_l667
"""
import sys

import numpy as np

from history_diff import histories

TIMES = [40, 50, 60, 65, 70, 75, 80, 85, 90, 100, 150]


def speeds(run):
    """Times (us), the projectile's downward speed and the plug's (m/s)."""
    rows = histories(run)
    return rows[:, 0] * 1e6, -rows[:, 1], rows[:, 2]


if __name__ == "__main__":
    print("t (us)".ljust(22) + " ".join(f"{t:6d}" for t in TIMES))
    for run in sys.argv[1:]:
        t, projectile, plug = speeds(run)
        print(f"{run:<12}projectile " + " ".join(f"{v:6.1f}" for v in np.interp(TIMES, t, projectile)))
        print(f"{'':<12}plug       " + " ".join(f"{v:6.1f}" for v in np.interp(TIMES, t, plug)))
