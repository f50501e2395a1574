#!/usr/bin/env python3
"""The bakes of run.sh against the mean of a reference and its twin (NOISE_OUT/SCENE-256's
summary.json): per scene and variant, relative MSE and MSE over every valid texel net of that
mean's noise (means over the seeds) and CPU seconds; then each variant against `old` (old's
error over the variant's: > 1, the variant is ahead) and against the unguided `off` (the guiding
targets' measure, docs/BENCHMARKS.md, "What falls short"; `offold`, the unguided bake of before, split into 4 iterations, beside it), at equal samples
and at equal CPU time (the error ratio divided by the CPU ratio).
Needs numpy and OpenEXR.
    compare.py NOISE_OUT OUT"""
import glob
import os
import sys

import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "surfaces"))
sys.path.insert(0, os.path.join(here, "..", "iterations"))
from compare import reference_at_valid  # noqa: E402
from error_maps import rgb  # noqa: E402

SCENES = ["cornell_box", "veach_ajar_no_teapots", "veach_bidir"]
VARIANTS = ["old", "offold", "new4", "new", "off"]


def measure(out, scene, variant, r, x, y, n):
    """Mean net relative MSE and MSE over the variant's seeds, and their summed CPU seconds."""
    eps = 1e-2 * r.mean() ** 2
    rel, mse, cpu = [], [], 0.0
    for p in sorted(glob.glob(os.path.join(out, f"{scene}-{variant}-*.exr"))):
        v = rgb(p)[y, x]
        rel.append((((v - r) ** 2) / (r ** 2 + eps)).mean() - n["rel_mse"])
        mse.append(((v - r) ** 2).mean() - n["mse"])
        cpu += sum(map(float, open(p[:-4] + ".time").read().split()[:2]))
    return np.mean(rel), np.mean(mse), cpu, len(rel)


def main():
    noise_out, out = sys.argv[1], sys.argv[2]
    print("| scene | variant | seeds | relMSE (net) | MSE (net) | CPU s | old ÷ it, equal samples: relMSE | MSE | "
          "CPU ÷ old's | old ÷ it, equal time: relMSE | off ÷ it, equal time: relMSE | MSE | offold ÷ it, equal time: relMSE |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for s in SCENES:
        if not os.path.exists(os.path.join(out, f"{s}.texels")):
            continue
        r, x, y, _, n = reference_at_valid(noise_out, out, s)
        m = {v: measure(out, s, v, r, x, y, n) for v in VARIANTS}
        ro, mo, co, _ = m["old"]
        ru, mu, cu, _ = m["off"]
        rv, _, cv, _ = m["offold"]
        for v, (rel, mse, cpu, k) in m.items():
            t = cpu / co
            print(f"| {s} | {v} | {k} | {rel:.3e} | {mse:.3e} | {cpu:.1f} | {ro / rel:.3f} | {mo / mse:.3f} | "
                  f"{t:.3f} | {ro / rel / t:.3f} | {ru / rel / (cpu / cu):.2f} | {mu / mse / (cpu / cu):.2f} | "
                  f"{rv / rel / (cpu / cv):.2f} |")


if __name__ == "__main__":
    main()
