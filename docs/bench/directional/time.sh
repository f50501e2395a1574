#!/bin/sh
# The bake's time with and without --directional sh-l1, side by side (docs/lightmaps.md,
# "Directional lightmaps"): the Veach bidir room at a SIZE page (default 512x512), default
# settings (series, 3 bounces, coherent guiding, global weights), 256 spp, 2 threads; the two
# runs of each round alternate, ROUNDS rounds (default 3). Prints gather and page-writing
# seconds per run.
# Usage: [SIZE=256x256] [ROUNDS=5] docs/bench/directional/time.sh [GUIDEBAKE] [SCENE]
set -eu
bin=${1:-target/release/guidebake}
scene=${2:-../shared/scenes/converted/bitterli_veach_bidir.glb}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin" prepare "$scene" -o "$work/t.texels" --size "${SIZE:-512x512}" >/dev/null
for round in $(seq "${ROUNDS:-3}"); do
  for mode in none sh-l1; do
    "$bin" bake "$work/t.texels" --scene "$scene" -o "$work/$mode.exr" --threads 2 \
      --directional "$mode" --stats "$work/$mode.json" >/dev/null 2>&1
    python3 - "$work/$mode.json" "$mode" "$round" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["seconds"]
print(f"round {sys.argv[3]} {sys.argv[2]:6} gather {s['gather']:.2f} s write_pages {s['write_pages']:.2f} s")
PY
    ls -l "$work/$mode.exr" | awk -v m="$mode" '{print "  " m " exr bytes " $5}'
    rm -f "$work/$mode.exr" "$work/$mode.png"
  done
done
