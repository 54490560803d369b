#!/usr/bin/env python3
"""Linear static total Lagrangian SPH in plane strain: where models::tlsph_elastic's bending
error comes from (issue 37; docs/results/cantilever_2d_convergence/README.md).

The stiffness is that of stdlib/solid/total_lagrangian.sph linearised about the reference
configuration (Wendland C2, h = 1.3 Δx): strains from the corrected gradient
    ∇u_i = Σ_j (u_j − u_i) ⊗ w_ij,    w_ij = L_i⁻¹ V_j ∇W_ij          (order 1, the model's)
or from a moving-least-squares gradient exact for quadratic fields (order 2: weights V_j W_ij,
basis ΔX, ΔY, ΔX², ΔX ΔY, ΔY²), the strain energy Σ_i V_i ½ ε_i : C : ε_i, and Ganzenmüller's
hourglass force linearised (α). Solving K u = f gives what the dynamic model settles to: the
cantilever at 8 particles across is +6.8 % with order 1 and α = 10 here and in
cases/cantilever_2d.toml.

Two experiments, each at 4, 8 and 16 particles across a 0.1 m depth (E = 10 MPa, ν = 0.3):
  cantilever    cases/cantilever_2d.toml's beam (0.5 m, 75 mm of fixed particles behind x = 0,
                100 N on the last 25 mm), the mean deflection there against plane-strain finite
                elements (scripts/beam_references.py: 4.33721 mm);
  pure bending  a free 0.5 m beam under end couples: the curvature in its middle against
                M / (E' I) (no clamp, no shear).
The odd clamp rows show what clamping by odd images would give; in the dynamic model such a clamp
(a symmetry plane whose images move as −u and carry the stress of that field) grew unstable in the
vibrating beam, so models::tlsph_elastic keeps the fixed particles.
Needs numpy and scipy. Takes a few seconds.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

E, NU, DEPTH, H_RATIO = 10e6, 0.3, 0.1, 1.3
REFERENCE = 4.33721e-3


def kernel(r, h):
    q = r / h
    norm = 7 / (4 * np.pi * h * h)
    w = np.where(q < 2, norm * (1 - q / 2) ** 4 * (2 * q + 1), 0.0)
    dw = np.where(q < 2, norm / h * -5 * q * (1 - q / 2) ** 3, 0.0)
    return w, dw


def lattice(x0, x1, dx):
    xs = np.arange(x0 + dx / 2, x1 - 1e-12, dx)
    ys = np.arange(dx / 2, DEPTH - 1e-12, dx)
    return np.array([(x, y) for x in xs for y in ys])


def gradient_weights(pos, dx, order):
    """Sparse (i, j) pairs and their weights w_ij (a vec per pair)."""
    h = H_RATIO * dx
    n = len(pos)
    d = pos[:, None, :] - pos[None, :, :]  # X_i − X_j
    r = np.linalg.norm(d, axis=-1)
    i, j = np.nonzero((r > 0) & (r < 2 * h))
    a = -d[i, j]  # X_j − X_i
    w, dw = kernel(r[i, j], h)
    vol = dx * dx
    if order == 1:
        g = vol * (dw / r[i, j])[:, None] * d[i, j]
        moment = np.zeros((n, 2, 2))
        np.add.at(moment, i, g[:, :, None] * a[:, None, :])
        weights = np.einsum("pkl,pl->pk", np.linalg.inv(moment)[i], g)
    else:
        basis = np.stack([a[:, 0], a[:, 1], a[:, 0] ** 2, a[:, 0] * a[:, 1], a[:, 1] ** 2], -1)
        moment = np.zeros((n, 5, 5))
        np.add.at(moment, i, (vol * w)[:, None, None] * basis[:, :, None] * basis[:, None, :])
        weights = np.einsum("pkl,pl->pk", np.linalg.inv(moment)[i][:, :2, :], (vol * w)[:, None] * basis)
    return i, j, weights, d[i, j], r[i, j], w


def stiffness(pos, dx, order, alpha):
    n = len(pos)
    i, j, wt, d, r, w = gradient_weights(pos, dx, order)
    # G[l]: (∂φ/∂X_l)_i = Σ_j w_ij,l (φ_j − φ_i), as an n × n matrix
    grad = []
    for comp in range(2):
        m = sp.coo_matrix((wt[:, comp], (i, j)), shape=(n, n)).tocsr()
        grad.append(m - sp.diags(np.asarray(m.sum(axis=1)).ravel()))
    zero = sp.csr_matrix((n, n))
    ux = lambda m: sp.hstack([m, zero])  # noqa: E731  (acts on u_x of u = [u_x; u_y])
    uy = lambda m: sp.hstack([zero, m])  # noqa: E731
    exx, eyy, gxy = ux(grad[0]), uy(grad[1]), ux(grad[1]) + uy(grad[0])
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    vol = sp.diags(np.full(n, dx * dx))
    k = (lam + 2 * mu) * (exx.T @ vol @ exx + eyy.T @ vol @ eyy) + lam * (exx.T @ vol @ eyy + eyy.T @ vol @ exx)
    k = k + mu * gxy.T @ vol @ gxy
    if alpha > 0:
        # the hourglass force on i: α V_i V_j W E / r² · (e · (½(∇u_i + ∇u_j) X_ij − (u_i − u_j))) e
        e = d / r[:, None]
        rows = []
        for comp_u, parts in ((0, (exx, ux(grad[1]))), (1, (uy(grad[0]), eyy))):
            rows.append(
                sum(
                    sp.diags(0.5 * e[:, comp_u] * d[:, l]) @ (part[i] + part[j])
                    for l, part in enumerate(parts)
                )
            )
        sel_i = sp.coo_matrix((np.ones(len(i)), (np.arange(len(i)), i)), shape=(len(i), n))
        sel_j = sp.coo_matrix((np.ones(len(i)), (np.arange(len(i)), j)), shape=(len(i), n))
        diff = sp.hstack([sp.diags(e[:, 0]) @ (sel_i - sel_j), sp.diags(e[:, 1]) @ (sel_i - sel_j)])
        miss = rows[0] + rows[1] - diff
        c = alpha * (dx * dx) ** 2 * w * E / r**2
        force = [sel_i.T @ sp.diags(c * e[:, comp]) @ miss for comp in range(2)]
        k = k - sp.vstack(force)
    return k.tocsc()


def cantilever(across, order, alpha, odd_clamp=False):
    """The mean deflection of the loaded end. The particles behind x = 0 are fixed, or, with
    `odd_clamp`, move as the odd image of the beam (u(−X, Y) = −u(X, Y)): u = 0 at x = 0 with
    no kink in the displacement field at the clamp's face."""
    dx = DEPTH / across
    pos = lattice(-0.075, 0.5, dx)
    n = len(pos)
    k = stiffness(pos, dx, order, alpha)
    loaded = pos[:, 0] > 0.475
    f = np.zeros(2 * n)
    f[n + np.nonzero(loaded)[0]] = -100.0 / loaded.sum()
    beam = np.nonzero(pos[:, 0] > 0)[0]
    # u (all particles, both components) = T u_beam
    rows, cols, vals = [], [], []
    index = {tuple(np.round(pos[b] / dx, 3)): col for col, b in enumerate(beam)}
    for p in range(n):
        if pos[p, 0] > 0:
            rows.append(p), cols.append(index[tuple(np.round(pos[p] / dx, 3))]), vals.append(1.0)
        elif odd_clamp:
            rows.append(p), cols.append(index[tuple(np.round((-pos[p, 0] / dx, pos[p, 1] / dx), 3))]), vals.append(-1.0)
    t1 = sp.coo_matrix((vals, (rows, cols)), shape=(n, len(beam)))
    t = sp.block_diag([t1, t1]).tocsc()
    # the beam particles' equations of motion at rest, with the clamp's particles as T says
    rows = np.concatenate([beam, n + beam])
    u = t @ spl.spsolve((k[rows] @ t).tocsc(), f[rows])
    return -u[n + np.nonzero(loaded)[0]].mean()


def pure_bending(across, order, alpha):
    dx = DEPTH / across
    pos = lattice(0.0, 0.5, dx)
    n = len(pos)
    k = stiffness(pos, dx, order, alpha)
    inertia, c = DEPTH**3 / 12, DEPTH / 2
    ends = (pos[:, 0] == pos[:, 0].max(), pos[:, 0] == pos[:, 0].min())
    f = np.zeros(2 * n)
    f[np.nonzero(ends[0])[0]] = (pos[ends[0], 1] - c) / inertia * dx
    f[np.nonzero(ends[1])[0]] = -(pos[ends[1], 1] - c) / inertia * dx
    couple = np.sum(f[np.nonzero(ends[0])[0]] * (pos[ends[0], 1] - c))
    # hold the rigid motions: u_x and u_y of one particle, u_y of another on its row
    held = [0, n + 0, n + np.argmax(pos[:, 0] + (pos[:, 1] != pos[0, 1]) * -1e9)]
    free = np.ones(2 * n, bool)
    free[held] = False
    u = np.zeros(2 * n)
    u[free] = spl.spsolve(k[free][:, free], f[free])
    mid = (pos[:, 0] > 0.15) & (pos[:, 0] < 0.35)
    x, y = pos[mid, 0], pos[mid, 1] - c
    fit = np.linalg.lstsq(np.c_[np.ones(mid.sum()), x, y, x * y], u[np.nonzero(mid)[0]], rcond=None)[0]
    return fit[3] / (couple / (E / (1 - NU**2) * inertia))


def main():
    print("variant                                 | cantilever, 4 / 8 / 16 across     | pure bending κ / κ_exact")
    for order, alpha, odd in ((1, 0.0, False), (1, 10.0, False), (2, 0.0, False), (2, 10.0, False), (1, 0.0, True), (1, 10.0, True), (2, 0.0, True), (2, 10.0, True)):
        cant = [cantilever(a, order, alpha, odd) / REFERENCE - 1 for a in (4, 8, 16)]
        bend = [pure_bending(a, order, alpha) for a in (4, 8, 16)]
        name = f"order {order}, alpha = {alpha:g}, " + ("odd clamp" if odd else "fixed clamp")
        print(
            f"{name:39s} | "
            + " / ".join(f"{100 * e:+6.2f} %" for e in cant)
            + " | "
            + " / ".join(f"{b:.4f}" for b in bend)
        )


if __name__ == "__main__":
    main()
