#!/usr/bin/env python3
"""Mean irradiance over a texel file's valid texels, and the share of them exactly 0, for each
lightmap given (docs/bench/surfaces/zdm2.sh).   means.py TEXELS A.exr [B.exr ...]"""
import sys

from error_maps import rgb, texels

t = texels(sys.argv[1])
valid = (t["flags"] & 1) != 0
if (t["page"][valid] != 0).any():
    sys.exit(f"{sys.argv[1]}: more than one page; means.py reads one-page texel files")
for path in sys.argv[2:]:
    v = rgb(path)[t["px"][valid, 1], t["px"][valid, 0]]
    print(f"{path}: mean {v.mean():.4f} over {valid.sum()} valid texels, "
          f"{(v.sum(1) == 0).mean():.1%} exactly 0")
