#!/usr/bin/env python3
"""Probe files against a reference probe file (docs/probes.md, "How good the probes are").

  compare.py REF.probes RUN.probes [RUN.probes ...]   -> one line of JSON per run

Reads the probe file format (docs/probes.md, "The probe file") without guidebake: the
64-byte header, then 128-byte records (position, spacing, relative error, 27 SH floats).
The runs must hold the same probes as the reference, in the same order. For each probe and
each of the 26 judged directions n (a cube's faces, edges and corners), the irradiance
E(n) = sum_l A_l L_lm Y_lm(n) per RGB channel; over all of them:
  mse     = mean (E - R)^2
  rel_mse = mean (E - R)^2 / (R^2 + eps), eps = 1e-2 * mean(R)^2   (as `guidebake bench`)
"""
import json
import struct
import sys

import numpy as np

A = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)


def basis(d):
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x,
                     1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1),
                     1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=1)


def directions():
    d = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)
                  if (x, y, z) != (0, 0, 0)], dtype=np.float64)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def read(path):
    b = open(path, "rb").read()
    if b[:8] != b"GBPROBES":
        sys.exit(f"{path}: not a probe file")
    version, record, count = struct.unpack_from("<IIQ", b, 8)
    if version != 1 or record != 128 or len(b) != 64 + 128 * count:
        sys.exit(f"{path}: version {version}, {record}-byte records, {len(b)} bytes for {count}")
    rec = np.frombuffer(b[64:], dtype="<f4").reshape(count, 32).astype(np.float64)
    return rec[:, :3], rec[:, 5:32].reshape(count, 9, 3)


def irradiance(sh):
    w = basis(directions()) * A  # (26, 9)
    return np.einsum("dk,pkc->pdc", w, sh)  # (probes, 26, 3)


def main():
    ref_pos, ref_sh = read(sys.argv[1])
    r = irradiance(ref_sh)
    eps = 1e-2 * r.mean() ** 2
    for path in sys.argv[2:]:
        pos, sh = read(path)
        if pos.shape != ref_pos.shape or not np.allclose(pos, ref_pos):
            sys.exit(f"{path}: not the reference's probes")
        e = irradiance(sh)
        print(json.dumps({"run": path, "probes": len(pos),
                          "mse": float(((e - r) ** 2).mean()),
                          "rel_mse": float(((e - r) ** 2 / (r * r + eps)).mean())}))


if __name__ == "__main__":
    main()
