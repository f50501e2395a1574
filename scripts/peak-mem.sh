#!/usr/bin/env bash
# Runs a command and reports its peak memory, polled from /proc/PID/status every 20 ms:
#   scripts/peak-mem.sh COMMAND [ARGS...]
# prints to stderr, after the command's own output, one line
#   peak-mem: rss_kb=R anon_kb=A file_kb=F hwm_kb=H wall_s=S status=X
# rss/anon/file: the largest VmRSS, RssAnon and RssFile seen; hwm: the kernel's VmHWM (peak
# RSS) at the last poll. Exits with the command's status.
set -uo pipefail
start=$(date +%s.%N)
"$@" &
pid=$!
rss=0 anon=0 file=0 hwm=0
while kill -0 "$pid" 2>/dev/null; do
    if status=$(cat "/proc/$pid/status" 2>/dev/null); then
        while read -r key value _; do
            case $key in
                VmRSS:) ((value > rss)) && rss=$value ;;
                RssAnon:) ((value > anon)) && anon=$value ;;
                RssFile:) ((value > file)) && file=$value ;;
                VmHWM:) ((value > hwm)) && hwm=$value ;;
            esac
        done <<<"$status"
    fi
    sleep 0.02
done
wait "$pid"
code=$?
wall=$(echo "$(date +%s.%N) - $start" | bc)
echo "peak-mem: rss_kb=$rss anon_kb=$anon file_kb=$file hwm_kb=$hwm wall_s=$wall status=$code" >&2
exit "$code"
