#!/usr/bin/env bash
# Hits within a texel of the ray's origin not read (docs/series.md, "Guiding at equal time on a level (zdm2)";
# `NEAR_PATH_TEXELS`): the build before (OLD) and after (NEW) side by side, the default
# and the unguided bake (`--guiding off`), 256 spp, seeds 1 and 2, one thread, each bake timed
# (user + system CPU), interleaved; on the three converted scenes at 256² against the
# references and twins of a reference-noise bench run (NOISE_OUT: docs/bench/reference-noise/run.sh
# ... 256), and on zdm2 at 768² against those of docs/bench/zdm2-guiding/run.sh (ZDM2_OUT);
# then errors.py prints each bake's relative MSE and MSE net of the references' noise and
# the new build over the old at equal time.
#   docs/bench/near-path/run.sh OLD NEW SCENES_DIR NOISE_OUT ZDM2_OUT OUT
set -euo pipefail
old=$(realpath "${1:?old guidebake}"); new=$(realpath "${2:?new guidebake}")
scenes=${3:?scenes dir}; noise=${4:?reference-noise OUT (256²)}; zdm2=${5:?zdm2-guiding OUT}; out=${6:?output dir}
here=$(dirname "$(realpath "$0")")
mkdir -p "$out"
bake() { # NAME TEXELS SCENE BUILD GUIDING SEED
  /usr/bin/time -f "%U %S" -o "$out/$1.time" "$4" bake "$2" --scene "$3" -o "$out/$1.exr" \
    --guiding "$5" --spp 256 --seed "$6" --threads 1 >/dev/null 2>&1
}
for s in ${SCENES:-cornell_box veach_ajar_no_teapots veach_bidir zdm2}; do
  if [ "$s" = zdm2 ]; then
    src="$zdm2/src/zdm2.toml"
    "$new" prepare "$src" -o "$out/$s.texels" --unwrap always --size 768x768 >/dev/null 2>&1
  else
    src="$scenes/converted/bitterli_$s.glb"
    "$new" prepare "$src" -o "$out/$s.texels" --size 256x256 >/dev/null 2>&1
  fi
  for seed in 1 2; do
    for guiding in coherent off; do
      for build in old new; do
        bin=$old; [ "$build" = new ] && bin=$new
        bake "$s-$build-$guiding-$seed" "$out/$s.texels" "$src" "$bin" "$guiding" "$seed"
      done
    done
  done
done
# where.py --bias reads the level's texel file as OUT/z.texels.
[ -e "$out/zdm2.texels" ] && ln -sf zdm2.texels "$out/z.texels"
python3 "$here/errors.py" "$noise" "$zdm2" "$out"
