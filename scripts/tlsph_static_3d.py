#!/usr/bin/env python3
"""Total Lagrangian SPH in 3D, linearised: cases/cantilever_3d.toml's beam (the LSR beam, 0.5 × 0.1 ×
0.1 m, E = 10 MPa, ν = 0.3, 10 N spread over its last 25 mm, clamped by odd images across x = 0)
as stdlib/solid/total_lagrangian.sph computes it at rest (issue 37), the 3D counterpart of
scripts/tlsph_static.py: strains from the corrected gradient (order 1, the model's) or from a
moving-least-squares gradient exact for quadratic fields (order 2: 9 × 9 moment matrices), the
strain energy of the beam's particles only (its odd images carry none), and Ganzenmüller's
hourglass force linearised (α). The mean deflection of the loaded end against 3D Q27 finite
elements (scripts/beam_references.py: 4.7169 mm).

At 4 particles across it gives +21.56 % (α = 10) and +53.10 % (α = 0), the dynamic model's
+21.54 % and +53.06 %; at 8 across +6.17 % (the run: +6.16 %), and +1.82 % with the order-2
gradient. The model's gradient since stop 54, one Jacobi step toward one exact for quadratic
fields ("jacobi": H = D u − S D u, solid/total_lagrangian.sph), gives +7.74 % at 4 across and
+2.16 % at 8 (+10.84 / +2.85 % without hourglass control); two steps would give +2.01 % at 8
across. No det_min here: the model's earlier det_min of 0.1 dropped the correction at every 3D
corner and edge (det L0 = 0.023 at a corner), which made its 3D beam 33 % too stiff at 4 across.
`scripts/tlsph_static_3d.py cell` adds each particle's cell energy (the model since stop 56,
solid/total_lagrangian.sph's cell_quadrature; scripts/tlsph_static.py cell in plane strain):
+2.88 % at 4 across and +0.71 % at 8.
Needs numpy and scipy. Takes about ten minutes (the 8-across rows most of it; `cell` three).
"""

import sys

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl
from scipy.spatial import cKDTree
from tlsph_static import gradient_operators

E, NU, H_RATIO, L, D = 10e6, 0.3, 1.3, 0.5, 0.1
REF = 4.7169e-3


def kernel(r, h):
    q = r / h
    a = 21 / (16 * np.pi * h**3)
    return np.where(q < 2, a * (1 - q / 2) ** 4 * (2 * q + 1), 0.0), np.where(
        q < 2, a / h * -5 * q * (1 - q / 2) ** 3, 0.0
    )


def lattice(x0, dx):
    xs = np.arange(x0 + dx / 2, L - 1e-12, dx)
    ys = np.arange(dx / 2, D - 1e-12, dx)
    return np.array([(x, y, z) for x in xs for y in ys for z in ys])


def weights(pos, dx, order):
    h = H_RATIO * dx
    n = len(pos)
    pairs = np.array(sorted(cKDTree(pos).query_pairs(2 * h - 1e-12)))
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    d = pos[i] - pos[j]
    r = np.linalg.norm(d, axis=1)
    a = -d
    w, dw = kernel(r, h)
    vol = dx**3
    if order == 1:
        g = vol * (dw / r)[:, None] * d
        m = np.zeros((n, 3, 3))
        np.add.at(m, i, g[:, :, None] * a[:, None, :])
        wt = np.einsum("pkl,pl->pk", np.linalg.inv(m)[i], g)
    else:
        b = np.stack(
            [
                a[:, 0],
                a[:, 1],
                a[:, 2],
                a[:, 0] ** 2,
                a[:, 1] ** 2,
                a[:, 2] ** 2,
                a[:, 0] * a[:, 1],
                a[:, 0] * a[:, 2],
                a[:, 1] * a[:, 2],
            ],
            -1,
        )
        m = np.zeros((n, 9, 9))
        np.add.at(m, i, (vol * w)[:, None, None] * b[:, :, None] * b[:, None, :])
        wt = np.einsum("pkl,pl->pk", np.linalg.inv(m)[i][:, :3, :], (vol * w)[:, None] * b)
    return i, j, wt, d, r, w


def jacobi_step(grad, i, j, wt, d, n):
    """H = D u − S D u (solid/total_lagrangian.sph, quadratic_gradient): one Jacobi step of
    H = D u − S H from H = D u, S H_i = Σ_j ½ ((H_j − H_i) X_ji) ⊗ w_ij; the operators per axis."""
    a = -d  # X_j − X_i
    m = {(b, l): gradient_operators(i, j, (wt[:, l] * a[:, b])[:, None], n)[0] for b in range(3) for l in range(3)}
    s = sp.bmat([[0.5 * m[(b, l)] for b in range(3)] for l in range(3)]).tocsr()
    stacked = sp.vstack(grad).tocsr()
    stepped = (stacked - s @ stacked).tocsr()
    return [stepped[:n], stepped[n : 2 * n], stepped[2 * n :]]


def strains(grad):
    """ε (xx, yy, zz, xy, xz, yz; engineering shears) on u = [u_x; u_y; u_z] from gradient operators."""
    on = lambda comp, m: sp.hstack([m if k == comp else sp.csr_matrix(m.shape) for k in range(3)])  # noqa: E731
    H = [[on(c, grad[l]) for l in range(3)] for c in range(3)]
    return [H[0][0], H[1][1], H[2][2], H[0][1] + H[1][0], H[0][2] + H[2][0], H[1][2] + H[2][1]]


def stiffness(pos, dx, order, alpha, energy, cell=False):
    n = len(pos)
    i, j, wt, d, r, w = weights(pos, dx, 1 if order == "jacobi" else order)
    grad = gradient_operators(i, j, wt, n)
    first = grad
    if order == "jacobi":
        grad = jacobi_step(grad, i, j, wt, d, n)
    on = lambda comp, m: sp.hstack([m if k == comp else sp.csr_matrix(m.shape) for k in range(3)])
    # H[c][l] = d u_c / d X_l
    H = [[on(c, grad[l]) for l in range(3)] for c in range(3)]
    eps = [H[0][0], H[1][1], H[2][2], H[0][1] + H[1][0], H[0][2] + H[2][0], H[1][2] + H[2][1]]
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[range(3), range(3)] += 2 * mu
    C[range(3, 6), range(3, 6)] = mu
    V = sp.diags(np.where(energy, dx**3, 0.0))
    K = sum(C[a, b] * (eps[a].T @ V @ eps[b]) for a in range(6) for b in range(6) if C[a, b] != 0)
    if cell:  # each particle's cell energy: V (Δ²/24) Σ_k ∂_kε : C : ∂_kε, ε and ∂_k from D u
        cell_v = sp.diags(np.where(energy, dx**5 / 12, 0.0))
        for along in first:
            g = [along @ e for e in strains(first)]
            K = K + sum(C[a, b] * (g[a].T @ cell_v @ g[b]) for a in range(6) for b in range(6) if C[a, b] != 0)
    hg = None
    if alpha > 0:
        np_ = len(i)
        si = sp.coo_matrix((np.ones(np_), (np.arange(np_), i)), shape=(np_, n)).tocsr()
        sj = sp.coo_matrix((np.ones(np_), (np.arange(np_), j)), shape=(np_, n)).tocsr()
        e = d / r[:, None]
        # miss = e · (½ (H_i + H_j) X_ij − u_ij)
        miss = None
        for c in range(3):
            row = sum(sp.diags(0.5 * d[:, l]) @ (si @ H[c][l] + sj @ H[c][l]) for l in range(3)) - on(
                c, si - sj
            )
            term = sp.diags(e[:, c]) @ row
            miss = term if miss is None else miss + term
        k = alpha * (dx**3) ** 2 * w * E / r**2
        hg = -sp.vstack([si.T @ sp.diags(k * e[:, c]) @ miss for c in range(3)])
    return K, hg


def cantilever(across, order, alpha, cell=False):
    dx = D / across
    pos = lattice(-0.075, dx)
    n = len(pos)
    beam = np.nonzero(pos[:, 0] > 0)[0]
    index = {tuple(np.round(pos[b] / dx, 3)): c for c, b in enumerate(beam)}
    rows, cols, vals = [], [], []
    for p in range(n):
        q = pos[p] if pos[p, 0] > 0 else pos[p] * [-1, 1, 1]
        rows.append(p)
        cols.append(index[tuple(np.round(q / dx, 3))])
        vals.append(1.0 if pos[p, 0] > 0 else -1.0)
    t1 = sp.coo_matrix((vals, (rows, cols)), shape=(n, len(beam)))
    T = sp.block_diag([t1, t1, t1]).tocsc()
    K, hg = stiffness(pos, dx, order, alpha, pos[:, 0] > 0, cell)
    br = np.concatenate([beam, n + beam, 2 * n + beam])
    Keff = T.T @ K @ T
    if hg is not None:
        Keff = Keff + hg.tocsr()[br] @ T
    loaded = pos[:, 0] > 0.475
    f = np.zeros(3 * n)
    f[n + np.nonzero(loaded)[0]] = -10.0 / loaded.sum()
    u = T @ spl.spsolve(Keff.tocsc(), f[br])
    return -u[n + np.nonzero(loaded)[0]].mean() / REF - 1


def main():
    if sys.argv[1:] == ["cell"]:
        for across in (4, 8):
            error = cantilever(across, "jacobi", 10.0, cell=True)
            print(f"{across} across, jacobi with the cell energy, alpha = 10: {100 * error:+.2f} %", flush=True)
        return
    for across in (4, 8):
        for order, alpha in ((1, 10.0), (1, 0.0), (2, 0.0), (2, 10.0), ("jacobi", 10.0), ("jacobi", 0.0)):
            error = cantilever(across, order, alpha)
            print(f"{across} across, order {order}, alpha = {alpha:g}: {100 * error:+.2f} %", flush=True)


if __name__ == "__main__":
    main()
