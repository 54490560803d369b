#!/usr/bin/env python3
"""Total Lagrangian SPH in plane strain, linearised: where models::tlsph_elastic's bending error
and its growing modes come from (issue 37; docs/results/cantilever_2d_convergence/report.md).

The stiffness is that of stdlib/solid/total_lagrangian.sph linearised about the reference
configuration (Wendland C2, h = 1.3 Δx): strains from the corrected gradient
    ∇u_i = Σ_j (u_j − u_i) ⊗ w_ij,    w_ij = L_i⁻¹ V_j ∇W_ij          (order 1, the model's)
or from a moving-least-squares gradient exact for quadratic fields (order 2: weights V_j W_ij,
basis ΔX, ΔY, ΔX², ΔX ΔY, ΔY²), the strain energy Σ_i V_i ½ ε_i : C : ε_i, and Ganzenmüller's
hourglass force linearised (α). Solving K u = f gives what the dynamic model settles to: the
cantilever at 8 particles across is +3.30 % with order 1, α = 10 and the odd clamp here and in
cases/cantilever_2d.toml before stop 54, and the vibrating beam's period 0.120788 s against the
run's 0.120785 s; with the model's gradient since then (`jacobi`, below) +1.76 % against the run's
+1.75 %, and 0.119837 s against 0.119832 s.

Three experiments:
  cantilever    cases/cantilever_2d.toml's beam (0.5 × 0.1 m, 100 N on the last 25 mm) at 4, 8 and
                16 particles across, the mean deflection there against plane-strain finite
                elements (scripts/beam_references.py: 4.33721 mm). The clamp is 75 mm of fixed
                particles behind x = 0 ("fixed"), or odd images of the beam across x = 0 (u(−X, Y)
                = −u(X, Y)) with no strain energy of their own, the model's clamp ("odd"), or odd
                images that carry the stress of the odd field ("odd, own stress", tried before:
                its stiffness is unsymmetric).
  pure bending  a free 0.5 m beam under end couples: the curvature in its middle against
                M / (E' I) (no clamp, no shear).
  growth        the vibrating beam of cases/beam_vibration_2d.toml (0.2 × 0.02 m) at 4 and 8
                across, undamped: the fastest growth rate among its modes (the real part of the
                eigenvalues of the first-order system), with and without the pair viscosity
                (viscosity_alpha), and the first bending mode's period.
The hourglass control is Ganzenmüller's force ("G", the model's), or its variational form
("var": the energy ¼ Σ_ij k_ij (ε_ij · x̂_ij)², whose force adds the transpose of G's part through
H_i and H_j), which is symmetric but much less stiffening.
Needs numpy and scipy. Takes about two minutes.

A fourth, `scripts/tlsph_static.py quadratic` (about three minutes): a gradient exact for quadratic
fields from the pair misses alone, H_i = D u − Σ_j ½ ((H_j − H_i) X_ji) ⊗ w_ij (the trapezoidal rule
u_j − u_i = ½ (H_i + H_j) X_ji, exact for a quadratic u), which needs only d × d tensors. Solved
exactly ("trapezoid": H = (I + S)⁻¹ D u) it gives the cantilever +2.04 % at 8 across without
hourglass control and +1.90 % with it, and pure bending κ/κ_exact = 1.0157: the 1/N² of the
particles' own quadrature of the second moment of area (N layers at the cell centres give
Σ y² Δ = I (1 − 1/N²)), which no gradient removes. Taken from the last step's H instead of solved
(one pass a step), the iteration's factor is −S, whose spectral radius is 0.88–0.90, and the
delay makes the dynamics grow: every step multiplies the fastest mode of the vibrating beam at 4
across by 1.17 (1.06 with hourglass control), so the lagged form is unusable and the exact one
needs a linear solve a step, or the quadratic MLS gradient ("order 2": a 5 × 5 system per
particle in 2D, 9 × 9 in 3D) in the language.

A fifth, `scripts/tlsph_static.py jacobi` (about half a minute): the model's gradient since stop 54,
one Jacobi step of that equation from H = D u, H = D u − S D u (solid/total_lagrangian.sph,
quadratic_gradient): two passes a step more, no lag, and a symmetric stiffness (the force is the
energy's derivative through Q). The cantilever +10.59 / +2.70 / +0.78 % at 4 / 8 / 16 across
without hourglass control and +5.48 / +1.76 / +0.53 % with it (α = 10), pure bending
κ/κ_exact 1.0939 / 1.0207 / 1.0047 (1.0540 / 1.0152 / 1.0040 with α = 10, for the corrected
gradient's 1.0927 / 1.0326 / 1.0093), the vibrating beam's first period 0.122051 / 0.119837 s
at 4 / 8 across (the runs: 0.122054 / 0.119832 s); undamped, its fastest modes grow at 227 and
328 1/s, and with the pair viscosity (viscosity_alpha = 0.1) every mode decays. Two Jacobi steps
give +1.80 % at 8 across, three +1.83 %, the exact solve +1.90 %: one step is as good as any.
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
    return lattice_of(x0, x1, DEPTH, dx)


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


RHO = 1000.0
P_WAVE = np.sqrt((E / (3 * (1 - 2 * NU)) + 4 * E / (2 * (1 + NU)) / 3) / RHO)


def gradient_operators(i, j, wt, n):
    """G[l]: (∂φ/∂X_l)_i = Σ_j w_ij,l (φ_j − φ_i), as n × n matrices, one per axis of the weights."""
    grad = []
    for comp in range(wt.shape[1]):
        m = sp.coo_matrix((wt[:, comp], (i, j)), shape=(n, n)).tocsr()
        grad.append(m - sp.diags(np.asarray(m.sum(axis=1)).ravel()))
    return grad


def gradients(pos, dx, order):
    """The gradient operators (gradient_operators) and the pairs."""
    i, j, wt, d, r, w = gradient_weights(pos, dx, order)
    return gradient_operators(i, j, wt, len(pos)), (i, j, d, r, w)


# The corrected gradient's operators, whichever gradient an experiment puts in `gradients`.
first_order_gradients = gradients


# Whether the particles' cell energy is in (the `cell` experiment; the model's default since stop 56).
CELL = False


def stress_stiffness(grad, dx, energy):
    """Σ_i V_i ½ ε_i : C : ε_i over the particles in `energy`, as a matrix on u = [u_x; u_y]."""
    n = grad[0].shape[0]
    zero = sp.csr_matrix((n, n))
    ux = lambda m: sp.hstack([m, zero])  # noqa: E731  (acts on u_x of u = [u_x; u_y])
    uy = lambda m: sp.hstack([zero, m])  # noqa: E731
    exx, eyy, gxy = ux(grad[0]), uy(grad[1]), ux(grad[1]) + uy(grad[0])
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    vol = sp.diags(np.where(energy, dx * dx, 0.0))
    k = (lam + 2 * mu) * (exx.T @ vol @ exx + eyy.T @ vol @ eyy) + lam * (exx.T @ vol @ eyy + eyy.T @ vol @ exx)
    return k + mu * gxy.T @ vol @ gxy


def cell_stiffness(first, dx, energy):
    """Each particle's cell energy (solid/total_lagrangian.sph, cell_quadrature): Σ_i V_i (Δ²/24)
    Σ_k ∂_kε_i : C : ∂_kε_i, ε from the corrected gradient D u and ∂_k by D again (`first`: the
    corrected gradient's operators), as a matrix on u."""
    n = first[0].shape[0]
    zero = sp.csr_matrix((n, n))
    ux = lambda m: sp.hstack([m, zero])  # noqa: E731
    uy = lambda m: sp.hstack([zero, m])  # noqa: E731
    exx, eyy, gxy = ux(first[0]), uy(first[1]), ux(first[1]) + uy(first[0])
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    vol = sp.diags(np.where(energy, dx * dx * dx * dx / 12, 0.0))
    k = sp.csr_matrix((2 * n, 2 * n))
    for along in first:
        a, b, c = along @ exx, along @ eyy, along @ gxy
        k = k + (lam + 2 * mu) * (a.T @ vol @ a + b.T @ vol @ b) + lam * (a.T @ vol @ b + b.T @ vol @ a)
        k = k + mu * c.T @ vol @ c
    return k


def pair_misses(grad, pairs):
    """ε_ij · x̂_ij = x̂_ij · (½ (H_i + H_j) X_ij − u_ij) for each pair, a row on u."""
    i, j, d, r, _ = pairs
    n = grad[0].shape[0]
    sel_i = sp.coo_matrix((np.ones(len(i)), (np.arange(len(i)), i)), shape=(len(i), n)).tocsr()
    sel_j = sp.coo_matrix((np.ones(len(i)), (np.arange(len(i)), j)), shape=(len(i), n)).tocsr()
    core = sum(sp.diags(0.5 * d[:, l]) @ (sel_i @ grad[l] + sel_j @ grad[l]) for l in range(2)) - (sel_i - sel_j)
    e = d / r[:, None]
    return sp.hstack([sp.diags(e[:, 0]) @ core, sp.diags(e[:, 1]) @ core]), sel_i, e


def hourglass_stiffness(grad, pairs, dx, alpha, form, rows):
    """−(the hourglass force) as a matrix on u, for the pairs whose i is in `rows`."""
    keep = rows[pairs[0]]
    pairs = tuple(a[keep] for a in pairs)
    i, j, d, r, w = pairs
    miss, sel_i, e = pair_misses(grad, pairs)
    k = alpha * (dx * dx) ** 2 * w * E / r**2
    if form == "var":  # the energy ¼ Σ k miss², both sides of each pair counted
        return miss.T @ sp.diags(0.5 * k) @ miss
    # Ganzenmüller: f_i = Σ_j k miss e on i only
    return -sp.vstack([sel_i.T @ sp.diags(k * e[:, comp]) @ miss for comp in range(2)])


def pair_viscosity(pos, pairs, dx, viscosity_alpha):
    """The damping matrix of the pair viscosity (reference configuration): force −c (e·v_ij) e."""
    i, j, d, r, _ = pairs
    n = len(pos)
    h = H_RATIO * dx
    _, dw = kernel(r, h)
    mass = RHO * dx * dx
    c = mass * mass * viscosity_alpha * P_WAVE * h * (-dw) * r / (RHO * (r**2 + 0.01 * h * h))
    e = d / r[:, None]
    blocks = []
    for a in range(2):
        row = []
        for b in range(2):
            pair = sp.coo_matrix((c * e[:, a] * e[:, b], (i, j)), shape=(n, n)).tocsr()
            row.append(sp.diags(np.asarray(pair.sum(axis=1)).ravel()) - pair)
        blocks.append(row)
    return sp.bmat(blocks).tocsr()


def clamped_beam(length, depth, behind, dx, clamp):
    """The lattice with `behind` of clamp particles behind x = 0, the beam's particles, and T
    with u (every particle) = T u_beam: the clamp's particles fixed, or the odd images."""
    pos = lattice_of(-behind, length, depth, dx)
    n = len(pos)
    beam = np.nonzero(pos[:, 0] > 0)[0]
    index = {tuple(np.round(pos[b] / dx, 3)): col for col, b in enumerate(beam)}
    rows, cols, vals = [], [], []
    for p in range(n):
        if pos[p, 0] > 0:
            rows.append(p), cols.append(index[tuple(np.round(pos[p] / dx, 3))]), vals.append(1.0)
        elif clamp != "fixed":
            rows.append(p), cols.append(index[tuple(np.round((-pos[p, 0] / dx, pos[p, 1] / dx), 3))]), vals.append(-1.0)
    t1 = sp.coo_matrix((vals, (rows, cols)), shape=(n, len(beam)))
    return pos, beam, sp.block_diag([t1, t1]).tocsc()


def beam_stiffness(pos, beam, t, dx, order, alpha, clamp, form="G"):
    """The beam particles' stiffness K (K u_beam = the forces on them at rest)."""
    n = len(pos)
    grad, pairs = gradients(pos, dx, order)
    rows = np.concatenate([beam, n + beam])
    in_beam = pos[:, 0] > 0
    if clamp == "odd":  # the images have no energy: K = Tᵀ (∂² energy of the beam) T
        k = t.T @ stress_stiffness(grad, dx, in_beam) @ t
        if CELL:
            k = k + t.T @ cell_stiffness(first_order_gradients(pos, dx, 1)[0], dx, in_beam) @ t
    else:  # fixed particles, or images with the odd field's stress: the beam's rows of the whole
        k = stress_stiffness(grad, dx, np.ones(n, bool))[rows] @ t
        if CELL:
            k = k + cell_stiffness(first_order_gradients(pos, dx, 1)[0], dx, np.ones(n, bool))[rows] @ t
    if alpha > 0:
        hg = hourglass_stiffness(grad, pairs, dx, alpha, form, in_beam if form == "var" and clamp == "odd" else np.ones(n, bool))
        k = k + (t.T @ hg @ t if form == "var" else hg[rows] @ t)
    return k.tocsc(), pairs


def lattice_of(x0, x1, depth, dx):
    xs = np.arange(x0 + dx / 2, x1 - 1e-12, dx)
    ys = np.arange(dx / 2, depth - 1e-12, dx)
    return np.array([(x, y) for x in xs for y in ys])


def cantilever(across, order, alpha, clamp="fixed", form="G"):
    """The mean deflection of the loaded end, relative to the finite-element reference."""
    dx = DEPTH / across
    pos, beam, t = clamped_beam(0.5, DEPTH, 0.075, dx, clamp)
    n = len(pos)
    k, _ = beam_stiffness(pos, beam, t, dx, order, alpha, clamp, form)
    loaded = pos[:, 0] > 0.475
    f = np.zeros(2 * n)
    f[n + np.nonzero(loaded)[0]] = -100.0 / loaded.sum()
    u = t @ spl.spsolve(k, f[np.concatenate([beam, n + beam])])
    return -u[n + np.nonzero(loaded)[0]].mean() / REFERENCE - 1


def pure_bending(across, order, alpha, form="G"):
    dx = DEPTH / across
    pos = lattice(0.0, 0.5, dx)
    n = len(pos)
    everyone = np.arange(n)
    k, _ = beam_stiffness(pos, everyone, sp.identity(2 * n, format="csc"), dx, order, alpha, "free", form)
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


def growth(across, clamp, viscosity_alpha, alpha=10.0):
    """The vibrating beam, undamped: the largest growth rate of any mode (1/s, > 0 grows) and the
    first bending mode's period."""
    dx = 0.02 / across
    pos, beam, t = clamped_beam(0.2, 0.02, 0.015, dx, clamp)
    k, pairs = beam_stiffness(pos, beam, t, dx, 1, alpha, clamp)
    n = len(pos)
    rows = np.concatenate([beam, n + beam])
    c = (pair_viscosity(pos, pairs, dx, viscosity_alpha)[rows] @ t).toarray()
    m = len(rows)
    mass = RHO * dx * dx
    system = np.block([[np.zeros((m, m)), np.eye(m)], [-k.toarray() / mass, -c / mass]])
    ev = np.linalg.eigvals(system)
    oscillating = ev[ev.imag > 1]
    first = oscillating[np.argmin(oscillating.imag)]
    return ev.real.max(), 2 * np.pi / first.imag


def main():
    print("cantilever (mean deflection against FE), 4 / 8 / 16 across; pure bending κ / κ_exact")
    for order, alpha, form, clamp in (
        (1, 0.0, "G", "fixed"),
        (1, 10.0, "G", "fixed"),
        (1, 10.0, "var", "fixed"),
        (2, 0.0, "G", "fixed"),
        (2, 10.0, "G", "fixed"),
        (1, 0.0, "G", "odd"),
        (1, 10.0, "G", "odd"),
        (1, 10.0, "G", "odd, own stress"),
        (1, 10.0, "var", "odd"),
        (2, 0.0, "G", "odd"),
        (2, 10.0, "G", "odd"),
    ):
        cant = [cantilever(a, order, alpha, clamp, form) for a in (4, 8, 16)]
        name = f"order {order}, alpha = {alpha:g} ({form}), {clamp} clamp"
        bend = ""
        if clamp == "fixed":
            bend = " | " + " / ".join(f"{pure_bending(a, order, alpha, form):.4f}" for a in (4, 8, 16))
        print(f"{name:47s} | " + " / ".join(f"{100 * e:+6.2f} %" for e in cant) + bend)
    print("\nvibrating beam (undamped, alpha = 10): fastest growth [1/s] and first period [s]")
    for across in (4, 8):
        for clamp in ("fixed", "odd", "odd, own stress"):
            for viscosity_alpha in (0.0, 0.01, 0.1):
                rate, period = growth(across, clamp, viscosity_alpha)
                print(f"{across} across, {clamp:16s} clamp, viscosity_alpha = {viscosity_alpha:4g}: growth {rate:+10.4g}, period {period:.6f}")


def trapezoid_operators(pos, dx):
    """The corrected gradient D and the trapezoidal correction S on H (the rows of H ordered
    H_x0, H_x1 | H_y0, H_y1 per displacement component, the same S for each): H = D u − S H."""
    i, j, wt, d, r, w = gradient_weights(pos, dx, 1)
    n = len(pos)
    a = -d  # X_j − X_i
    moment = {(b, l): gradient_operators(i, j, (wt[:, l] * a[:, b])[:, None], n)[0] for b in range(2) for l in range(2)}
    s = sp.bmat([[0.5 * moment[(0, 0)], 0.5 * moment[(1, 0)]], [0.5 * moment[(0, 1)], 0.5 * moment[(1, 1)]]]).tocsc()
    return gradient_operators(i, j, wt, n), s, (i, j, d, r, w)


def trapezoid_gradients(pos, dx, order):
    """The gradient operators of H = (I + S)⁻¹ D u, in the form gradients() returns."""
    grad, s, pairs = trapezoid_operators(pos, dx)
    n = len(pos)
    solved = sp.csr_matrix(spl.spsolve((sp.identity(2 * n) + s).tocsc(), sp.vstack([grad[0], grad[1]]).tocsc()))
    return [solved[:n], solved[n:]], pairs


def lagged_amplification(across, alpha):
    """The vibrating beam (fixed clamp, undamped) with H = D u − S H_last, H_last the last step's
    H, symplectic Euler at 0.3 h / c: the largest modulus of the one-step map's eigenvalues."""
    dx = 0.02 / across
    pos, beam, t = clamped_beam(0.2, 0.02, 0.015, dx, "fixed")
    n = len(pos)
    grad, s, pairs = trapezoid_operators(pos, dx)
    zero = sp.csr_matrix((n, n))
    d = sp.bmat([[grad[0], zero], [grad[1], zero], [zero, grad[0]], [zero, grad[1]]]).tocsr()
    s4 = sp.block_diag([s, s]).toarray()
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    eye = sp.identity(n)
    energy = dx * dx * sp.bmat([[(lam + 2 * mu) * eye, None, None, lam * eye], [None, mu * eye, mu * eye, None],
                                [None, mu * eye, mu * eye, None], [lam * eye, None, None, (lam + 2 * mu) * eye]])
    rows = np.concatenate([beam, n + beam])
    force_of_h = -(d.T @ energy).toarray()[rows]
    force_of_u = np.zeros((len(rows), len(rows)))
    if alpha > 0:  # Ganzenmüller's force with the miss of this step's H
        i, j, dd, r, w = pairs
        m = len(i)
        sel_i = sp.coo_matrix((np.ones(m), (np.arange(m), i)), shape=(m, n)).tocsr()
        sel_j = sp.coo_matrix((np.ones(m), (np.arange(m), j)), shape=(m, n)).tocsr()
        e = dd / r[:, None]
        k = alpha * (dx * dx) ** 2 * w * E / r**2
        miss_u = sp.hstack([sp.diags(-e[:, c]) @ (sel_i - sel_j) for c in range(2)])
        miss_h = sp.hstack([sp.diags(0.5 * e[:, c] * dd[:, l]) @ (sel_i + sel_j) for c in range(2) for l in range(2)])
        spring = [sel_i.T @ sp.diags(k * e[:, c]) for c in range(2)]
        force_of_u = (sp.vstack([f @ miss_u for f in spring])[rows] @ t).toarray()
        force_of_h = force_of_h + sp.vstack([f @ miss_h for f in spring]).toarray()[rows]
    h_of_u, h_of_last = (d @ t).toarray(), -s4
    mass, dt = RHO * dx * dx, 0.3 * H_RATIO * dx / P_WAVE
    nb, nh = len(rows), 4 * n
    kick = np.hstack([dt * (force_of_h @ h_of_u + force_of_u) / mass, np.eye(nb), dt * force_of_h @ h_of_last / mass])
    drift = np.hstack([np.eye(nb), np.zeros((nb, nb + nh))]) + dt * kick
    last = np.hstack([h_of_u, np.zeros((nh, nb)), h_of_last])
    return np.abs(np.linalg.eigvals(np.vstack([drift, kick, last]))).max()


def jacobi_gradients(pos, dx, order):
    """The gradient operators of H = D u − S D u (one Jacobi step of H = D u − S H from H = D u),
    the model's (solid/total_lagrangian.sph, quadratic_gradient), in the form gradients() returns."""
    grad, s, pairs = trapezoid_operators(pos, dx)
    n = len(pos)
    d = sp.vstack([grad[0], grad[1]]).tocsr()
    stepped = (d - s @ d).tocsr()
    return [stepped[:n], stepped[n:]], pairs


def bending_report(name):
    """The cantilever, pure bending and the vibrating beam with the gradient in `gradients`."""
    for alpha in (0.0, 10.0):
        cant = [cantilever(a, 1, alpha, "odd") for a in (4, 8, 16)]
        print(f"{name}, alpha = {alpha:g}, odd clamp | " + " / ".join(f"{100 * e:+6.2f} %" for e in cant))
    for alpha in (0.0, 10.0):
        bend = " / ".join(f"{pure_bending(a, 1, alpha):.4f}" for a in (4, 8, 16))
        print(f"{name}, alpha = {alpha:g}, pure bending κ / κ_exact | {bend}")
    for across in (4, 8):
        for viscosity_alpha in (0.0, 0.1):
            rate, period = growth(across, "odd", viscosity_alpha)
            print(f"vibrating beam, {across} across, odd clamp, viscosity_alpha = {viscosity_alpha:g}: growth {rate:+10.4g}, period {period:.6f}")


def jacobi():
    """The model's gradient (jacobi_gradients): the cantilever, pure bending and the vibrating beam."""
    global gradients
    first_order = gradients
    gradients = jacobi_gradients
    bending_report("one Jacobi step")
    gradients = first_order


def quadratic():
    global gradients
    first_order = gradients
    gradients = lambda pos, dx, order: trapezoid_gradients(pos, dx, order)  # noqa: E731
    for alpha in (0.0, 10.0):
        cant = [cantilever(a, 1, alpha, "odd") for a in (4, 8, 16)]
        print(f"trapezoid, alpha = {alpha:g}, odd clamp | " + " / ".join(f"{100 * e:+6.2f} %" for e in cant))
    print("trapezoid pure bending κ / κ_exact | " + " / ".join(f"{pure_bending(a, 1, 0.0):.4f}" for a in (4, 8, 16)))
    gradients = first_order
    for across in (4, 8):
        ev = spl.eigs(trapezoid_operators(clamped_beam(0.2, 0.02, 0.015, 0.02 / across, "fixed")[0], 0.02 / across)[1],
                      k=2, which="LM", return_eigenvectors=False)
        print(f"vibrating beam, {across} across: spectral radius of S {np.abs(ev).max():.4f}")
    for alpha in (0.0, 10.0):
        print(f"lagged trapezoid, 4 across, alpha = {alpha:g}: one step multiplies the fastest mode by {lagged_amplification(4, alpha):.4f}")


def cell():
    """The model since stop 56: the gradient of `jacobi` and each particle's cell energy
    (cell_stiffness): the cantilever, pure bending and the vibrating beam."""
    global gradients, CELL
    first_order = gradients
    gradients, CELL = jacobi_gradients, True
    bending_report("cell energy")
    gradients, CELL = first_order, False


if __name__ == "__main__":
    import sys

    {"quadratic": quadratic, "jacobi": jacobi, "cell": cell}.get(sys.argv[1] if sys.argv[1:] else "", main)()
