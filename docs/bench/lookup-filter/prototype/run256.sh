#!/usr/bin/env bash
# The prototype (prototype.diff) at 256² (2026-11-29 07:30–08:08 UTC): per scene the baseline
# and the default unfiltered (o256u, which built the 4 096-spp path references), then with
# the filter GB_LF=2 GB_LF_K=1 and +lookup=25 (o256f). ./gb: the prototype's build.
# run256.sh SCENE: prepare at 256², unfiltered (baseline+default; builds the 4096-spp path ref), then filtered
set -euo pipefail
s=$1; cd /work/m/lf
t=/work/m/$s-256.texels
[ -f $t ] || ./gb prepare /work/shared/scenes/converted/bitterli_$s.glb -o $t --size 256x256 > /dev/null
for cfg in "u GB_LF=0" "f GB_LF=2 GB_LF_K=1"; do
  set -- $cfg; name=$1; shift
  m="off/average/-,coherent/cluster/rho"; [ $name = f ] && m="$m,coherent/cluster/rho+lookup=25"
  env "$@" ./gb bench /work/shared/scenes/converted/bitterli_$s.glb --texels $t -o o256$name/$s \
    --cache /work/m/cache256 --methods "$m" --spp 128,256 --ref-spp 4096 --seeds 2 --repeats 0 --threads 1 > o256$name-$s.log 2>&1
  echo "$s $name done"
done
