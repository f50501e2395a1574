#!/bin/bash
# The series ladder of series.md "The direct pass": baseline and the default,
# 64 and 256 spp, 2 seeds, 128x128, against 4096-spp series references, with 3 interleaved
# Figure-5 repeats. From the repository root, after `cargo build --release -p guidebake`;
# about 10 minutes on 2 cores (the references are cached in out/bench-cache).
set -euo pipefail
M='off/average/-,coherent/cluster/rho'
for s in bitterli_veach_ajar_no_teapots:veach-ajar bitterli_cornell_box:cornell-box bitterli_veach_bidir:veach-bidir; do
  target/release/guidebake bench ../shared/scenes/converted/${s%%:*}.glb \
      --name ${s##*:} --size 128x128 --transport series --reference-transport series \
      --spp 64,256 --seeds 2 --ref-spp 4096 --repeats 3 --methods "$M" \
      -o out/bench/direct-pass/series/${s##*:}
done
