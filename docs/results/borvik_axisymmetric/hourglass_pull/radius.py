#!/usr/bin/env python3
"""How much of the edge places' scatter is the projectile's radius (stop 128).

    python3 docs/results/borvik_axisymmetric/hourglass_pull/radius.py

`edge_phase` φ moves the projectile's edge on the plate's lattice by moving its radius:
R = 10 mm + φ Δx (cases/borvik_axisymmetric.toml), so its mass by 2 φ Δx / 10 mm and the
perimeter it shears by φ Δx / 10 mm. That is a change of the problem, not of the lattice alone.
The symmetric places −0.4 … +0.4 cancel it to first order in the level's mean, but it is counted
as noise in the level's standard error. For the m = −3 runs with the weakened pull over five
places (dwm3<place>_<plate>_k<k>, stop 127; on 12 mm nine places from 0.667 to 0.333 mm, stop 128),
this prints, per plate,
  - the slope dv/dR from the energy balance: with the plate's work W ∝ R and the projectile's and
    plug's masses ∝ R², v_r² = a (v_i² − b / R), so dv_r/dR = (a v_i² − v_r²) / (2 v_r R), with
    a = M / (M + m_plug) (M = 197 g, the plug a disc of the projectile's radius through the plate);
  - one slope common to all levels (each its own intercept), fitted to the places: it mixes the
    radius with the lattice's own dependence on the place, which over one period correlates with
    φ, so it is shown, not used;
  - the slope measured directly, from runs at R = 9.5 / 10.5 mm (0.5 mm, k = 8; both plates) and
    9.6 / 10.4 mm (0.4 mm, k = 10; 12 mm) with the edge at place 0 on their lattice
    (r95_<plate>_k8, r105_<plate>_k8, r96_12_k10, r104_12_k10);
  - each level's values with the measured slope taken out, v − (dv/dR) φ Δx, their mean and
    standard error beside the values as run, and the `pairsum uncertainty` arguments."""
import math
import os
import statistics as st
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "lattice_conserving"))
import lattice  # noqa: E402

FIVE = {"m04": -0.4, "m02": -0.2, "0": 0.0, "p02": 0.2, "p04": 0.4}
# Stop 128 added −0.3, −0.1, +0.1 and +0.3 on 12 mm from 0.667 to 0.333 mm: nine places there.
PLACES = dict(FIVE, m03=-0.3, m01=-0.1, p01=0.1, p03=0.3)
KS = (6, 8, 10, 12, 16)
IMPACT = {8: 298.0, 12: 399.6}  # m/s


def folder(plate, place, k):
    return os.path.join(HERE, f"dwm3{'' if place == '0' else place}_{plate}_k{k}")


def levels(plate):
    """{k: [(φ Δx in mm, residual)]} for the levels with the five places run, with any more."""
    out = {}
    for k in KS:
        run = {p: lattice.residual(plate, p, k, folder) for p in PLACES}
        if all(run[p] is not None for p in FIVE):
            out[k] = sorted((PLACES[p] * 4 / k, v) for p, v in run.items() if v is not None)
    return out


def common_slope(data):
    """The slope of v on the radius's shift, one for all levels, each level its own intercept:
    the slope of the values about their level's mean on the shifts about theirs."""
    centred = []
    for runs in data.values():
        mx = st.mean(x for x, _ in runs)
        my = st.mean(v for _, v in runs)
        centred += [(x - mx, v - my) for x, v in runs]
    sxx = sum(x * x for x, _ in centred)
    slope = sum(x * v for x, v in centred) / sxx
    dof = len(centred) - len(data) - 1
    rss = sum((v - slope * x) ** 2 for x, v in centred)
    return slope, math.sqrt(rss / dof / sxx)


def balance_slope(plate, v_r, radius=10.0):
    plug = 7850 * math.pi * (radius * 1e-3) ** 2 * plate * 1e-3  # kg
    a = 0.197 / (0.197 + plug)
    return (a * IMPACT[plate] ** 2 - v_r ** 2) / (2 * v_r * radius)  # m/s per mm


def report(plate):
    data = levels(plate)
    if not data:
        return
    finest = st.mean(v for _, v in data[max(data)])
    fitted, se = common_slope(data)
    print(f"== {plate} mm: dv/dR from the energy balance {balance_slope(plate, finest):.1f} m/s per mm; "
          f"fitted to the places, one slope for all levels, {fitted:.1f} ± {se:.1f}; measured:")
    measured = direct_slopes(plate)
    if not measured:
        return
    slope = st.mean(measured)
    print(f"  each level with the measured {slope:.2f} m/s per mm taken out, v − (dv/dR) φ Δx:")
    args = []
    for k, runs in data.items():
        raw = [v for _, v in runs]
        taken = [v - slope * x for x, v in runs]
        sd = st.stdev(taken) / len(taken) ** 0.5
        print(f"  Δx {4 / k:.3f} mm: " + " / ".join(f"{v:.2f}" for v in taken)
              + f"   mean {st.mean(taken):.2f} ± {sd:.2f} (as run {st.mean(raw):.2f} ± {st.stdev(raw) / len(raw) ** 0.5:.2f},"
              + f" n = {len(raw)})")
        args.append(f"{4 / k:.6g}={st.mean(taken):.3f}±{sd:.3f}")
    print("  pairsum uncertainty " + " ".join(args))


RADIUS_RUNS = ((12, "r95", "r105", 8), (12, "r96", "r104", 10), (8, "r95", "r105", 8))


def direct_slopes(plate):
    """dv/dR from the runs at two radii with the edge at place 0 on their lattice, printed."""
    slopes = []
    for p, small, large, k in RADIUS_RUNS:
        v = [lattice.residual(p, "0", k, lambda pp, ph, kk, n=n: os.path.join(HERE, f"{n}_{pp}_k{kk}"))
             for n in (small, large)]
        if p != plate or None in v:
            continue
        middle = lattice.residual(plate, "0", k, folder)
        dr = (int(large[1:]) - int(small[1:])) / 10
        slopes.append((v[1] - v[0]) / dr)
        print(f"  Δx {4 / k:.3f} mm, R {int(small[1:]) / 10} / 10 / {int(large[1:]) / 10} mm at edge place 0: "
              f"{v[0]:.2f} / {middle:.2f} / {v[1]:.2f} m/s, slope {slopes[-1]:.1f} m/s per mm")
    return slopes


if __name__ == "__main__":
    for plate in (12, 8):
        report(plate)
