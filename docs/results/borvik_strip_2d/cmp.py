#!/usr/bin/python3
"""Projectile and plug speed (m/s) of runs at given times (µs), from histories.csv: the sample
nearest each time (within 1 µs; — where the run ended before it), printed projectile/plug.
Usage: python3 cmp.py 40,80,150 RUN…"""
import csv
import sys

times = [float(t) for t in sys.argv[1].split(',')]
for d in sys.argv[2:]:
    with open(d + '/histories.csv') as f:
        data = [[float(x) for x in r] for r in list(csv.reader(f))[1:]]
    out = []
    for t in times:
        r = min(data, key=lambda r: abs(r[0] - t * 1e-6))
        r = r if abs(r[0] - t * 1e-6) <= 1e-6 else None
        out.append("      —/—      " if r is None else f"{-r[1]:7.2f}/{r[2]:7.2f}")
    print(f"{d:30s}", ' '.join(out))
