#!/usr/bin/env bash
# The whole bake's scaling with threads (docs/farm.md, "Scaling with threads"): the 10^6-texel
# synth city (--transport path --spp 16 --iterations 2 --bounces 1) and the Veach ajar room at
# 512x512 (--transport path --spp 256), each baked ROUNDS times per thread count; per run the
# process's wall time and the stats' gather and write_pages seconds, and whether the EXR and
# PNG are the bytes of the 1-thread bake (they must be).
#
#   scripts/scale-bake.sh [DIR]     # default DIR: target/scale-bake
#
# Prepared for a bare many-core machine without network: it needs only bash, awk, cmp and the
# binary (GUIDEBAKE, default target/release/guidebake; build it beforehand and bring it), and
# the ajar scene (SCENES, default ../shared/scenes; the converted glb). The worlds are made
# once in DIR and reused.
# Settings: THREADS (default "1 2 4 8 16", capped at nproc unless FORCE_THREADS=1), ROUNDS
# (default 3), AJAR_SPP (default 256), CITY_TEXELS (default 1000000), WORKLOADS (default
# "city ajar"), NICE (default 0: on a shared machine use 5 or more).
# Writes DIR/runs.tsv (one row per bake) and DIR/summary.tsv (medians per workload and thread
# count, speed-up against 1 thread, write_pages' share of the wall), and prints the summary.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir=${1:-$root/target/scale-bake}
bin=${GUIDEBAKE:-$root/target/release/guidebake}
scenes=${SCENES:-$root/../shared/scenes}
threads_list=(${THREADS:-1 2 4 8 16})
rounds=${ROUNDS:-3}
ajar_spp=${AJAR_SPP:-256}
city_texels=${CITY_TEXELS:-1000000}
workloads=(${WORKLOADS:-city ajar})
nice_level=${NICE:-0}
cores=$(nproc)

[[ -x $bin ]] || { echo "scale-bake: no binary at $bin (set GUIDEBAKE)" >&2; exit 1; }
mkdir -p "$dir"
runs=$dir/runs.tsv
printf 'workload\tthreads\tround\twall_s\tgather_s\twrite_pages_s\tsame_bytes\n' >"$runs"
{
    echo "# $(date -u +%FT%TZ) $(uname -n): $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //'), $cores cores"
    echo "# $bin ($(stat -c %s "$bin") bytes), rounds $rounds, ajar spp $ajar_spp, city texels $city_texels"
} >"$dir/machine.txt"
cat "$dir/machine.txt"

now() { date +%s.%N; }
# The stats JSON's seconds.<key> (flat numbers only; no jq on a bare machine).
stat_of() { grep -o "\"$2\": *[0-9.e+-]*" "$1" | head -1 | sed 's/.*: *//'; }

setup() {
    case $1 in
    city)
        if [[ ! -s $dir/city.texels ]]; then
            nice -n "$nice_level" "$bin" synth --texels "$city_texels" -o "$dir/city.texels" >/dev/null
        fi
        args=("$dir/city.texels" --scene "$dir/city.toml" --transport path --spp 16 --iterations 2 --bounces 1)
        ;;
    ajar)
        local glb=$scenes/converted/bitterli_veach_ajar_no_teapots.glb
        [[ -s $glb ]] || { echo "scale-bake: no ajar scene at $glb (set SCENES)" >&2; exit 1; }
        if [[ ! -s $dir/ajar.texels ]]; then
            nice -n "$nice_level" "$bin" prepare "$glb" --size 512x512 -o "$dir/ajar.texels" >/dev/null
        fi
        args=("$dir/ajar.texels" --scene "$glb" --transport path --spp "$ajar_spp")
        ;;
    *)
        echo "scale-bake: unknown workload $1" >&2
        exit 1
        ;;
    esac
}

for w in "${workloads[@]}"; do
    setup "$w"
    for t in "${threads_list[@]}"; do
        if ((t > cores)) && [[ ${FORCE_THREADS:-0} != 1 ]]; then
            echo "scale-bake: $w at $t threads skipped: $cores cores here"
            continue
        fi
        for r in $(seq 1 "$rounds"); do
            out=$dir/$w-t$t.exr
            rm -rf "$out" "$out.bake" "${out%.exr}.atlas.png" "$dir/$w-t$t.json"
            start=$(now)
            if ! nice -n "$nice_level" "$bin" bake "${args[@]}" -o "$out" --threads "$t" \
                --stats "$dir/$w-t$t.json" >"$dir/$w-t$t.log" 2>&1; then
                echo "scale-bake: $w at $t threads failed ($dir/$w-t$t.log):" >&2
                tail -5 "$dir/$w-t$t.log" >&2
                exit 1
            fi
            end=$(now)
            wall=$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.3f", b - a }')
            gather=$(stat_of "$dir/$w-t$t.json" gather)
            pages=$(stat_of "$dir/$w-t$t.json" write_pages)
            same=reference
            if [[ $t != "${threads_list[0]}" || $r != 1 ]]; then
                if cmp -s "$out" "$dir/$w-reference.exr" &&
                    cmp -s "${out%.exr}.atlas.png" "$dir/$w-reference.png"; then
                    same=yes
                else
                    same=NO
                fi
            else
                cp "$out" "$dir/$w-reference.exr"
                cp "${out%.exr}.atlas.png" "$dir/$w-reference.png"
            fi
            printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$w" "$t" "$r" "$wall" "$gather" "$pages" "$same" |
                tee -a "$runs"
        done
    done
done

# Medians per workload and thread count; speed-up of the wall against the first thread count.
awk -F'\t' '
function median(list,   n, a, i, j, x) {
    n = split(list, a, " ")
    for (i = 2; i <= n; i++) { x = a[i]; for (j = i - 1; j >= 1 && a[j] > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
    return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
}
NR > 1 {
    key = $1 "\t" $2
    if (!(key in wall)) order[++keys] = key
    wall[key] = wall[key] " " $4; gather[key] = gather[key] " " $5; pages[key] = pages[key] " " $6
    n[key]++
    if ($7 == "NO") bad[key] = 1
}
END {
    print "workload\tthreads\truns\twall_s\tgather_s\twrite_pages_s\twall_speedup\twrite_pages_share\tsame_bytes"
    for (k = 1; k <= keys; k++) {
        key = order[k]; split(key, p, "\t")
        w = median(wall[key]); g = median(gather[key]); s = median(pages[key])
        if (!(p[1] in base)) base[p[1]] = w
        printf "%s\t%d\t%.3f\t%.3f\t%.3f\t%.2fx\t%.1f%%\t%s\n", key, n[key], w, g, s, base[p[1]] / w, 100 * s / w, (key in bad) ? "NO" : "yes"
    }
}' "$runs" >"$dir/summary.tsv"
column -t -s$'\t' "$dir/summary.tsv" 2>/dev/null || cat "$dir/summary.tsv"
if grep -q $'\tNO$' "$runs"; then
    echo "scale-bake: some bake's bytes differ from the reference" >&2
    exit 1
fi
