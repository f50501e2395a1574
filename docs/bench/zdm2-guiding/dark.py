#!/usr/bin/env python3
"""Where a bake's relative error sits against a reference: the mean over the texels the
reference has dark (luminance under DARK, 0.015: the level's darkest tenth) beside the
reference's there; the texels the reference has exactly black, their share of the bake's
relative MSE and the bake's mean there; and per band of the reference's luminance (deciles
and quartiles of the other valid texels), the band's share and the bake's mean relative error.
The reference is the mean of the REFERENCE files given before `--`.
    dark.py TEXELS REFERENCE.exr [REFERENCE2.exr] -- BAKE.exr...
Needs numpy and OpenEXR (pip install numpy OpenEXR)."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "surfaces"))
from error_maps import rgb, texels  # noqa: E402

DARK = 0.015


def main():
    split = sys.argv.index("--")
    t = texels(sys.argv[1])
    refs = [rgb(p) for p in sys.argv[2:split]]
    valid = (t["flags"] & 1) != 0
    x, y = t["px"][valid, 0].astype(int), t["px"][valid, 1].astype(int)
    ref = sum(refs)[y, x] / len(refs)
    eps = 1e-2 * ref.mean() ** 2
    lum = ref.mean(-1)
    bands = np.quantile(lum, [0, 0.1, 0.25, 0.5, 0.75, 0.9, 1])
    dark = lum < DARK
    print(f"{valid.sum()} valid texels; {dark.sum()} under {DARK} (reference mean there {lum[dark].mean():.5f})")
    for path in sys.argv[split + 1:]:
        bake = rgb(path)[y, x]
        e = (((bake - ref) ** 2) / (ref ** 2 + eps)).mean(-1)
        print(f"{path}: relative MSE {e.mean():.3e}, relative bias {(bake - ref).mean() / ref.mean():+.4f}, "
              f"dark texels' mean {bake.mean(-1)[dark].mean():.5f}")
        black = lum == 0
        if black.any():
            print(f"  reference exactly 0 ({black.sum()} texels): {e[black].sum() / e.sum():.0%} of the "
                  f"relative MSE, the bake's mean there {bake.mean(-1)[black].mean():.5f}")
        for lo, hi in zip(bands[:-1], bands[1:]):
            m = (lum >= lo) & (lum <= hi) & ~black
            if not m.any():
                continue
            rel = (bake - ref)[m].mean(-1).mean() / lum[m].mean()
            print(f"  reference luminance {lo:.3g}–{hi:.3g}: {e[m].sum() / e.sum():.0%} of the relative MSE, "
                  f"mean relative error {rel:+.3f}")


if __name__ == "__main__":
    main()
