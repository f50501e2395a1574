#!/usr/bin/env bash
# The default bake against path transport at equal time, against unbiased path references
# (docs/bake.md, "Where series reads the lightmap"; docs/series.md, "The default bake is
# right where surfaces meet"). For each converted Bitterli scene at SIZE² texels: prepare,
# then `guidebake bench` with the ladder 64, 256, 1024 spp × 2 seeds, one thread, methods
#   off/average/-                        unguided series (the bench's baseline)
#   coherent/cluster/rho                 the default (series, guided)
#   coherent/cluster/rho+transport=path  guided path transport
#   off/average/-+transport=path         unguided path transport
# against a 16 384-spp path reference (16× the top rung). Writes OUT/SCENE-SIZE/ (the
# bench's runs.csv, summary.json, table.md, charts). METHODS, SPP (the ladder), REF_SPP and
# SEEDS (how many) replace those (docs/bench/budget/run.sh runs its own methods through this script);
# REFERENCE_NOISE=1 adds --reference-noise (docs/bench/reference-noise/run.sh); the references
# bake on every core unless REFERENCE_THREADS says otherwise (1 when two of these run side by side).
#   docs/bench/surfaces/run.sh SCENES_DIR OUT [SIZE...]      (default sizes: 128 256)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; shift 2
sizes=("${@:-128 256}"); [ $# -gt 0 ] && sizes=("$@") || sizes=(128 256)
g=${GUIDEBAKE:-target/release/guidebake}
mkdir -p "$out"
for n in "${sizes[@]}"; do
  for s in cornell_box veach_ajar_no_teapots veach_bidir; do
    glb="$scenes/converted/bitterli_$s.glb"
    dir="$out/$s-$n"
    mkdir -p "$dir"
    "$g" prepare "$glb" -o "$dir/scene.texels" --size "${n}x${n}" >/dev/null
    "$g" bench "$glb" --texels "$dir/scene.texels" -o "$dir" --cache "$out/cache" \
      --methods "${METHODS:-coherent/cluster/rho,coherent/cluster/rho+transport=path,off/average/-+transport=path}" \
      --spp "${SPP:-64,256,1024}" --ref-spp "${REF_SPP:-16384}" --seeds "${SEEDS:-2}" --repeats 0 --threads 1 ${REFERENCE_NOISE:+--reference-noise} \
      ${REFERENCE_THREADS:+--reference-threads "$REFERENCE_THREADS"} > "$dir/bench.log" 2>&1
    rm -f "$dir/scene.texels" "$dir/scene.texels.seams"
    echo "$s $n: $(grep -c '' "$dir/runs.csv") rows"
  done
done
