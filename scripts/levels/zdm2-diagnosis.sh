#!/usr/bin/env bash
# Where the error sits on zdm2 (docs/guiding-on-levels.md, "zdm2: where the error sits"): the
# level as the benches bake it (docs/bench/surfaces/zdm2-scene.sh: no textures, its sun and sky),
# prepared at 768² with --unwrap always; two 2 048-spp path references (seeds 1001, 1002), the
# direct light alone (the level with every material black, 4 096 next-event samples), the sky
# view (the black level under the sky alone), then each variant at 64 spp with
# --direct-spp 1024 (the direct light's noise out), --aux, --stats, one thread, seeds 1 and 2;
# then where_guiding_loses.py over them into OUT/where.md.
#   scripts/levels/zdm2-diagnosis.sh SCENES_DIR OUT      (GUIDEBAKE=path/to/guidebake)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
mkdir -p "$out/black"; cd "$out"
"$here/../../docs/bench/surfaces/zdm2-scene.sh" "$scenes" src
S=src/zdm2.toml
[ -f z.texels ] || "$g" prepare $S -o z.texels --unwrap always --size 768x768 -q > /dev/null 2>&1
for s in 1001 1002; do
  [ -f ref$s.exr ] || "$g" bake z.texels --scene $S -o ref$s.exr --transport path --guiding off \
    --combine average --spp 2048 --seed $s --threads 1 -q &
done
wait
# The black level: every material Kd 0, the same sun and sky (and the sky alone).
ln -sf ../src/zdm2.obj black/zdm2.obj
awk '/^newmtl/{print; print "Kd 0 0 0"; next} /^(map_)?Kd/{next} {print}' src/zdm2.mtl > black/zdm2.mtl
sed 's/^geometry.*/geometry = "zdm2.obj"/' src/zdm2.toml > black/zdm2.toml
sed 's/^geometry.*/geometry = "zdm2.obj"/' src/zdm2-sky.toml > black/zdm2-sky.toml
[ -f direct.exr ] || "$g" bake z.texels --scene black/zdm2.toml -o direct.exr --guiding off \
  --combine average --spp 1024 --direct-spp 4096 --seed 1003 --threads 1 -q
[ -f skyview.exr ] || "$g" bake z.texels --scene black/zdm2-sky.toml -o skyview.exr --guiding off \
  --combine average --spp 256 --direct-spp 8 --seed 1004 --threads 1 -q
declare -A V=([unguided]="--guiding off --combine average" [default]=""
  [bounded]="--guiding off --combine average --budget bounded" [uniform]="--budget uniform"
  [flat1000]="--flat-below 1000")
for s in 1 2; do for n in unguided default bounded uniform flat1000; do
  [ -f $n-$s.exr ] || "$g" bake z.texels --scene $S -o $n-$s.exr --spp 64 --direct-spp 1024 --aux \
    --stats $n-$s.json --seed $s --threads 1 -q ${V[$n]}
done; done
python3 "$here/where_guiding_loses.py" z.texels ref1001.exr direct.exr unguided-1.exr,unguided-2.exr \
  $(for n in default bounded uniform flat1000; do printf '%s=%s-1.exr,%s-2.exr ' $n $n $n; done) \
  --ref2 ref1002.exr --sky skyview.exr --sky-radiance 0.4,0.5,0.7 > where.md
