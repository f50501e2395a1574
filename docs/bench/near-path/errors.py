#!/usr/bin/env python3
"""The bakes of run.sh against their references (the mean of a reference and its twin, named
in a reference-noise bench's summary.json: NOISE_OUT/SCENE-256 for the converted scenes,
ZDM2_OUT/zdm2-768 for the level): per scene, build and guiding, relative MSE and MSE over
every valid texel net of that mean's noise (means over seeds 1 and 2) and CPU seconds; then
the new build over the old at equal time (the old one's error over the new one's, divided by
the new one's CPU over the old one's; > 1: the new build is ahead). Needs numpy and OpenEXR.
    errors.py NOISE_OUT ZDM2_OUT OUT"""
import os
import sys

import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "surfaces"))
sys.path.insert(0, os.path.join(here, "..", "iterations"))
from compare import reference_mean_at  # noqa: E402
from error_maps import rgb  # noqa: E402

SCENES = ["cornell_box", "veach_ajar_no_teapots", "veach_bidir", "zdm2"]


def errors(summary, texel_file, bakes):
    """Relative MSE and MSE of each of `bakes` (EXR paths) net of the references' noise."""
    a, b, x, y, _, n = reference_mean_at(summary, texel_file)
    r = (a + b) / 2
    eps = 1e-2 * r.mean() ** 2
    out = []
    for b in bakes:
        v = rgb(b)[y, x]
        out.append(((((v - r) ** 2) / (r ** 2 + eps)).mean() - n["rel_mse"], ((v - r) ** 2).mean() - n["mse"]))
    return out


def main():
    noise_out, zdm2_out, out = sys.argv[1:4]
    print("| scene | guiding | build | relMSE (net) | MSE (net) | CPU s | new over old at equal time: relMSE | MSE |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for s in SCENES:
        if not os.path.exists(os.path.join(out, f"{s}.texels")):
            continue
        summary = (os.path.join(zdm2_out, "zdm2-768", "summary.json") if s == "zdm2"
                   else os.path.join(noise_out, f"{s}-256", "summary.json"))
        runs = {(g, b): [f"{s}-{b}-{g}-{k}" for k in (1, 2)] for g in ["coherent", "off"] for b in ["old", "new"]}
        e = iter(errors(summary, os.path.join(out, f"{s}.texels"),
                        [os.path.join(out, f"{n}.exr") for names in runs.values() for n in names]))
        measured = {run: [next(e) for _ in names] for run, names in runs.items()}
        for g in ["coherent", "off"]:
            res = {}
            for build in ["old", "new"]:
                m, names = measured[(g, build)], runs[(g, build)]
                cpu = sum(sum(map(float, open(os.path.join(out, f"{n}.time")).read().split())) for n in names)
                res[build] = (np.mean([a for a, _ in m]), np.mean([b for _, b in m]), cpu)
            (ro, mo, co), (rn, mn, cn) = res["old"], res["new"]
            for build, (rel, mse, cpu) in res.items():
                ratio = f"{ro / rn / (cn / co):.3f} | {mo / mn / (cn / co):.3f}" if build == "new" else " | "
                print(f"| {s} | {g} | {build} | {rel:.3e} | {mse:.3e} | {cpu:.1f} | {ratio} |")


if __name__ == "__main__":
    main()
