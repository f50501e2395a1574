#!/usr/bin/env bash
# The guiding targets' measure (docs/BENCHMARKS.md, "What falls short") on a level none of the defaults were tuned on: the Cube 2 level zdm2
# (../shared/scenes/calinou_zdm2, CC BY 4.0; textures stripped, a sun and a sky from a TOML
# file: docs/bench/surfaces/zdm2-scene.sh) at SIZE², the default against the uniform
# unguided bake, 64 / 256 spp, SEEDS seeds (2), one thread, against a 4 096-spp path reference
# and its twin (--reference-noise); then docs/bench/reference-noise/net.py: the equal-time
# ratios raw and net of the reference's noise (docs/series.md, "Guiding at equal time on a level (zdm2)").
#   docs/bench/zdm2-guiding/run.sh SCENES_DIR OUT [SIZE]      (default SIZE: 768; 17 552 charts do not fit 512²)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; n=${3:-768}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
"$here/../surfaces/zdm2-scene.sh" "$scenes" "$out/src"
dir="$out/zdm2-$n"
mkdir -p "$dir"
"$g" prepare "$out/src/zdm2.toml" -o "$dir/scene.texels" --unwrap always --size "${n}x${n}" >/dev/null
"$g" bench "$out/src/zdm2.toml" --texels "$dir/scene.texels" -o "$dir" --cache "$out/cache" \
  --methods "${METHODS:-off/average/-,coherent/cluster/rho}" --spp 64,256 --ref-spp 4096 \
  --seeds "${SEEDS:-2}" --repeats 0 --threads 1 --reference-noise > "$dir/bench.log" 2>&1
rm -f "$dir/scene.texels" "$dir/scene.texels.seams"
python3 "$here/../reference-noise/net.py" "$out"
