#!/bin/bash
# Figure-5 overhead on a 1M-triangle world: `guidebake synth` city of 3.3e7 texels (1.03 M
# triangles, sun and sky), re-prepared at 512 x 512 texels so a bake fits in seconds, then
# baked unguided (`--guiding off --combine average`) and with the defaults, one thread,
# 256 spp, interleaved for ROUNDS rounds. Prints CPU seconds (user + system) per bake and
# the median of the per-round ratios coherent / off.
# Usage (repository root): docs/bench/guided-passes/city.sh BIN ROUNDS OUT_DIR [BAKE OPTIONS]
set -euo pipefail
bin=${1:?BIN}; rounds=${2:?ROUNDS}; out=${3:?OUT_DIR}; shift 3
mkdir -p "$out"
if [ ! -s "$out/small.texels" ]; then
    "$bin" synth --texels 33000000 -o "$out/city.texels" >/dev/null
    rm -f "$out/city.texels"
    "$bin" prepare "$out/city.toml" -o "$out/small.texels" --size 512x512 >/dev/null
fi
log=$out/city.tsv; : > "$log"
for r in $(seq "$rounds"); do
    row=$r
    for m in off coherent; do
        extra=(); [ $m = off ] && extra=(--guiding off --combine average)
        rm -rf "$out/$m.exr" "$out/$m.exr".*
        /usr/bin/time -f "%U %S" -o "$out/t" "$bin" bake "$out/small.texels" --scene "$out/city.toml" \
            -o "$out/$m.exr" --spp 256 --seed 1 --threads 1 --stats "$out/$m.json" "${extra[@]}" "$@" >/dev/null 2>&1
        row="$row	$(awk '{print $1 + $2}' "$out/t")"
    done
    echo "$row" | tee -a "$log"
done
python3 - "$log" <<'PY'
import statistics as st, sys
rows = [list(map(float, l.split()[1:])) for l in open(sys.argv[1])]
print(f"city: off {st.median(r[0] for r in rows):.2f} s, coherent {st.median(r[1] for r in rows):.2f} s, "
      f"coherent/off per round (median) {st.median(r[1] / r[0] for r in rows):.3f}")
PY
