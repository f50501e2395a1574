#!/usr/bin/env bash
# The series pass image's memory and build time against the path transport's, on synth
# worlds (docs/series.md, "The pass image: only what is baked"):
#   scripts/pass-image-memory.sh OUT TEXELS... -- BINARY...
# e.g. scripts/pass-image-memory.sh /tmp/pim 1000000 10000000 -- old/guidebake new/guidebake
# For each texel count (a world `guidebake synth` writes once, with the first binary, into
# OUT) and each binary, bakes `--spp 16 --iterations 2 --bounces 1 --threads 2` with
# `--transport series` and `--transport path`, rounds interleaved (ROUNDS, default 1), under
# `/usr/bin/time -v`, polling the bake's /proc/PID/status every 0.2 s (POLL) for its peak
# RssAnon and RssFile. Prints one row per bake:
#   texels binary transport round peak_anon_MB peak_file_MB peak_rss_MB(time -v) wall_s
#   previous_pass_images_s pass_image_bytes filter_window_bytes
# (MB = 10⁶ bytes; pass_image_bytes from the stats JSON, `-` where a build does not report it).
# Each bake runs twice and the second is measured (WARM=0: once): a bake right after `synth`
# wrote its texel file holds that file's fresh pages (docs/bake.md, "Memory and throughput").
# TRANSPORTS (default "series path") picks the transports; BAKE_ARGS (default "--spp 16
# --iterations 2 --bounces 1") the bake's settings: BAKE_ARGS="--spp 24" bakes the default
# (three bounces, the last two passes' images filtered). Each measured bake's pages
# stay (OUT/TEXELS-BINARY-TRANSPORT-ROUND.page*.exr), to compare the binaries' bytes.
set -euo pipefail
out=$1
shift
texels=()
while [[ $# -gt 0 && $1 != -- ]]; do
    texels+=("$1")
    shift
done
shift
binaries=("$@")
rounds=${ROUNDS:-1}
warm=${WARM:-1}
read -r -a transports <<<"${TRANSPORTS:-series path}"
poll=${POLL:-0.2}
read -r -a bake_args <<<"${BAKE_ARGS:---spp 16 --iterations 2 --bounces 1}"
mkdir -p "$out"

# Runs a bake under /usr/bin/time -v; prints "anon_kb file_kb maxrss_kb wall_s".
measure() {
    local log=$1
    shift
    /usr/bin/time -v "$@" 2>"$log" >/dev/null &
    local timer=$! pid="" anon=0 file=0
    while kill -0 "$timer" 2>/dev/null; do
        [[ -z $pid ]] && pid=$(pgrep -P "$timer" | head -1 || true)
        if [[ -n $pid ]] && status=$(cat "/proc/$pid/status" 2>/dev/null); then
            while read -r key value _; do
                case $key in
                    RssAnon:) ((value > anon)) && anon=$value ;;
                    RssFile:) ((value > file)) && file=$value ;;
                esac
            done <<<"$status"
        fi
        sleep "$poll"
    done
    wait "$timer"
    local maxrss wall
    maxrss=$(awk -F': ' '/Maximum resident set size/ {print $2}' "$log")
    wall=$(awk -F'): ' '/Elapsed \(wall clock\)/ {n = split($2, p, ":"); s = 0;
        for (i = 1; i <= n; i++) s = s * 60 + p[i]; print s}' "$log")
    echo "$anon $file $maxrss $wall"
}

printf '%s\n' "texels binary transport round peak_anon_MB peak_file_MB peak_rss_MB wall_s previous_pass_images_s pass_image_bytes filter_window_bytes"
for n in "${texels[@]}"; do
    world=$out/w$n
    [[ -f $world.texels ]] || "${binaries[0]}" synth --texels "$n" -o "$world.texels" >&2
    for round in $(seq 1 "$rounds"); do
        for b in "${!binaries[@]}"; do
            for transport in "${transports[@]}"; do
                tag=$out/$n-$b-$transport-$round
                bake=("${binaries[$b]}" bake "$world.texels" --scene "$world.toml" -o "$tag.exr"
                    "${bake_args[@]}" --threads 2 --transport "$transport"
                    --stats "$tag.json" -q)
                rm -rf "$tag.exr"*
                if [[ $warm == 1 ]]; then "${bake[@]}" && rm -rf "$tag.exr"*; fi
                read -r anon file maxrss wall < <(measure "$tag.time" "${bake[@]}")
                python3 - "$tag.json" "$n" "$b" "$transport" "$round" "$anon" "$file" "$maxrss" "$wall" <<'EOF'
import json, sys
stats, n, b, transport, rnd, anon, file, maxrss, wall = sys.argv[1:]
s = json.load(open(stats))
t = s["seconds"]
wall = float(wall)
image = s.get("pass_image_bytes", "-")
window = s.get("filter_window_bytes", "-")
print(n, b, transport, rnd, f"{int(anon) * 1024 / 1e6:.0f}", f"{int(file) * 1024 / 1e6:.0f}",
      f"{int(maxrss) * 1024 / 1e6:.0f}", f"{wall:.2f}", f"{t['previous_pass_images']:.2f}", image, window)
EOF
                rm -rf "$tag.exr"*
            done
        done
    done
done
