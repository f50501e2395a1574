#!/usr/bin/env bash
# How many learning iterations (docs/guiding-levers.md, "The records a guide learns from, and three iterations"): for each
# converted Bitterli scene at 256², the default bake with `--iterations` 3, 4, 5 and 6 and the
# unguided bake (4), 256 spp, seeds 1 and 2, one thread, timed (user + system CPU); then
# compare.py measures them against the 4 096-spp path references and twins that
# docs/bench/reference-noise/run.sh baked (its OUT, size 256: the references do not depend on
# the bakes' iteration count, and the bench keys its cache by it, so the bakes run outside it).
#   docs/bench/iterations/run.sh SCENES_DIR NOISE_OUT OUT
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; noise=${2:?reference-noise/run.sh OUT (256²)}; out=${3:?output dir}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
mkdir -p "$out"
for s in cornell_box veach_ajar_no_teapots veach_bidir; do
  glb="$scenes/converted/bitterli_$s.glb"
  "$g" prepare "$glb" -o "$out/$s.texels" --size 256x256 >/dev/null 2>&1
  for seed in 1 2; do
    for cfg in off-4 coherent-3 coherent-4 coherent-5 coherent-6; do
      /usr/bin/time -f "%U %S" -o "$out/$s-$cfg-$seed.time" "$g" bake "$out/$s.texels" --scene "$glb" \
        -o "$out/$s-$cfg-$seed.exr" --guiding "${cfg%-*}" --iterations "${cfg#*-}" --spp 256 \
        --seed "$seed" --threads 1 >/dev/null 2>&1
    done
  done
done
python3 "$here/compare.py" "$noise" "$out"
