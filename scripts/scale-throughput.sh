#!/usr/bin/env bash
# Throughput side by side: the same number of texels (about 10^6: the whole 10^6 world, shard
# 0/10 of the 10^7 world, shard 0/100 of the 10^8 world) baked from each world, the worlds
# alternated for ROUNDS rounds, so that a shared machine's load falls on every size alike.
# Prints texels/s and Mrays/s per run and the median per world.
#
#   scripts/scale-throughput.sh DIR [ROUNDS]
#
# DIR holds city-N.texels / .toml for N in 1000000 10000000 100000000 (from `guidebake synth
# --texels N -o DIR/city-N.texels`; scripts/scale.sh deletes its worlds after measuring).
# BAKE_ARGS and GUIDEBAKE as in scripts/scale.sh. Runs under `nice -n 10`.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir=$1
rounds=${2:-3}
bake_args=(${BAKE_ARGS:---spp 16 --iterations 2 --bounces 1})
bin=${GUIDEBAKE:-$root/target/release/guidebake}
threads=${THREADS:-$(nproc)}
declare -A rates
for ((round = 1; round <= rounds; round++)); do
    for n in 1000000 10000000 100000000; do
        [[ -s $dir/city-$n.texels ]] || continue
        shards=$((n / 1000000))
        shard=()
        ((shards > 1)) && shard=(--shard "0/$shards")
        out=$dir/tp-$n.exr
        rm -rf "$out".*
        nice -n 10 "$bin" bake "$dir/city-$n.texels" --scene "$dir/city-$n.toml" -o "$out" \
            "${bake_args[@]}" --threads "$threads" "${shard[@]}" --stats "$dir/tp-$n.json" 2>/dev/null
        rate=$(python3 -c "import json,sys; d=json.load(open(sys.argv[1])); \
print(round(d['counters']['texels_baked']/d['seconds']['gather']), round(d['rays_per_second']/1e6,2))" "$dir/tp-$n.json")
        echo "round $round  $n texels: ${shard[*]:-whole}  texels/s, Mrays/s: $rate"
        rates[$n]+="${rate%% *} "
        rm -rf "$out"* "$dir/tp-$n.json"
    done
done
for n in 1000000 10000000 100000000; do
    [[ -n ${rates[$n]:-} ]] || continue
    echo "$n: median texels/s $(tr ' ' '\n' <<<"${rates[$n]}" | grep . | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}') of ${rates[$n]}"
done
