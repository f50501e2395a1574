#!/usr/bin/env bash
# The README's and docs/engines.md's pictures of the viewer: each scene seen by `guidebake
# render` and by the three.js viewer (`guidebake view`) in headless Chromium, from one camera
# at one exposure. Writes docs/img/view-{demo,zdm2}-{render,browser}.png.
#   scripts/view-figures.sh [WORK_DIR]      # default target/view-figures; needs chromium
# zdm2 is read from ../shared/scenes/calinou_zdm2 (skipped when absent). About 3 minutes on
# 2 cores, most of it the two bakes.
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:-target/view-figures}
mkdir -p "$work" docs/img
cargo build --release -p guidebake --bin guidebake
bin=${CARGO_TARGET_DIR:-target}/release/guidebake
W=640 H=400

# Screenshot of the viewer for one scene: shot NAME TEXELS SCENE LIGHTMAP EXPOSURE [LIGHT...]
shot() {
    local name=$1 texels=$2 scene=$3 lightmap=$4 exposure=$5
    shift 5
    "$bin" view "$texels" --scene "$scene" --lightmap "$lightmap" -o "$work/$name.web" \
        --port 0 --exposure "$exposure" "$@" 2>"$work/$name.view.log" &
    local server=$!
    local url=""
    for _ in $(seq 100); do
        url=$(sed -n 's/^open \(http[^ ]*\).*/\1/p' "$work/$name.view.log")
        [[ -n $url ]] && break
        sleep 0.2
    done
    [[ -n $url ]] || { cat "$work/$name.view.log"; kill "$server"; exit 1; }
    chromium --headless --no-sandbox --enable-unsafe-swiftshader --use-angle=swiftshader \
        --hide-scrollbars --virtual-time-budget=30000 --user-data-dir="$work/chromium" \
        --window-size=$W,$H --screenshot="docs/img/view-$name-browser.png" "${url}?shot" \
        >/dev/null 2>&1
    kill "$server"
}

# The demo room, guided, 256 spp (the demo's default), from the glb's camera.
"$bin" demo -o "$work/demo"
d=$work/demo
err=$("$bin" render "$d/ajar.glb" --texels "$d/ajar.texels" --lightmap "$d/guided.exr" \
    -o docs/img/view-demo-render.png --width $W --height $H --sky 0.6,0.75,1.0 2>&1)
echo "$err"
exposure=$(sed -n 's/.*exposure \([0-9.]*\).*/\1/p' <<<"$err")
shot demo "$d/ajar.texels" "$d/ajar.glb" "$d/guided.exr" "$exposure" --sky 0.6,0.75,1.0

# zdm2, docs/levels.md's recipe at 64 spp, from render's view inside it.
level=../shared/scenes/calinou_zdm2/zdm2.obj
if [[ -f $level ]]; then
    LIGHT=(--sun 0.3,1,0.45:4 --sky 0.45,0.55,0.7)
    z=$work/zdm2
    mkdir -p "$z"
    "$bin" prepare "$level" -o "$z/zdm2.texels" "${LIGHT[@]}"
    "$bin" bake "$z/zdm2.texels" --scene "$level" -o "$z/zdm2.exr" --spp 64 --denoise atrous --quiet "${LIGHT[@]}"
    err=$("$bin" render "$level" --texels "$z/zdm2.texels" --lightmap "$z/zdm2.exr" \
        -o docs/img/view-zdm2-render.png --width $W --height $H "${LIGHT[@]}" 2>&1)
    echo "$err"
    exposure=$(sed -n 's/.*exposure \([0-9.]*\).*/\1/p' <<<"$err")
    shot zdm2 "$z/zdm2.texels" "$level" "$z/zdm2.exr" "$exposure" "${LIGHT[@]}"
else
    echo "no $level: the zdm2 pictures are not made"
fi
ls -l docs/img/view-*.png
