"""Each Børvik level as a mean over five projectile radii (stop 115).
    python3 lattice_mean.py              (from docs/results/borvik_axisymmetric/)
For both plates, prints each level's residual speeds at 150 us with the projectile's radius
9.90 / 9.95 / 10.00 / 10.05 / 10.10 mm, their mean, standard error and spread, and the
`pairsum uncertainty` arguments (Δx in mm, SPACING=MEAN±SE) over the levels named below. The
runs are `m8_r<R>_k<k>` and `m12_r<R>_k<k>` (Δx = 4 mm / k; R in hundredths of a mm), the 8 mm
plate at ℓ = 4 mm `m8l4_r<R>_k<k>`, and each plate with the edge moved by a fraction of the
spacing (`edge_phase` −0.4 … +0.4) `p8_<phase>_k<k>` and `p12_<phase>_k<k>` (phase m04, m02, 0,
p02, p04; stop 116 added k = 16 and the 12 mm plate, whose phase 0 is the committed case's
`z12_*`, `m12_r1000_k5`); stop 114's three radii (`z8r099_k*`, `z8r100_k*`,
`z8r101_k*`, `z8_*`, `z12_*`, `z12r099_*`, `z12r101_*`) stand in where this stop did not run a
radius (k = 9, 11, 13–16) or reran it to the same digits (not kept twice). Stop 117 added the
8 mm plate at k = 20 and `timeline`: each level's period mean of the projectile's speed over time,
from the runs' histories.csv.
"""
import csv
import glob
import statistics

from phase_average import residual  # the residual speed from a run's report.md

RADII = ["0990", "0995", "1000", "1005", "1010"]
# Stop 114's names for the three radii it ran, where this stop did not rerun them.
OLDER = {"0990": "z8r099_k{k}", "1000": "z8r100_k{k}", "1010": "z8r101_k{k}"}
COMMITTED_8 = {4: "z8_l1000", 5: "z8_k5", 6: "z8_l667", 7: "z8_k7", 8: "z8_l500", 9: "z8_k9", 10: "z8_l400",
               11: "z8r100_k11", 12: "z8_l333", 13: "z8r100_k13", 14: "z8_k14", 15: "z8r100_k15", 16: "z8_l250"}
# The 12 mm plate's, from stops 108 and 114.
COMMITTED_12 = {4: "z12_l1000", 6: "z12_l667", 8: "z12_l500", 10: "z12_l400", 12: "z12_l333"}


def level(prefix, k):
    values = {}
    for r in RADII:
        v = residual(f"{prefix}_r{r}_k{k}")
        if v is None and prefix in ("m8", "m12"):
            committed = COMMITTED_8 if prefix == "m8" else COMMITTED_12
            older = OLDER.get(r, "-").replace("z8", "z" + prefix[1:])
            v = residual(committed.get(k, "-") if r == "1000" else older.format(k=k))
        if v is not None:
            values[r] = v
    return values


def table(prefix, ks):
    print(f"{prefix}: k  dx (mm)  " + "  ".join(f"R {r}" for r in RADII) + "    mean ± se     spread")
    levels = []
    for k in ks:
        v = level(prefix, k)
        if len(v) < 2:
            continue
        mean = statistics.mean(v.values())
        se = statistics.stdev(v.values()) / len(v) ** 0.5
        cells = "  ".join(f"{v[r]:7.2f}" if r in v else "     — " for r in RADII)
        print(f"  {k:<3} {4 / k:7.4f}  {cells}   {mean:7.2f} ± {se:4.2f}  {max(v.values()) - min(v.values()):5.2f}")
        levels.append((k, mean, se))
    return levels


def arguments(levels, ks):
    return "pairsum uncertainty " + " ".join(f"{4 / k:.6g}={m:.4f}±{s:.4f}" for k, m, s in levels if k in ks)


PHASES = ["m04", "m02", "0", "p02", "p04"]


def phase_folder(plate, phase, k):
    """The run with the edge at `phase`; at phase 0 the 12 mm plate's is the committed case's."""
    name = f"p{plate}_{phase}_k{k}"
    if plate == 12 and residual(name) is None:
        if phase == "0":
            name = COMMITTED_12.get(k, {5: "m12_r1000_k5", 16: "z12_l250"}.get(k, "-"))
        elif k == 8:
            # ±0.2 at 0.5 mm are the radii 9.9 and 10.1 mm of stop 114.
            name = {"m02": "z12r099_k8", "p02": "z12r101_k8"}.get(phase, name)
    if plate == 8 and k == 16 and residual(name) is None:
        # Phase 0 and ±0.4 (the radii 10.0, 9.9 and 10.1 mm) are stop 108's and 114's runs,
        # which stop 116's reruns matched to the last digit.
        name = {"0": COMMITTED_8[16], "m04": "z8r099_k16", "p04": "z8r101_k16"}.get(phase, name)
    return name


def phase_run(plate, phase, k):
    """The projectile's residual speed with the edge at `phase`, or None where not run."""
    return residual(phase_folder(plate, phase, k))


def phase_table(plate, ks):
    """A plate at each level with its edge at five places over one period of the lattice."""
    print(f"p{plate}: k  dx (mm)  " + "  ".join(f"{p:>7}" for p in PHASES) + "    mean ± se     spread")
    levels = []
    for k in ks:
        v = [phase_run(plate, p, k) for p in PHASES]
        if None in v:
            continue
        mean, se = statistics.mean(v), statistics.stdev(v) / len(v) ** 0.5
        cells = "  ".join(f"{x:7.2f}" for x in v)
        print(f"  {k:<3} {4 / k:7.4f}  {cells}   {mean:7.2f} ± {se:4.2f}  {max(v) - min(v):5.2f}")
        levels.append((k, mean, se))
    print("  " + arguments(levels, ks))


def every_radius():
    """The 8 mm plate at 0.5 mm (k = 8) at every radius run, 9.80 to 10.20 mm."""
    found = {r.split("_r")[1][:4]: residual(r) for r in glob.glob("m8_r*_k8")}
    found.update({r: v for r, v in level("m8", 8).items() if r not in found})
    values = sorted((int(r) / 100, v) for r, v in found.items() if v is not None)
    print("m8 at k = 8: " + ", ".join(f"{r:.2f} mm {v:.2f}" for r, v in values))
    speeds = [v for _, v in values]
    sd = statistics.stdev(speeds)
    print(f"  {len(speeds)} radii: mean {statistics.mean(speeds):.2f}, standard deviation {sd:.2f}, "
          f"standard error {sd / len(speeds) ** 0.5:.2f}, range {min(speeds):.2f}–{max(speeds):.2f} m/s")


def phase_name(phase):
    """edge_phase as the run names write it: -0.4 -> m04, 1.0 -> p10, 0 -> 0."""
    if phase == 0:
        return "0"
    return ("m" if phase < 0 else "p") + f"{abs(phase):.1f}".replace(".", "")


def two_periods():
    """The 8 mm plate at 0.5 mm over two periods of the lattice (stop 116): the radius 9.5 to 10.5 mm
    in steps of 0.1 mm (edge_phase -1.0 ... +1.0). Pairs one spacing apart sit at the same place on
    the lattice; what differs between them is the radius itself."""
    phases = [round(-1.0 + 0.2 * i, 1) for i in range(11)]
    v = {f: phase_run(8, phase_name(f), 8) for f in phases}
    print("p8 at k = 8, radius 9.5 ... 10.5 mm: " + ", ".join(f"{10 + f / 2:.1f} {x:.2f}" for f, x in v.items() if x))
    steps = [v[round(f + 1.0, 1)] - v[f] for f in phases if f + 1.0 <= 1.0 and v.get(f) and v.get(round(f + 1.0, 1))]
    slope = statistics.mean(steps) / 0.5
    print("  one spacing (0.5 mm) apart: " + ", ".join(f"{d:+.2f}" for d in steps)
          + f" m/s; mean {statistics.mean(steps):+.2f}, the radius's own slope {slope:.2f} m/s per mm")
    flat = {f: x - slope * f / 2 for f, x in v.items() if x}
    by_phase = {}
    for f, x in flat.items():
        by_phase.setdefault(round(f % 1.0, 1) % 1.0, []).append(x)
    print("  less that slope, by place on the lattice (edge_phase mod 1): " + ", ".join(
        f"{p:.1f}: " + "/".join(f"{x:.2f}" for x in xs) for p, xs in sorted(by_phase.items())))
    means = [statistics.mean(xs) for xs in by_phase.values()]
    print(f"  the period's mean {statistics.mean(means):.2f}, its swing {max(means) - min(means):.2f} m/s; "
          f"runs at one place differ by {max(max(xs) - min(xs) for xs in by_phase.values() if len(xs) > 1):.2f} at most")


def speeds_at(run, times):
    """The projectile's speed (m/s) at each of `times` (s) in a run's histories.csv, linearly
    interpolated (the last recorded speed beyond its end)."""
    with open(run + "/histories.csv") as f:
        rows = list(csv.reader(f))
    col = rows[0].index("projectile_velocity [m/s]")
    points = [(float(r[0]), abs(float(r[col]))) for r in rows[1:]]

    def at(t):
        for (t0, v0), (t1, v1) in zip(points, points[1:]):
            if t0 <= t <= t1:
                return v0 + (v1 - v0) * (t - t0) / (t1 - t0) if t1 > t0 else v0
        return points[-1][1]

    return [at(t) for t in times]


def timeline(plate, ks, times_us, uncertain_at=()):
    """The period's mean of the projectile's speed over time at each level (stop 117): where in the
    perforation the levels part. With `pairsum uncertainty` arguments at the times `uncertain_at`."""
    print(f"p{plate} over time (us): k " + " ".join(f"{t:7g}" for t in times_us))
    means = {}
    for k in ks:
        runs = [phase_folder(plate, p, k) for p in PHASES]
        if any(residual(r) is None for r in runs):
            continue
        rows = [speeds_at(r, [t * 1e-6 for t in times_us]) for r in runs]
        means[k] = [(statistics.mean(c), statistics.stdev(c) / len(c) ** 0.5) for c in zip(*rows)]
        print(f"  {k:<3} " + " ".join(f"{m:7.2f}" for m, _ in means[k]))
    for t in uncertain_at:
        i = list(times_us).index(t)
        print(f"  at {t} us: " + arguments([(k, m[i][0], m[i][1]) for k, m in means.items()], ks))


if __name__ == "__main__":
    eight = table("m8", range(4, 17))
    print("  all levels:   " + arguments(eight, range(4, 17)))
    print("  from 0.5 mm:  " + arguments(eight, range(8, 17)))
    print("  from 0.444 mm: " + arguments(eight, range(9, 17)))
    twelve = table("m12", range(4, 13))
    print("  all levels:   " + arguments(twelve, range(4, 13)))
    print("  from 0.667 mm: " + arguments(twelve, range(6, 13)))
    table("m8l4", range(4, 9))
    every_radius()
    phase_table(8, range(4, 21))
    phase_table(12, range(4, 17))
    two_periods()
    timeline(8, range(8, 21), [20, 40, 50, 55, 60, 61, 62, 63, 64, 65, 70, 80, 100, 150], (50, 60, 150))
    timeline(12, range(4, 17), [20, 40, 50, 51, 52, 53, 54, 55, 60, 80, 100, 150], (40, 50, 150))
