#!/bin/bash
# The direct pass (docs/bake.md, "The direct pass"): whole-bake CPU time (user + system) of
# two guidebake builds, unguided (`--guiding off --combine average`) and with the defaults
# (coherent guiding), one thread, 256 spp, series, 128 x 128, interleaved round by round.
# Usage (repository root): docs/bench/direct-pass/run.sh OLD_BIN NEW_BIN ROUNDS OUT_DIR
# Prints per scene the median CPU seconds of each build and mode, the per-round medians of
# new/old, and of coherent/off for each build (the Figure-5 overhead).
set -euo pipefail
old=${1:?OLD_BIN}; new=${2:?NEW_BIN}; rounds=${3:?ROUNDS}; out=${4:?OUT_DIR}
mkdir -p "$out"
for s in bitterli_veach_ajar_no_teapots bitterli_cornell_box bitterli_veach_bidir; do
    scene=../shared/scenes/converted/$s.glb
    texels=$out/$s.texels
    [ -s "$texels" ] || "$new" prepare "$scene" -o "$texels" --size 128x128 >/dev/null 2>&1
    log=$out/$s.tsv; : > "$log"
    for r in $(seq "$rounds"); do
        row=$r
        for v in old new; do
            bin=$old; [ $v = new ] && bin=$new
            for m in off coherent; do
                extra=(); [ $m = off ] && extra=(--guiding off --combine average)
                rm -rf "$out/$v-$m.exr" "$out/$v-$m.exr".*
                /usr/bin/time -f "%U %S" -o "$out/t" "$bin" bake "$texels" --scene "$scene" \
                    -o "$out/$v-$m.exr" --spp 256 --seed 1 --threads 1 "${extra[@]}" >/dev/null 2>&1
                row="$row	$(awk '{print $1 + $2}' "$out/t")"
            done
        done
        echo "$row" >> "$log"
    done
    python3 - "$log" "$s" <<'PY'
import statistics as st, sys
rows = [list(map(float, l.split()[1:])) for l in open(sys.argv[1])]
med = lambda f: st.median(f(r) for r in rows)
print(f"{sys.argv[2]}: CPU s old off {med(lambda r: r[0]):.2f}, old coherent {med(lambda r: r[1]):.2f}, "
      f"new off {med(lambda r: r[2]):.2f}, new coherent {med(lambda r: r[3]):.2f}; "
      f"new/old off {med(lambda r: r[2] / r[0]):.3f}, coherent {med(lambda r: r[3] / r[1]):.3f}; "
      f"coherent/off old {med(lambda r: r[1] / r[0]):.3f}, new {med(lambda r: r[3] / r[2]):.3f}")
PY
done
