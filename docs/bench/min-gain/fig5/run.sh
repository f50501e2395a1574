#!/usr/bin/env bash
# Figure-5 overhead at the defaults with --min-gain 25 (docs/BENCHMARKS.md, "Figure-5
# overhead"): coherent / off at equal samples, 9 interleaved repeats, one thread, 128²,
# series references of 4 096 spp (only overhead.csv is used), then the paired medians.
#   docs/bench/min-gain/fig5/run.sh SCENES_DIR OUT
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}
g=${GUIDEBAKE:-target/release/guidebake}
mkdir -p "$out"
for s in veach_ajar_no_teapots cornell_box veach_bidir; do
  "$g" prepare "$scenes/converted/bitterli_$s.glb" -o "$out/$s.texels" --size 128x128 >/dev/null
  "$g" bench "$scenes/converted/bitterli_$s.glb" --texels "$out/$s.texels" -o "$out/$s" --cache "$out/cache" \
    --transport series --reference-transport series --spp 64,256 --seeds 1 --repeats 9 --threads 1 \
    --methods 'off/average/-,coherent/cluster/rho' > "$out/$s.log" 2>&1
  rm -f "$out/$s.texels" "$out/$s.texels.seams"
done
python3 "$(dirname "$0")/medians.py" "$out" veach_ajar_no_teapots cornell_box veach_bidir
