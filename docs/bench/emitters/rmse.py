import sys, OpenEXR, numpy as np
def load(path):
    ch = OpenEXR.File(path).parts[0].channels
    return {k: np.array(c.pixels, dtype=np.float64) for k, c in ch.items()}
ref = load(sys.argv[1])
mask = ref['validity'] > 0 if 'validity' in ref else np.ones(ref['RGB'].shape[:2], bool)
r = ref['RGB'][mask]
for p in sys.argv[2:]:
    img = load(p)
    x = img['RGB'][mask]
    err = np.sqrt(np.mean((x - r) ** 2))
    bias = np.mean(x - r) / np.mean(r)
    extra = ''
    if 'rel_std_error' in img:
        rse = img['rel_std_error'][mask]
        extra = f" median rel_std_error {np.median(rse):.4f}"
    print(f"{p}: RMSE {err:.5e} rel.bias {bias*100:+.3f}%{extra}")
