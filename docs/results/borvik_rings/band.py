"""The plate's damage and plastic strain in a ring-filled Børvik run, from its VTK output.

    python3 band.py RUN [RUN ...]     (each RUN the --out folder of a run, its vtk/ still there)

For each output time after the first: over the plate (body 1) the largest D, the number of
failed particles (D = 1), and the largest ε_p with where that particle started (its distance from
the axis r0 and its depth z0, the plate's top face at z = 0, in mm). The runs' VTK output is not
kept here (README.md has the figures this printed); rerun a case to read it.
"""
import os
import sys

import numpy as np

sys.dont_write_bytecode = True  # nothing written beside the stored results
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "scripts"))
from shear_band import outputs, read_vtu  # noqa: E402


def read(path):
    """The Float64 arrays of a VTU file pairsum wrote (scripts/shear_band.py's reader), as numpy arrays."""
    return {name: np.array(values) for name, values in read_vtu(path).items()}


def main(run):
    frames = outputs(run)
    first = read(frames[0][1])
    start = dict(zip(first["id"], first["Points"] * 1e3))
    for t, path in frames[1:]:
        d = read(path)
        plate = d["body"] == 1
        ids, eps, damage = d["id"][plate], d["eps_p"][plate], d["D"][plate]
        i = np.argmax(eps)
        x0 = start[ids[i]]
        print(
            f"{t * 1e6:6.1f} us  D max {damage.max():.3f}  failed {np.sum(damage >= 1):4d}  "
            f"eps_p max {eps[i]:.3f} from r0 {np.hypot(x0[0], x0[1]):.2f} mm, z0 {x0[2]:.2f} mm"
        )


if __name__ == "__main__":
    for run in sys.argv[1:]:
        print("==", run)
        main(run)
