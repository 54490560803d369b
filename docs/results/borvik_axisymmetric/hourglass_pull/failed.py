#!/usr/bin/env python3
"""The failed plate particles (D ≥ 1) of Børvik runs about the axis at 50, 100 and 150 µs (stop 127).

    python3 failed.py RUN_FOLDER …

Reads a run's VTK snapshots (vtk/borvik_axisymmetric_00000{1,2,3}.vtu, the case's output every
50 µs, binary Float64 arrays under a UInt64 header). The folders committed here keep only
report.md and histories.csv, so rerun a case's command (README.md, stop 127) to count its
particles. Prints, per snapshot, the number of plate particles (body 1) with D ≥ 1."""
import base64
import os
import re
import struct
import sys

ARRAY = re.compile(r'<DataArray type="Float64" Name="(\w+)" NumberOfComponents="\d+" format="binary">\s*([A-Za-z0-9+/=]+)')


def arrays(path):
    """Every Float64 array of a .vtu file by name."""
    out = {}
    for name, text in ARRAY.findall(open(path).read()):
        raw = base64.b64decode(text)
        n = struct.unpack("<Q", raw[:8])[0]
        out[name] = struct.unpack(f"<{n // 8}d", raw[8 : 8 + n])
    return out


if __name__ == "__main__":
    for run in sys.argv[1:]:
        counts = []
        for snapshot, t_us in ((1, 50), (2, 100), (3, 150)):
            a = arrays(os.path.join(run, "vtk", f"borvik_axisymmetric_{snapshot:06d}.vtu"))
            failed = sum(1 for d, b in zip(a["D"], a["body"]) if b == 1 and d >= 1)
            counts.append(f"{t_us} µs {failed}")
        print(f"{os.path.basename(run.rstrip('/'))}: " + ", ".join(counts))
