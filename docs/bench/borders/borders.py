#!/usr/bin/env python3
"""Where the default's relative error sits against the unguided bake's: the texels beside a
texel that is not baked (chart borders, texels inside geometry: one texel away on the page)
and the rest. Reads the bakes of docs/bench/iterations/run.sh (OUT: the default,
`coherent-4`, and the unguided bake, `off-4`, seeds 1 and 2) and the references and twins of
a reference-noise bench run at 256² (NOISE_OUT); raw errors (the references' noise is
spread over all texels alike). Needs numpy and OpenEXR.
    borders.py NOISE_OUT OUT"""
import os
import sys

import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "surfaces"))
sys.path.insert(0, os.path.join(here, "..", "iterations"))
from compare import SCENES, reference_at_valid  # noqa: E402
from error_maps import rgb  # noqa: E402


def beside(mask):
    """The pixels within one pixel (8-neighbourhood) of `mask`."""
    out = mask.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= np.roll(np.roll(mask, dy, 0), dx, 1)
    return out


def main():
    noise_out, out = sys.argv[1], sys.argv[2]
    print("| scene | bake | relMSE | border texels | their share of it | border mean ÷ rest's mean |")
    print("|---|---|---:|---:|---:|---:|")
    for s in SCENES:
        r, x, y, shape, _ = reference_at_valid(noise_out, out, s)
        baked = np.zeros(shape, bool)
        baked[y, x] = True
        border = beside(~baked)[y, x]
        eps = 1e-2 * r.mean() ** 2
        for cfg in ["off-4", "coherent-4"]:
            e = np.mean([(((rgb(os.path.join(out, f"{s}-{cfg}-{k}.exr"))[y, x] - r) ** 2)
                          / (r ** 2 + eps)).mean(-1) for k in (1, 2)], axis=0)
            print(f"| {s} | {cfg} | {e.mean():.3e} | {border.mean():.0%} | {e[border].sum() / e.sum():.0%} | "
                  f"{e[border].mean() / e[~border].mean():.2f} |")


if __name__ == "__main__":
    main()
