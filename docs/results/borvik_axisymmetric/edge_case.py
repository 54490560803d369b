"""Writes cases/borvik_axisymmetric.toml with the projectile's edge rounded (stop 113).
    python3 edge_case.py 1.0 > case_e10.toml     # an edge radius of 1 mm, 24 segments
The box of the projectile (∅20 mm from the gap to 81.5 mm) becomes a polygon whose corner at the
plate is a quarter circle of the given radius (mm); everything else is the case as committed.
"""
import math
import sys
from pathlib import Path

BOX = 'shape = { box = { min = ["0 mm", "${gap} mm"], max = ["${projectile_radius} mm", "${projectile_top} mm"] } }'
GAP, TOP, RADIUS, SEGMENTS = 1.5, 81.5, 10.0, 24


def polygon(edge):
    """The projectile's section (mm): axis, nose, the rounded edge, flank, rear."""
    arc = [(RADIUS - edge + edge * math.cos(a), GAP + edge + edge * math.sin(a))
           for a in (-math.pi / 2 + math.pi / 2 * i / SEGMENTS for i in range(1, SEGMENTS))]
    return [(0, GAP), (RADIUS - edge, GAP), *arc, (RADIUS, GAP + edge), (RADIUS, TOP), (0, TOP)]


if __name__ == "__main__":
    case = (Path(__file__).resolve().parents[3] / "cases/borvik_axisymmetric.toml").read_text()
    vertices = ", ".join(f'["{x:.6f} mm", "{y:.6f} mm"]' for x, y in polygon(float(sys.argv[1])))
    sys.stdout.write(case.replace(BOX, f"shape = {{ polygon = {{ vertices = [{vertices}] }} }}"))
