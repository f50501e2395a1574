#!/usr/bin/env python3
"""Three atlases side by side, as ../shared/evidence draws them: the unbiased reference
(tone-mapped), then the per-texel error of bake A against it, then of bake B. Error colour:
red where the bake is brighter, blue where darker, (bake - ref) / (ref + 0.1 mean), full colour
at +-25 %; green marks the valid texels.
    error_maps.py TEXELS REFERENCE.exr A.exr B.exr OUT.png [SCALE]
Needs numpy, OpenEXR and Pillow (pip install numpy OpenEXR pillow)."""
import struct
import sys

import numpy as np
import OpenEXR
from PIL import Image


def texels(path):
    b = open(path, "rb").read()
    count = struct.unpack_from("<Q", b, 24)[0]
    offset = struct.unpack_from("<Q", b, 72)[0]
    record = np.dtype([("pos", "<f4", 3), ("n", "<f4", 3), ("du", "<f4", 3), ("dv", "<f4", 3),
                       ("page", "<u4"), ("px", "<u2", 2), ("tri", "<u4"), ("flags", "<u4")])
    return np.frombuffer(b, dtype=record, count=count, offset=offset)


def rgb(path):
    return np.asarray(OpenEXR.File(path).channels()["RGB"].pixels, dtype=np.float64)


def main():
    t = texels(sys.argv[1])
    ref, a, b = (rgb(p) for p in sys.argv[2:5])
    scale = int(sys.argv[6]) if len(sys.argv) > 6 else 4
    valid = (t["flags"] & 1) != 0
    x, y = t["px"][valid, 0].astype(int), t["px"][valid, 1].astype(int)
    h, w = ref.shape[:2]
    r = ref[y, x].sum(-1)
    mean = r.mean()
    panels = []
    tone = np.zeros((h, w, 3))
    tone[y, x] = (r / (r + mean))[:, None]
    panels.append(tone)
    for est in (a, b):
        d = (est[y, x].sum(-1) - r) / (r + 0.1 * mean)
        img = np.zeros((h, w, 3))
        img[y, x, 0] = np.clip(d / 0.25, 0, 1)
        img[y, x, 2] = np.clip(-d / 0.25, 0, 1)
        img[y, x, 1] = 0.15
        panels.append(img)
    out = np.concatenate(panels, axis=1)
    Image.fromarray((out * 255).astype(np.uint8)).resize(
        (out.shape[1] * scale, out.shape[0] * scale), Image.NEAREST).save(sys.argv[5])


if __name__ == "__main__":
    main()
