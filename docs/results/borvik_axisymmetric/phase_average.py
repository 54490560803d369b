"""The full 8 mm runs with the projectile's radius 9.9, 10.0 and 10.1 mm at each spacing, and their mean (stop 114).
    python3 phase_average.py            (from docs/results/borvik_axisymmetric/)
Prints each level's three residual speeds at 150 us, their mean and spread, and the
`pairsum uncertainty` arguments for the means (Δx in mm).
"""
import os

# The committed case (radius 10.0 mm) was run before under these names.
COMMITTED = {8: "z8_l500", 9: "z8_k9", 10: "z8_l400", 12: "z8_l333", 14: "z8_k14", 16: "z8_l250"}


def residual(run):
    """The projectile's residual speed (m/s) from a run's report, or None where it was not run."""
    path = run + "/report.md"
    if not os.path.exists(path):
        return None
    for line in open(path):
        if line.startswith("| projectile_residual_velocity"):
            return float(line.split("|")[4])


def level(k):
    runs = [f"z8r099_k{k}", COMMITTED.get(k, f"z8r100_k{k}"), f"z8r101_k{k}"]
    return [residual(run) for run in runs]


if __name__ == "__main__":
    print("k    dx (mm)  R 9.9    10.0    10.1     mean  spread")
    means = []
    for k in range(8, 17):
        values = level(k)
        if None in values:
            print(f"{k:<4} {4 / k:7.4f}  " + "  ".join("   —  " if v is None else f"{v:6.2f}" for v in values))
            continue
        mean = sum(values) / 3
        means.append((4 / k, mean))
        print(f"{k:<4} {4 / k:7.4f}  " + "  ".join(f"{v:6.2f}" for v in values) + f"   {mean:6.2f}  {max(values) - min(values):5.2f}")
    print("pairsum uncertainty " + " ".join(f"{dx:.4f}={m:.3f}" for dx, m in means))
