"""The projectile's blow on its plug at the release (stop 117), from a run's particle profiles.
    python3 release.py OUT [OUT ...]
OUT is a run of borvik_axisymmetric.toml with the `[[profiles]]` of release_profiles.toml appended
(the plate within 14 mm of the axis and the projectile, every microsecond from 56 to 68 us). Prints,
at each time, the axial momentum (N s, each particle's ring: m 2 pi r v_y) of the projectile, of
the plug (the plate more than 1 mm inside the projectile's edge), of the band (1 mm inside to
1.5 mm outside the edge) and of the plate beyond it (to the profile's edge); the projectile's nose;
the mean pressure of the plate particles within 2 mm ahead of the nose (positive: compressed); the
band's intact and failed particles; and the two bodies' momentum as the profiles hold it (the whole
plate's only with the plate's box widened to r < 260 mm: the axial momentum the scheme makes).
"""
import csv
import math
import sys

EDGE = 10e-3  # the projectile's radius (m) at edge_phase 0


def load(path):
    with open(path) as f:
        return [{k.split(" ")[0]: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def ring_sum(particles, key):
    """Σ m 2π r q over the particles, for the field q named `key`: each particle weighed as its ring."""
    return sum(d["m"] * 2 * math.pi * d["x"] * d[key] for d in particles)


def momentum(particles):
    return ring_sum(particles, "v.y")


def release(out):
    print(out)
    print(" t (us)  projectile    plug    band  beyond  nose (mm)  p ahead (GPa)  band intact  failed  bodies")
    for k in range(13):
        projectile = load(f"{out}/profiles/projectile_{k}.csv")
        plate = load(f"{out}/profiles/plate_{k}.csv")
        nose = min(d["y"] for d in projectile)
        plug = [d for d in plate if d["x"] < EDGE - 1e-3]
        band = [d for d in plate if EDGE - 1e-3 <= d["x"] < EDGE + 1.5e-3]
        beyond = [d for d in plate if d["x"] >= EDGE + 1.5e-3]
        ahead = [d for d in plate if d["x"] < EDGE and nose - 2e-3 < d["y"] < nose + 1e-4]
        p = sum(d["p"] for d in ahead) / max(len(ahead), 1)
        failed = sum(1 for d in band if d["D"] >= 1)
        print(f"  {56 + k:5d}  {momentum(projectile):10.3f}  {momentum(plug):6.3f}  {momentum(band):6.3f}  "
              f"{momentum(beyond):6.3f}  {nose * 1e3:9.3f}  {p / 1e9:13.3f}  {len(band) - failed:11d}  {failed:6d}  "
              f"{momentum(projectile) + momentum(plate):7.3f}")


if __name__ == "__main__":
    for out in sys.argv[1:]:
        release(out)
