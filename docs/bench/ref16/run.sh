#!/bin/bash
# The six runs of references.md "A reference has 16× the top rung's samples": baseline, the
# default and cluster weights + rho, 64 and 256 spp, 2 seeds, 128x128, each transport against
# a 4096-spp reference of its own. From the repository root, after
# `cargo build --release -p guidebake`; about 25 minutes on 2 cores.
set -euo pipefail
M='off/average/-,coherent/global/-,coherent/cluster/rho'
for s in bitterli_veach_ajar_no_teapots:veach-ajar bitterli_cornell_box:cornell-box \
         bitterli_veach_bidir:veach-bidir; do
  for t in series path; do
    target/release/guidebake bench ../shared/scenes/converted/${s%%:*}.glb \
        --name ${s##*:} --size 128x128 --transport $t --reference-transport $t \
        --spp 64,256 --seeds 2 --ref-spp 4096 --repeats 0 --methods "$M" \
        -o out/bench/ref16/$t/${s##*:}
  done
done
