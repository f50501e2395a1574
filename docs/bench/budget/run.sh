#!/usr/bin/env bash
# The spatial budget (`--budget`, docs/estimator.md "The spatial budget") against the default's
# uniform budget at equal time, against unbiased path references. For each converted Bitterli
# scene at SIZE² texels: prepare, then `guidebake bench` with the ladder 64, 256, 1024 spp × 2
# seeds, one thread, methods
#   coherent/cluster/rho                  the default (series, guided, uniform budget)
#   coherent/cluster/rho+budget=balanced  n ∝ σ/√(μ·μ̄)
#   coherent/cluster/rho+budget=mse       n ∝ σ
#   coherent/cluster/rho+budget=relative  n ∝ σ/√(μ² + ε)
# and the bench's unguided baseline, against a 16 384-spp path reference (16× the top rung;
# the same references as docs/bench/surfaces/run.sh, so OUT/cache can be that run's).
# SPP (default 64,256,1024) and REF_SPP (default 16384) change the ladder and the reference.
# Writes OUT/SCENE-SIZE/ (runs.csv, summary.json, table.md, charts); then
# `docs/bench/surfaces/summary.py OUT` prints the per-method means.
#   docs/bench/budget/run.sh SCENES_DIR OUT [SIZE...]      (default size: 128)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; shift 2
[ $# -gt 0 ] && sizes=("$@") || sizes=(128)
g=${GUIDEBAKE:-target/release/guidebake}
mkdir -p "$out"
for n in "${sizes[@]}"; do
  for s in cornell_box veach_ajar_no_teapots veach_bidir; do
    glb="$scenes/converted/bitterli_$s.glb"
    dir="$out/$s-$n"
    mkdir -p "$dir"
    "$g" prepare "$glb" -o "$dir/scene.texels" --size "${n}x${n}" >/dev/null
    "$g" bench "$glb" --texels "$dir/scene.texels" -o "$dir" --cache "$out/cache" \
      --methods "coherent/cluster/rho,coherent/cluster/rho+budget=balanced,coherent/cluster/rho+budget=mse,coherent/cluster/rho+budget=relative" \
      --spp "${SPP:-64,256,1024}" --ref-spp "${REF_SPP:-16384}" --seeds 2 --repeats 0 --threads 1 > "$dir/bench.log" 2>&1
    rm -f "$dir/scene.texels" "$dir/scene.texels.seams"
    echo "$s $n: $(grep -c '' "$dir/runs.csv") rows"
  done
done
