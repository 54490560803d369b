"""The energy of a run at its end from the plate's and the projectile's profiles, against the
kinetic energy it started with (stop 113). The profiles need the fields m, v and e
(profiles_energy.toml appended to the case).
    python3 energy_balance.py RUN...
"""
import math
import sys

from corner_particle import profile
from history_diff import histories


def ring(p):
    """A particle's ring mass (kg): m is per unit length of its circle, so m · 2π r."""
    return p["m"] * 2 * math.pi * p["x"]


def body(run, name):
    """A body's internal and kinetic energy (J) at its last profile."""
    P = profile(f"{run}/profiles/{name}_0.csv")
    return sum(ring(p) * p["e"] for p in P), sum(0.5 * ring(p) * (p["v.x"] ** 2 + p["v.y"] ** 2) for p in P)


if __name__ == "__main__":
    print("run          plate e   plate KE  proj. e  proj. KE   total  start  excess (J)  speed (m/s)")
    for run in sys.argv[1:]:
        rows = histories(run)
        start, speed = rows[0, 4], -rows[-1, 1]
        parts = [*body(run, "plate"), *body(run, "projectile")]
        total = sum(parts)
        print(f"{run:<12}" + "".join(f"{x:9.1f}" for x in parts) + f" {total:8.1f} {start:6.0f} {total - start:8.1f}  {speed:10.3f}")
