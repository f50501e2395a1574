#!/usr/bin/env python3
"""Where a --target-error bake's error sits: the relative error (the bench's, per texel, over
the valid texels) of the texels that ran to the cap and of those that stopped before it.

    guidebake bake --scene SCENE TEXELS -o LIGHTMAP.exr --aux --spp CAP --iterations 8 --target-error E
    docs/bench/stop/capped.py LIGHTMAP.exr REFERENCE.exr CAP
"""
import sys

import numpy as np
import OpenEXR

x = OpenEXR.File(sys.argv[1]).parts[0].channels
r = OpenEXR.File(sys.argv[2]).parts[0].channels["RGB"].pixels
cap = float(sys.argv[3])
valid = x["validity"].pixels > 0.5
a, b, samples = x["RGB"].pixels[valid], r[valid], x["samples"].pixels[valid]
eps = 1e-2 * b.mean() ** 2
e = ((a - b) ** 2 / (b**2 + eps)).mean(axis=1)
capped = samples >= cap
rms = lambda v: float(np.sqrt(v.mean())) if v.size else 0.0
print(f"{sys.argv[1]}: all {rms(e):.4f}; capped {100 * capped.mean():.0f} % of the texels, "
      f"{100 * e[capped].sum() / e.sum():.0f} % of the squared error, {rms(e[capped]):.4f}; "
      f"stopped {rms(e[~capped]):.4f}")
