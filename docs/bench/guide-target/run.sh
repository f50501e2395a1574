#!/usr/bin/env bash
# The guide's target (docs/guiding-levers.md, "The guide's target"): the default bake, whose guides
# learn the square root of the second moment, against the same with the radiance target
# (`+target=radiance`, the paper's) and the unguided series bake, side by side in one bench
# run per scene, through docs/bench/surfaces/run.sh (the converted Bitterli scenes, 2 seeds,
# one thread, against path references 16× the top rung; OUT/cache keeps the references).
# Then compare.py prints the default's gain over each, at equal samples and at equal time.
#   docs/bench/guide-target/run.sh SCENES_DIR OUT            (128²: 64 / 256 / 1024 spp)
#   SPP=64,256 REF_SPP=4096 docs/bench/guide-target/run.sh SCENES_DIR OUT 256
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; size=${3:-128}
here=$(dirname "$0")
b=coherent/cluster/rho
METHODS="off/average/-,$b,$b+target=radiance" "$here/../surfaces/run.sh" "$scenes" "$out" "$size"
python3 "$here/compare.py" "$out"
