"""The projectile's speed every 2 us from 6 to 40 us of a base run, and the others' less it (stop 112).
    python3 history_diff.py uf8_k12 uf8_k10 uf8_k11 uf8_k13
"""
import csv
import sys

import numpy as np


def histories(run):
    """A run's histories.csv as an array, one column a probe (time first, in s)."""
    return np.array([[float(x) for x in row] for row in list(csv.reader(open(run + "/histories.csv")))[1:]])


def load(run):
    """A run's times (s) and the projectile's downward speed (m/s)."""
    history = histories(run)
    return history[:, 0], -history[:, 1]


if __name__ == "__main__":
    T = np.arange(6, 40.01, 2) * 1e-6
    base = sys.argv[1]
    tb, vb = load(base)
    Vb = np.interp(T, tb, vb)
    print("t (us)".ljust(9) + " ".join(f"{t * 1e6:6.0f}" for t in T))
    print(base.ljust(9) + " ".join(f"{v:6.2f}" for v in Vb))
    for run in sys.argv[2:]:
        t, v = load(run)
        print(run.ljust(9) + " ".join(f"{x:6.2f}" for x in np.interp(T, t, v) - Vb))
