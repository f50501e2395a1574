#!/usr/bin/env python3
"""Where the squared error of a bake comes from, by region of the Veach bidir room.
   regions.py TEXELS REF.exr RUN_A_seed1.exr RUN_A_seed2.exr [label] ...  (pairs of seeds)"""
import os
import sys

import numpy as np

# The texel-file and EXR readers, one home: docs/bench/surfaces/error_maps.py.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "surfaces"))
from error_maps import rgb, texels  # noqa: E402

t = texels(sys.argv[1])
valid = (t["flags"] & 1) != 0
t = t[valid]
x, y = t["px"][:, 0].astype(int), t["px"][:, 1].astype(int)
ref = rgb(sys.argv[2])[y, x]
pos, nrm, tri = t["pos"], t["n"], t["tri"]
# mesh of each triangle (scene order: Wood 12, table 256, floor lamp 3008, lamp A 2, room 200, lamp B 2, shade 128)
bounds = np.cumsum([12, 256, 3008, 2, 200, 2, 128])
names = ["table top", "table", "floor lamp stand", "lamp A", "room", "lamp B", "shade"]
mesh = np.searchsorted(bounds, tri, side="right")
region = np.array([names[m] for m in mesh], dtype=object)
room = mesh == 4
region[room & (pos[:, 1] > 7.9)] = "room: ceiling"
region[room & (pos[:, 1] < 0.05)] = "room: floor"
region[room & (pos[:, 2] < -3.95)] = "room: wall z=-4 (behind lamp B)"
region[room & (pos[:, 2] > 3.95)] = "room: wall z=+4"
region[room & (np.abs(pos[:, 0]) > 3.95)] = "room: side walls x=+-4"
near_b = room & (pos[:, 2] < -3.95) & (np.hypot(pos[:, 0] + 2.69, pos[:, 1] - 5.1) < 1.0)
region[near_b] = "room: wall z=-4 within 1 m of lamp B"
mean = ref.mean()
eps = 1e-2 * mean * mean
n = ref.size
print(f"{len(t)} valid texels, mean reference {mean:.3f}")
args = sys.argv[3:]
runs = []
while args:
    a, b, label = args[0], args[1], args[2]; args = args[3:]
    runs.append((label, rgb(a)[y, x], rgb(b)[y, x]))
regs = sorted(set(region))
for label, a, b in runs:
    se = ((a - ref) ** 2 + (b - ref) ** 2) / 2       # per texel, channel; mean of two seeds
    rse = se / (ref ** 2 + eps)
    var = (a - b) ** 2 / 2                            # unbiased per-texel variance, from the seeds
    print(f"\n== {label}: MSE {se.sum()/n:.4g}, relMSE {rse.sum()/n:.4g}, seed-variance {var.sum()/n:.4g}")
    print(f"{'region':40s} {'texels':>6s} {'ref mean':>9s} {'%SE':>6s} {'%relSE':>7s} {'MSE':>9s} {'relMSE':>8s}")
    for r in regs:
        m = region == r
        print(f"{r:40s} {m.sum():6d} {ref[m].mean():9.3f} {100*se[m].sum()/se.sum():6.1f} {100*rse[m].sum()/rse.sum():7.1f} {se[m].sum()/(m.sum()*3):9.3g} {rse[m].sum()/(m.sum()*3):8.3g}")
    s = np.sort(se.sum(1))[::-1]
    print("share of SE in the worst 1% / 5% texels:", f"{100*s[:len(s)//100].sum()/s.sum():.1f}%", f"{100*s[:len(s)//20].sum()/s.sum():.1f}%")
