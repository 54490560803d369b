"""The failed particles of a Børvik run from its VTK output: at each output time from 40 µs on,
the plate's (body 1) particles with D = 1, counted by their radius in the reference configuration
(matched by id to the first output), and those with D > 0.5. Usage: python3 failed.py RUN..."""
import os, sys
import numpy as np
sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', 'borvik_rings'))
from band import outputs, read


def main(run):
    fr = outputs(run)
    d0 = read(fr[0][1])
    o0 = np.argsort(d0['id'])
    body, x0 = d0['body'][o0], d0['Points'][o0] * 1e3
    r0 = np.hypot(x0[:, 0], x0[:, 1])
    for t, f in fr[2:]:
        d = read(f)
        o = np.argsort(d['id'])
        assert (d['id'][o] == d0['id'][o0]).all(), 'the ids differ from the first output'
        damage = d['D'][o]
        plate = body == 1
        failed = plate & (damage >= 0.999)
        half = plate & (damage > 0.5)
        bins = [0, 5, 6, 7, 8, 9, 10, 11, 12, 15, 300]
        print(f"{run} {t * 1e6:.0f} us: failed {failed.sum()}, by r0 {bins}: {np.histogram(r0[failed], bins=bins)[0]}; "
              f"D > 0.5: {half.sum()}, by r0: {np.histogram(r0[half], bins=bins)[0]}")


if __name__ == '__main__':
    for run in sys.argv[1:]:
        main(run)
