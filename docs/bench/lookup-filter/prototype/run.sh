#!/usr/bin/env bash
# The prototype of the lookups' filter (prototype.diff on 188fafe: GB_LF=R the radius, 0 off;
# GB_LF_K=1 the noise term; GB_LF_SIGMA, GB_LF_PLANE, GB_LF_COS the other weights), as run on
# 2026-11-29 07:05–07:30 UTC: texel files prepared at 128² beside the scenes, the cached
# 16 384-spp path references of docs/bench/surfaces/run.sh.
#   run.sh OUT BIN [ENV=VALUE...]: the three scenes, baseline + default, 128 / 256 spp, 2 seeds
set -euo pipefail
out=$1; bin=$2; shift 2
mkdir -p $out
for s in cornell_box veach_ajar_no_teapots veach_bidir; do
  env "$@" $bin bench /work/shared/scenes/converted/bitterli_$s.glb --texels /work/m/$s-128.texels -o $out/$s \
    --cache /work/m/base/cache --methods "${METHODS:-off/average/-,coherent/cluster/rho}" --spp ${SPP:-128,256} --ref-spp 16384 \
    --seeds ${SEEDS:-2} --repeats 0 --threads 1 > $out/$s.log 2>&1
  echo "$s done"
done
