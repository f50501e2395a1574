#!/usr/bin/env bash
# The lookups' filter and the quarter of the rays for the lookup passes (docs/estimator.md,
# "The lookups: filtered, a quarter of the rays"): the default bake and the unguided one
# against the same two with every gather ray and no filter (the bakes before them,
# `+lookup=100+filter=0`), through docs/bench/surfaces/run.sh: the converted Bitterli scenes,
# 4 seeds, one thread, path references (128²: 128 / 256 / 1024 spp against 16 384 spp;
# 256²: 128 / 256 spp against 4 096 spp), then the ratios (compare.py).
#   docs/bench/lookup-filter/run.sh SCENES_DIR OUT [SIZE]      (default size: 128)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; size=${3:-128}
here=$(dirname "$0")
old="+lookup=100+filter=0"
methods="off/average/-,coherent/cluster/rho,coherent/cluster/rho$old,off/average/-$old"
if [ "$size" = 128 ]; then spp=128,256,1024 ref=16384; else spp=128,256 ref=4096; fi
METHODS="$methods" SPP=$spp REF_SPP=$ref SEEDS=4 "$here/../surfaces/run.sh" "$scenes" "$out" "$size"
python3 "$here/compare.py" "$out"
