#!/usr/bin/env python3
"""The default bake with filtered lookups and a quarter of the rays for the lookup passes
against the unguided bake of the same transport, and both against the bakes before them
(`+lookup=100+filter=0`), from docs/bench/lookup-filter/run.sh's bench runs: per scene and
sample count, A's error over B's at equal samples and divided by B's CPU time over A's (at
equal time; > 1: B is ahead), by relative MSE and MSE; means over the seeds.
   compare.py OUT"""
import glob
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


# lightmap-direct/compare.py's `table`: per (method, spp) the seeds' mean CPU time, errors, bias.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lightmap-direct"))
from compare import table  # noqa: E402
def ratios(x, y):
    """A's error over B's at equal samples and at equal CPU time, and the time ratio B ÷ A."""
    time = y["cpu"] / x["cpu"]
    rel, mse = x["rel"] / y["rel"], x["mse"] / y["mse"]
    return [time, rel, rel / time, mse, mse / time]


HEADER = ["A over B", "spp", "CPU B ÷ A", "relMSE A ÷ B", "at equal time", "MSE A ÷ B", "at equal time", "rel. bias A / B"]
runs = sorted(glob.glob(os.path.join(sys.argv[1], "*", "runs.csv")))
for scene, t in ((os.path.basename(os.path.dirname(p)), table(p)) for p in runs):
    print(f"## {scene}")
    print("| " + " | ".join(HEADER) + " |")
    print("|---|" + "---:|" * (len(HEADER) - 1))
    for what, a, b in PAIRS:
        for spp in sorted(s for (m, s) in t if m == b):
            x, y = t[(a, spp)], t[(b, spp)]
            cells = [what, str(spp)] + [f"{r:.2f}" for r in ratios(x, y)]
            cells.append(f"{100 * x['bias']:+.2f} % / {100 * y['bias']:+.2f} %")
            print("| " + " | ".join(cells) + " |")
    print()
