#!/usr/bin/env bash
# Fewer rays for the lookups (`--lookup-spp`, docs/estimator.md): the default bake against the
# same with the passes before the last at 50 % and 25 % of the rung's spp (`+lookup=P`),
# through docs/bench/surfaces/run.sh (the converted Bitterli scenes at SIZE², the ladder 256
# and 1024 spp × 2 seeds — 25 % of 64 leaves less than a packet per iteration — one thread,
# 16 384-spp path references), then the ratios against the default of the same run.
#   docs/bench/lookup-spp/run.sh SCENES_DIR OUT [SIZE]      (default size: 128)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; size=${3:-128}
here=$(dirname "$0")
b=coherent/cluster/rho
METHODS="$b,$b+lookup=50,$b+lookup=25" SPP=256,1024 "$here/../surfaces/run.sh" "$scenes" "$out" "$size"
python3 "$here/../lightmap-direct/compare.py" "$out" "$out"
