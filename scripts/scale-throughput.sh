#!/usr/bin/env bash
# Throughput side by side: the same amount of work (about 10^6 texels per bake) from each
# world, the worlds alternated round by round, so that a shared machine's load falls on every
# size alike. The 10^6 world is baked whole; the 10^7 and 10^8 worlds are split into N/10^6
# shards (`--shard i/n`: contiguous runs of tiles, docs/farm.md) and STRATA of them, evenly
# spread over the world (i = (2j + 1) n / (2 STRATA)), are baked each round — a contiguous
# shard is one region of the city, and regions differ (an edge strip sees more open sky than
# the middle), so one shard would not stand for the world. Each round bakes, for j = 0 ..
# STRATA - 1, the 10^6 world and stratum j of the others, back to back. Per world and round:
# texels/s and Mrays/s over its bakes (Σ texels / Σ gather seconds), and the ratio to the 10^6
# world of the same round. Prints every bake, then medians and paired ratios.
#
#   scripts/scale-throughput.sh DIR [ROUNDS]
#
# DIR holds city-N.texels / .toml for N in 1000000 10000000 100000000 (from `guidebake synth
# --texels N -o DIR/city-N.texels`; scripts/scale.sh deletes its worlds after measuring).
# THREADS and GUIDEBAKE as in scripts/scale.sh; STRATA (default 3); BAKE_ARGS (default
# "--transport path --spp 16 --iterations 2 --bounces 1": one gather per texel and a shadow ray
# at each hit, the work of the scale runs; a series bake of one bounce now has two passes, the
# direct pass and the gather, and a shard of the gather needs the whole direct pass merged
# first, docs/farm.md). Runs under `nice -n 10`. Every bake's line goes to DIR/throughput.tsv
# too.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir=$1
rounds=${2:-3}
strata=${STRATA:-3}
bake_args=(${BAKE_ARGS:---transport path --spp 16 --iterations 2 --bounces 1})
bin=${GUIDEBAKE:-$root/target/release/guidebake}
threads=${THREADS:-$(nproc)}
sizes=()
for n in 1000000 10000000 100000000; do
    [[ -s $dir/city-$n.texels ]] && sizes+=("$n")
done
((${#sizes[@]})) || { echo "no city-N.texels in $dir" >&2; exit 1; }
log=$dir/throughput.tsv
printf 'round\ttexels\tshard\tload\ttexels_baked\trays\tgather_s\n' >"$log"

# bake N SHARD: one bake of world N (SHARD = i/n, or "whole"); appends its line to the log.
bake() {
    local n=$1 shard=$2 out=$dir/tp-$1.exr args=()
    [[ $shard == whole ]] || args=(--shard "$shard")
    rm -rf "$out".*
    nice -n 10 "$bin" bake "$dir/city-$n.texels" --scene "$dir/city-$n.toml" -o "$out" \
        "${bake_args[@]}" --threads "$threads" "${args[@]}" --stats "$dir/tp-$n.json" >/dev/null 2>&1
    python3 - "$dir/tp-$n.json" "$round" "$n" "$shard" "$(cut -d' ' -f1 /proc/loadavg)" >>"$log" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
c = d["counters"]
rays = c["gather_rays"] + c["shadow_rays"] + c["path_rays"]
print("\t".join(sys.argv[2:6] + [str(c["texels_baked"]), str(rays), str(d["seconds"]["gather"])]))
PY
    tail -1 "$log"
    rm -rf "$out"* "$dir/tp-$n.json"
}

for ((round = 1; round <= rounds; round++)); do
    # One bake of every world per stratum (the 10^6 world whole every time), the worlds'
    # order rotated, so that bakes compared are minutes apart at most.
    for ((j = 0; j < strata; j++)); do
        for ((k = 0; k < ${#sizes[@]}; k++)); do
            n=${sizes[$(((k + j + round) % ${#sizes[@]}))]}
            count=$((n / 1000000))
            if ((count == 1)); then
                bake "$n" whole
            else
                bake "$n" "$(((2 * j + 1) * count / (2 * strata)))/$count"
            fi
        done
    done
done

python3 - "$log" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1]), delimiter="\t"))
per = {}  # (texels, round) -> [texels, rays, seconds]
loads = [float(r["load"]) for r in rows]
for r in rows:
    s = per.setdefault((int(r["texels"]), int(r["round"])), [0, 0, 0.0])
    s[0] += int(r["texels_baked"]); s[1] += int(r["rays"]); s[2] += float(r["gather_s"])
sizes = sorted({t for t, _ in per})
rounds = sorted({r for _, r in per})
base = sizes[0]
print(f"load average (1 min) {min(loads):.1f}-{max(loads):.1f}, median {statistics.median(loads):.1f}")
print("texels\ttexels/s median (min-max)\tMrays/s median\tvs smallest, medians\tvs smallest, paired (median, min-max)")
for t in sizes:
    rate = [per[t, r][0] / per[t, r][2] for r in rounds if (t, r) in per]
    mrays = [per[t, r][1] / per[t, r][2] / 1e6 for r in rounds if (t, r) in per]
    paired = [(per[t, r][0] / per[t, r][2]) / (per[base, r][0] / per[base, r][2])
              for r in rounds if (t, r) in per and (base, r) in per]
    b = statistics.median(per[base, r][0] / per[base, r][2] for r in rounds if (base, r) in per)
    print(f"{t}\t{statistics.median(rate):.0f} ({min(rate):.0f}-{max(rate):.0f})\t"
          f"{statistics.median(mrays):.2f}\t{statistics.median(rate) / b:.2f}\t"
          f"{statistics.median(paired):.2f} ({min(paired):.2f}-{max(paired):.2f})")
PY
