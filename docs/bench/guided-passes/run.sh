#!/bin/bash
# BENCHMARKS.md "Guiding the last pass": the baseline, the default (coherent
# guiding of the last series pass only) and every pass guided, 64 and 256 spp, 2 seeds,
# 128x128, against 4096-spp series references, with 5 interleaved Figure-5 repeats (the
# bake's defaults). From the repository root, after `cargo build --release -p guidebake`.
set -euo pipefail
bin=${GUIDEBAKE:-target/release/guidebake}
M='off/average/-,coherent/cluster/rho,coherent/cluster/rho+passes=every'
for s in bitterli_veach_ajar_no_teapots:veach-ajar bitterli_cornell_box:cornell-box \
         bitterli_veach_bidir:veach-bidir; do
  "$bin" bench ../shared/scenes/converted/${s%%:*}.glb \
      --name ${s##*:} --size 128x128 --transport series --reference-transport series \
      --spp 64,256 --seeds 2 --ref-spp 4096 --repeats 5 --methods "$M" \
      -o ${OUT:-out/bench/guided-passes}/${s##*:}
done
