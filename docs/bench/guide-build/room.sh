#!/bin/bash
# The guide build's sort room (`guide::build_in`) side by side: every round bakes each scene
# with the default settings once per build, one thread, and reads the bake's CPU time
# (`perf stat -e task-clock`) and its guide builds' time (`--stats`, `guide_build_ns`).
# Prints per scene the medians over rounds of each build's figures against the first
# build's, and whether the builds' lightmaps are the same bytes.
# Usage (repository root, after building each binary):
#   [SIZE=128] [SPP=1024] [SCENES="cornell_box ..."] docs/bench/guide-build/room.sh SCENES_DIR ROUNDS OUT_DIR BIN...
# Needs `perf` (linux-perf).
set -euo pipefail
scenes=${1:?SCENES_DIR}; rounds=${2:?ROUNDS}; out=${3:?OUT_DIR}; shift 3
size=${SIZE:-128}; spp=${SPP:-1024}
mkdir -p "$out"; log=$out/log.tsv; : > "$log"
for s in ${SCENES:-cornell_box veach_ajar_no_teapots veach_bidir}; do
  glb=$scenes/converted/bitterli_$s.glb
  [ -s "$out/$s.texels" ] || "$1" prepare "$glb" -o "$out/$s.texels" --size ${size}x${size} >/dev/null
  for r in $(seq "$rounds"); do
    for k in $(seq $#); do
      b=${!k}; o=$out/$s-$k.exr; rm -rf "$o"*
      perf stat -x, -e task-clock -o "$out/ps" "$b" bake "$out/$s.texels" --scene "$glb" \
        -o "$o" --spp "$spp" --seed "$r" --threads 1 --stats "$out/stats.json" >/dev/null 2>&1
      build=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['counters']['guide_build_ns'])" "$out/stats.json")
      same=1; [ "$k" = 1 ] || cmp -s "$o" "$out/$s-1.exr" || same=0
      echo -e "$s\t$r\t$k\t$(grep task-clock "$out/ps" | cut -d, -f1)\t$build\t$same" >> "$log"
    done
  done
done
python3 - "$log" "$@" <<'PY'
import statistics as st, sys
rows = [l.rstrip('\n').split('\t') for l in open(sys.argv[1])]
bins = sys.argv[2:]
for s in dict.fromkeys(r[0] for r in rows):
    d = {}
    for _, r, k, ms, ns, same in (x for x in rows if x[0] == s):
        d.setdefault(int(k), {})[r] = (float(ms), int(ns) / 1e6, same == '1')
    base = d[1]
    print(f"{s}: build 1 ({bins[0]}) CPU median {st.median(v[0] for v in base.values()):.0f} ms, "
          f"guide builds {st.median(v[1] for v in base.values()):.0f} ms")
    for k in sorted(d)[1:]:
        cpu = st.median(d[k][r][0] / base[r][0] for r in d[k] if r in base)
        bld = st.median(d[k][r][1] / base[r][1] for r in d[k] if r in base)
        same = all(v[2] for v in d[k].values())
        print(f"  build {k} ({bins[k - 1]}) over build 1: CPU {cpu:.3f}, guide builds {bld:.3f}, "
              f"lightmaps {'the same bytes' if same else 'differ'} ({len(d[k])} rounds)")
PY
