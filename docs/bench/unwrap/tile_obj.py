#!/usr/bin/env python3
"""Tiles an OBJ level N times on a grid, for the unwrap benchmark (docs/texels.md,
"Unwrapping big meshes").

usage: tile_obj.py SRC.obj N OUT_DIR

Writes OUT_DIR/tiled.obj and OUT_DIR/tiled.mtl. Copy k is moved by whole bounding-box
widths (plus 10 %) on a grid of ceil(sqrt(N)) columns. Faces are grouped by their group
(`g`/`o`) across copies: a group of the source becomes one mesh N times as big, so big meshes
are cut into chunks. The MTL is the source's with its texture lines (`map_*`, `bump`,
`disp`, `decal`, `refl`) dropped: downloaded levels often come without their textures.
"""
import math
import os
import re
import sys


def main():
    src, n, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    os.makedirs(out, exist_ok=True)
    v, vt, vn = [], [], []
    groups = {}  # name -> [(usemtl, [face tokens])]
    order = []
    mtllib = None
    group = "default"
    material = None
    with open(src) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            k = parts[0]
            if k == "v":
                v.append(tuple(float(x) for x in parts[1:4]))
            elif k == "vt":
                vt.append(line.split(None, 1)[1].strip())
            elif k == "vn":
                vn.append(line.split(None, 1)[1].strip())
            elif k in ("g", "o"):
                group = " ".join(parts[1:]) or "default"
            elif k == "usemtl":
                material = " ".join(parts[1:])
            elif k == "mtllib":
                mtllib = " ".join(parts[1:])
            elif k == "f":
                if group not in groups:
                    groups[group] = []
                    order.append(group)
                g = groups[group]
                if not g or g[-1][0] != material:
                    g.append((material, []))
                # Resolve relative (negative) indices now, against the elements so far.
                face = []
                for tok in parts[1:]:
                    idx = tok.split("/")
                    counts = (len(v), len(vt), len(vn))
                    res = []
                    for i, s in enumerate(idx):
                        if s == "":
                            res.append(None)
                        else:
                            x = int(s)
                            res.append(x - 1 if x > 0 else counts[i] + x)
                    face.append(res)
                g[-1][1].append(face)
    lo = [min(p[i] for p in v) for i in range(3)]
    hi = [max(p[i] for p in v) for i in range(3)]
    step_x = (hi[0] - lo[0]) * 1.1
    step_z = (hi[2] - lo[2]) * 1.1
    cols = math.ceil(math.sqrt(n))
    with open(os.path.join(out, "tiled.obj"), "w") as o:
        o.write("mtllib tiled.mtl\n")
        for k in range(n):
            dx, dz = (k % cols) * step_x, (k // cols) * step_z
            for p in v:
                o.write(f"v {p[0] + dx:.6f} {p[1]:.6f} {p[2] + dz:.6f}\n")
        for _ in range(n):
            for t in vt:
                o.write(f"vt {t}\n")
            for t in vn:
                o.write(f"vn {t}\n")
        for name in order:
            o.write(f"g {name}\n")
            for material, faces in groups[name]:
                if material is not None:
                    o.write(f"usemtl {material}\n")
                for k in range(n):
                    offs = (k * len(v), k * len(vt), k * len(vn))
                    for face in faces:
                        toks = []
                        for res in face:
                            toks.append("/".join("" if x is None else str(x + offs[i] + 1)
                                                 for i, x in enumerate(res)))
                        o.write("f " + " ".join(toks) + "\n")
    if mtllib:
        drop = re.compile(r"^\s*(map_\w+|bump|disp|decal|refl)\b", re.I)
        with open(os.path.join(os.path.dirname(src), mtllib)) as f, \
                open(os.path.join(out, "tiled.mtl"), "w") as o:
            for line in f:
                if not drop.match(line):
                    o.write(line)


if __name__ == "__main__":
    main()
