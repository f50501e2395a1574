#!/usr/bin/env bash
# The spatial budget (`--budget`, docs/budget.md "The spatial budget") against the default's
# uniform budget, against unbiased path references: docs/bench/surfaces/run.sh (each converted
# Bitterli scene at SIZE², the bench's ladder 64, 256, 1024 spp × 2 seeds, one thread,
# 16 384-spp path references, the same as that run's, so OUT/cache can be its) with methods
#   coherent/cluster/rho                  the default (series, guided, `bounded` budget)
#   coherent/cluster/rho+budget=uniform   every texel --spp (the default before 2026-11-29)
#   coherent/cluster/rho+budget=balanced  n ∝ σ/√(μ·μ̄)
#   coherent/cluster/rho+budget=mse       n ∝ σ
#   coherent/cluster/rho+budget=relative  n ∝ σ/√(μ² + ε)
# and the bench's unguided baseline (uniform). SPP, REF_SPP and SEEDS change the ladder, the
# reference and the seeds (the 256² figures: SPP=64,256 REF_SPP=4096 SEEDS=4). Writes
# OUT/SCENE-SIZE/; then `docs/bench/guide-target/compare.py OUT METHOD...` sets each method
# beside the default at equal time.
#   docs/bench/budget/run.sh SCENES_DIR OUT [SIZE...]      (default size: 128)
set -euo pipefail
[ $# -gt 2 ] || set -- "${1:?scenes dir (../shared/scenes)}" "${2:?output dir}" 128
b=coherent/cluster/rho
METHODS="$b,$b+budget=uniform,$b+budget=balanced,$b+budget=mse,$b+budget=relative" \
  exec "$(dirname "$0")/../surfaces/run.sh" "$@"
