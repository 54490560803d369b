#!/usr/bin/env python3
"""The plate's plastic strain and failure about the axis (stop 121), from the VTK a run of
cases/borvik_axisymmetric.toml wrote (every 50 µs):

    python3 band.py RUN_DIR [RUN_DIR ...]     # each RUN_DIR ends in _k<coarse_factor>

For each run, over the plate's particles (body 1) within 20 mm of the axis, each the ring it
sweeps (volume 2π r Δx², Δx = 4 mm / k): at 50 and 100 µs the rings' plastic strain Σ V ε_p
(mm³), the largest ε_p of one particle, the failed rings' (D = 1) count and volume; and
Σ V ε_p gained from 50 to 100 µs, while the plug is sheared off. Reads the VTK with
scripts/shear_band.py's reader (binary VTU as pairsum writes it)."""
import importlib.util
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[4]
spec = importlib.util.spec_from_file_location("shear_band", ROOT / "scripts/shear_band.py")
shear_band = importlib.util.module_from_spec(spec)
spec.loader.exec_module(shear_band)


def at(run, index, dx):
    a = shear_band.read_vtu(next(Path(run, "vtk").glob(f"*_{index:06d}.vtu")))
    pts, body, damage, eps_p = a["Points"], a["body"], a["D"], a["eps_p"]
    plate = [i for i in range(len(body)) if body[i] == 1 and pts[i][0] < 0.020]
    volume = {i: 2 * math.pi * pts[i][0] * 1e3 * dx * dx for i in plate}
    failed = [i for i in plate if damage[i] >= 1]
    return (sum(volume[i] * eps_p[i] for i in plate), max(eps_p[i] for i in plate),
            len(failed), sum(volume[i] for i in failed))


print("run".ljust(16), "Δx mm", "| 50 µs: Σ V ε_p  peak ε_p", "| 100 µs: Σ V ε_p  peak ε_p  failed  volume (mm³)", "| gained 50→100")
for run in sys.argv[1:]:
    dx = 4.0 / int(run.rstrip("/").split("_k")[-1])
    s50, p50, _, _ = at(run, 1, dx)
    s100, p100, n, v = at(run, 2, dx)
    print(f"{Path(run).name:16} {dx:.3f} | {s50:13.1f} {p50:9.2f} | {s100:14.1f} {p100:9.2f} {n:7d} {v:13.1f} | {s100 - s50:10.1f}")
