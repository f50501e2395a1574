#!/usr/bin/env python3
"""The default against the default without its guide seed (`+seed=off`), from one run of
run.sh: per scene and sample count, the seedless bake's error over the default's at equal
samples (relative MSE and MSE, the reference's noise subtracted from both), the default's CPU
time over the seedless one's, and the relative MSE ratio at equal time (> 1: the seed pays).
Means over the seeds.
   compare.py OUT"""
import glob
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "lightmap-direct"))
from compare import table  # noqa: E402

DEFAULT, SEEDLESS = "coherent/cluster/rho", "coherent/cluster/rho+seed=off"


def main():
    print("| scene | spp | relMSE, seedless ÷ default | MSE, seedless ÷ default | CPU, default ÷ seedless | relMSE at equal time |")
    print("|---|---:|---:|---:|---:|---:|")
    for path in sorted(glob.glob(os.path.join(sys.argv[1], "*", "runs.csv"))):
        scene = os.path.basename(os.path.dirname(path))
        n = json.load(open(os.path.join(os.path.dirname(path), "summary.json")))["reference_noise"]
        t = table(path)
        for spp in sorted(s for (m, s) in t if m == DEFAULT):
            a, b = t[(DEFAULT, spp)], t[(SEEDLESS, spp)]
            rel = (b["rel"] - n["rel_mse"]) / (a["rel"] - n["rel_mse"])
            mse = (b["mse"] - n["mse"]) / (a["mse"] - n["mse"])
            cpu = a["cpu"] / b["cpu"]
            print(f"| {scene} | {spp} | {rel:.3f} | {mse:.3f} | {cpu:.3f} | {rel / cpu:.3f} |")


if __name__ == "__main__":
    main()
