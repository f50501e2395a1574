#!/usr/bin/env bash
# The tables of docs/guiding-on-levels.md from the bakes of scripts/levels/bakes.sh OUT 4
# (unguided, flat0 and mix75 at seeds 1-4, the levers at seeds 1-2, the black level's at
# seed 1; the diagnosis's default, which guided every cluster, is flat0).
#   scripts/levels/tables.sh OUT
set -euo pipefail
o=${1:?the bakes.sh output dir}; here=$(dirname "$(realpath "$0")")
w() { python3 "$here/where_guiding_loses.py" "$o/cx.texels" "$@" --sky "$o/skyview.exr" 2>/dev/null; }
seeds() { local n=$1 k=$2; local s; s=$(for i in $(seq 1 "$k"); do printf "%s," "$o/$n-$i.exr"; done); echo "${s%,}"; }
echo "# 1. The default before --flat-below (flat0) against the unguided bake, 4 seeds"
w "$o/ref1001.exr" "$o/direct.exr" "$(seeds unguided 4)" default="$(seeds flat0 4)" \
  mix75="$(seeds mix75 4)" --ref2 "$o/ref1002.exr"
echo; echo "# 2. The levers, 2 seeds (the unguided bake at the same 2 seeds)"
args=()
for n in flat0 uniform unguided-bounded mix50 mix75 mix75-uniform gain150 gain1000 noseed noseed-gain1000 radiance; do
  [ -f "$o/$n-2.exr" ] && args+=("$n=$(seeds $n 2)")
done
w "$o/ref1001.exr" "$o/direct.exr" "$(seeds unguided 2)" "${args[@]}" --ref2 "$o/ref1002.exr"
echo; echo "# 3. The black level (every material black: the gather sees the sky alone), seed 1,"
echo "#    against its 1 024-spp unguided bake"
args=()
for n in flat0 uniform mix75; do [ -f "$o/black-$n-1.exr" ] && args+=("$n=$o/black-$n-1.exr"); done
w "$o/direct.exr" "$o/direct.exr" "$o/black-unguided-1.exr" "${args[@]}"
echo; echo "# 4. --flat-below (docs/guiding-on-levels.md, \"The fix\"), 2 seeds, beside the unguided bake"
args=()
for n in flat0 flat3 flat10 flat30 flat100 flat300 flat1000 flat100-mix50 unguided-bounded; do
  [ -f "$o/$n-2.exr" ] && args+=("$n=$(seeds $n 2)")
done
w "$o/ref1001.exr" "$o/direct.exr" "$(seeds unguided 2)" "${args[@]}" --ref2 "$o/ref1002.exr"
