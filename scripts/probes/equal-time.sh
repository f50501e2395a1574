#!/usr/bin/env bash
# Guided against unguided light probes at equal time, against an unbiased reference
# (docs/probes.md, "How good the probes are").
#
#   scripts/probes/equal-time.sh SCENES_DIR OUT [SCENE...]
#     SCENE: cornell, ajar, bidir (the converted Bitterli rooms), zdm2 (the Cube 2 level, its
#     sun and sky from docs/bench/surfaces/zdm2-scene.sh); default all four.
#     Env: SPP (default "64 128 256"), SEEDS (default "1 2"), SPACING (the finest probe
#     spacing; default the probes command's), GUIDEBAKE (default target/release/guidebake).
#
# Per scene: the default lattice (its clusters as the product bakes them); the reference
# gathers its probes by path transport at 16× the largest SPP, unguided, one iteration;
# then each SPP and seed, guided and unguided, path transport, one thread, interleaved. scripts/probes/equal-time.py reads the gather times from the stats and the
# errors from scripts/probes/compare.py, and puts each guided run against the unguided
# runs of its seed interpolated (log-log) to the same time. Writes OUT/SCENE/* and
# OUT/table.md.
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; shift 2
list=(cornell ajar bidir zdm2); [ $# -gt 0 ] && list=("$@")
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
spps=(${SPP:-64 128 256}); seeds=(${SEEDS:-1 2})
max=0; for s in "${spps[@]}"; do [ "$s" -gt "$max" ] && max=$s; done
mkdir -p "$out/src"
for name in "${list[@]}"; do
  prep=(--size 256x256)
  case $name in
    cornell) scene=$scenes/converted/bitterli_cornell_box.glb ;;
    ajar) scene=$scenes/converted/bitterli_veach_ajar_no_teapots.glb ;;
    bidir) scene=$scenes/converted/bitterli_veach_bidir.glb ;;
    zdm2)
      "$here/../../docs/bench/surfaces/zdm2-scene.sh" "$scenes" "$out/src"
      scene=$out/src/zdm2.toml prep=(--size 768x768 --unwrap always) ;;
    *) echo "equal-time.sh: no scene '$name' (cornell, ajar, bidir, zdm2)" >&2; exit 2 ;;
  esac
  dir=$out/$name; mkdir -p "$dir"
  [ -f "$dir/scene.texels" ] || "$g" prepare "$scene" -o "$dir/scene.texels" "${prep[@]}" -q > "$dir/prepare.log" 2>&1
  common=("$dir/scene.texels" --scene "$scene" --transport path --volume off --quiet)
  spacing=(); [ -n "${SPACING:-}" ] && spacing=(--spacing "$SPACING")
  points=("${spacing[@]}")
  [ -f "$dir/ref.probes" ] || "$g" probes "${common[@]}" "${points[@]}" -o "$dir/ref.probes" \
    --spp $((16 * max)) --guiding off --iterations 1 --seed 1000
  for seed in "${seeds[@]}"; do
    for spp in "${spps[@]}"; do
      for guiding in on off; do
        "$g" probes "${common[@]}" "${points[@]}" -o "$dir/$guiding-$spp-$seed.probes" \
          --spp "$spp" --guiding "$guiding" --seed "$seed" --threads 1
      done
    done
  done
  echo "$name: $(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['probes'])" "$dir/ref.probes.json") probes" >&2
done
python3 "$here/equal-time.py" "$out" "${list[@]}" | tee "$out/table.md"
