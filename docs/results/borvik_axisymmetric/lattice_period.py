"""The part of the projectile's speed that repeats with the lattice (stop 112).

For each run (a folder named *_k<k>, the spacing 4 mm / k, histories sampled every step), the
speed between 12 and 40 us less a quartic in the projectile's travel d since contact, and the
amplitude of that remainder's Fourier component of period dx / f in d, for f = 0.5 … 2: if the
plug's slip past the lattice drove the speed, f = 1 would stand out.
    python3 lattice_period.py uf8_k10 uf8_k11 uf8_k12 uf8_k13
"""
import sys, csv, numpy as np
for run in sys.argv[1:]:
    k=int(run.split('_k')[1]); dx=4e-3/k
    R=np.array([[float(x) for x in r[:2]] for r in list(csv.reader(open(run+"/histories.csv")))[1:]])
    t=R[:,0]; v=-R[:,1]
    t0=1.5e-3/298
    d=np.concatenate([[0],np.cumsum(0.5*(v[1:]+v[:-1])*np.diff(t))])
    d=d-298*t0  # displacement after nominal contact
    sel=(t>12e-6)&(t<40e-6)
    # decel vs displacement: a = -dv/dd ; use v as function of d, remove smooth trend (cubic) 
    dd=d[sel]; vv=v[sel]
    p=np.polyfit(dd,vv,4); res=vv-np.polyval(p,dd)
    out=[]
    for f in [0.5,0.73,1.0,1.37,2.0]:
        ph=2*np.pi*dd/(dx/f)
        c=np.trapezoid(res*np.exp(1j*ph),dd)/ (dd[-1]-dd[0])*2
        out.append(f"{f}:{abs(c):.3f}")
    print(run, f"rms {res.std():.3f}", " ".join(out), f"d(40us)={d[-1]*1e3:.3f}mm d/dx={d[-1]/dx:.2f}")
