#!/usr/bin/env python3
"""The default bake against the radiance target and the unguided bake of the same bench runs
(docs/bench/guide-target/run.sh OUT): per scene and sample count, the CPU time ratio and the
other method's error over the default's, alone and divided by the time ratio (> 1: the default
is ahead at equal time), by relative MSE and MSE, and each method's relative bias; means over
the seeds. Other methods of the runs in place of those two: compare.py OUT METHOD...
   compare.py OUT [METHOD...]"""
import glob
import importlib.util
import os
import sys

DEFAULT = "coherent/cluster/rho"
OTHERS = sys.argv[2:] or ["coherent/cluster/rho+target=radiance", "off/average/-"]


def load_table():
    """`table(runs.csv)` of lightmap-direct/compare.py: per (method, spp) the seeds' mean
    CPU time, relative MSE, MSE and relative bias."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lightmap-direct", "compare.py")
    spec = importlib.util.spec_from_file_location("lightmap_direct_compare", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.table


table = load_table()


for path in sorted(glob.glob(os.path.join(sys.argv[1], "*", "runs.csv"))):
    scene = os.path.basename(os.path.dirname(path))
    t = table(path)
    print(f"## {scene}: the default ({DEFAULT}) against")
    print("| method | spp | CPU default ÷ it | relMSE it ÷ default | at equal time | MSE it ÷ default | at equal time | rel. bias it / default |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for other in OTHERS:
        for spp in sorted({s for (m, s) in t if m == DEFAULT}):
            d, o = t[(DEFAULT, spp)], t[(other, spp)]
            time = d["cpu"] / o["cpu"]
            rel, mse = o["rel"] / d["rel"], o["mse"] / d["mse"]
            print(f"| {other} | {spp} | {time:.2f} | {rel:.2f} | {rel / time:.2f} | {mse:.2f} | {mse / time:.2f} | {100 * o['bias']:+.2f} % / {100 * d['bias']:+.2f} % |")
    print()
