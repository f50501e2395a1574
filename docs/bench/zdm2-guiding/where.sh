#!/usr/bin/env bash
# Which of zdm2's texels guiding gains least at (docs/series.md, "Guiding at equal time on a level (zdm2)"):
# after run.sh (its OUT holds the level, the TOML scene and the cached reference and twin),
# bakes the default and the unguided bake (`--guiding off`), series and path transport,
# 256 spp, seeds 1 and 2, one thread; where.py splits each pair's relative MSE (net of the
# references' noise) by texel kind: partial (no triangle covers the centre) or not, beside
# an unbaked texel or not, by the reference's brightness. Needs numpy and OpenEXR.
#   docs/bench/zdm2-guiding/where.sh OUT [SIZE]      (default SIZE: 768)
set -euo pipefail
out=${1:?output dir of run.sh}; n=${2:-768}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
d="$out/where"; mkdir -p "$d"
"$g" prepare "$out/src/zdm2.toml" -o "$d/z.texels" --unwrap always --size "${n}x${n}" >/dev/null
for transport in series path; do
  for seed in 1 2; do
    for guiding in off coherent; do
      /usr/bin/time -f "%U %S" -o "$d/$transport-$guiding-$seed.time" "$g" bake "$d/z.texels" \
        --scene "$out/src/zdm2.toml" -o "$d/$transport-$guiding-$seed.exr" --transport "$transport" \
        --guiding "$guiding" --spp 256 --seed "$seed" --threads 1 >/dev/null 2>&1
    done
  done
done
for transport in series path; do
  echo "# $transport transport"
  python3 "$here/where.py" "$out/zdm2-$n/summary.json" "$d" "$transport"
done
