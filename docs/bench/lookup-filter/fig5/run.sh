#!/usr/bin/env bash
# Figure-5 overhead of the default with the lookups filtered (2026-11-29 08:58–09:06 UTC,
# one thread, 9 interleaved repeats, series references of 4 096 spp, the machine shared with a
# clean-clone CI run): texel files prepared at 128² beside the scenes, ./gbp the build of
# ed0ba61. The paired medians of the CPU time per repeat: see docs/BENCHMARKS.md.
set -euo pipefail
for s in veach_ajar_no_teapots cornell_box veach_bidir; do
  ./gbp bench /work/shared/scenes/converted/bitterli_$s.glb --texels /work/m/$s-128.texels -o fig5/$s --cache /work/m/cache-series \
    --transport series --reference-transport series --spp 64,256 --seeds 1 --repeats 9 --threads 1 \
    --methods 'off/average/-,coherent/cluster/rho' > fig5/$s.log 2>&1
  echo "$s $(date +%H:%M)"
done
