#!/usr/bin/env bash
# The "after" pictures of docs/series.md, "The default bake is right where surfaces meet":
# per-texel error maps of the default (series) and of path transport, 256 spp each, against a
# 16 384-spp unguided path reference (Cornell box at 128², Veach ajar at 256²), and the Cornell
# box rendered from each lightmap (path | default). The references take about 9 minutes on 2 cores.
#   docs/bench/surfaces/maps.sh SCENES_DIR OUT
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
ref=(--transport path --guiding off --combine average --bias-correction off --spp 16384)
mkdir -p "$out"; cd "$out"
for job in cornell_box:128:cornell-128 veach_ajar_no_teapots:256:ajar-256; do
  IFS=: read -r scene n name <<< "$job"
  glb="$scenes/converted/bitterli_$scene.glb"
  "$g" prepare "$glb" -o "$name.texels" --size "${n}x${n}" > /dev/null
  [ -f "$name-ref.exr" ] || "$g" bake "$name.texels" --scene "$glb" -o "$name-ref.exr" "${ref[@]}" > /dev/null
  for t in series path; do
    "$g" bake "$name.texels" --scene "$glb" -o "$name-$t.exr" --spp 256 --transport "$t" > /dev/null
  done
  python3 "$here/error_maps.py" "$name.texels" "$name-ref.exr" "$name-series.exr" "$name-path.exr" \
    "$name-after.png"
done
for t in path series; do
  "$g" render "$scenes/converted/bitterli_cornell_box.glb" --texels cornell-128.texels \
    --lightmap "cornell-128-$t.exr" -o "cornell-render-$t.png"
done
python3 -c "
from PIL import Image
a, b = Image.open('cornell-render-path.png'), Image.open('cornell-render-series.png')
c = Image.new('RGB', (a.width + b.width, a.height)); c.paste(a, (0, 0)); c.paste(b, (a.width, 0))
c.save('cornell-render-after.png')"
ls -l "$out"/*-after.png
