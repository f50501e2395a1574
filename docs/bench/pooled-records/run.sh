#!/usr/bin/env bash
# A guide learning from every iteration of its cluster, 3 iterations by default, and an unguided
# pass baking in one (docs/guiding-levers.md, "The records a guide learns from"; docs/sampling.md, "One
# set, not four"): the build before (OLD: a guide learns from the last iteration's records, 4
# iterations in every pass) and after (NEW) side by side, 256², 256 spp, seeds 5–8, one thread,
# each bake timed (user + system CPU), interleaved per seed:
#   old     OLD's default                 offold  OLD unguided (--guiding off --combine average)
#   new4    NEW with --iterations 4       new     NEW's default
#   off     NEW unguided (the bench's baseline: one iteration in every pass)
# on the three converted scenes, against the references and twins of a reference-noise bench
# run (NOISE_OUT: docs/bench/reference-noise/run.sh SCENES_DIR NOISE_OUT 256); then compare.py
# prints each against `old` and against the unguided bakes, at equal samples and at equal CPU time.
#   docs/bench/pooled-records/run.sh OLD NEW SCENES_DIR NOISE_OUT OUT
set -euo pipefail
old=$(realpath "${1:?old guidebake}"); new=$(realpath "${2:?new guidebake}")
scenes=${3:?scenes dir}; noise=${4:?reference-noise OUT (256²)}; out=${5:?output dir}
here=$(dirname "$(realpath "$0")")
mkdir -p "$out"
unguided="--guiding off --combine average"
variants=("old|$old|" "offold|$old|$unguided" "new4|$new|--iterations 4" "new|$new|" "off|$new|$unguided")
for s in ${SCENES:-cornell_box veach_ajar_no_teapots veach_bidir}; do
  src="$scenes/converted/bitterli_$s.glb"
  "$new" prepare "$src" -o "$out/$s.texels" --size 256x256 >/dev/null 2>&1
  for seed in ${SEEDS:-5 6 7 8}; do
    for v in "${variants[@]}"; do
      IFS='|' read -r name bin args <<< "$v"
      # shellcheck disable=SC2086 # args are words
      /usr/bin/time -f "%U %S" -o "$out/$s-$name-$seed.time" "$bin" bake "$out/$s.texels" --scene "$src" \
        -o "$out/$s-$name-$seed.exr" --spp 256 --seed "$seed" --threads 1 $args >/dev/null 2>&1
    done
  done
done
python3 "$here/compare.py" "$noise" "$out" | tee "$out/compare.md"
