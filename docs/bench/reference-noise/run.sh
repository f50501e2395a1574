#!/usr/bin/env bash
# The guiding targets' measure with the reference's own noise taken out (docs/references.md, "The
# reference's own noise"): the default and the unguided bake through docs/bench/surfaces/run.sh
# with --reference-noise (the reference and its twin, the runs against their mean), 4 seeds,
# one thread (128²: 128 / 256 / 1024 spp against 16 384-spp path references; 256²: 128 / 256
# spp against 4 096-spp ones), then net.py: the ratios raw and net. METHODS adds methods
# (docs/BENCHMARKS.md's runs took `off/average/-,coherent/cluster/rho,coherent/cluster/rho+gain=150`).
#   docs/bench/reference-noise/run.sh SCENES_DIR OUT [SIZE]      (default size: 128)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; size=${3:-128}
here=$(dirname "$0")
if [ "$size" = 128 ]; then spp=128,256,1024 ref=16384; else spp=128,256 ref=4096; fi
METHODS=${METHODS:-off/average/-,coherent/cluster/rho} SPP=$spp REF_SPP=$ref SEEDS=4 REFERENCE_NOISE=1 \
  "$here/../surfaces/run.sh" "$scenes" "$out" "$size"
python3 "$here/net.py" "$out"
