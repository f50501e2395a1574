#!/bin/bash
# Point sampling on emitters: the default build (solid angle near an emitter, area far) against
# a build with area sampling everywhere (SPHERICAL_SOLID_ANGLES emptied in
# transport/emitters.rs, binary copied to /tmp/gb-area), interleaved per seed. Runs in the
# directory of equal_time.sh's outputs (the texel files and the 4096-spp references).
S=/work/shared/scenes/converted
common="--guiding off --combine average --bias-correction off --transport path --bounces 3 --threads 2"
for s in bitterli_cornell_box:cornell bitterli_veach_ajar_no_teapots:ajar bitterli_veach_bidir:bidir; do
  f=${s%%:*}; n=${s##*:}
  for seed in 1 2; do
    for v in solid:/work/main/target/release/guidebake area:/tmp/gb-area; do
      name=${v%%:*}; B=${v#*:}
      rm -rf sa-$n-$name-$seed.exr*
      $B bake $n.texels --scene $S/$f.glb -o sa-$n-$name-$seed.exr --spp 256 --seed $seed $common --stats sa-$n-$name-$seed.json > /dev/null 2>&1
      echo "$n $name $seed $(python3 -c "import json;d=json.load(open('sa-$n-$name-$seed.json'));print(d['seconds']['gather'])") $(python3 rmse.py $n-ref.exr sa-$n-$name-$seed.exr | cut -d: -f2-)"
    done
  done
done
