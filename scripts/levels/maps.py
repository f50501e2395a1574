#!/usr/bin/env python3
"""The atlas panels of docs/guiding-on-levels.md, half size (2x2 texels averaged): the texel's
sky view (black: none, white: open sky), then each bake's squared error against the reference,
on one log scale (white: 1e-2 and above, black: 1e-5 and below); blue marks texels not
baked. A bake is one EXR or several, comma-separated (seeds): their squared errors averaged.
    maps.py TEXELS REF.exr REF2.exr SKY.exr BAKE.exr[,...] [BAKE.exr[,...] ...] OUT.png
Needs numpy, OpenEXR and Pillow."""
import sys

import numpy as np
from PIL import Image

import where_guiding_loses as w


def main():
    tp, r1, r2, skyp = sys.argv[1:5]
    bakes, out = sys.argv[5:-1], sys.argv[-1]
    t, _ = w.read_texels(tp)
    v = (t["flags"] & 1) != 0
    x, y = t["px"][v, 0].astype(int), t["px"][v, 1].astype(int)
    rgb = lambda p: w.channels(p)["RGB"]
    ref = (rgb(r1) + rgb(r2)) / 2
    h, wd = ref.shape[:2]
    valid = np.zeros((h, wd), bool)
    valid[y, x] = True

    def se(paths):
        s = 0
        for p in paths.split(","):
            s = s + ((rgb(p) - ref) ** 2).mean(-1)
        return s / len(paths.split(","))

    sky = rgb(skyp).sum(-1) / (np.pi * w.SKY.sum())
    panels = [np.clip(sky, 0, 1)]
    for p in bakes:
        e = se(p)
        panels.append(np.clip((np.log10(np.maximum(e, 1e-12)) + 5) / 3, 0, 1))
    imgs = []
    for p in panels:
        g = np.where(valid, p, 0.0)
        c = valid.reshape(h // 2, 2, wd // 2, 2).sum((1, 3))
        g = g.reshape(h // 2, 2, wd // 2, 2).sum((1, 3)) / np.maximum(c, 1)
        img = np.stack([g, g, g], -1)
        img[c == 0] = (0.1, 0.15, 0.35)
        imgs.append(img)
        imgs.append(np.ones((h // 2, 4, 3)))
    im = (np.concatenate(imgs[:-1], 1) * 255).astype(np.uint8)
    Image.fromarray(im).quantize(32).save(out, optimize=True)


if __name__ == "__main__":
    main()
