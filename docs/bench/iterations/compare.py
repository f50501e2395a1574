#!/usr/bin/env python3
"""The bakes of run.sh against the references (and twins) of a reference-noise bench run at
256² (its summary.json names them and their noise): per scene and iteration count, relative
MSE and MSE over every valid texel net of the references' noise (means over the seeds), CPU
time, equal-sample ratios against 4 iterations (> 1: fewer errors than 4) and the guiding targets'
measure against the unguided bake. Needs numpy and OpenEXR.
    compare.py NOISE_OUT OUT"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "surfaces"))
from error_maps import rgb, texels  # noqa: E402

CONFIGS = ["off-4", "coherent-3", "coherent-4", "coherent-5", "coherent-6"]
SCENES = ["cornell_box", "veach_ajar_no_teapots", "veach_bidir"]


def reference_mean_at(summary_path, texel_path):
    """The reference and its twin that a reference-noise bench's summary.json names, at the
    valid texels of a texel file: (the reference's values, the twin's, their pixels x and y,
    the page's shape, the noise of their mean as the bench measured it)."""
    summary = json.load(open(summary_path))
    n = summary["reference_noise"]
    ref, twin = rgb(summary["reference"]["path"]), rgb(n["twin"]["path"])
    t = texels(texel_path)
    valid = (t["flags"] & 1) != 0
    x, y = t["px"][valid, 0].astype(int), t["px"][valid, 1].astype(int)
    return ref[y, x], twin[y, x], x, y, ref.shape[:2], n


def reference_at_valid(noise_out, out, scene):
    """The mean of the reference and its twin named in NOISE_OUT's summary.json at the valid
    texels of OUT's texel file: (reference values, their pixels x and y, the page's shape,
    the references' noise)."""
    a, b, x, y, shape, n = reference_mean_at(os.path.join(noise_out, f"{scene}-256", "summary.json"),
                                             os.path.join(out, f"{scene}.texels"))
    return (a + b) / 2, x, y, shape, n


def main():
    noise_out, out = sys.argv[1], sys.argv[2]
    print("| scene | bake | relMSE (net) | MSE (net) | CPU s | 4's relMSE ÷ this, equal samples | 4's MSE ÷ this | CPU ÷ 4's | against unguided at equal CPU: relMSE | MSE |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for s in SCENES:
        r, x, y, _, n = reference_at_valid(noise_out, out, s)
        eps = 1e-2 * r.mean() ** 2
        res = {}
        for cfg in CONFIGS:
            rel, mse, cpu = [], [], 0.0
            for seed in (1, 2):
                b = rgb(os.path.join(out, f"{s}-{cfg}-{seed}.exr"))[y, x]
                rel.append((((b - r) ** 2) / (r ** 2 + eps)).mean() - n["rel_mse"])
                mse.append(((b - r) ** 2).mean() - n["mse"])
                cpu += sum(map(float, open(os.path.join(out, f"{s}-{cfg}-{seed}.time")).read().split()))
            res[cfg] = (np.mean(rel), np.mean(mse), cpu)
        u, d = res["off-4"], res["coherent-4"]
        for cfg, (rel, mse, cpu) in res.items():
            print(f"| {s} | {cfg} | {rel:.3e} | {mse:.3e} | {cpu:.1f} | {d[0] / rel:.3f} | {d[1] / mse:.3f} | "
                  f"{cpu / d[2]:.3f} | {u[0] / rel / (cpu / u[2]):.2f} | {u[1] / mse / (cpu / u[2]):.2f} |")


if __name__ == "__main__":
    main()
