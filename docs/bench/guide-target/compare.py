#!/usr/bin/env python3
"""The default bake against the radiance target and the unguided bake of the same bench runs
(docs/bench/guide-target/run.sh OUT): per scene and sample count, the CPU time ratio and the
other method's error over the default's, alone and divided by the time ratio (> 1: the default
is ahead at equal time), by relative MSE and MSE, and each method's relative bias; means over
the seeds.   compare.py OUT"""
import collections
import csv
import glob
import os
import sys

DEFAULT = "coherent/cluster/rho"
OTHERS = ["coherent/cluster/rho+target=radiance", "off/average/-"]


def table(path):
    agg = collections.defaultdict(list)
    for r in csv.DictReader(open(path)):
        agg[(r["method"], int(r["spp"]))].append(r)
    mean = lambda rows, f: sum(f(r) for r in rows) / len(rows)
    return {
        k: {
            "cpu": mean(v, lambda r: float(r["cpu_s"])),
            "rel": mean(v, lambda r: float(r["rel_mse"])),
            "mse": mean(v, lambda r: float(r["rmse"]) ** 2),
            "bias": mean(v, lambda r: float(r["rel_bias"])),
        }
        for k, v in agg.items()
    }


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
