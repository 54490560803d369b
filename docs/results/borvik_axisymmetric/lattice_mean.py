"""Each Børvik level as a mean over five projectile radii (stop 115).
    python3 lattice_mean.py              (from docs/results/borvik_axisymmetric/)
For both plates, prints each level's residual speeds at 150 us with the projectile's radius
9.90 / 9.95 / 10.00 / 10.05 / 10.10 mm, their mean, standard error and spread, and the
`pairsum uncertainty` arguments (Δx in mm, SPACING=MEAN±SE) over the levels named below. The
runs are `e8_r<R>_k<k>` and `e12_r<R>_k<k>` (Δx = 4 mm / k; R in hundredths of a mm), the 8 mm
plate at ℓ = 4 mm `L4_8_r<R>_k<k>`; stop 114's three radii (`z8r099_k*`, `z8r100_k*`,
`z8r101_k*`, `z8_*`) stand in where this stop did not run a radius (k = 9, 11, 13–16).
"""
import os
import statistics

RADII = ["0990", "0995", "1000", "1005", "1010"]
# Stop 114's names for the three radii it ran, where this stop did not rerun them.
OLDER = {"0990": "z8r099_k{k}", "1000": "z8r100_k{k}", "1010": "z8r101_k{k}"}
COMMITTED_8 = {9: "z8_k9", 11: "z8r100_k11", 13: "z8r100_k13", 14: "z8_k14", 15: "z8r100_k15", 16: "z8_l250"}


def residual(run):
    """The projectile's residual speed (m/s) from a run's report, or None where it was not run."""
    path = run + "/report.md"
    if not os.path.exists(path):
        return None
    for line in open(path):
        if line.startswith("| projectile_residual_velocity"):
            return float(line.split("|")[4])


def level(prefix, k):
    values = {}
    for r in RADII:
        v = residual(f"{prefix}_r{r}_k{k}")
        if v is None and prefix == "e8":
            v = residual(COMMITTED_8.get(k, "-") if r == "1000" else OLDER.get(r, "-").format(k=k))
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


if __name__ == "__main__":
    eight = table("e8", range(4, 17))
    print("  all levels:   " + arguments(eight, range(4, 17)))
    print("  from 0.5 mm:  " + arguments(eight, range(8, 17)))
    print("  from 0.444 mm: " + arguments(eight, range(9, 17)))
    twelve = table("e12", range(4, 13))
    print("  all levels:   " + arguments(twelve, range(4, 13)))
    print("  from 0.667 mm: " + arguments(twelve, range(6, 13)))
    table("L4_8", range(4, 9))
