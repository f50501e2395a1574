#!/usr/bin/env bash
# The lightmap's direct light (docs/estimator.md, "The lightmap's direct light"): the default
# bake of an older build (OLD_BIN, e.g. one whose last pass estimated its texels' direct light
# itself) against this build's default and its `--budget`s, against unbiased path references,
# each through docs/bench/surfaces/run.sh (the converted Bitterli scenes at SIZE², the ladder
# 64, 256, 1024 spp × 2 seeds, one thread, 16 384-spp path references; OUT/cache shared, so
# the references are baked once). Then compare.py prints each method's error and CPU time
# against the old default. The CPU time, paired round by round:
#   docs/bench/direct-pass/run.sh OLD_BIN target/release/guidebake 5 DIR
# The sweep of the direct pass's samples (`+direct=P`, P % of the rung's spp):
#   METHODS=coherent/cluster/rho,coherent/cluster/rho+direct=150,coherent/cluster/rho+direct=200 \
#     docs/bench/surfaces/run.sh SCENES_DIR OUT SIZE
#   docs/bench/lightmap-direct/run.sh SCENES_DIR OUT OLD_BIN [SIZE]      (default size: 128)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; old=${3:?older guidebake binary}
size=${4:-128}
here=$(dirname "$0")
b=coherent/cluster/rho
mkdir -p "$out/cache"
mkdir -p "$out/old" "$out/new"
ln -sfn ../cache "$out/old/cache"; ln -sfn ../cache "$out/new/cache"
GUIDEBAKE=$old METHODS=$b "$here/../surfaces/run.sh" "$scenes" "$out/old" "$size"
METHODS="$b,$b+budget=balanced,$b+budget=relative" "$here/../surfaces/run.sh" "$scenes" "$out/new" "$size"
python3 "$here/compare.py" "$out/old" "$out/new"
