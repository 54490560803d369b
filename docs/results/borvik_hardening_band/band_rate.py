"""The strain rate in the plug's band against its average over ℓ (stop 80).

    python3 band_rate.py RUN_DIR [RUN_DIR ...]

Each RUN_DIR is a run of the case with `[output] fields` including `edot` and `rate_nl`
(a copy of cases/borvik_perforation.toml), e.g.
    pairsum run my_borvik.toml --resolution refined --set model=models::ftlr19_perforation_shaped
      --set damage_length=2 --set visc_a=1 --set visc_b=1 --set skin=0.1 --set v_impact=298
      --set thickness=8 --set end_time="21 us" --set nonlocal_hardening=1 --set nonlocal_rate=1
Reads the plate's particles in the second VTK snapshot (20 µs) and prints, over the 50 particles
of the largest equivalent strain rate √(2/3 ė':ė'), its mean, the averaged rate rate_nl there,
and C ln(own / averaged) with Johnson–Cook's C = 0.0114.
"""
import base64, glob, re, struct, sys
import numpy as np


def read_vtu(path):
    text = open(path).read()
    out = {}
    pattern = r'<DataArray type="Float64" Name="(\w+)" NumberOfComponents="(\d+)"[^>]*format="binary">\s*([A-Za-z0-9+/=]+)\s*</DataArray>'
    for m in re.finditer(pattern, text):
        raw = base64.b64decode(m.group(3))
        n = struct.unpack('<Q', raw[:8])[0]
        a = np.frombuffer(raw[8:8 + n], dtype='<f8')
        comps = int(m.group(2))
        out[m.group(1)] = a.reshape(-1, comps) if comps > 1 else a
    return out


for run in sys.argv[1:]:
    d = read_vtu(sorted(glob.glob(run + '/vtk/*.vtu'))[1])
    plate = d['body'] > 0.5
    a = d['edot'][plate]  # XX YY ZZ XY YZ XZ
    e = np.zeros((len(a), 3, 3))
    e[:, 0, 0], e[:, 1, 1], e[:, 2, 2] = a[:, 0], a[:, 1], a[:, 2]
    e[:, 0, 1] = e[:, 1, 0] = a[:, 3]
    e[:, 1, 2] = e[:, 2, 1] = a[:, 4]
    e[:, 0, 2] = e[:, 2, 0] = a[:, 5]
    dev = e - np.trace(e, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    own = np.sqrt(2 / 3 * np.einsum('nij,nij->n', dev, dev))
    averaged = d['rate_nl'][plate]
    top = np.argsort(own)[-50:]
    ratio = np.median(own[top] / np.maximum(averaged[top], 1.0))
    print(f'{run}: own rate {own[top].mean():.3e} 1/s, averaged {averaged[top].mean():.3e} 1/s '
          f'(largest {averaged.max():.3e}), C ln(own/averaged) {0.0114 * np.log(ratio):.4f}')
