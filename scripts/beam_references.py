#!/usr/bin/env python3
"""Reference values for the 2D elastic beam cases, by plane-strain finite elements.

  cases/cantilever_2d.toml:  the mean vertical displacement of the last 25 mm of a 0.5 × 0.1 m
                             cantilever under 100 N per metre of depth spread over those 25 mm;
  cases/beam_vibration_2d.toml: the period of the first bending mode of a 0.2 × 0.02 m cantilever.
  cases/clamped_plate_2d.toml: the mean vertical displacement of the middle 20 mm of a 0.4 × 0.04 m
                             strip clamped at both ends (a plate in cylindrical bending) under a
                             uniform load of 100 Pa × 0.4 m spread by volume (a body force).
  cases/water_on_plate_tl_2d.toml: the same strip under 0.1 m of water at rest (its pressure
                             ρ g H = 981 Pa on the top face) and its own weight (ρ g t by volume).

  cases/cantilever.toml's probe: the same for the 0.5 × 0.1 × 0.1 m LSR beam in 3D under 10 N (Q27
                             elements to 8 deep; the clamp's edges and corners make them converge
                             slowly, so the finest mesh is the reference). That case compares the
                             mean over its last 25 mm with LSR's 5.153 mm, the tip's deflection
                             under a point load at the tip: 9 % more than this.

All beams are clamped over their whole depth at x = 0 (and the plate at x = L too: all
displacements zero, as the fixed particles beyond the span hold them), E = 10 MPa, ν = 0.3, ρ = 1000 kg/m³. Biquadratic (Q9)
elements on meshes refined three times; the printed reference is Richardson's extrapolation of
the two finest. Beam theories for comparison: Timoshenko's deflection (E' = E/(1 − ν²), κ = 5/6)
and the Euler–Bernoulli period, 2π / (1.8751² √(E'I / (ρ A L⁴))); for the plate, plate theory
with Timoshenko's shear term, w = q L⁴ / (384 D) + q L² / (8 κ G t).

Needs numpy and scipy (python3 -m pip install numpy scipy). Runs in a few seconds.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

E, NU, RHO = 10e6, 0.3, 1000.0


def shape_1d(s):
    return np.array([s * (s - 1) / 2, 1 - s * s, s * (s + 1) / 2]), np.array([s - 0.5, -2 * s, s + 0.5])


def assemble(length, depth, nx, ny, clamped_ends=1):
    """Stiffness and consistent mass of a Q9 mesh of nx × ny elements; node (i, j) is i * NY + j.
    The end x = 0 is clamped, and with `clamped_ends = 2` the end x = length too."""
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    c = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    n_y = 2 * ny + 1
    hx, hy = length / nx, depth / ny
    gauss, weights = np.polynomial.legendre.leggauss(3)
    ke, me, ne = np.zeros((18, 18)), np.zeros((18, 18)), np.zeros(9)
    for a, wa in zip(gauss, weights):
        for b, wb in zip(gauss, weights):
            na, dna = shape_1d(a)
            nb, dnb = shape_1d(b)
            n = np.outer(na, nb).ravel()
            dnx = np.outer(dna, nb).ravel() * 2 / hx
            dny = np.outer(na, dnb).ravel() * 2 / hy
            bm = np.zeros((3, 18))
            bm[0, 0::2], bm[1, 1::2], bm[2, 0::2], bm[2, 1::2] = dnx, dny, dny, dnx
            jw = hx * hy / 4 * wa * wb
            ke += bm.T @ c @ bm * jw
            nn = np.zeros((2, 18))
            nn[0, 0::2], nn[1, 1::2] = n, n
            me += RHO * nn.T @ nn * jw
            ne += n * jw
    rows, cols, kv, mv, elements = [], [], [], [], []
    for ex in range(nx):
        for ey in range(ny):
            ids = np.array([(2 * ex + i) * n_y + 2 * ey + j for i in range(3) for j in range(3)])
            dofs = np.stack([2 * ids, 2 * ids + 1], 1).ravel()
            rows.append(np.repeat(dofs, 18))
            cols.append(np.tile(dofs, 18))
            kv.append(ke.ravel())
            mv.append(me.ravel())
            elements.append(((ex + 0.5) * hx, ids))
    size = 2 * (2 * nx + 1) * n_y
    r, cc = np.concatenate(rows), np.concatenate(cols)
    k = sp.csr_matrix((np.concatenate(kv), (r, cc)), shape=(size, size))
    m = sp.csr_matrix((np.concatenate(mv), (r, cc)), shape=(size, size))
    free = np.ones(size, bool)
    free[: 2 * n_y] = False  # the clamped end x = 0
    if clamped_ends == 2:
        free[-2 * n_y :] = False  # and x = length
    return k, m, free, elements, ne


def cantilever_mean_deflection(ny, length=0.5, depth=0.1, load=100.0, end=0.025):
    nx = 5 * ny
    k, _, free, elements, ne = assemble(length, depth, nx, ny)
    f = np.zeros(k.shape[0])
    loaded = [ids for xc, ids in elements if xc > length - end]
    for ids in loaded:
        f[2 * ids + 1] -= load / (end * depth) * ne
    u = np.zeros(k.shape[0])
    u[free] = spl.spsolve(k[free][:, free].tocsc(), f[free])
    return -sum(ne @ u[2 * ids + 1] for ids in loaded) / (len(loaded) * ne.sum())


def clamped_plate_mean_deflection(ny, length=0.4, depth=0.04, load=40.0, strip=(0.19, 0.21)):
    """The strip clamped at both ends under `load` (N per metre of depth) spread by volume; the
    area mean of u_y over the strip (whole elements: nx is a multiple of 20)."""
    nx = 10 * ny
    k, _, free, elements, ne = assemble(length, depth, nx, ny, clamped_ends=2)
    f = np.zeros(k.shape[0])
    for _, ids in elements:
        f[2 * ids + 1] -= load / (length * depth) * ne
    u = np.zeros(k.shape[0])
    u[free] = spl.spsolve(k[free][:, free].tocsc(), f[free])
    inside = [ids for xc, ids in elements if strip[0] < xc < strip[1]]
    return -sum(ne @ u[2 * ids + 1] for ids in inside) / (len(inside) * ne.sum())


def clamped_plate_under_water_mean_deflection(ny, length=0.4, depth=0.04, water=981.0, weight=392.4, strip=(0.19, 0.21)):
    """The strip of `clamped_plate_mean_deflection` under a pressure `water` (Pa) on its top face
    (consistent nodal loads of each element's top edge) and its own weight `weight` (Pa, by
    volume); the area mean of u_y over the strip."""
    nx = 10 * ny
    k, _, free, elements, ne = assemble(length, depth, nx, ny, clamped_ends=2)
    n_y, hx = 2 * ny + 1, length / nx
    f = np.zeros(k.shape[0])
    for _, ids in elements:
        f[2 * ids + 1] -= weight / depth * ne
    for ex in range(nx):
        for i, share in enumerate((1 / 6, 4 / 6, 1 / 6)):
            f[2 * ((2 * ex + i) * n_y + 2 * ny) + 1] -= water * hx * share
    u = np.zeros(k.shape[0])
    u[free] = spl.spsolve(k[free][:, free].tocsc(), f[free])
    inside = [ids for xc, ids in elements if strip[0] < xc < strip[1]]
    return -sum(ne @ u[2 * ids + 1] for ids in inside) / (len(inside) * ne.sum())


def first_period(ny, length=0.2, depth=0.02):
    nx = 10 * ny
    k, m, free, _, _ = assemble(length, depth, nx, ny)
    kf, mf = k[free][:, free].tocsc(), m[free][:, free].tocsc()
    w2 = spl.eigsh(kf, k=1, M=mf, sigma=0, which="LM")[0][0]
    return 2 * np.pi / np.sqrt(w2)


def cantilever_3d_mean_deflection(ny, length=0.5, depth=0.1, load=10.0, end=0.025):
    """cases/cantilever.toml's beam (0.5 × 0.1 × 0.1 m) clamped at x = 0, 10 N spread by volume
    over its last 25 mm; the volume mean of u_y there (the case's probe). Q27 elements."""
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    c = np.zeros((6, 6))
    c[:3, :3] = lam
    c[np.arange(3), np.arange(3)] += 2 * mu
    c[np.arange(3, 6), np.arange(3, 6)] = mu
    nx = 20 * -(-5 * ny // 20)  # a whole number of elements in the loaded 25 mm
    h = (length / nx, depth / ny, depth / ny)
    n_nodes = (2 * nx + 1, 2 * ny + 1, 2 * ny + 1)
    gauss, weights = np.polynomial.legendre.leggauss(3)
    ke, ne = np.zeros((81, 81)), np.zeros(27)
    for a, wa in zip(gauss, weights):
        for b, wb in zip(gauss, weights):
            for g, wg in zip(gauss, weights):
                (na, dna), (nb, dnb), (ng, dng) = shape_1d(a), shape_1d(b), shape_1d(g)
                n = np.einsum("i,j,k->ijk", na, nb, ng).ravel()
                dn = [
                    np.einsum("i,j,k->ijk", dna, nb, ng).ravel() * 2 / h[0],
                    np.einsum("i,j,k->ijk", na, dnb, ng).ravel() * 2 / h[1],
                    np.einsum("i,j,k->ijk", na, nb, dng).ravel() * 2 / h[2],
                ]
                bm = np.zeros((6, 81))
                for k in range(3):
                    bm[k, k::3] = dn[k]
                for row, (p, q) in zip((3, 4, 5), ((1, 2), (0, 2), (0, 1))):
                    bm[row, p::3], bm[row, q::3] = dn[q], dn[p]
                jw = h[0] * h[1] * h[2] / 8 * wa * wb * wg
                ke += bm.T @ c @ bm * jw
                ne += n * jw
    node = lambda i, j, k: (i * n_nodes[1] + j) * n_nodes[2] + k  # noqa: E731
    rows, cols, vals, loaded = [], [], [], []
    for ex in range(nx):
        for ey in range(ny):
            for ez in range(ny):
                ids = np.array(
                    [node(2 * ex + i, 2 * ey + j, 2 * ez + k) for i in range(3) for j in range(3) for k in range(3)]
                )
                dofs = np.stack([3 * ids, 3 * ids + 1, 3 * ids + 2], 1).ravel()
                rows.append(np.repeat(dofs, 81))
                cols.append(np.tile(dofs, 81))
                vals.append(ke.ravel())
                if (ex + 0.5) * h[0] > length - end:
                    loaded.append(ids)
    size = 3 * n_nodes[0] * n_nodes[1] * n_nodes[2]
    k = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size))
    f = np.zeros(size)
    for ids in loaded:
        f[3 * ids + 1] -= load / (end * depth * depth) * ne
    free = np.ones(size, bool)
    free[: 3 * n_nodes[1] * n_nodes[2]] = False
    u = np.zeros(size)
    u[free] = spl.spsolve(k[free][:, free].tocsc(), f[free])
    return -sum(ne @ u[3 * ids + 1] for ids in loaded) / (len(loaded) * ne.sum())


def richardson(values):
    (a, b, c) = values[-3:]
    p = np.log(abs((b - a) / (c - b))) / np.log(2)
    return c + (c - b) / (2**p - 1), p


def print_refinement(title, meshes, value_of, unit):
    """Prints a value on Q9 meshes `meshes` elements deep and its Richardson extrapolation."""
    values = [value_of(n) for n in meshes]
    limit, order = richardson(values)
    print(title)
    for n, v in zip(meshes, values):
        print(f"  Q9, {n:2d} elements deep: {v:.7e} {unit}")
    print(f"  Richardson (order {order:.2f}): {limit:.6e} {unit}")


def main():
    ep = E / (1 - NU**2)
    g = E / (2 * (1 + NU))
    meshes = [4, 8, 16, 32]
    print_refinement("cantilever_2d: mean deflection of the last 25 mm", meshes, cantilever_mean_deflection, "m")
    x = np.linspace(0, 0.5, 200001)
    # Timoshenko for the same load, averaged over the same span
    load, end, length, depth = 100.0, 0.025, 0.5, 0.1
    shear = np.where(x < length - end, load, load / end * (length - x))
    moment = np.flip(np.concatenate([[0], np.cumsum(np.flip((shear[1:] + shear[:-1]) / 2 * np.diff(x)))]))
    inertia = depth**3 / 12

    def integrate(y):
        return np.concatenate([[0], np.cumsum((y[1:] + y[:-1]) / 2 * np.diff(x))])

    w = integrate(integrate(moment / (ep * inertia))) + integrate(shear / (5 / 6 * g * depth))
    span = x >= length - end
    print(f"  Timoshenko beam, same load and span: {np.trapezoid(w[span], x[span]) / end:.5e} m")
    print_refinement("clamped_plate_2d: mean deflection of the middle 20 mm", meshes, clamped_plate_mean_deflection, "m")
    q, span, thick = 100.0, 0.4, 0.04
    plate = q * span**4 / (384 * ep * thick**3 / 12) + q * span**2 / (8 * 5 / 6 * g * thick)
    print(f"  plate theory at mid-span (with shear): {plate:.5e} m")
    print_refinement(
        "water_on_plate_tl_2d: mean deflection of the middle 20 mm under 0.1 m of water and its own weight",
        meshes,
        clamped_plate_under_water_mean_deflection,
        "m",
    )
    q = 1000 * 9.81 * (0.1 + 0.04)
    plate = q * span**4 / (384 * ep * thick**3 / 12) + q * span**2 / (8 * 5 / 6 * g * thick)
    print(f"  plate theory at mid-span (with shear), {q:.1f} Pa: {plate:.5e} m")
    d3 = [cantilever_3d_mean_deflection(n) for n in (2, 4, 8)]
    print("cantilever (3D, 10 N): mean deflection of the last 25 mm")
    for n, v in zip((2, 4, 8), d3):
        print(f"  Q27, {n:2d} elements deep: {v:.6e} m")
    print(f"  (the finest is the reference; it moved {100 * (d3[2] / d3[1] - 1):+.2f} % from 4 to 8 deep)")
    print_refinement("beam_vibration_2d: period of the first bending mode", meshes, first_period, "s")
    omega = 1.875104**2 * np.sqrt(ep * 0.02**2 / 12 / (RHO * 0.2**4))
    print(f"  Euler–Bernoulli: {2 * np.pi / omega:.6f} s (ω = {omega:.4f} rad/s)")


if __name__ == "__main__":
    main()
