"""The plate's most strained particles at the end of a run with a plate profile (stop 113).
    python3 corner_particle.py RUN...          the largest ε_p, where it started and how far it stands out
    python3 corner_particle.py --track RUN...  the two largest: ε_p and x at each profile time
A run's profiles come from the case with profiles_40us.toml or profiles_track.toml appended (README).
"""
import csv
import glob
import sys

from history_diff import load


def profile(path):
    """One profile CSV as a list of dicts, the units dropped from the column names."""
    return [{k.split(" ")[0]: float(v) for k, v in row.items()} for row in csv.DictReader(open(path))]


def origin(p):
    """Where a plate particle started (mm): its position less its displacement."""
    return (p["x"] - p["u.x"]) * 1e3, (p["y"] - p["u.y"]) * 1e3


def profiles(run):
    return [profile(f) for f in sorted(glob.glob(run + "/profiles/plate_*.csv"), key=lambda f: int(f[f.rindex("_") + 1 : -4]))]


def summary(run):
    series = profiles(run)
    if not series:
        return print(f"{run:<12} no plate profile")
    last = series[-1]
    first, second = sorted(last, key=lambda p: -p["eps_p"])[:2]
    X, Y = origin(first)
    print(f"{run:<12} {load(run)[1][-1]:8.3f} {first['eps_p']:6.3f}  ({X:6.3f}, {Y:6.3f})  {second['eps_p']:6.3f}  {first['eps_p'] / second['eps_p']:5.2f}")


def track(run):
    series = profiles(run)
    print(run)
    for top in sorted(series[-1], key=lambda p: -p["eps_p"])[:2]:
        X, Y = origin(top)
        path = [next(p for p in P if p["id"] == top["id"]) for P in series]
        print(f"  from ({X:.3f}, {Y:.3f}) mm: ε_p " + " ".join(f"{p['eps_p']:.2f}" for p in path))
        print("      at x (mm)              " + " ".join(f"{p['x'] * 1e3:.2f}" for p in path))


if __name__ == "__main__":
    if sys.argv[1] == "--track":
        for run in sys.argv[2:]:
            track(run)
    else:
        print("run          speed    ε_p max  from (X, Y) mm        next   ratio")
        for run in sys.argv[1:]:
            summary(run)
