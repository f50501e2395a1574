#!/usr/bin/env python3
"""Each method of NEW against the default of OLD (two docs/bench/surfaces/run.sh outputs of
the same scenes, sizes and ladder): per scene and sample count, the CPU time ratio and the
old default's error over the method's, alone and divided by the time ratio (> 1: the method
is ahead at equal time), by relative MSE and MSE, and the method's relative bias; means over
the seeds.   compare.py OLD NEW [OLD_METHOD]"""
import collections
import csv
import glob
import os
import sys

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


def main():
    old_dir, new_dir = sys.argv[1], sys.argv[2]
    old_method = sys.argv[3] if len(sys.argv) > 3 else "coherent/cluster/rho"
    for path in sorted(glob.glob(os.path.join(new_dir, "*", "runs.csv"))):
        scene = os.path.basename(os.path.dirname(path))
        new = table(path)
        old = table(os.path.join(old_dir, scene, "runs.csv"))
        print(f"## {scene}: against {old_method} of {old_dir}")
        print("| method | spp | CPU × | relMSE ÷ | at equal time | MSE ÷ | at equal time | rel. bias |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        for (m, spp), v in sorted(new.items(), key=lambda kv: (kv[0][1], kv[0][0])):
            if m.startswith("off/"):
                continue
            o = old[(old_method, spp)]
            t = v["cpu"] / o["cpu"]
            rel, mse = o["rel"] / v["rel"], o["mse"] / v["mse"]
            print(f"| {m} | {spp} | {t:.2f} | {rel:.2f} | {rel / t:.2f} | {mse:.2f} | {mse / t:.2f} | {100 * v['bias']:+.2f} % |")
        print()


if __name__ == "__main__":
    main()
