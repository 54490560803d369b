"""The projectile's speed every 2 us from 6 to 40 us of a base run, and the others' less it (stop 112).
    python3 history_diff.py uf8_k12 uf8_k10 uf8_k11 uf8_k13
"""
import sys, csv, numpy as np
def load(r):
    R=np.array([[float(x) for x in row[:2]] for row in list(csv.reader(open(r+"/histories.csv")))[1:]]); return R[:,0],-R[:,1]
T=np.arange(6,40.01,2)*1e-6
base=sys.argv[1]; tb,vb=load(base); Vb=np.interp(T,tb,vb)
print("t (us)".ljust(9)+" ".join(f"{t*1e6:6.0f}" for t in T))
print(base.ljust(9)+" ".join(f"{v:6.2f}" for v in Vb))
for r in sys.argv[2:]:
    t,v=load(r); V=np.interp(T,t,v); print(r.ljust(9)+" ".join(f"{x:6.2f}" for x in V-Vb))
