#!/usr/bin/env bash
# Writes the zdm2 level (Cube 2, ../shared/scenes/calinou_zdm2, CC BY 4.0) into DIR as the
# benches bake it: the level comes without its textures and without lights, so the OBJ is
# copied with the MTL's texture lines stripped and wrapped in DIR/zdm2.toml with a sun and a
# sky, and in DIR/zdm2-sky.toml with the sky alone. Used by zdm2.sh and
# docs/bench/zdm2-guiding/ (run.sh; dark.sh bakes the sky alone).
#   docs/bench/surfaces/zdm2-scene.sh SCENES_DIR DIR
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; dir=${2:?output dir}
mkdir -p "$dir"
cp "$scenes/calinou_zdm2/zdm2.obj" "$dir/"
grep -v -E '^\s*map_' "$scenes/calinou_zdm2/zdm2.mtl" > "$dir/zdm2.mtl"
cat > "$dir/zdm2-sky.toml" <<'TOML'
geometry = "zdm2.obj"
[sky]
constant = [0.4, 0.5, 0.7]
TOML
{ cat "$dir/zdm2-sky.toml"; cat <<'TOML'
[sun]
direction = [0.4, 1.0, 0.3]
angular_radius_deg = 0.267
irradiance = [3.0, 2.9, 2.7]
TOML
} > "$dir/zdm2.toml"
