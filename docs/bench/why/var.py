import sys, OpenEXR, numpy as np, json
def load(p):
    ch = OpenEXR.File(p).parts[0].channels
    return np.array(ch['RGB'].pixels, dtype=np.float64)
def stack(prefix, seeds):
    return np.stack([load(f"{prefix}-{s}.exr") for s in seeds])
seeds = [int(s) for s in sys.argv[3].split(',')]
a = stack(sys.argv[1], seeds); b = stack(sys.argv[2], seeds)
lum = lambda x: x @ np.array([0.2126, 0.7152, 0.0722])
la, lb = lum(a), lum(b)
mean = 0.5*(la.mean(0)+lb.mean(0))
valid = mean > 0
va = la.var(0, ddof=1); vb = lb.var(0, ddof=1)
print("total var (sum over texels): A %.4g  B %.4g  ratio A/B %.3f" % (va[valid].sum(), vb[valid].sum(), va[valid].sum()/vb[valid].sum()))
rel_a = va[valid]/ (mean[valid]**2 + 1e-2*mean[valid].mean()**2); rel_b = vb[valid]/(mean[valid]**2+1e-2*mean[valid].mean()**2)
print("relative var: A %.4g B %.4g ratio %.3f" % (rel_a.mean(), rel_b.mean(), rel_a.mean()/rel_b.mean()))
m = mean[valid]; qs = np.quantile(m, [0, .5, .9, .99, 1.0])
print("brightness quantiles", qs)
order = np.argsort(m)
for lo, hi in [(0,.5),(.5,.9),(.9,.99),(.99,1.0)]:
    sel = order[int(lo*len(m)):int(hi*len(m))]
    print(f"texels {lo:.2f}-{hi:.2f}: share of A's var {va[valid][sel].sum()/va[valid].sum():.3f}, B's {vb[valid][sel].sum()/vb[valid].sum():.3f}, ratio A/B {va[valid][sel].sum()/vb[valid][sel].sum():.3f}")
