"""The plate's pressure where it first fails, from a Børvik run's VTK output: at each output time,
the plate's (body 1) particles within 15 mm of the axis in tension beyond 2 GPa and in compression
beyond 3 GPa, and at the first output with a failed particle, each failed particle with the D and
pressure range of its neighbours within 1.3 mm. Usage: python3 pressure.py RUN..."""
import os, sys
import numpy as np
from failed import outputs, read


def main(run):
    reported = False
    for t, f in outputs(run)[1:]:
        d = read(f)
        plate = d['body'] == 1
        x, p, damage = d['Points'][plate] * 1e3, d['p'][plate] / 1e6, d['D'][plate]
        r = np.hypot(x[:, 0], x[:, 1])
        near = r < 15
        print(f"{run} {t * 1e6:.0f} us: within 15 mm p {p[near].min():.0f} to {p[near].max():.0f} MPa, "
              f"{(near & (p < -2000)).sum()} below -2 GPa, {(near & (p > 3000)).sum()} above 3 GPa")
        failed = np.flatnonzero(damage >= 0.999)
        if len(failed) and not reported:
            reported = True
            for i in failed:
                dist = np.linalg.norm(x - x[i], axis=1)
                nb = (dist < 1.3) & (dist > 0)
                around = (f"D {damage[nb].min():.2f}-{damage[nb].max():.2f}, p {p[nb].min():.0f} to {p[nb].max():.0f} MPa"
                          if nb.any() else "none within 1.3 mm")
                print(f"  failed at r {r[i]:.2f} z {x[i, 2]:.2f} mm, p {p[i]:.0f} MPa; {nb.sum()} neighbours: {around}")


if __name__ == '__main__':
    for run in sys.argv[1:]:
        main(run)
