#!/usr/bin/env bash
# The filter's window, as run on 2026-11-29 08:25–08:33 UTC (128², 128 / 256 spp, 2 seeds, one
# thread, the cached 16 384-spp path references; ./gbt a build of the product with a test hook,
# not committed, GB_TMP_MEAN=1 turning the window into a plain weighted mean):
#   pL: a weighted least-squares plane (an intermediate build): the default (radius 2),
#       +filter=1, and the bake before (+lookup=100+filter=0)
#   pM: GB_TMP_MEAN=1, +filter=1 (a plain mean of radius 1)
#   pS: the mirror-symmetric mean (the product): the default and the bake before
#   pick.sh OUT METHODS [ENV=VALUE...]
set -euo pipefail
out=$1; shift
M=$1; shift
for s in cornell_box veach_ajar_no_teapots veach_bidir; do
  mkdir -p $out/$s
  env "$@" ./gbt bench /work/shared/scenes/converted/bitterli_$s.glb --texels /work/m/$s-128.texels -o $out/$s \
    --cache /work/m/base/cache --methods "$M" --spp 128,256 --ref-spp 16384 --seeds 2 --repeats 0 --threads 1 > $out/$s.log 2>&1
  echo "$s $(date +%H:%M)"
done
