#!/usr/bin/env python3
"""Per method and sample count, the mean over seeds of wall time, relative MSE, MSE and
relative bias, from the runs.csv files under OUT (docs/bench/surfaces/run.sh); then, per
scene, the default's error ratios.   summary.py OUT"""
import collections
import csv
import glob
import os
import sys

for path in sorted(glob.glob(os.path.join(sys.argv[1], "*", "runs.csv"))):
    rows = list(csv.DictReader(open(path)))
    agg = collections.defaultdict(list)
    for r in rows:
        agg[(r["method"], int(r["spp"]))].append(r)
    print(f"## {os.path.basename(os.path.dirname(path))}")
    print("| method | spp | wall s | relMSE | MSE | rel. bias |")
    print("|---|---:|---:|---:|---:|---:|")
    for (m, spp), v in sorted(agg.items()):
        f = lambda c: sum(float(x[c]) for x in v) / len(v)
        print(f"| {m} | {spp} | {f('wall_s'):.2f} | {f('rel_mse'):.3e} | {f('rmse') ** 2:.3e} | {100 * f('rel_bias'):+.2f} % |")
    print()
