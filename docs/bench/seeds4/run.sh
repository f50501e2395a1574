#!/bin/bash
# From the repository root, after cargo build --release -p guidebake.
mkdir -p out/bench/seeds4
M='off/average/-,coherent/global/-,coherent/cluster/rho'
for st in series:bitterli_veach_bidir:veach-bidir path:bitterli_veach_bidir:veach-bidir path:bitterli_veach_ajar_no_teapots:veach-ajar; do
  IFS=: read t f n <<< "$st"
  target/release/guidebake bench ../shared/scenes/converted/$f.glb --name $n --size 128x128 \
     --transport $t --reference-transport $t --spp 64,256 --seeds 4 --ref-spp 4096 --repeats 0 \
     --methods "$M" -o out/bench/seeds4/$t/$n > out/bench/seeds4/$t-$n.log 2>&1
done
