#!/usr/bin/env python3
"""The exact solution of the Riemann problem of an ideal gas (Toro, *Riemann Solvers and Numerical
Methods for Fluid Dynamics*, ch. 4): the star state (p*, u*, rho*L, rho*R), the wave speeds, and
the profile rho, u, p, e at a time. The references of cases/sod_shock_tube.toml come from here.

    python3 scripts/riemann_exact.py                      # Sod's problem: star state and waves
    python3 scripts/riemann_exact.py --profile 0.2 > exact.csv   # x, rho, u, p, e at t = 0.2 s
    python3 scripts/riemann_exact.py --compare 0.2 out/sod_shock_tube/profiles/tube_1.csv
        # a profile pairsum wrote at t = 0.2 s against the exact solution: the mean |error| per
        # particle of rho, u and p, and the largest pressure error between the waves
"""
import argparse
import math


def pressure_function(p, rho_k, p_k, c_k, g):
    """f_K(p) and its derivative (Toro Eq 4.6, 4.7)."""
    if p > p_k:  # shock
        a = 2.0 / ((g + 1.0) * rho_k)
        b = (g - 1.0) / (g + 1.0) * p_k
        q = math.sqrt(a / (p + b))
        return (p - p_k) * q, q * (1.0 - 0.5 * (p - p_k) / (p + b))
    # rarefaction
    r = p / p_k
    f = 2.0 * c_k / (g - 1.0) * (r ** ((g - 1.0) / (2.0 * g)) - 1.0)
    df = 1.0 / (rho_k * c_k) * r ** (-(g + 1.0) / (2.0 * g))
    return f, df


def star_state(left, right, g):
    (rl, ul, pl), (rr, ur, pr) = left, right
    cl, cr = math.sqrt(g * pl / rl), math.sqrt(g * pr / rr)
    p = max(1e-12, 0.5 * (pl + pr))
    for _ in range(100):
        fl, dfl = pressure_function(p, rl, pl, cl, g)
        fr, dfr = pressure_function(p, rr, pr, cr, g)
        step = (fl + fr + ur - ul) / (dfl + dfr)
        p_new = max(1e-12, p - step)
        if abs(p_new - p) < 1e-15 * (p_new + p):
            p = p_new
            break
        p = p_new
    fl, _ = pressure_function(p, rl, pl, cl, g)
    fr, _ = pressure_function(p, rr, pr, cr, g)
    u = 0.5 * (ul + ur) + 0.5 * (fr - fl)

    def star_density(rho_k, p_k):
        if p > p_k:
            ratio = (g - 1.0) / (g + 1.0)
            return rho_k * (p / p_k + ratio) / (ratio * p / p_k + 1.0)
        return rho_k * (p / p_k) ** (1.0 / g)

    return p, u, star_density(rl, pl), star_density(rr, pr), cl, cr


def sample(xi, left, right, g, star):
    """The state at x/t = xi, for a left rarefaction and a right shock (Sod's case)."""
    (rl, ul, pl), (rr, ur, pr) = left, right
    p, u, rsl, rsr, cl, cr = star
    if xi < u:
        head = ul - cl
        csl = cl * (p / pl) ** ((g - 1.0) / (2.0 * g))
        tail = u - csl
        if xi <= head:
            return rl, ul, pl
        if xi >= tail:
            return rsl, u, p
        c = 2.0 / (g + 1.0) * (cl + 0.5 * (g - 1.0) * (ul - xi))
        v = 2.0 / (g + 1.0) * (cl + 0.5 * (g - 1.0) * ul + xi)
        rho = rl * (c / cl) ** (2.0 / (g - 1.0))
        return rho, v, pl * (c / cl) ** (2.0 * g / (g - 1.0))
    shock = ur + cr * math.sqrt((g + 1.0) / (2.0 * g) * p / pr + (g - 1.0) / (2.0 * g))
    return (rsr, u, p) if xi < shock else (rr, ur, pr)


def compare(t, path, x0, left, right, g, star):
    import csv

    rows = list(csv.DictReader(open(path)))
    keys = ["rho [kg/m^3]", "v.x [m/s]", "p [Pa]"]
    total = [0.0, 0.0, 0.0]
    worst = (0.0, 0.0)
    p, u = star[0], star[1]
    for row in rows:
        x = float(row["x [m]"])
        exact = sample((x - x0) / t, left, right, g, star)
        values = [float(row[k]) for k in keys]
        for k in range(3):
            total[k] += abs(values[k] - exact[k])
        # the blip at the contact: within 0.03 m of it, where the exact pressure is p*
        if abs(x - x0 - u * t) < 0.03 and abs(values[2] - p) > abs(worst[1]):
            worst = (x, values[2] - p)
    n = len(rows)
    print(f"{path}: {n} particles; mean |error| rho {total[0] / n:.5f} kg/m^3, u {total[1] / n:.5f} m/s, "
          f"p {total[2] / n:.5f} Pa; at the contact ({x0 + u * t:.4f} m) the pressure is off by up to "
          f"{worst[1]:+.4f} Pa ({100 * worst[1] / p:+.1f} % of p*) at x = {worst[0]:.4f} m")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gamma", type=float, default=1.4)
    ap.add_argument("--left", type=float, nargs=3, default=[1.0, 0.0, 1.0], metavar=("RHO", "U", "P"))
    ap.add_argument("--right", type=float, nargs=3, default=[0.125, 0.0, 0.1], metavar=("RHO", "U", "P"))
    ap.add_argument("--x0", type=float, default=0.0, help="the diaphragm's position")
    ap.add_argument("--profile", type=float, metavar="T", help="print x, rho, u, p, e at time T")
    ap.add_argument("--compare", nargs=2, metavar=("T", "CSV"), help="compare a pairsum profile at time T")
    ap.add_argument("--x", type=float, nargs=2, default=[-0.5, 0.5], metavar=("FROM", "TO"))
    ap.add_argument("--points", type=int, default=1001)
    a = ap.parse_args()
    g, left, right = a.gamma, tuple(a.left), tuple(a.right)
    star = star_state(left, right, g)
    if a.compare:
        compare(float(a.compare[0]), a.compare[1], a.x0, left, right, g, star)
        return
    if a.profile is None:
        p, u, rsl, rsr, cl, cr = star
        shock = right[1] + cr * math.sqrt((g + 1) / (2 * g) * p / right[2] + (g - 1) / (2 * g))
        tail = u - cl * (p / left[2]) ** ((g - 1) / (2 * g))
        print(f"p* = {p:.6f}, u* = {u:.6f}, rho*L = {rsl:.6f}, rho*R = {rsr:.6f}")
        print(f"e*L = {p / ((g - 1) * rsl):.6f}, e*R = {p / ((g - 1) * rsr):.6f}")
        print(f"rarefaction head {left[1] - cl:.6f}, tail {tail:.6f}, contact {u:.6f}, shock {shock:.6f} (speeds)")
        return
    t = a.profile
    print("x,rho,u,p,e")
    for k in range(a.points):
        x = a.x[0] + (a.x[1] - a.x[0]) * k / (a.points - 1)
        rho, u, p = sample((x - a.x0) / t, left, right, g, star)
        print(f"{x:.6f},{rho:.6f},{u:.6f},{p:.6f},{p / ((g - 1) * rho):.6f}")


if __name__ == "__main__":
    main()
