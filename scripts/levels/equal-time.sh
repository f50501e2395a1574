#!/usr/bin/env bash
# The levels' equal-time measure (docs/guiding-on-levels.md, "At equal CPU time"): on the Tesseract
# level `complex` (512², the sun and sky of README's level recipe) and the Cube 2 level zdm2
# (768², its sun and sky from docs/bench/surfaces/zdm2-scene.sh), both without their textures,
# `guidebake bench` at 64 and 256 spp, SEEDS seeds (2), one thread, against a 4 096-spp path
# reference and its twin (--reference-noise), with the methods
#   off/average/-                     the unguided bake (the baseline)
#   coherent/cluster/rho              the default
#   coherent/cluster/rho+flat=0       the default guiding every cluster (as before --flat-below)
#   off/average/-+transport=path      unguided path transport
# then docs/bench/reference-noise/net.py: each method against the unguided bake at equal CPU
# time, by relative MSE and MSE, raw and net of the reference's noise, into OUT/net.md.
#   scripts/levels/equal-time.sh SCENES_DIR OUT [LEVEL...]    (LEVEL: complex, zdm2; default both)
# METHODS, SPP, SEEDS replace those; the references bake on every core (REFERENCE_THREADS).
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; shift 2
levels=(complex zdm2); [ $# -gt 0 ] && levels=("$@")
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
docs=$here/../../docs/bench
mkdir -p "$out/src"
for level in "${levels[@]}"; do
  unwrap=()
  case $level in
    complex)
      cp "$scenes/calinou_complex/complex.obj" "$out/src/"
      grep -v -E '^\s*map_' "$scenes/calinou_complex/complex.mtl" > "$out/src/complex.mtl"
      cat > "$out/src/complex.toml" <<'TOML'
geometry = "complex.obj"
[sky]
constant = [0.45, 0.55, 0.7]
[sun]
direction = [0.3, 1.0, 0.45]
angular_radius_deg = 0.267
irradiance = [4.0, 4.0, 4.0]
TOML
      scene=$out/src/complex.toml size=512 ;;
    zdm2)
      "$docs/surfaces/zdm2-scene.sh" "$scenes" "$out/src"
      # 17 552 charts do not fit 512²; the level's OBJ carries UVs the atlas does not use.
      scene=$out/src/zdm2.toml size=768 unwrap=(--unwrap always) ;;
    *) echo "equal-time.sh: no level '$level' (complex, zdm2)" >&2; exit 2 ;;
  esac
  dir=$out/$level-$size
  mkdir -p "$dir"
  "$g" prepare "$scene" -o "$dir/scene.texels" "${unwrap[@]}" --size "${size}x${size}" -q > "$dir/prepare.log" 2>&1
  "$g" bench "$scene" --texels "$dir/scene.texels" -o "$dir" --cache "$out/cache" \
    --methods "${METHODS:-off/average/-,coherent/cluster/rho,coherent/cluster/rho+flat=0,off/average/-+transport=path}" \
    --spp "${SPP:-64,256}" --ref-spp 4096 --seeds "${SEEDS:-2}" --repeats 0 --threads 1 \
    --reference-noise ${REFERENCE_THREADS:+--reference-threads "$REFERENCE_THREADS"} > "$dir/bench.log" 2>&1
  rm -f "$dir/scene.texels" "$dir/scene.texels.seams"
  echo "$level $size: $(grep -c '' "$dir/runs.csv") rows"
done
python3 "$docs/reference-noise/net.py" "$out" > "$out/net.md"
cat "$out/net.md"
