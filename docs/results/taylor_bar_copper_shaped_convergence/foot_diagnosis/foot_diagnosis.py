"""Where the copper Taylor bar's foot grows with refinement (issue 37), from a run's VTK snapshots:
the first (t = 0) and a later one of the same run, and the run's particle spacing in metres.

  foot_diagnosis.py opening FIRST.vtu LATER.vtu DX [RHO0]
      The layer of particles next to the wall (z < 0.75 dx), by band of distance from the axis
      (r/R, R the largest): medians of det F_pos, the volume ratio of the particles' own
      arrangement (F fitted by least squares to the displacements of the neighbours within 1.5 dx
      at t = 0, the symmetry planes x = 0, y = 0 and z = 0 mirrored in); rho0/rho, the volume
      ratio the density holds (with RHO0, where the snapshot has `rho`); r/r0, the hoop stretch of
      the particle's own displacement; and |A E_theta|, the hoop stretch of the kernel's shape A
      (integrated as A' = grad v A: the deformation gradient as the pair sums see it), where the
      snapshot has `kernel_shape`.
  foot_diagnosis.py layers FIRST.vtu LATER.vtu DX
      For columns of particles by their starting distance from the axis, the mean distance from
      the axis of the layers 1, 2, 3 and 5 from the wall (a frictionless wall has du_r/dz = 0, so
      a layer that slid out along it would stand out from the one above).
  foot_diagnosis.py energy FIRST.vtu LATER.vtu DX
      Kinetic energy at both snapshots and the plastic work of linear hardening,
      sum V (A eps_p + B eps_p^2 / 2) with A = 400 MPa, B = 100 MPa, V = dx^3 (the ratio to the
      first kinetic energy does not depend on V).
Needs numpy."""
import base64, math, re, struct, sys
import numpy as np


def arrays(path):
    text = open(path).read()
    out = {}
    pat = (r'<DataArray[^>]*type="(\w+)"[^>]*Name="(\w+)"[^>]*NumberOfComponents="(\d+)"[^>]*'
           r'format="binary"[^>]*>\s*([A-Za-z0-9+/=]+)\s*</DataArray>')
    types = {'Float64': '<f8', 'Float32': '<f4', 'Int64': '<i8', 'UInt8': 'u1', 'Int32': '<i4', 'UInt32': '<u4'}
    for m in re.finditer(pat, text):
        ty, name, comps, data = m.group(1), m.group(2), int(m.group(3)), m.group(4)
        raw = base64.b64decode(data)
        n = struct.unpack('<Q', raw[:8])[0]
        a = np.frombuffer(raw[8:8 + n], dtype=types[ty])
        out[name] = a.reshape(-1, comps) if comps > 1 else a
    return out


def by_id(a):
    o = np.argsort(a['id'])
    return {k: v[o] for k, v in a.items() if len(v) == len(o)}


def opening(first, later, dx, rho0):
    X, x = first['Points'], later['Points']
    r0, r = np.hypot(X[:, 0], X[:, 1]), np.hypot(x[:, 0], x[:, 1])
    signs = [np.array((sx, sy, sz)) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]
    XI, xI = np.concatenate([X * s for s in signs]), np.concatenate([x * s for s in signs])
    layer = np.where(x[:, 2] < 0.75 * dx)[0]
    R = r.max()
    rows = []
    for i in layer:
        d = XI - X[i]
        near = (d * d).sum(1) < (1.5 * dx) ** 2
        near[i] = False
        Ft, *_ = np.linalg.lstsq(d[near], xI[near] - x[i], rcond=None)
        row = [r[i] / R, np.linalg.det(Ft), r[i] / max(r0[i], 1e-12), math.nan, math.nan]
        if 'rho' in later and rho0:
            row[3] = rho0 / later['rho'][i]
        if 'kernel_shape' in later and r0[i] > 0:
            e = np.array([-X[i, 1], X[i, 0], 0.0]) / r0[i]
            row[4] = np.linalg.norm(later['kernel_shape'][i].reshape(3, 3) @ e)
        rows.append(row)
    rows = np.array(rows)
    print('foot radius %.4f mm, wall layer %d particles' % (R * 1e3, len(layer)))
    print('r/R band      n  det F_pos  rho0/rho     r/r0  |A E_theta|')
    for lo, hi in [(0, .5), (.5, .7), (.7, .8), (.8, .9), (.9, 1.01)]:
        m = (rows[:, 0] >= lo) & (rows[:, 0] < hi)
        if m.any():
            med = np.median(rows[m], axis=0)
            print('%.2f-%.2f %5d %10.3f %9.3f %8.3f %12.3f' % (lo, min(hi, 1), m.sum(), med[1], med[3], med[2], med[4]))


def layers(first, later, dx):
    X, x = first['Points'], later['Points']
    r0, r = np.hypot(X[:, 0], X[:, 1]), np.hypot(x[:, 0], x[:, 1])
    layer = np.rint(X[:, 2] / dx - 0.5).astype(int)
    R0 = r0.max()
    print('r0/R0 band    n   layer 1  layer 2  layer 3  layer 5 (mm from the axis)  (1-2)/dx  (2-3)/dx')
    for lo, hi in [(0.0, 0.5), (0.5, 0.8), (0.8, 0.95), (0.95, 1.01)]:
        cols = (r0 / R0 >= lo) & (r0 / R0 < hi)
        means = [r[cols & (layer == k)].mean() * 1e3 if (cols & (layer == k)).any() else math.nan for k in (0, 1, 2, 4)]
        print('%.2f-%.2f %5d %9.3f %8.3f %8.3f %8.3f %27.2f %9.2f' % (
            lo, min(hi, 1), (cols & (layer == 0)).sum(), *means,
            (means[0] - means[1]) / (dx * 1e3), (means[1] - means[2]) / (dx * 1e3)))


def energy(first, later, dx):
    V, rho0, A, B = dx ** 3, 8930.0, 400e6, 100e6
    ke0, ke = (0.5 * rho0 * V * (a['v'] ** 2).sum() for a in (first, later))
    wp = V * (A * later['eps_p'] + 0.5 * B * later['eps_p'] ** 2).sum()
    print('KE0 %.3f J, KE %.3f J, plastic work %.3f J: (KE + W_p) / KE0 %.4f, W_p / KE0 %.4f' % (
        ke0, ke, wp, (ke + wp) / ke0, wp / ke0))


what, first, later, dx = sys.argv[1], by_id(arrays(sys.argv[2])), by_id(arrays(sys.argv[3])), float(sys.argv[4])
if what == 'opening':
    opening(first, later, dx, float(sys.argv[5]) if len(sys.argv) > 5 else None)
elif what == 'layers':
    layers(first, later, dx)
else:
    energy(first, later, dx)
