#!/usr/bin/env python3
"""What a spatial budget could buy at equal samples (docs/budget.md, "The spatial budget").

    ceiling.py REF.exr BAKE.exr PILOT.exr [BLOCK]

BAKE: the uniform bake (`--aux`); REF: its unbiased reference; PILOT: an independent bake
with `--aux` whose per-texel error estimate (rel_std_error × mean) stands in for what the
budget knows before the pass. Per BLOCK×BLOCK block of texels (default 8) the realised
squared error E_b of BAKE falls as 1/n_b with the block's samples; at equal total samples
  oracle:  n_b ∝ √E_b (the best any allocation can do with these blocks), and
  each allocation of bake/budget.rs from PILOT's σ and μ (clamped to ¼…4 times, as the bake),
print how many times lower the relative MSE and the MSE would be (> 1: better). Needs numpy
and OpenEXR (pip install openexr)."""
import sys

import Imath
import numpy as np
import OpenEXR


def load(path):
    f = OpenEXR.InputFile(path)
    h = f.header()
    dw = h["dataWindow"]
    w, hh = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    return {c: np.frombuffer(f.channel(c, pt), dtype=np.float32).reshape(hh, w).astype(np.float64)
            for c in h["channels"]}


def main():
    ref, bake, pilot = (load(p) for p in sys.argv[1:4])
    block = int(sys.argv[4]) if len(sys.argv) > 4 else 8
    total = lambda d: d["R"] + d["G"] + d["B"]
    valid = bake["validity"] > 0.5
    r = total(ref)
    eps = 1e-2 * np.mean(r[valid]) ** 2
    err = {"relMSE": np.where(valid, (total(bake) - r) ** 2 / (r ** 2 + eps), 0.0),
           "MSE": np.where(valid, (total(bake) - r) ** 2, 0.0)}
    mu = 0.2126 * pilot["R"] + 0.7152 * pilot["G"] + 0.0722 * pilot["B"]
    var = (pilot["rel_std_error"] * mu) ** 2 * pilot["samples"]
    mean = np.mean(mu[valid])
    h, w = valid.shape
    hb, wb = h // block, w // block
    blocks = lambda a: np.where(valid, a, 0.0)[:hb * block, :wb * block].reshape(hb, block, wb, block).sum(axis=(1, 3))
    count = blocks(np.ones_like(mu))
    used = count > 0
    weight = count[used] / count[used].sum()
    per = lambda a: blocks(a)[used] / count[used]
    allocations = {
        "mse (n ∝ σ)": per(var),
        "balanced (n ∝ σ/√(μ·μ̄))": per(var / (np.maximum(mu, 0.1 * mean) * mean)),
        "relative (n ∝ σ/√(μ²+ε))": per(var / (mu ** 2 + 1e-2 * mean ** 2)),
    }
    for name, e in err.items():
        eb = per(e)
        uniform = (weight * eb).sum()
        line = [f"{name}: oracle {uniform / (weight * np.sqrt(eb)).sum() ** 2:.2f}"]
        for label, a2 in allocations.items():
            n = np.sqrt(a2)
            n = np.clip(n / (weight * n).sum(), 0.25, 4.0)
            n = np.clip(n / (weight * n).sum(), 0.25, 4.0)
            line.append(f"{label} {uniform / (weight * eb / n).sum():.2f}")
        print(" | ".join(line))


if __name__ == "__main__":
    main()
