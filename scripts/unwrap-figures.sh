#!/usr/bin/env bash
# The unwrap figures of docs/texels.md ("Lightmap UVs when a mesh has none"): each scene of
# ../shared/scenes prepared ROUNDS times at the default resolution with `--unwrap` and
# `--write-gltf`; prints one Markdown table row per scene: meshes unwrapped, xatlas charts,
# atlas and page sizes, texels/unit, texels, utilisation (texels / page area), the median
# (min–max) seconds in xatlas (`unwrap.seconds` of `prepare --json`), triangles too small
# for a UV, and whether the first and last run wrote the same bytes.
#
#   cargo build --release -p guidebake --bin guidebake
#   scripts/unwrap-figures.sh [SCENES_DIR] [ROUNDS]
set -euo pipefail
cd "$(dirname "$0")/.."
scenes=${1:-../shared/scenes}
rounds=${2:-5}
bin=target/release/guidebake
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
vinc3r=vinc3r_cornellbox/BJS-2.80-Eevee-gltf/assets/cornellBox-2.80-Eevee-gltf.gltf
echo "| scene | --unwrap | meshes | charts | atlas | page | texels/unit | texels | utilisation | xatlas s, median (min–max) | tiny triangles | same bytes |"
echo "|---|---|---:|---:|---|---|---:|---:|---:|---|---:|---|"
for spec in "converted/bitterli_cornell_box.glb always" "converted/bitterli_veach_bidir.glb always" \
    "converted/bitterli_veach_ajar_no_teapots.glb always" "$vinc3r missing" "$vinc3r always"; do
    read -r file mode <<<"$spec"
    for ((i = 1; i <= rounds; i++)); do
        "$bin" prepare "$scenes/$file" -o "$out/$i.texels" --unwrap "$mode" \
            --write-gltf "$out/$i.glb" --json 2>/dev/null >"$out/$i.json"
    done
    same=no
    cmp -s "$out/1.texels" "$out/$rounds.texels" && cmp -s "$out/1.glb" "$out/$rounds.glb" && same=yes
    python3 - "$out" "$rounds" "$(basename "$file")" "$mode" "$same" <<'PY'
import json, statistics, sys
out, rounds, name, mode, same = sys.argv[1:]
runs = [json.load(open(f"{out}/{i}.json")) for i in range(1, int(rounds) + 1)]
r, u = runs[0], runs[0]["unwrap"]
s = [x["unwrap"]["seconds"] for x in runs]
size = lambda l: ", ".join(f"{w}×{h}" for w, h in l)
print(f"| {name} | {mode} | {len(u['meshes'])} | {u['charts']} | {size(u['atlases'])} | {size(r['pages'])} "
      f"| {r['texels_per_unit']:.1f} | {r['texels']} | {u['utilisation']:.3f} "
      f"| {statistics.median(s):.3f} ({min(s):.3f}–{max(s):.3f}) | {u['tiny_triangles']} | {same} |")
PY
    rm -f "$out"/*
done
