#!/bin/bash
# Figure-5 overhead of two (or more) builds side by side: every round bakes the scene
# unguided (`--guiding off --combine average`) and with the defaults (coherent guiding) with
# each build in turn, one thread, 256 spp, and reads each bake's CPU time (`perf stat -e
# task-clock`, ms resolution). Prints per build the median over rounds of coherent / off.
# Usage (repository root, after building each binary):
#   [TRANSPORT=path] [EXTRA="--min-gain 0"] docs/bench/overhead/ab.sh SCENE.glb ROUNDS OUT_DIR BIN...
# Needs `perf` (linux-perf). EXTRA goes to every bake.
set -euo pipefail
scene=${1:?SCENE}; rounds=${2:?ROUNDS}; out=${3:?OUT_DIR}; shift 3
mkdir -p "$out"
[ -s "$out/scene.texels" ] || "$1" prepare "$scene" -o "$out/scene.texels" --size 128x128 >/dev/null
log=$out/log.tsv; : > "$log"
for r in $(seq "$rounds"); do
  for b in "$@"; do
    for m in off coherent; do
      extra=(); [ $m = off ] && extra=(--guiding off --combine average)
      rm -rf "$out"/o.exr*
      perf stat -x, -e task-clock -o "$out/ps" "$b" bake "$out/scene.texels" --scene "$scene" \
        -o "$out/o.exr" --spp 256 --seed 1 --threads 1 ${TRANSPORT:+--transport $TRANSPORT} \
        "${extra[@]}" ${EXTRA:-} >/dev/null 2>&1
      echo -e "$r\t$b\t$m\t$(grep task-clock "$out/ps" | cut -d, -f1)" >> "$log"
    done
  done
done
python3 - "$log" <<'PY'
import statistics as st, sys
d = {}
for line in open(sys.argv[1]):
    r, b, m, ms = line.rstrip('\n').split('\t')
    d.setdefault(b, {}).setdefault(r, {})[m] = float(ms)
for b, rounds in d.items():
    ratios = [v['coherent'] / v['off'] for v in rounds.values() if len(v) == 2]
    print(f"{b}: coherent / off CPU, median of {len(ratios)} rounds {st.median(ratios):.4f}"
          f" (rounds {' '.join(f'{x:.3f}' for x in ratios)})")
PY
