#!/usr/bin/env python3
"""The default bake with filtered lookups and a quarter of the rays for the lookup passes
against the unguided bake of the same transport, and both against the bakes before them
(`+lookup=100+filter=0`), from docs/bench/lookup-filter/run.sh's bench runs: per scene and
sample count, A's error over B's at equal samples and divided by B's CPU time over A's (at
equal time; > 1: B is ahead), by relative MSE and MSE; means over the seeds.
   compare.py OUT"""
import glob
import importlib.util
import os
import sys

OLD = "+lookup=100+filter=0"
DEFAULT, UNGUIDED = "coherent/cluster/rho", "off/average/-"
PAIRS = [
    ("the default against the unguided bake (the issue's measure)", UNGUIDED, DEFAULT),
    ("the default against the default before", DEFAULT + OLD, DEFAULT),
    ("the unguided bake against the unguided bake before", UNGUIDED + OLD, UNGUIDED),
    ("the default against the unguided bake before", UNGUIDED + OLD, DEFAULT),
    ("before: the default against the unguided bake", UNGUIDED + OLD, DEFAULT + OLD),
]


def load_table():
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lightmap-direct", "compare.py")
    spec = importlib.util.spec_from_file_location("lightmap_direct_compare", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.table


table = load_table()
for path in sorted(glob.glob(os.path.join(sys.argv[1], "*", "runs.csv"))):
    scene = os.path.basename(os.path.dirname(path))
    t = table(path)
    print(f"## {scene}")
    print("| A over B | spp | CPU B ÷ A | relMSE A ÷ B | at equal time | MSE A ÷ B | at equal time | rel. bias A / B |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for what, a, b in PAIRS:
        for spp in sorted({s for (m, s) in t if m == b}):
            x, y = t[(a, spp)], t[(b, spp)]
            time = y["cpu"] / x["cpu"]
            rel, mse = x["rel"] / y["rel"], x["mse"] / y["mse"]
            print(f"| {what} | {spp} | {time:.2f} | {rel:.2f} | {rel / time:.2f} | {mse:.2f} | {mse / time:.2f} | {100 * x['bias']:+.2f} % / {100 * y['bias']:+.2f} % |")
    print()
