#!/usr/bin/env python3
"""The guiding targets' measure with the reference's own noise taken out, from bench runs made with
--reference-noise (run.sh; OUT holds scene-size directories with runs.csv and summary.json,
whose `reference_noise` is the noise of the reference the runs were measured against). Per
scene, size and sample count: the default (A; then every other method of the runs) against
the unguided bake (B), B's error over A's divided by A's CPU time over B's (> 1: A is ahead at
equal time), by relative MSE and MSE, raw (as the bench prints them) and net (the reference's
noise subtracted from both); the reference's share of A's raw error; and the relative bias of
both. Means over the seeds.
   net.py OUT"""
import glob
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lightmap-direct"))
from compare import table  # noqa: E402

DEFAULT, UNGUIDED = "coherent/cluster/rho", "off/average/-"


def main():
    print("| scene | spp | method (A) | CPU A ÷ B | relMSE, raw | relMSE, net | MSE, raw | MSE, net | reference's share of A's relMSE / MSE | rel. bias A / B |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for path in sorted(glob.glob(os.path.join(sys.argv[1], "*", "runs.csv"))):
        scene = os.path.basename(os.path.dirname(path))
        n = json.load(open(os.path.join(os.path.dirname(path), "summary.json")))["reference_noise"]
        t = table(path)
        methods = [DEFAULT] + sorted({m for (m, _) in t} - {DEFAULT, UNGUIDED})
        for spp in sorted(s for (m, s) in t if m == DEFAULT):
            for m in methods:
                a, b = t[(m, spp)], t[(UNGUIDED, spp)]
                time = a["cpu"] / b["cpu"]
                rel_raw, mse_raw = b["rel"] / a["rel"] / time, b["mse"] / a["mse"] / time
                rel_net = (b["rel"] - n["rel_mse"]) / (a["rel"] - n["rel_mse"]) / time
                mse_net = (b["mse"] - n["mse"]) / (a["mse"] - n["mse"]) / time
                share = f"{100 * n['rel_mse'] / a['rel']:.0f} % / {100 * n['mse'] / a['mse']:.0f} %"
                bias = f"{100 * a['bias']:+.2f} % / {100 * b['bias']:+.2f} %"
                print(f"| {scene} | {spp} | {m} | {time:.2f} | {rel_raw:.2f} | {rel_net:.2f} | {mse_raw:.2f} | {mse_net:.2f} | {share} | {bias} |")


if __name__ == "__main__":
    main()
