#!/usr/bin/env python3
"""When the levels part (stop 121): the projectile's speed at given times, averaged over the five
places of its edge on the lattice (the runs of lattice.py), level by level, and each level's step
over the coarser one. Run from anywhere:
    python3 docs/results/borvik_axisymmetric/lattice_conserving/when.py"""
from lattice import mean_speeds_at

TIMES = [20, 30, 40, 48, 56, 65, 100, 150]  # µs

for plate in (12, 8):
    print(f"== {plate} mm plate: the projectile's speed (m/s), mean of the five edge places, at t (µs)")
    print("Δx (mm)".ljust(9), " ".join(f"{t:>7}" for t in TIMES))
    first = before = None
    for k in (6, 8, 10, 12, 16):
        mean = mean_speeds_at(plate, k, TIMES)
        print(f"{4 / k:<9.3f}", " ".join(f"{v:7.2f}" for v in mean))
        if before:
            print("  step".ljust(9), " ".join(f"{a - b:+7.2f}" for a, b in zip(mean, before)))
        first = first or mean
        before = mean
    print("0.667→0.25".ljust(9), " ".join(f"{a - b:+7.2f}" for a, b in zip(before, first)))
