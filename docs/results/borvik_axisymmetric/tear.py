"""How the plug came off the plate: read a run's VTK output (`pairsum run ... --out RUN`) at one
output time and print, for the plate within 24 mm of the axis, the band (largest ε_p; the width of
ε_p > 1, its area in the r–z plane over the plate's thickness), how many particles failed (D = 1)
or reached D > 0.5, and the mean damage of the plug's outer face (in each Δx-high slice of the
intact plug, moving at more than 0.7 times the projectile's mean speed, its outermost particle).

    python3 tear.py [--at 100] [--thickness 12] RUN [RUN ...]
"""
import argparse, json, math, os, sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../../scripts"))
from shear_band import outputs, read_vtu  # noqa: E402


def summary(run, at_us, thickness_mm):
    found = [o for o in outputs(run) if abs(o[0] * 1e6 - at_us) < 1]
    if not found:
        return "%s: no output at %g µs" % (run, at_us)
    d = read_vtu(found[0][1])
    P, body, v, D, eps = d["Points"], d["body"], d["v"], d["D"], d["eps_p"]
    dx = json.load(open(os.path.join(run, "report.json")))["dx"]
    plate = [k for k in range(len(body)) if body[k] == 1 and P[k][0] < 0.024]
    proj = [-v[k][1] for k in range(len(body)) if body[k] == 0]
    v_proj = sum(proj) / len(proj)
    slices = {}
    for k in plate:
        if -v[k][1] > 0.7 * v_proj and D[k] < 1:
            slices.setdefault(math.floor(P[k][1] / dx), []).append(k)
    face = [max(ks, key=lambda k: P[k][0]) for ks in slices.values()]
    face_d = sum(D[k] for k in face) / len(face) if face else float("nan")
    band = sum(1 for k in plate if eps[k] > 1) * (dx * 1e3) ** 2 / thickness_mm
    return "%-24s %5.0f µs  Δx %.3f mm  max ε_p %.2f  w(ε_p > 1) %.2f mm  failed %d  D > 0.5: %d  plug face D %.2f" % (
        run[-24:], at_us, dx * 1e3, max(eps[k] for k in plate), band,
        sum(1 for k in plate if D[k] >= 1), sum(1 for k in plate if D[k] > 0.5), face_d)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--at", type=float, default=100.0, help="output time (µs)")
    ap.add_argument("--thickness", type=float, default=12.0, help="the plate's thickness (mm)")
    ap.add_argument("runs", nargs="+")
    a = ap.parse_args()
    for r in a.runs:
        print(summary(r, a.at, a.thickness))
