#!/usr/bin/env python3
"""The failed plate particles (D ≥ 1) of Børvik runs about the axis at 50, 100 and 150 µs (stop 127).

    python3 failed.py RUN_FOLDER …

Reads a run's VTK snapshots (vtk/borvik_axisymmetric_00000{1,2,3}.vtu, the case's output every
50 µs) with scripts/shear_band.py's reader, as ../edge_hardening/band.py does. The folders
committed here keep only report.md and histories.csv, so rerun a case's command (README.md,
stop 127) to count its particles. Prints, per snapshot, the number of plate particles (body 1)
with D ≥ 1."""
import importlib.util
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[4]
spec = importlib.util.spec_from_file_location("shear_band", ROOT / "scripts/shear_band.py")
shear_band = importlib.util.module_from_spec(spec)
spec.loader.exec_module(shear_band)

if __name__ == "__main__":
    for run in sys.argv[1:]:
        counts = []
        for snapshot, t_us in ((1, 50), (2, 100), (3, 150)):
            a = shear_band.read_vtu(os.path.join(run, "vtk", f"borvik_axisymmetric_{snapshot:06d}.vtu"))
            failed = sum(1 for d, b in zip(a["D"], a["body"]) if b == 1 and d >= 1)
            counts.append(f"{t_us} µs {failed}")
        print(f"{os.path.basename(run.rstrip('/'))}: " + ", ".join(counts))
