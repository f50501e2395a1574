#!/usr/bin/env bash
# Where series transport's error on zdm2 sits, against path transport's (docs/series.md, "Guiding at equal time on a level (zdm2)"): after run.sh (its OUT holds the level, the TOML scene and the cached references),
# bakes the default and path transport at 256 spp against the reference, then both at 64 spp
# with 1 and 2 bounces, the default with `--lookup-filter 0`, and both lit by the sky alone
# (the texel file prepared with the sun), one thread; dark.py prints where each one's error sits.
#   docs/bench/zdm2-guiding/dark.sh OUT [SIZE]      (default SIZE: 768)
set -euo pipefail
out=${1:?output dir of run.sh}; n=${2:-768}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
d="$out/dark"; mkdir -p "$d"
"$g" prepare "$out/src/zdm2.toml" -o "$d/z.texels" --unwrap always --size "${n}x${n}" >/dev/null
bake() { "$g" bake "$d/z.texels" -o "$d/$1.exr" --threads 1 "${@:2}" >/dev/null 2>&1; }
bake series --scene "$out/src/zdm2.toml" --spp 256
bake path --scene "$out/src/zdm2.toml" --spp 256 --transport path
for b in 1 2; do
  bake series-b$b --scene "$out/src/zdm2.toml" --spp 64 --bounces $b
  bake path-b$b --scene "$out/src/zdm2.toml" --spp 64 --bounces $b --transport path
done
bake series-filter0 --scene "$out/src/zdm2.toml" --spp 64 --lookup-filter 0
bake sky-series-b2 --scene "$out/src/zdm2-sky.toml" --spp 64 --bounces 2
bake sky-path-b2 --scene "$out/src/zdm2-sky.toml" --spp 256 --bounces 2 --transport path
refs=$(python3 -c "
import json,glob
for f in sorted(glob.glob('$out/cache/ref-*.json')): print(json.load(open(f))['path'])")
echo "# against the 3-bounce references"
python3 "$here/dark.py" "$d/z.texels" $refs -- "$d/series.exr" "$d/path.exr" "$d/series-filter0.exr"
echo "# 1 and 2 bounces, against path transport's bake of as many"
for b in 1 2; do python3 "$here/dark.py" "$d/z.texels" "$d/path-b$b.exr" -- "$d/series-b$b.exr"; done
echo "# lit by the sky alone, 2 bounces"
python3 "$here/dark.py" "$d/z.texels" "$d/sky-path-b2.exr" -- "$d/sky-series-b2.exr"
