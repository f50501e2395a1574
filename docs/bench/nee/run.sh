#!/usr/bin/env bash
# Emitter selection at equal time (docs/bake.md, "Next-event estimation on the bidir room"):
# for each converted Bitterli scene at SIZE² texels, prepared as docs/bench/surfaces/run.sh
# prepares them (so its cached 16 384-spp path references hit), `guidebake bench` with the
# ladder 64, 256 spp × 2 seeds, one thread, every method with `local` selection (the default)
# and with `+select=power` (the default before), plus unguided path transport with the tree.
#   docs/bench/nee/run.sh SCENES_DIR OUT CACHE [SIZE...]      (default sizes: 128 256)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; cache=${3:?reference cache}
shift 3
sizes=("$@"); [ $# -gt 0 ] || sizes=(128 256)
g=${GUIDEBAKE:-target/release/guidebake}
m="off/average/-+select=power"
m+=",coherent/cluster/rho,coherent/cluster/rho+select=power"
m+=",coherent/cluster/rho+transport=path,coherent/cluster/rho+transport=path+select=power"
m+=",off/average/-+transport=path,off/average/-+transport=path+select=power"
m+=",off/average/-+transport=path+select=tree"
mkdir -p "$out"
for n in "${sizes[@]}"; do
  for s in veach_bidir cornell_box veach_ajar_no_teapots; do
    glb="$scenes/converted/bitterli_$s.glb"
    dir="$out/$s-$n"
    mkdir -p "$dir"
    "$g" prepare "$glb" -o "$dir/scene.texels" --size "${n}x${n}" >/dev/null
    "$g" bench "$glb" --texels "$dir/scene.texels" -o "$dir" --cache "$cache" --methods "$m" \
      --spp 64,256 --ref-spp 16384 --seeds 2 --repeats 0 --threads 1 > "$dir/bench.log" 2>&1
    rm -f "$dir/scene.texels" "$dir/scene.texels.seams"
    echo "$s $n: $(grep -c '' "$dir/runs.csv") rows"
  done
done
