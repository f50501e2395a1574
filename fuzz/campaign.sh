#!/usr/bin/env bash
# A fuzz campaign: every target at once, in the background, for TOTAL_SECONDS of wall time,
# each stopping early once it reaches its execution goal; then a table of what ran.
#
#   fuzz/campaign.sh TOTAL_SECONDS [TARGET...]
#
# - Resumes from the grown corpus: each target reads fuzz/artifacts/corpus/TARGET (written by
#   earlier runs and campaigns, kept between them) and the checked-in seeds fuzz/corpus/TARGET,
#   and adds new inputs to the former only.
# - Goals: 10^6 executions, raised to 10^7 once a target has run faster than
#   5 000 executions per CPU second. GOAL_<target>=N fixes one (e.g. GOAL_guide=2000000),
#   GOAL=N all of them. A target stops at its goal (libFuzzer -runs) or when the time is up,
#   whichever is first, so the fast targets hand their core to the slow ones.
# - A crash does not end the target's campaign: its input is written to
#   fuzz/artifacts/TARGET/crash-* and the target restarts for the time left (at most
#   MAX_RESTARTS=5 times). Once fixed, copy the input into fuzz/corpus/TARGET/ so
#   `cargo test --test fuzz_corpus` replays it.
# - The table (target, executions, wall time, executions per wall second and per CPU second,
#   corpus size, crashes) is printed and written to fuzz/artifacts/campaign.md; with
#   REPORT=path (e.g. REPORT=docs/RELIABILITY.md) it also replaces the part of that file
#   between the markers `<!-- campaign:begin -->` and `<!-- campaign:end -->`.
#   MACHINE="..." describes the machine in the table's caption (default: /proc/cpuinfo).
# - An input running past 60 s counts as a crash (libFuzzer's -timeout), as in fuzz/run.sh.
# - Toolchain as fuzz/run.sh: nightly with AddressSanitizer when installed, else stable with
#   -s none (SANITIZER=none forces the latter on nightly); release with debug assertions;
#   the AVX2 code path when the CPU has it. Builds every target first, in the foreground,
#   then runs the built binaries themselves: `cargo fuzz run` would rebuild on a source
#   change and, after a crash, build the target once more to print the input.
#
# - SEQUENTIAL=1 runs the targets one after another instead (on a shared machine: one core
#   for the fuzzer), each until its goal or the common deadline, in the order given.
# - `fuzz/campaign.sh --table TARGET...` only writes the table again from the targets' last
#   results (fuzz/artifacts/campaign-TARGET.sum), e.g. after campaigns of separate targets.
#
# Logs: fuzz/artifacts/campaign-TARGET.log (every restart appended).
set -euo pipefail
cd "$(dirname "$0")"
usage="usage: fuzz/campaign.sh TOTAL_SECONDS [TARGET...] | fuzz/campaign.sh --table TARGET..."
total=${1:?$usage}
shift
max_restarts=${MAX_RESTARTS:-5}
table_only=$([ "$total" = --table ] && echo 1 || echo "")

if [ "${SANITIZER:-}" != none ] && rustup run nightly rustc --version >/dev/null 2>&1; then
    tc=(+nightly); san=(); sanitizer="nightly, AddressSanitizer"
else
    tc=(); san=(-s none); sanitizer="$(rustc --version | cut -d' ' -f1-2), no sanitizer"
    if rustup run nightly rustc --version >/dev/null 2>&1; then tc=(+nightly); sanitizer="nightly, no sanitizer"; fi
fi
if grep -q avx2 /proc/cpuinfo 2>/dev/null; then
    export RUSTFLAGS="${RUSTFLAGS:+$RUSTFLAGS }-C target-feature=+avx2,+fma"
fi
if [ $# -gt 0 ]; then targets=("$@"); else mapfile -t targets < <(cargo "${tc[@]}" fuzz list); fi
[ -z "$table_only" ] || [ $# -gt 0 ] || { echo "$usage" >&2; exit 2; }

# goal_of TARGET EXECUTIONS CPU_SECONDS [final]: the target's goal after that much work
# (while running, the rate counts only after 10^6 executions: the seeds run fast).
goal_of() {
    local var="GOAL_$1"
    if [ -n "${!var:-}" ]; then echo "${!var}"; return; fi
    if [ -n "${GOAL:-}" ]; then echo "$GOAL"; return; fi
    awk -v e="$2" -v c="$3" -v f="${4:-}" 'BEGIN {
        print ((e >= 1000000 || f) && c > 0 && e / c > 5000) ? 10000000 : 1000000 }'
}

mkdir -p artifacts
if [ -z "$table_only" ]; then
    echo "building every target ($sanitizer)"
    cargo "${tc[@]}" fuzz build "${san[@]}" >artifacts/campaign-build.log 2>&1 ||
        { tail -40 artifacts/campaign-build.log; exit 1; }
    start=$(date +%s)
    deadline=$((start + total))
fi
bin_dir="target/$(rustc -vV | sed -n 's/^host: //p')/release"

# One target's campaign: runs until its goal or the deadline, restarting after a crash.
# Writes "executions cpu_seconds crashes segments seconds goal started toolchain" to
# artifacts/campaign-TARGET.sum.
campaign() {
    local target=$1 log="artifacts/campaign-$1.log" done_execs=0 cpu=0 crashes=0 segments=0
    local before after left execs t goal t0
    t0=$(date +%s)
    mkdir -p "artifacts/corpus/$target" "artifacts/$target"
    : >"$log"
    while :; do
        left=$((deadline - $(date +%s)))
        [ "$left" -gt 0 ] || break
        goal=$(goal_of "$target" "$done_execs" "$cpu")
        [ "$done_execs" -lt "$goal" ] || break
        segments=$((segments + 1))
        before=$(find "artifacts/$target" -type f | wc -l)
        t=$( { TIMEFORMAT='%U %S'; time "$bin_dir/$target" -artifact_prefix="artifacts/$target/" \
            -max_total_time="$left" -runs=$((goal - done_execs)) -print_final_stats=1 \
            -rss_limit_mb=4096 -timeout=60 "artifacts/corpus/$target" "corpus/$target" >>"$log" 2>&1 ||
            true; } 2>&1 | tail -1)
        cpu=$(awk -v a="$cpu" -v t="$t" 'BEGIN { split(t, p, " "); printf "%.1f", a + p[1] + p[2] }')
        execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1 || true)
        done_execs=$((done_execs + ${execs:-0}))
        # Mark the segment's end so the next segment's stats are not read twice.
        echo "campaign: segment $segments ended, $done_execs executions so far" >>"$log"
        sed -i 's/^stat::number_of_executed_units/done::number_of_executed_units/' "$log"
        after=$(find "artifacts/$target" -type f | wc -l)
        if [ "$after" -gt "$before" ]; then
            crashes=$((crashes + after - before))
            [ "$crashes" -le "$max_restarts" ] || break
        elif [ "${execs:-0}" -eq 0 ]; then
            break # neither ran nor crashed: do not spin
        fi
    done
    goal=$(goal_of "$target" "$done_execs" "$cpu" final)
    echo "$done_execs $cpu $crashes $segments $(( $(date +%s) - t0 )) $goal" \
        "$(date -u -d "@$t0" +%Y-%m-%dT%H:%M)" "${sanitizer// /_}" >"artifacts/campaign-$target.sum"
}

if [ -z "$table_only" ]; then
    echo "campaign of ${total} s: ${targets[*]} (from $(date -u +%H:%M:%S) UTC)"
    if [ "${SEQUENTIAL:-}" = 1 ]; then
        for target in "${targets[@]}"; do campaign "$target" || true; done
    else
        pids=()
        for target in "${targets[@]}"; do
            campaign "$target" &
            pids+=($!)
        done
        for pid in "${pids[@]}"; do wait "$pid" || true; done
    fi
fi

machine=${MACHINE:-"$(nproc)-core $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"}
table=artifacts/campaign.md
{
    echo "Fuzz campaign, $machine; release with debug assertions. Each target resumes from its grown corpus and stops at its goal (10^7 executions for targets faster than 5 000 per CPU second, else 10^6) or at the campaign's end; started: its start (UTC), time: its wall time. Executions per second are per wall second of the target and per CPU second of it (the machine is shared, so the wall rate is indicative only)."
    echo
    echo "| target | started (UTC) | toolchain | executions | goal | time | exec/s (wall) | exec/s (CPU) | corpus | crashes |"
    echo "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"
    for target in "${targets[@]}"; do
        read -r execs cpu crashes segments secs goal started toolchain <"artifacts/campaign-$target.sum"
        corpus=$(find "artifacts/corpus/$target" -type f | wc -l)
        seeds=$(find "corpus/$target" -type f | wc -l)
        met=$([ "$execs" -ge "$goal" ] && echo "" || echo " **(missed)**")
        awk -v t="$target" -v e="$execs" -v g="$goal" -v s="$secs" -v c="$cpu" -v k="$corpus" \
            -v d="$seeds" -v x="$crashes" -v m="$met" -v st="${started/T/ }" \
            -v tc="${toolchain//_/ }" 'function th(n,   s, r) {
                s = sprintf("%d", n); r = ""
                while (length(s) > 3) { r = "," substr(s, length(s) - 2) r; s = substr(s, 1, length(s) - 3) }
                return s r }
            BEGIN { printf "| `%s` | %s | %s | %s%s | %s | %d s | %s | %s | %s + %d seeds | %d |\n",
                t, st, tc, th(e), m, th(g), s, th(s > 0 ? e / s : 0), th(c > 0 ? e / c : 0), th(k), d, x }'
    done
} >"$table"
cat "$table"

if [ -n "${REPORT:-}" ]; then
    report=$REPORT
    case "$report" in /*) ;; *) report="$(cd .. && pwd)/$report" ;; esac
    if grep -q '<!-- campaign:begin -->' "$report" && grep -q '<!-- campaign:end -->' "$report"; then
        awk -v table="$table" '
            /<!-- campaign:begin -->/ { print; while ((getline line < table) > 0) print line; skip = 1; next }
            /<!-- campaign:end -->/ { skip = 0 }
            !skip { print }' "$report" >"$report.tmp" && mv "$report.tmp" "$report"
        echo "table written into $report"
    else
        echo "$report has no <!-- campaign:begin --> / <!-- campaign:end --> markers: table left in fuzz/$table" >&2
    fi
fi
crashed=$(for target in "${targets[@]}"; do cat "artifacts/campaign-$target.sum"; done |
    awk '{ s += $3 } END { print s + 0 }')
[ "$crashed" -eq 0 ] || { echo "crashes: see fuzz/artifacts/*/crash-*" >&2; exit 1; }
