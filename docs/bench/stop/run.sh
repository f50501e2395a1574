#!/usr/bin/env bash
# The stopping rule's calibration (docs/budget.md, "The stopping rule"): for each converted
# Bitterli scene at SIZE² texels, the default bake with `--target-error` 0.05 and 0.02
# (`+stop=50`, `+stop=20`), 8 iterations (a stop at every doubling), the cap CAP spp, one
# seed, one thread, against a path reference of 16× the cap (the bench's baseline, unguided at
# the cap, runs too). Writes OUT/SCENE-SIZE/ (runs.csv, bench.log); `calibration.py OUT`
# prints each bake's measured relative error (√ relative MSE) beside its target and the
# samples it took. REF_SPP overrides the reference's samples; REFERENCE_NOISE=1 bakes the
# reference's twin too (`--reference-noise`), and calibration.py then prints each error net
# of the reference's own noise as well; REFERENCE_THREADS passes --reference-threads. SCENES
# (space-separated) picks the scenes.
#   docs/bench/stop/run.sh SCENES_DIR OUT [SIZE [CAP]]     (default 128, 4096)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}
n=${3:-128}; cap=${4:-4096}
g=${GUIDEBAKE:-target/release/guidebake}
mkdir -p "$out"
for s in ${SCENES:-cornell_box veach_ajar_no_teapots veach_bidir}; do
  glb="$scenes/converted/bitterli_$s.glb"
  dir="$out/$s-$n${REF_SPP:+-ref$REF_SPP}"
  mkdir -p "$dir"
  "$g" prepare "$glb" -o "$dir/scene.texels" --size "${n}x${n}" >/dev/null
  "$g" bench "$glb" --texels "$dir/scene.texels" -o "$dir" --cache "$out/cache" \
    --methods "${METHODS:-coherent/cluster/rho+stop=50,coherent/cluster/rho+stop=20}" \
    --spp "$((cap / 4)),$cap" --ref-spp "${REF_SPP:-$((16 * cap))}" ${REFERENCE_NOISE:+--reference-noise} \
    ${REFERENCE_THREADS:+--reference-threads "$REFERENCE_THREADS"} --iterations 8 --seeds 1 --repeats 0 --threads 1 \
    > "$dir/bench.log" 2>&1
  rm -f "$dir/scene.texels" "$dir/scene.texels.seams"
  echo "$s $n: $(grep -c '' "$dir/runs.csv") rows"
done
