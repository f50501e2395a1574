#!/usr/bin/env bash
# Side-by-side bakes of one scene by two guidebake binaries (e.g. before and after a change to
# hit shading), alternating so the shared machine's noise falls on both alike:
#   scripts/texture-duel.sh BEFORE AFTER SCENE [SIZE] [RUNS]
# Prepares SCENE once at SIZE (default 128x128, with --write-gltf so unwrapped meshes bake),
# then bakes it RUNS times (default 5) with each binary, seed 0, 2 threads, and prints every
# run's wall seconds, the medians and the median of the paired ratios AFTER/BEFORE, whether
# the two lightmaps are the same bits, and the mean relative change of their luminance
# (needs python3 with OpenEXR and numpy). docs/lightmaps.md, "Textured albedo at hits".
set -euo pipefail
before=$1 after=$2 scene=$3 size=${4:-128x128} runs=${5:-5}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
"$after" prepare "$scene" -o "$dir/s.texels" --size "$size" --write-gltf "$dir/s.glb" >/dev/null
baked=$dir/s.glb
case $scene in *.gltf | *.glb) ;; *) baked=$scene ;; esac
for i in $(seq "$runs"); do
    for v in before after; do
        bin=${!v}
        start=$(date +%s.%N)
        "$bin" bake "$dir/s.texels" --scene "$baked" -o "$dir/$v.exr" --threads 2 --seed 0 >/dev/null
        echo "$v $(echo "$(date +%s.%N) - $start" | bc)"
    done
done | tee "$dir/times"
python3 - "$dir" <<'EOF'
import sys, statistics, hashlib
d = sys.argv[1]
t = {"before": [], "after": []}
for line in open(f"{d}/times"):
    k, v = line.split()
    t[k].append(float(v))
ratios = [a / b for a, b in zip(t["after"], t["before"])]
print(f"median wall s: before {statistics.median(t['before']):.2f}, after {statistics.median(t['after']):.2f}, "
      f"median paired ratio after/before {statistics.median(ratios):.3f}")
same = hashlib.md5(open(f"{d}/before.exr", "rb").read()).digest() == hashlib.md5(open(f"{d}/after.exr", "rb").read()).digest()
print(f"lightmaps identical: {same}")
try:
    import OpenEXR, numpy as np
    def lum(p):
        ch = OpenEXR.File(p).parts[0].channels
        rgb = ch["RGB"].pixels if "RGB" in ch else np.stack([ch[c].pixels for c in "RGB"], -1)
        return rgb.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    a, b = lum(f"{d}/before.exr"), lum(f"{d}/after.exr")
    m = (a > 0) & (b > 0)
    print(f"texels {m.sum()}: mean luminance {a[m].mean():.5f} -> {b[m].mean():.5f}, "
          f"mean |change| / mean {np.abs(a[m] - b[m]).mean() / a[m].mean():.4f}")
except ImportError:
    print("(python3 OpenEXR/numpy missing: no per-texel comparison)")
EOF
