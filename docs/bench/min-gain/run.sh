#!/bin/bash
# BENCHMARKS.md "Guiding only where it pays": the baseline, the default and
# `--min-gain` levels, 64 and 256 spp, SEEDS (2) seeds, 128x128, against 4096-spp references
# of the same transport, with 3 interleaved Figure-5 repeats (the bake's defaults). From the
# repository root, after `cargo build --release -p guidebake`:
#   [M=methods] [SEEDS=4] docs/bench/min-gain/run.sh series|path
set -euo pipefail
bin=${GUIDEBAKE:-target/release/guidebake}
transport=${1:-series}
M=${M:-'off/average/-,coherent/cluster/rho,coherent/cluster/rho+gain=100,coherent/cluster/rho+gain=150,coherent/cluster/rho+gain=200'}
for s in bitterli_veach_ajar_no_teapots:veach-ajar bitterli_cornell_box:cornell-box \
         bitterli_veach_bidir:veach-bidir; do
  "$bin" bench ../shared/scenes/converted/${s%%:*}.glb \
      --name ${s##*:} --size 128x128 --transport $transport --reference-transport $transport \
      --spp 64,256 --seeds ${SEEDS:-2} --ref-spp 4096 --repeats ${REPEATS:-3} --methods "$M" \
      -o ${OUT:-out/bench/min-gain}/$transport/${s##*:}
done
