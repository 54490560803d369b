"""Pairs of intact plate particles that have lost each other: read a run's VTK series (a copy of
cases/borvik_axisymmetric.toml with `fields` adding "kernel_metric", and a short output
`interval`) and print, at each output, how many pairs of step-0 neighbours (|X_ij| < 1.5 Δx,
within 16 mm of the axis), neither failed (D < 1), now lie beyond both shaped kernels' support:
|x_ij|_i = √(x_ij · B_i⁻¹ x_ij) ≥ 2 h0 and the same for j (Wendland C2, h0 = 1.3 Δx), with the
median over those pairs of the larger D of the two.

    python3 reach.py RUN
"""
import json, math, os, sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../../scripts"))
from shear_band import outputs, read_vtu  # noqa: E402


def by_id(d):
    """The arrays in particle-id order (the output's order follows the cell list)."""
    order = sorted(range(len(d["id"])), key=lambda k: int(d["id"][k]))
    return {key: [d[key][k] for k in order] for key in d}


def first_neighbours(d0, dx):
    body, P = d0["body"], d0["Points"]
    plate = [k for k in range(len(body)) if body[k] == 1 and P[k][0] < 0.016]
    cells = {}
    for k in plate:
        cells.setdefault((int(P[k][0] / dx), int(P[k][1] / dx)), []).append(k)
    pairs = []
    for k in plate:
        cx, cy = int(P[k][0] / dx), int(P[k][1] / dx)
        for ax in range(-2, 3):
            for ay in range(-2, 3):
                for j in cells.get((cx + ax, cy + ay), []):
                    if j > k and math.dist(P[k][:2], P[j][:2]) < 1.5 * dx:
                        pairs.append((k, j))
    return pairs


def shaped_length(M, x, y):
    """|x|_i for a 2D metric stored as (xx, xy, yy)."""
    return math.sqrt(max(M[0] * x * x + 2 * M[1] * x * y + M[2] * y * y, 0.0))


def main(run):
    dx = json.load(open(os.path.join(run, "report.json")))["dx"]
    reach = 2 * 1.3 * dx
    series = outputs(run)
    pairs = first_neighbours(by_id(read_vtu(series[0][1])), dx)
    print("%s: %d pairs of step-0 neighbours" % (run, len(pairs)))
    for t, f in series[1:]:
        d = by_id(read_vtu(f))
        P, M, D, v, body = d["Points"], d["kernel_metric"], d["D"], d["v"], d["body"]
        proj = [-v[k][1] for k in range(len(body)) if body[k] == 0]
        lost = []
        for i, j in pairs:
            if D[i] >= 1 or D[j] >= 1:
                continue
            x, y = P[i][0] - P[j][0], P[i][1] - P[j][1]
            if shaped_length(M[i], x, y) >= reach and shaped_length(M[j], x, y) >= reach:
                lost.append(max(D[i], D[j]))
        lost.sort()
        print("%6.1f µs  projectile %7.2f m/s  intact pairs out of reach %4d  their larger D (median) %s  failed %d" % (
            t * 1e6, sum(proj) / len(proj), len(lost), "%.2f" % lost[len(lost) // 2] if lost else "-",
            sum(1 for k in range(len(body)) if body[k] == 1 and D[k] >= 1)))


if __name__ == "__main__":
    for r in sys.argv[1:]:
        main(r)
