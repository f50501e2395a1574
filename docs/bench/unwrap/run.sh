#!/bin/sh
# Unwrap time and peak RSS of zdm2 and zdm2 tiled 15x (docs/texels.md, "Unwrapping big
# meshes"). Usage: docs/bench/unwrap/run.sh [SHARED_SCENES_DIR] [OUT_DIR]
set -eu
scenes=${1:-../shared/scenes}
out=${2:-/tmp/unwrap-bench}
bin=target/release/guidebake
cargo build --release -p guidebake --bin guidebake
dir=$(dirname "$0")
python3 "$dir/tile_obj.py" "$scenes/calinou_zdm2/zdm2.obj" 1 "$out/x1"
python3 "$dir/tile_obj.py" "$scenes/calinou_zdm2/zdm2.obj" 15 "$out/x15"
for run in "x1 768x768 always" "x15 4096x4096 never" "x15 4096x4096 always"; do
  set -- $run
  echo "== $1 --size $2 --unwrap $3"
  /usr/bin/time -v "$bin" prepare "$out/$1/tiled.obj" -o "$out/$1.texels" --unwrap "$3" \
    --size "$2" 2>&1 | grep -E "unwrapped|Elapsed|Maximum resident"
done
