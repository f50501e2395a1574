#!/bin/bash
# Whole-bake CPU time of two guidebake builds, interleaved round by round on one thread:
# the before/after figure of a traversal change that must not change a single bit.
# Usage (repository root): docs/bench/single-rays/ab.sh OLD_BIN NEW_BIN ROUNDS OUT_DIR \
#     NAME TEXELS SCENE [BAKE OPTIONS...]
# Prints per round the two CPU times (user + system, s) and at the end the median of each
# and the median of the per-round ratios new/old; checks the two lightmaps are identical.
set -euo pipefail
old=${1:?OLD_BIN}; new=${2:?NEW_BIN}; rounds=${3:?ROUNDS}; out=${4:?OUT_DIR}
name=${5:?NAME}; texels=${6:?TEXELS}; scene=${7:?SCENE}; shift 7
mkdir -p "$out"
log="$out/$name.tsv"; : > "$log"
for r in $(seq "$rounds"); do
    row="$r"
    for v in old new; do
        bin=$old; [ $v = new ] && bin=$new
        rm -rf "$out/$name-$v.exr" "$out/$name-$v.exr".*
        /usr/bin/time -f "%U %S" -o "$out/$v.time" "$bin" bake "$texels" --scene "$scene" \
            -o "$out/$name-$v.exr" --threads 1 "$@" >/dev/null 2>&1
        row="$row	$(awk '{print $1 + $2}' "$out/$v.time")"
    done
    echo "$row" | tee -a "$log"
done
cmp -s "$out/$name-old.exr" "$out/$name-new.exr" && echo "$name: lightmaps identical" \
    || echo "$name: LIGHTMAPS DIFFER"
python3 - "$log" "$name" <<'PY'
import statistics as st, sys
rows = [list(map(float, l.split()[1:])) for l in open(sys.argv[1])]
old, new = [r[0] for r in rows], [r[1] for r in rows]
print(f"{sys.argv[2]}: old {st.median(old):.2f} s, new {st.median(new):.2f} s, "
      f"new/old per round (median) {st.median(n / o for o, n in rows):.3f}")
PY
