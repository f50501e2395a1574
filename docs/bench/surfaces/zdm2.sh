#!/usr/bin/env bash
# zdm2 (Cube 2 level, ../shared/scenes/calinou_zdm2, CC BY 4.0) baked by the default
# (series) and by path transport at equal samples; prints each bake's mean irradiance over the
# valid texels (docs/series.md, "The default bake is right where surfaces meet").
# The level as zdm2-scene.sh writes it: textures stripped, a sun and a sky from a TOML file.
#   docs/bench/surfaces/zdm2.sh SCENES_DIR OUT [SPP]      (default SPP: 64)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; spp=${3:-64}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
"$here/zdm2-scene.sh" "$scenes" "$out"
cd "$out"
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
