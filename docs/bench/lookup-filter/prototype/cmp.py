#!/usr/bin/env python3
# cmp.py A B [C...]: per scene, method and spp the relative MSE, MSE, bias and CPU time of
# run A, and A's error over each other run's (> 1: the other run lower), its bias and its CPU
# time over A's; then the default against the baseline within each run. The prototype's runs:
#   python3 cmp.py o0 o2 o1 o2k o3k     (o2kL: +lookup=50 and +lookup=25 under GB_LF=2 GB_LF_K=1)
import sys, os, importlib.util, glob
here = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("c", os.path.join(here, "..", "..", "lightmap-direct", "compare.py"))
m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)
dirs = sys.argv[1:]
for scene in ["cornell_box", "veach_ajar_no_teapots", "veach_bidir"]:
    ts = []
    for d in dirs:
        p = os.path.join(d, scene, "runs.csv")
        ts.append(m.table(p) if os.path.exists(p) else {})
    print(f"## {scene}")
    base = ts[0]
    keys = sorted(base)
    for k in keys:
        row = f"{k[0]:40s} {k[1]:5d} rel {base[k]['rel']:.3e} mse {base[k]['mse']:.3e} b {100*base[k]['bias']:+.2f}% cpu {base[k]['cpu']:.2f}"
        for d, t in zip(dirs[1:], ts[1:]):
            if k in t:
                o = t[k]
                row += f" | {os.path.basename(d)}: rel {base[k]['rel']/o['rel']:.2f}x mse {base[k]['mse']/o['mse']:.2f}x b {100*o['bias']:+.2f}% cpu {o['cpu']/base[k]['cpu']:.2f}"
        print(row)
    # default vs baseline within each dir
    for d, t in zip(dirs, ts):
        for spp in sorted({s for (mm, s) in t}):
            b = t.get(("off/average/-", spp)); g = t.get(("coherent/cluster/rho", spp))
            if b and g:
                tr = g['cpu']/b['cpu']
                print(f"  {os.path.basename(d)} spp {spp}: default vs baseline relMSE {b['rel']/g['rel']:.2f}x (eq time {b['rel']/g['rel']/tr:.2f}) mse {b['mse']/g['mse']:.2f}x (eq {b['mse']/g['mse']/tr:.2f})")
