#!/bin/bash
# Series transport against a path reference: two builds of guidebake (e.g. before and after a
# transport change), each baking the unguided baseline at 1024 spp, timed (user + system CPU
# seconds), and every lightmap's RMSE and mean bias against a 2048-spp path bake.
# Usage (repository root): docs/bench/series-total/vs-path.sh OLD_BIN NEW_BIN SCENE.glb OUT_DIR
# Needs python3 with numpy and OpenEXR. The NEAR_FIELD_TEXELS sweep in BENCHMARKS.md was
# this script run with NEW_BIN built at each value of the constant.
set -euo pipefail
old=${1:?OLD_BIN}; new=${2:?NEW_BIN}; scene=${3:?SCENE.glb}; out=${4:?OUT_DIR}
mkdir -p "$out"
"$new" prepare "$scene" -o "$out/scene.texels" --size 128x128 >/dev/null
"$new" bake "$out/scene.texels" --scene "$scene" -o "$out/path-ref.exr" --spp 2048 \
    --transport path --guiding off --combine average --aux >/dev/null
for v in old new; do
    bin=$old; [ $v = new ] && bin=$new
    /usr/bin/time -f "%U %S" -o "$out/$v.time" "$bin" bake "$out/scene.texels" --scene "$scene" \
        -o "$out/$v.exr" --spp 1024 --guiding off --combine average --aux >/dev/null
    echo "$v CPU s: $(awk '{print $1 + $2}' "$out/$v.time")"
done
python3 "$(dirname "$0")/rmse_vs_path.py" "$out/path-ref.exr" "$out/old.exr" "$out/new.exr"
