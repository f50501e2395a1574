#!/bin/bash
# BENCHMARKS.md "The mixture folded into the guide": the unguided baseline and
# the defaults, 64 and 256 spp, 4 seeds, 128x128, against 4096-spp references of the same
# transport, with 5 interleaved Figure-5 repeats, for each build given (run one after the
# other per scene). From the repository root:
#   docs/bench/mixture/run.sh series|path OUT_DIR BIN...
set -euo pipefail
transport=${1:?series|path}; out=${2:?OUT_DIR}; shift 2
for s in bitterli_veach_bidir:veach-bidir bitterli_veach_ajar_no_teapots:veach-ajar \
         bitterli_cornell_box:cornell-box; do
  for b in "$@"; do
    "$b" bench ../shared/scenes/converted/${s%%:*}.glb --name ${s##*:} --size 128x128 \
      --transport $transport --reference-transport $transport --spp 64,256 --seeds 4 \
      --ref-spp 4096 --repeats ${REPEATS:-5} --methods 'off/average/-,coherent/cluster/rho' \
      -o "$out/$transport/$(basename "$b")/${s##*:}"
  done
done
