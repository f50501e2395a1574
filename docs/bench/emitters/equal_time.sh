#!/bin/bash
# Emitters as lights, measured at equal time (docs/bake.md, "Emitters as lights: measured"): emitters found by hits alone (the bake before) against
# next-event estimation + MIS, on the three converted scenes at 64x64, path transport, the
# unbiased estimator (--guiding off --combine average), 256 spp x 2 seeds, against a 4096-spp
# MIS reference. Hits alone get one more vertex so both reach the emitters' light reflected
# 3 times. Run from the repository root after `cargo build --release -p guidebake`; writes
# into out/emitters/. Output lines: scene, emitters, seed, gather s, gather/shadow/path rays,
# RMSE, relative bias, median rel_std_error. rmse.py needs `pip install OpenEXR numpy`.
set -u
B=$(realpath ${B:-target/release/guidebake})
S=$(realpath ${S:-../shared/scenes/converted})
R=$(realpath docs/bench/emitters/rmse.py)
mkdir -p out/emitters && cd out/emitters
for s in bitterli_cornell_box:cornell bitterli_veach_ajar_no_teapots:ajar bitterli_veach_bidir:bidir; do
  f=${s%%:*}; n=${s##*:}
  [ -e $n.texels ] || $B prepare $S/$f.glb -o $n.texels --size 64x64 > /dev/null 2>&1
  common="--guiding off --combine average --bias-correction off --transport path --aux --threads 2"
  [ -e $n-ref.exr ] || $B bake $n.texels --scene $S/$f.glb -o $n-ref.exr --spp 4096 --bounces 3 $common --stats $n-ref.json > /dev/null 2>&1
  for e in hits mis; do
    for seed in 1 2; do
      # hits alone reach the emitters' light reflected B times with one more vertex
      b=3; [ $e = hits ] && b=4
      rm -rf $n-$e-$seed.exr*
      $B bake $n.texels --scene $S/$f.glb -o $n-$e-$seed.exr --spp 256 --seed $seed --bounces $b --emitters $e $common --stats $n-$e-$seed.json > /dev/null 2>&1
      echo "$n $e $seed $(python3 -c "import json;d=json.load(open('$n-$e-$seed.json'));print(d['seconds']['gather'], d['counters']['gather_rays'], d['counters']['shadow_rays'], d['counters']['path_rays'])") $(python3 $R $n-ref.exr $n-$e-$seed.exr | cut -d: -f2-)"
    done
  done
done
