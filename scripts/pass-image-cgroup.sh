#!/usr/bin/env bash
# A bake under a memory limit gives the same bytes as one without (docs/series.md, "Under a
# memory limit"):
#   scripts/pass-image-cgroup.sh LIMIT_MIB BINARY WORLD.texels [BAKE ARGS...]
# e.g. scripts/pass-image-cgroup.sh 96 target/release/guidebake /tmp/pim/w1000000.texels --spp 24
# Bakes WORLD (its scene WORLD.toml beside it) once without a limit and once in a cgroup v1
# memory group of LIMIT_MIB (`memory.limit_in_bytes`; needs root and /sys/fs/cgroup/memory),
# both with `--threads 2` and the BAKE ARGS, then prints both bakes' wall times, how
# often it reached the limit (`memory.failcnt`), its peak usage and whether every page it
# wrote has the unlimited bake's bytes. Exits 1 when the limited bake fails or differs.
set -euo pipefail
limit_mib=$1
binary=$(realpath "$2")
world=$3
shift 3
scene=${world%.texels}.toml
group=/sys/fs/cgroup/memory/guidebake-limit-$$
out=$(mktemp -d)
trap 'rmdir "$group" 2>/dev/null || true; rm -rf "$out"' EXIT

start=$(date +%s.%N)
"$binary" bake "$world" --scene "$scene" -o "$out/free.exr" --threads 2 -q "$@"
free_wall=$(echo "$(date +%s.%N) - $start" | bc)

mkdir "$group"
echo $((limit_mib * 1024 * 1024)) >"$group/memory.limit_in_bytes"
start=$(date +%s.%N)
status=0
# The subshell moves itself into the group, then becomes the bake.
(echo "$BASHPID" >"$group/cgroup.procs" && exec "$binary" bake "$world" --scene "$scene" \
    -o "$out/limited.exr" --threads 2 -q "$@") || status=$?
end=$(date +%s.%N)
failcnt=$(cat "$group/memory.failcnt")
peak=$(cat "$group/memory.max_usage_in_bytes")
echo "without a limit: wall $free_wall s"
echo "limit ${limit_mib} MiB: exit $status, wall $(echo "$end - $start" | bc) s," \
    "limit reached $failcnt times, peak usage $((peak / 1024 / 1024)) MiB"
[[ $status == 0 ]] || exit 1
same=yes
for free in "$out"/free*.exr; do
    limited=${free/free/limited}
    cmp -s "$free" "$limited" || same=no
done
echo "same bytes as the bake without a limit: $same"
[[ $same == yes ]]
