#!/usr/bin/env bash
# The scale runs of docs/farm.md: synthesise cities of 10^6, 10^7 and 10^8 texels (fixed
# texel density: the world, its triangles and its BVH grow with N), bake each in one process,
# and record per size texels/s, rays/s, peak RSS and peak anonymous memory (polled from
# /proc every 20 ms by scripts/peak-mem.sh), and the disk used (texel file, scene, the work
# directory at its largest, pages).
#
#   scripts/scale.sh [DIR] [SIZES...]       # default: target/scale 1000000 10000000 100000000
#
# Resumable: a size whose row exists in DIR/rows.tsv is skipped, a synthesised world is
# reused, and an interrupted bake is continued with --resume (its row then says so: the
# times cover the last run only). Runs under `nice -n 10` (the machine is shared).
# Settings: BAKE_ARGS (default "--spp 16 --iterations 2 --bounces 1"), THREADS (default: all
# cores), GUIDEBAKE (default target/release/guidebake, built if missing).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir=${1:-$root/target/scale}
shift || true
sizes=("$@")
((${#sizes[@]})) || sizes=(1000000 10000000 100000000)
bake_args=(${BAKE_ARGS:---spp 16 --iterations 2 --bounces 1})
threads=${THREADS:-$(nproc)}
bin=${GUIDEBAKE:-$root/target/release/guidebake}
if [[ ! -x $bin ]]; then
    (cd "$root" && nice -n 10 cargo build --release -p guidebake)
fi
mkdir -p "$dir"
rows=$dir/rows.tsv
[[ -s $rows ]] || printf 'texels\tgrid\ttriangles\ttexels_per_m\tpasses\ttexels_per_s\tmrays_per_s\tgather_s\tpages_s\twall_s\tpeak_rss_mb\tpeak_anon_mb\tpeak_file_mb\tdisk_gb\tresumed\n' >"$rows"

for n in "${sizes[@]}"; do
    if awk -v n="$n" 'NR > 1 && $1 == n { found = 1 } END { exit !found }' "$rows"; then
        echo "scale: $n already measured"
        continue
    fi
    world=$dir/city-$n
    if [[ ! -s $world.json ]]; then
        echo "scale: synthesising $n texels"
        nice -n 10 "$bin" synth --texels "$n" -o "$world.texels" --json >"$world.json.tmp"
        mv "$world.json.tmp" "$world.json"
    fi
    out=$dir/lightmap-$n.exr
    resume=()
    resumed=no
    if [[ -d $out.bake ]]; then
        resume=(--resume)
        resumed=yes
    fi
    # The work directory's size, polled every 5 s in the background, its largest kept.
    (
        most=0
        while sleep 5; do
            now=$(du -sk "$out.bake" 2>/dev/null | cut -f1 || echo 0)
            ((now > most)) && most=$now && echo "$most" >"$dir/work-kb-$n"
        done
    ) &
    poller=$!
    echo "scale: baking $n texels: ${bake_args[*]} --threads $threads"
    nice -n 10 "$root/scripts/peak-mem.sh" "$bin" bake "$world.texels" --scene "$world.toml" \
        -o "$out" "${bake_args[@]}" --threads "$threads" --stats "$dir/stats-$n.json" \
        "${resume[@]}" 2>"$dir/bake-$n.log"
    kill "$poller" 2>/dev/null || true
    wait "$poller" 2>/dev/null || true
    mem=$(grep '^peak-mem:' "$dir/bake-$n.log" | tail -1)
    field() { sed -n "s/.*$1=\([0-9.]*\).*/\1/p" <<<"$mem"; }
    work_kb=$(cat "$dir/work-kb-$n" 2>/dev/null || echo 0)
    files_kb=$(du -skc "$world.texels" "$world.glb" "$dir"/lightmap-"$n"*.exr | tail -1 | cut -f1)
    python3 - "$world.json" "$dir/stats-$n.json" "$n" "$resumed" \
        "$(field rss_kb)" "$(field anon_kb)" "$(field file_kb)" "$(field wall_s)" \
        "$((work_kb + files_kb))" >>"$rows" <<'PY'
import json, sys
world, stats = (json.load(open(p)) for p in sys.argv[1:3])
n, resumed, rss, anon, file, wall, disk_kb = sys.argv[3:]
c, s = stats["counters"], stats["seconds"]
gather = s["gather"]
print("\t".join(str(v) for v in [
    world["texels"], world["grid"], world["triangles"], round(world["texels_per_unit"], 2),
    stats["passes"], round(c["texels_baked"] / gather), round(stats["rays_per_second"] / 1e6, 2),
    round(gather, 1), round(s["write_pages"], 1), round(float(wall), 1),
    round(int(rss) / 1024, 1), round(int(anon) / 1024, 1), round(int(file) / 1024, 1),
    round(int(disk_kb) / 1024 / 1024, 2), resumed]))
PY
    # The row is written: free the disk for the next size (the synth report stays).
    rm -f "$dir"/lightmap-"$n"*.exr "$dir"/lightmap-"$n"*.png "$world.texels" "$world.glb"
    tail -1 "$rows"
done
column -t "$rows"
