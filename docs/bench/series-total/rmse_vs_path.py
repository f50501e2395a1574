"""RMSE and mean relative bias (luminance, valid texels) of lightmaps against a reference.

Usage: python3 rmse_vs_path.py REFERENCE.exr LIGHTMAP.exr... (EXRs baked with --aux, for the
validity channel). Needs numpy and OpenEXR.
"""
import sys

import numpy as np
import OpenEXR


def load(path):
    channels = OpenEXR.File(path).parts[0].channels
    return {k: np.array(v.pixels, dtype=np.float64) for k, v in channels.items()}


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


reference = load(sys.argv[1])
ref = luminance(reference["RGB"])
valid = reference["validity"] > 0.5
for path in sys.argv[2:]:
    err = (luminance(load(path)["RGB"]) - ref)[valid]
    rmse = np.sqrt((err**2).mean())
    bias = 100 * err.mean() / ref[valid].mean()
    print(f"{path:<24} rmse {rmse:.5g} bias {bias:+.3f}%")
