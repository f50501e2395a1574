#!/usr/bin/env bash
# The bakes of docs/guiding-on-levels.md on the Tesseract level `complex`: prepare at 512²,
# two 4 096-spp path references (seeds 1001, 1002), the direct light alone (4 096 next-event
# samples), then every variant at 64 spp with --direct-spp 1024 (the direct
# light's noise out), --aux, --stats, one thread, seeds 1..SEEDS (the same seed for every
# variant: the bench's rule, driver/src/bench/harness.rs).
#   scripts/levels/bakes.sh OUT [SEEDS] [VARIANT...]    (GUIDEBAKE=path/to/guidebake)
# VARIANT is NAME (below); default: all of them. The references are baked once (skipped when
# OUT/ref1001.exr exists, or NO_REF=1 while they are being baked elsewhere).
set -euo pipefail
out=${1:?output dir}; seeds=${2:-4}; shift $(( $# >= 2 ? 2 : 1 ))
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
scenes=${SCENES:-$(realpath ../shared/scenes)}
S=$scenes/calinou_complex/complex.obj
LIGHT=(--sun 0.3,1,0.45:4 --sky 0.45,0.55,0.7)
mkdir -p "$out"; cd "$out"
[ -f cx.texels ] || "$g" prepare "$S" -o cx.texels --size 512x512 "${LIGHT[@]}" -q 2>/dev/null
if [ ! -f ref1001.exr ] && [ -z "${NO_REF:-}" ]; then
  for s in 1001 1002; do
    "$g" bake cx.texels --scene "$S" -o ref$s.exr --transport path --guiding off --combine average \
      --spp 4096 --seed $s --threads 1 -q "${LIGHT[@]}" 2>/dev/null &
  done
  wait
fi
# The direct light alone: --bounces 0 is refused, so the same level with every material black
# (a copy of the MTL with Kd 0 and no textures): its lightmap is the sun's irradiance (4 096
# next-event samples) plus the sky's that reaches the texel unoccluded (1 024 cosine rays).
if [ ! -f direct.exr ]; then
  mkdir -p black; ln -sf "$S" black/complex.obj
  awk '/^newmtl/{print; print "Kd 0 0 0"; next} /^map_Kd/{next} {print}' \
    "${S%.obj}.mtl" > black/complex.mtl
  "$g" bake cx.texels --scene black/complex.obj -o direct.exr --guiding off --combine average --spp 1024 \
    --direct-spp 4096 --seed 1003 --threads 1 -q "${LIGHT[@]}" 2>/dev/null
fi
# The sky view: the black level under the sky alone (no sun), 256 cosine rays a texel.
[ -f skyview.exr ] || "$g" bake cx.texels --scene black/complex.obj -o skyview.exr --guiding off \
  --combine average --spp 256 --direct-spp 8 --seed 1004 --threads 1 -q --sky 0.45,0.55,0.7 2>/dev/null
# The diagnosis's levers (uniform ... noseed-gain1000) were measured on the default that
# guided every cluster: they keep --flat-below 0; its default is flat0 here.
declare -A V=(
  [unguided]="--guiding off --combine average"
  [unguided-cluster]="--guiding off"
  [default]=""
  [uniform]="--budget uniform --flat-below 0"
  [radiance]="--guide-target radiance --flat-below 0"
  [mix50]="--mix 50 --flat-below 0"
  [radiance-uniform]="--guide-target radiance --budget uniform --flat-below 0"
  [gain150]="--min-gain 150 --flat-below 0"
  [mix75]="--mix 75 --flat-below 0"
  [noseed]="--guide-seed off --flat-below 0"
  [gain1000]="--min-gain 1000 --flat-below 0"
  [unguided-bounded]="--guiding off --combine average --budget bounded"
  [mix75-uniform]="--mix 75 --budget uniform --flat-below 0"
  [noseed-gain1000]="--guide-seed off --min-gain 1000 --flat-below 0"
  [flat0]="--flat-below 0"
  [flat3]="--flat-below 3"
  [flat10]="--flat-below 10"
  [flat30]="--flat-below 30"
  [flat100]="--flat-below 100"
  [flat300]="--flat-below 300"
  [flat1000]="--flat-below 1000"
  [flat100-mix50]="--flat-below 100 --mix 50"
)
names=("$@"); [ ${#names[@]} -gt 0 ] || names=(unguided flat0 default uniform radiance mix50)
# SPP=256 bakes the variants at 256 spp instead, as s256-NAME-SEED.exr
spp=${SPP:-64}; pre=; [ "$spp" = 64 ] || pre=s$spp-
for s in $(seq 1 "$seeds"); do
  for n in "${names[@]}"; do
    [ -f "$pre$n-$s.exr" ] && continue
    # black-NAME: variant NAME on the black level (its gather sees the sky alone)
    scene=$S; v=$n; [[ $n == black-* ]] && scene=black/complex.obj && v=${n#black-}
    /usr/bin/time -f "$n seed $s: %e s wall, %U s user" "$g" bake cx.texels --scene "$scene" \
      -o "$pre$n-$s.exr" --spp "$spp" --direct-spp 1024 --aux --stats "$pre$n-$s.json" --seed "$s" \
      --threads 1 -q ${V[$v]} "${LIGHT[@]}" 2>&1 | grep -v warning || true
  done
done
