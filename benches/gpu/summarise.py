#!/usr/bin/env python3
"""Summarises what benches/gpu/run.sh wrote: ns per particle-step on the GPU (the difference of two
runs of different lengths, so without set-up) and on the CPU, their ratio, the effective memory
bandwidth and the largest relative difference of the probes between the backends.

    benches/gpu/summarise.py OUT [PEAK_GB_S]

The bandwidth is a lower bound on the traffic: every stored byte of a particle read and written once
per evaluation of the step (2 B n E per step, B the stored bytes per particle from the report, E the
evaluations per step, given per case below); neighbours' reads are taken as cache hits. PEAK_GB_S is
the card's memory bandwidth (H100 SXM 3350, H100 PCIe 2000, H200 4800); without it, from the name
in OUT/machine.txt.
"""
import csv
import json
import math
import os
import sys

EVALUATIONS = {"pysph_impact3d": 2, "dam_break_2d": 2, "sod_shock_tube": 2}
PEAKS = [("H200", 4800.0), ("H100 PCIe", 2000.0), ("H100", 3350.0)]


def load(prefix):
    with open(prefix + ".report.json") as f:
        r = json.load(f)
    with open(prefix + ".histories.csv") as f:
        rows = list(csv.reader(f))
    return r, rows


def per_step_ns(r):
    return r["wall_s"] / (r["steps"] * r["particles"]) * 1e9


def probe_diff(a, b):
    """The largest difference over the probes at the last row both histories have, relative to the
    largest magnitude of that probe over the CPU's history (a momentum that stays near 0 is not
    divided by its own noise)."""
    (ha, *ra), (hb, *rb) = a, b
    if ha != hb or not ra or not rb:
        return float("nan"), ""
    n = min(len(ra), len(rb))
    worst, which = 0.0, ""
    for col in range(1, len(ha)):
        x, y = float(ra[n - 1][col]), float(rb[n - 1][col])
        scale = max(abs(float(r[col])) for r in rb[:n])
        d = abs(x - y) / max(scale, 1e-30)
        if not d <= worst:
            worst, which = d, ha[col]
    return worst, which


def main():
    out = sys.argv[1]
    peak = float(sys.argv[2]) if len(sys.argv) > 2 else None
    machine = open(os.path.join(out, "machine.txt")).read() if os.path.exists(os.path.join(out, "machine.txt")) else ""
    if peak is None:
        peak = next((p for name, p in PEAKS if name in machine), float("nan"))
    print(machine.strip())
    print(f"peak memory bandwidth taken: {peak} GB/s")
    print("| case | particles | GPU ns/particle-step (marginal) | GPU ms/step | CPU ns/particle-step | CPU/GPU | bytes/particle | bandwidth GB/s (≥) | of peak | probes GPU vs CPU |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    names = sorted({f[: -len(".report.json")].rsplit(".", 1)[0] for f in os.listdir(out) if f.endswith(".report.json")})
    for name in names:
        d = os.path.join(out, name)
        try:
            (gs, hs), (gl, hl) = load(d + ".gpu_short"), load(d + ".gpu_long")
        except (OSError, KeyError, ValueError) as e:
            print(f"| {name} | failed: {e} |")
            continue
        n = gl["particles"]
        extra = gl["steps"] - gs["steps"]
        marginal = (gl["wall_s"] - gs["wall_s"]) / (extra * n) * 1e9 if extra > 0 else float("nan")
        step_ms = marginal * n * 1e-6
        cpu, ratio, diff = float("nan"), float("nan"), "-"
        if os.path.exists(d + ".cpu_short.report.json"):
            cs, hc = load(d + ".cpu_short")
            cpu = per_step_ns(cs)
            ratio = cpu / marginal
            worst, which = probe_diff(hs, hc)
            diff = f"{worst:.2e} ({which})"
        stored = sum(g["bytes"] for g in gl.get("bytes_per_particle", [])) / max(len(gl.get("bytes_per_particle", [])), 1)
        evals = EVALUATIONS.get(gl["case"], 1)
        bw = 2 * stored * evals / marginal if marginal > 0 else float("nan")  # bytes per ns = GB/s
        print(f"| {name} | {n:,} | {marginal:.2f} | {step_ms:.3f} | {cpu:.1f} | {ratio:.1f} | {stored:.0f} | {bw:.0f} | {bw / peak:.1%} | {diff} |")


if __name__ == "__main__":
    main()
