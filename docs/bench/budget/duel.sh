#!/usr/bin/env bash
# What the spatial budget costs per sample: each converted Bitterli scene at SIZE², the four
# `--budget`s baked in turn, ROUNDS rounds (default 5), SPP samples (default 256), one thread;
# prints the median gather seconds per budget and the median over rounds of each budget's
# time over the uniform one's of the same round (paired: a shared machine's load falls on
# both alike), and the gather rays each traced.
#   docs/bench/budget/duel.sh SCENES_DIR OUT [SIZE] [ROUNDS] [SPP]
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}
size=${3:-128}; rounds=${4:-5}; spp=${5:-256}
g=${GUIDEBAKE:-target/release/guidebake}
budgets=(uniform balanced mse relative)
mkdir -p "$out"
for s in cornell_box veach_ajar_no_teapots veach_bidir; do
  glb="$scenes/converted/bitterli_$s.glb"
  "$g" prepare "$glb" -o "$out/$s.texels" --size "${size}x${size}" >/dev/null
  for r in $(seq "$rounds"); do
    for b in "${budgets[@]}"; do
      "$g" bake "$out/$s.texels" --scene "$glb" -o "$out/$s-$b.exr" --spp "$spp" --threads 1 \
        --denoise off --seams off --budget "$b" --stats "$out/$s-$b-$r.json" >/dev/null 2>&1
    done
  done
  python3 - "$out" "$s" "$rounds" "${budgets[@]}" <<'PY'
import json, statistics, sys
out, scene, rounds, budgets = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
stat = lambda b, r: json.load(open(f"{out}/{scene}-{b}-{r}.json"))
gather = {b: [stat(b, r)["seconds"]["gather"] for r in range(1, rounds + 1)] for b in budgets}
for b in budgets:
    paired = statistics.median(g / u for g, u in zip(gather[b], gather["uniform"]))
    rays = stat(b, 1)["counters"]["gather_rays"]
    print(f"{scene} {b}: gather {statistics.median(gather[b]):.3f} s, paired / uniform {paired:.3f}, {rays} gather rays")
PY
  rm -f "$out/$s.texels" "$out/$s.texels.seams"
done
