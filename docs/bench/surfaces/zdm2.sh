#!/usr/bin/env bash
# zdm2 (Cube 2 level, ../shared/scenes/calinou_zdm2, CC BY 4.0) baked by the default
# (series) and by path transport at equal samples; prints each bake's mean irradiance over the
# valid texels (docs/BENCHMARKS.md, "The default bake is right where surfaces meet").
# The level comes without its textures and without lights: the script copies it with the
# MTL's texture lines stripped and wraps it in a TOML scene with a sun and a sky.
#   docs/bench/surfaces/zdm2.sh SCENES_DIR OUT [SPP]      (default SPP: 64)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; spp=${3:-64}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
mkdir -p "$out"; cd "$out"
cp "$scenes/calinou_zdm2/zdm2.obj" .
grep -v -E '^\s*map_' "$scenes/calinou_zdm2/zdm2.mtl" > zdm2.mtl
cat > zdm2.toml <<'TOML'
geometry = "zdm2.obj"
[sky]
constant = [0.4, 0.5, 0.7]
[sun]
direction = [0.4, 1.0, 0.3]
angular_radius_deg = 0.267
irradiance = [3.0, 2.9, 2.7]
TOML
/usr/bin/time -v "$g" prepare zdm2.toml -o zdm2.texels --unwrap always --size 768x768 --json \
  > prepare.json 2> prepare.time
grep -E "Elapsed|Maximum resident" prepare.time
for t in series path; do
  /usr/bin/time -v "$g" bake zdm2.texels --scene zdm2.toml -o "$t.exr" --spp "$spp" \
    --transport "$t" --threads 1 --stats "$t.json" > /dev/null 2> "$t.time"
  echo "$t: $(grep Elapsed "$t.time")"
  "$g" render zdm2.toml --texels zdm2.texels --lightmap "$t.exr" -o "view-$t.png"
done
python3 "$here/means.py" zdm2.texels series.exr path.exr
