import numpy as np,sys
ref=0.118849
for r in sys.argv[1:]:
    try: d=np.genfromtxt(f'{r}/histories.csv',delimiter=',',names=True)
    except Exception as e: print(r,'none'); continue
    n=d.dtype.names; t=d[n[0]]; y=d[n[1]]
    z=[]
    for k in range(1,len(t)):
        if y[k-1]>0>=y[k] or y[k-1]<0<=y[k]:
            if t[k]>0.01: z.append(t[k-1]+(t[k]-t[k-1])*y[k-1]/(y[k-1]-y[k]))
    # first zero crossing after start at T/2 (starts at 0 moving up)
    if z:
        T=2*z[0]
        print(f'{r:22s} crossings {["%.4f"%x for x in z]} period {T:.5f} ({(T/ref-1)*100:+.2f} %) amp {np.abs(y).max()*1e3:.3f} mm')
    else: print(r,'no crossing', t[-1])
