#!/usr/bin/env python3
"""The shear band of a Børvik run (cases/borvik_perforation.toml), from the VTK it wrote.

    scripts/shear_band.py RUN_DIR [RUN_DIR ...]

For each output time of each run (RUN_DIR holds the run's report.json and vtk/), over the plate's
particles within 20 mm of the axis (the plate is body 1, its fine region reaches 24 mm):

- the peak of the plastic strain averaged over 1 mm rings about the axis (all depths, current
  positions), and the ring's radius;
- the band's width: the strain's integral over the rings from 6 to 16 mm divided by that peak;
- the plastic strain integrated over the volume, Σ V ε_p (mm³), and the volume with ε_p > 0.5;
- the plate's failed particles (D = 1), wherever they are, and their volume;
- the largest ε_p and the largest D of a single particle within 20 mm of the axis: with a
  damage length ℓ, D follows ε_p averaged over ℓ, and a band thinner than ℓ keeps D well below
  what its own strain would give.

A particle's volume is Δx³ (the report's `dx`; all of these particles are in the fine region).
The model is a quarter: volumes and counts are a quarter of the plate's. Pure Python, so that it
runs wherever pairsum does; it reads only what pairsum writes (binary VTU, UInt64 headers).
"""
import base64
import json
import math
import re
import struct
import sys
from pathlib import Path

ARRAY = re.compile(
    r'<DataArray type="Float64" Name="(\w+)" NumberOfComponents="(\d+)" format="binary">\s*(\S+)\s*</DataArray>'
)


def read_vtu(path):
    """The Float64 arrays of a VTU file pairsum wrote: {name: [value or tuple per point]}."""
    out = {}
    for name, comps, text in ARRAY.findall(Path(path).read_text()):
        raw = base64.b64decode(text)
        (nbytes,) = struct.unpack("<Q", raw[:8])
        values = struct.unpack("<%dd" % (nbytes // 8), raw[8 : 8 + nbytes])
        c = int(comps)
        out[name] = list(values) if c == 1 else [values[i : i + c] for i in range(0, len(values), c)]
    return out


def outputs(run):
    """The VTK outputs of a run (its --out folder), in time order: [(time in s, path of the VTU)]."""
    vtk = Path(run) / "vtk"
    pvd = next(vtk.glob("*.pvd")).read_text()
    return [(float(t), vtk / f) for t, f in re.findall(r'timestep="([^"]*)"[^>]*file="([^"]*)"', pvd)]


def band(d, dx_mm):
    rings = {}
    strain = high = failed = 0.0
    top_eps = top_D = 0.0
    volume = dx_mm**3
    for k, body in enumerate(d["body"]):
        if body != 1:
            continue
        failed += d["D"][k] >= 1.0
        x, y, _ = d["Points"][k]
        r = 1000.0 * math.hypot(x, y)
        if r > 20.0:
            continue
        e = d["eps_p"][k]
        top_eps = max(top_eps, e)
        top_D = max(top_D, d["D"][k])
        ring = rings.setdefault(int(r), [0, 0.0])
        ring[0] += 1
        ring[1] += e
        strain += volume * e
        high += volume * (e > 0.5)
    mean = {b + 0.5: s / n for b, (n, s) in rings.items()}
    peak_r, peak = max(mean.items(), key=lambda kv: kv[1])
    width = sum(e for r, e in mean.items() if 6.0 <= r <= 16.0) / peak if peak > 0 else float("nan")
    return peak, peak_r, width, strain, high, failed, failed * volume, top_eps, top_D


def main(dirs):
    print("run | t [µs] | peak ring ε_p | at r [mm] | width [mm] | Σ V ε_p [mm³] | V(ε_p > 0.5) [mm³] | failed | V failed [mm³] | largest ε_p | largest D")
    for run in dirs:
        run = Path(run)
        dx_mm = 1000.0 * json.loads((run / "report.json").read_text())["dx"]
        for t, f in outputs(run):
            if t == 0.0:
                continue
            peak, r, width, strain, high, failed, vfailed, top_eps, top_D = band(read_vtu(f), dx_mm)
            print(
                f"{run} | {1e6 * t:.0f} | {peak:.3f} | {r:.1f} | {width:.2f} | {strain:.0f} | {high:.0f} | {failed:.0f} | {vfailed:.0f}"
                f" | {top_eps:.2f} | {top_D:.2f}"
            )


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
