"""Writes cases/borvik_axisymmetric.toml with the projectile's edge rounded (stops 113 and 121).
    python3 edge_case.py 2.0 > case_r20.toml          # an edge radius of 2 mm
    python3 edge_case.py 2.0 0.2 12 > case.toml       # the radius 10 mm + 0.2 × 4 mm / 12: run it with --set edge_phase=0.2 at k = 12
The box of the projectile (∅20 mm from the gap to 81.5 mm) becomes a polygon whose corner at the
plate is a quarter circle of the given radius (mm), 32 segments (stop 113's runs had 24);
everything else is the case as committed. The polygon's bounding box is the box's, so the
projectile's lattice is the box's, clipped at the round edge.
"""
import math
import sys
from pathlib import Path

GAP, TOP, SEGMENTS = 1.5, 81.5, 32
BOX = 'shape = { box = { min = ["0 mm", "${gap} mm"]'


def polygon(edge, radius):
    """The projectile's section (mm): axis, nose, the rounded edge, flank, rear."""
    arc = [(radius - edge + edge * math.cos(a), GAP + edge + edge * math.sin(a))
           for a in (-math.pi / 2 + math.pi / 2 * i / SEGMENTS for i in range(1, SEGMENTS))]
    return [(0, GAP), (radius - edge, GAP), *arc, (radius, GAP + edge), (radius, TOP), (0, TOP)]


if __name__ == "__main__":
    case = (Path(__file__).resolve().parents[3] / "cases/borvik_axisymmetric.toml").read_text()
    start = case.index(BOX)
    end = case.index("\n", start)
    phase = float(sys.argv[2]) * 4 / float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    vertices = ", ".join(f'["{x:.6f} mm", "{y:.6f} mm"]' for x, y in polygon(float(sys.argv[1]), 10.0 + phase))
    sys.stdout.write(case[:start] + f"shape = {{ polygon = {{ vertices = [{vertices}] }} }}" + case[end:])
