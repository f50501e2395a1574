#!/usr/bin/env python3
"""Probes interpolated between lattice points against reference probes at those points
(docs/probes.md, "Where light changes").

  refine.py BOUNDS_FROM.probes N SEED > points.txt          -> N random points in its bounds
  refine.py REF.probes LATTICE.probes [LATTICE.probes ...]  -> one line of JSON per lattice

The reference holds probes at random points (`guidebake probes --placement points`); each
lattice's probes are interpolated there as `guidebake render` and an engine do
(driver/src/probes/field.rs: each probe weighs the tent of its own spacing along each axis,
the weights normalised; a point no probe reaches takes the nearest). The error is over the
26 judged directions' irradiance, as compare.py's: MSE and relative MSE (eps = 1e-2 mean^2)
over every reference point.
"""
import json
import sys

import numpy as np

from compare import irradiance, read


def interpolate(pos, sh, spacing, at):
    out = np.zeros((len(at), 9, 3))
    for start in range(0, len(at), 256):
        x = at[start:start + 256]
        d = np.abs(x[:, None, :] - pos[None, :, :]) / spacing[None, :, None]
        w = np.prod(np.clip(1 - d, 0, None), axis=2)  # (points, probes)
        total = w.sum(axis=1)
        nearest = np.argmin(((x[:, None, :] - pos[None, :, :]) ** 2).sum(axis=2), axis=1)
        o = np.einsum("pq,qkc->pkc", w, sh) / np.where(total > 0, total, 1)[:, None, None]
        o[total <= 0] = sh[nearest[total <= 0]]
        out[start:start + 256] = o
    return out


def spacing_of(path):
    b = open(path, "rb").read()
    return np.frombuffer(b[64:], dtype="<f4").reshape(-1, 32)[:, 3].astype(np.float64)


def main():
    if len(sys.argv) == 4 and sys.argv[2].isdigit():
        pos, _ = read(sys.argv[1])
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        rng = np.random.default_rng(int(sys.argv[3]))
        for p in lo + rng.random((int(sys.argv[2]), 3)) * (hi - lo):
            print(f"{p[0]:.5f} {p[1]:.5f} {p[2]:.5f}")
        return
    ref_pos, ref_sh = read(sys.argv[1])
    r = irradiance(ref_sh)
    eps = 1e-2 * r.mean() ** 2
    for path in sys.argv[2:]:
        pos, sh = read(path)
        e = irradiance(interpolate(pos, sh, spacing_of(path), ref_pos))
        sq = (e - r) ** 2
        print(json.dumps({
            "lattice": path, "probes": len(pos), "points": len(ref_pos),
            "mse": float(sq.mean()), "rel_mse": float((sq / (r * r + eps)).mean()),
        }))

if __name__ == "__main__":
    main()
