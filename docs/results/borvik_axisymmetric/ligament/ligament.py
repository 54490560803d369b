#!/usr/bin/env python3
"""What holds the Børvik plug, from a run written every 2.5 µs with ε̄_p (stop 122).

    python3 ligament.py RUN [RUN …]

RUN is the output folder of the case run with `[output] interval = "2.5 us"` and
`fields = ["v", "p", "eps_p", "D", "eps_nl"]` (dense_case.sh writes that case). The plate's
particles are grouped by the radius r0 they started at, and followed by id: the plug's core
(r0 < 9 mm), its rim (9–10 mm, where the plate fails: the projectile's radius is 10 mm) and the
ring outside it (10–11.5 mm). Each table row, from 40 µs: the projectile's speed; each group's
ring-weighted mean speed along the axis and the share of its weight failed (D = 1); and over the
plate within 7–13 mm of the axis, the largest D and its particle's D/ε̄_p, the largest ε̄_p and
where its particle started, the largest ε_p, and when and where the first particle failed. Last, a
line a run: the first failure, the largest ε̄_p at 50 and 60 µs and ε_p at 60 µs, and the
projectile's speed at 65 µs and at the end.
"""
import glob
import importlib.util
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("shear_band", os.path.join(HERE, "../../../../scripts/shear_band.py"))
shear_band = importlib.util.module_from_spec(spec)
spec.loader.exec_module(shear_band)

GROUPS = {"core": (0, 9), "rim": (9, 10), "ring": (10, 11.5)}
EVERY_US = 2.5


def outputs(run):
    """A dense run's VTK files in time order (every EVERY_US) and where each particle started:
    {id: (r0 mm, y0 mm, body)}, body 0 the projectile and 1 the plate."""
    files = sorted(glob.glob(os.path.join(run, "vtk", "*.vtu")))
    first = shear_band.read_vtu(files[0])
    if "eps_nl" not in first:
        sys.exit(f"{run}: no eps_nl in its VTK; run the case dense_case.sh writes")
    start = {int(i): (p[0] * 1e3, p[1] * 1e3, int(b)) for i, p, b in zip(first["id"], first["Points"], first["body"])}
    return files, start


def projectile_speed(a, start):
    """The projectile's ring-weighted mean speed towards the plate (m/s) in one output."""
    total = weight = 0.0
    for i, p, v in zip(a["id"], a["Points"], a["v"]):
        if start[int(i)][2] == 0:
            total += -v[1] * max(p[0], 1e-9)
            weight += max(p[0], 1e-9)
    return total / weight


def table(run):
    files, start = outputs(run)
    print(f"== {run}: speeds (m/s) along the axis; % of each group's weight failed")
    print("  t µs  proj |   core   % |    rim   % |   ring   % | max D, D/ε̄p there | max ε̄p at (r0, y0 mm) | max εp | first failed at")
    first_failed, seen = None, {}
    for n, path in enumerate(files):
        t = n * EVERY_US
        if t < 40:
            continue
        a = shear_band.read_vtu(path)
        sums = {g: [0.0, 0.0, 0.0] for g in GROUPS}
        most_d, most_nl, at, most_ep, ratio = 0.0, 0.0, None, 0.0, float("nan")
        for i, p, v, d, nl, ep in zip(a["id"], a["Points"], a["v"], a["D"], a["eps_nl"], a["eps_p"]):
            r0, y0, body = start[int(i)]
            weight = max(p[0], 1e-9)  # the ring's: 2π r, the 2π and Δx² alike within a body
            if body == 0:
                continue
            for g, (lo, hi) in GROUPS.items():
                if lo <= r0 < hi:
                    sums[g][0] += -v[1] * weight
                    sums[g][1] += weight
                    sums[g][2] += weight * (d >= 1)
            if 7 <= r0 <= 13:
                most_ep = max(most_ep, ep)
                if d > most_d:
                    most_d, ratio = d, d / nl if nl > 0 else float("nan")
                if nl > most_nl:
                    most_nl, at = nl, (r0, y0)
                if d >= 1 and first_failed is None:
                    first_failed = (t, r0, y0)
        groups = " | ".join(f"{s[0] / s[1]:6.1f} {100 * s[2] / s[1]:3.0f}" for s in sums.values())
        where = f"{first_failed[0]:.1f} µs ({first_failed[1]:.2f}, {first_failed[2]:.2f})" if first_failed else "—"
        proj = projectile_speed(a, start)
        seen[t] = (proj, most_nl, most_ep)
        print(f"{t:6.1f} {proj:5.1f} | {groups} | {most_d:5.3f} {ratio:5.3f} | {most_nl:5.3f} ({at[0]:5.2f}, {at[1]:5.2f}) | {most_ep:4.2f} | {where}")
    end = max(seen)
    return run, first_failed, seen[50][1], seen[60][1], seen[60][2], seen[65][0], seen[end][0], end


if __name__ == "__main__":
    summary = [table(run) for run in sys.argv[1:]]
    print("== run: first failed (µs; r0, y0 mm) | max ε̄p at 50, 60 µs | max εp at 60 µs | projectile at 65 µs, at the end, lost")
    for run, first, nl50, nl60, ep60, v65, v_end, end in summary:
        where = f"{first[0]:5.1f} ({first[1]:.2f}, {first[2]:.2f})" if first else "none"
        print(f"{run}: {where} | {nl50:.3f} {nl60:.3f} | {ep60:.2f} | {v65:.1f}, {v_end:.1f} at {end:.0f} µs, {v65 - v_end:.1f}")
