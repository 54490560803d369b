#!/usr/bin/env python3
"""When the levels part (stop 121): the projectile's speed at given times, averaged over the five
places of its edge on the lattice (the runs of lattice.py), level by level, and each level's step
over the coarser one. Run from anywhere:
    python3 docs/results/borvik_axisymmetric/lattice_conserving/when.py"""
import bisect
import csv
import os
import statistics as st

HERE = os.path.dirname(os.path.abspath(__file__))
PHASES = ["m04", "m02", "0", "p02", "p04"]
TIMES = [20, 30, 40, 48, 56, 65, 100, 150]  # µs


def speed_at(folder):
    rows = list(csv.reader(open(os.path.join(folder, "histories.csv"))))[1:]
    t = [float(r[0]) * 1e6 for r in rows]
    v = [-float(r[1]) for r in rows]
    return [v[min(bisect.bisect_left(t, x), len(t) - 1)] for x in TIMES]


def folder(plate, phase, k):
    return os.path.join(HERE, "..", f"c{plate}_0_k{k}") if phase == "0" else os.path.join(HERE, f"c{plate}_{phase}_k{k}")


for plate in (12, 8):
    print(f"== {plate} mm plate: the projectile's speed (m/s), mean of the five edge places, at t (µs)")
    print("Δx (mm)".ljust(9), " ".join(f"{t:>7}" for t in TIMES))
    before = None
    for k in (6, 8, 10, 12, 16):
        mean = [st.mean(c) for c in zip(*(speed_at(folder(plate, p, k)) for p in PHASES))]
        print(f"{4 / k:<9.3f}", " ".join(f"{v:7.2f}" for v in mean))
        if before:
            print("  step".ljust(9), " ".join(f"{a - b:+7.2f}" for a, b in zip(mean, before)))
        first = first if before else mean
        before = mean
    print("0.667→0.25".ljust(9), " ".join(f"{a - b:+7.2f}" for a, b in zip(before, first)))
