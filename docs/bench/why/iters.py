import numpy as np, sys
def rows_of(path, ntiles=16):
    blocks=[]; cur=None
    for l in open(path).read().split('\n'):
        if l.startswith('#'): cur=[]; blocks.append(cur)
        elif l.strip(): cur.append([float(x) for x in l.split()])
    r=np.array([r for b in blocks[-ntiles:] for r in b])
    key=r[:,0]*100000+r[:,1]; o=np.argsort(key); return r[o]
for name in sys.argv[1:]:
    R=np.stack([rows_of(f'dd-{name}-{s}.txt') for s in range(1,7)])
    n=R[0,:,2::3]; means=R[:,:,3::3]; var=R[:,:,4::3]
    act=means.var(0,ddof=1)   # actual var of each iteration's mean, per texel
    pred=var.mean(0)/n
    tot=(means*n).sum(2)/n.sum(1) # average combine
    m=tot.mean(0); order=np.argsort(m)
    print(name, 'n per it', n[0])
    for lo,hi in [(0,.5),(.5,.9),(.9,1),(0,1)]:
        sel=order[int(lo*len(m)):int(hi*len(m))]
        a=act[sel].sum(0); p=pred[sel].sum(0)
        # optimal inverse-actual-variance weights (oracle, per band)
        w=1/a; w/=w.sum(); opt=(w**2*a).sum()
        avg=tot[:,sel].var(0,ddof=1).sum()
        print(f'  band {lo}-{hi}: actual var per it {np.round(a,1)}, actual/pred {np.round(a/p,2)}, average-combine var {avg:.1f}, oracle-weights var {opt:.1f}')
