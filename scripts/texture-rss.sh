#!/usr/bin/env bash
# Peak memory of loading a glTF with a few big base-colour textures (docs/lightmaps.md,
# "Textured albedo", memory):
#   scripts/texture-rss.sh GUIDEBAKE [COUNT] [SIZE] [RUNS]
# writes COUNT PNGs of SIZE² RGB (default 4 of 4096², a smooth pattern, so the files stay
# small) and a glTF of COUNT quads, one textured material each, into a temporary directory,
# then runs `GUIDEBAKE prepare` on it RUNS times (default 3) under /usr/bin/time and prints
# each run's maximum resident set size. Needs python3 with Pillow (PIL).
set -euo pipefail
bin=$1 count=${2:-4} size=${3:-4096} runs=${4:-3}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
python3 - "$dir" "$count" "$size" <<'EOF'
import base64, json, struct, sys
from PIL import Image
out, count, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
for i in range(count):
    # A smooth gradient per channel: cheap to write, as big as any image once decoded.
    r = Image.linear_gradient("L").resize((size, size))
    g = r.transpose(Image.Transpose.ROTATE_90)
    b = Image.new("L", (size, size), 40 * i)
    Image.merge("RGB", (r, g, b)).save(f"{out}/tex{i}.png", compress_level=1)
positions, uvs, indices = [], [], []
for i in range(count):
    x = 1.1 * i
    positions += [x, 0, 0, x + 1, 0, 0, x + 1, 0, 1, x, 0, 1]
    uvs += [0, 0, 1, 0, 1, 1, 0, 1]
    indices += [0, 1, 2, 0, 2, 3]
blob = b"".join(struct.pack("<f", v) for v in positions)
blob_uv = b"".join(struct.pack("<f", v) for v in uvs)
blob_ix = b"".join(struct.pack("<H", v) for v in indices)
data = blob + blob_uv + blob_ix
views, accessors, meshes, nodes = [], [], [], []
for i in range(count):
    views += [
        {"buffer": 0, "byteOffset": 48 * i, "byteLength": 48},
        {"buffer": 0, "byteOffset": len(blob) + 32 * i, "byteLength": 32},
        {"buffer": 0, "byteOffset": len(blob) + len(blob_uv) + 12 * i, "byteLength": 12},
    ]
    lo, hi = [1.1 * i, 0, 0], [1.1 * i + 1, 0, 1]
    accessors += [
        {"bufferView": 3 * i, "componentType": 5126, "count": 4, "type": "VEC3", "min": lo, "max": hi},
        {"bufferView": 3 * i + 1, "componentType": 5126, "count": 4, "type": "VEC2"},
        {"bufferView": 3 * i + 2, "componentType": 5123, "count": 6, "type": "SCALAR"},
    ]
    meshes.append({"primitives": [{"attributes": {"POSITION": 3 * i, "TEXCOORD_0": 3 * i + 1},
                                   "indices": 3 * i + 2, "material": i}]})
    nodes.append({"mesh": i})
gltf = {
    "asset": {"version": "2.0"},
    "scene": 0,
    "scenes": [{"nodes": list(range(count))}],
    "nodes": nodes,
    "meshes": meshes,
    "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": i}}} for i in range(count)],
    "textures": [{"source": i} for i in range(count)],
    "images": [{"uri": f"tex{i}.png"} for i in range(count)],
    "buffers": [{"byteLength": len(data),
                 "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
    "bufferViews": views,
    "accessors": accessors,
}
json.dump(gltf, open(f"{out}/big.gltf", "w"))
EOF
for run in $(seq "$runs"); do
    /usr/bin/time -f "run $run: max RSS %M KiB, %e s" "$bin" prepare "$dir/big.gltf" --sky 1 \
        -o "$dir/big.texels" >/dev/null
done
