#!/usr/bin/env bash
# Runs the fuzz targets for SECONDS (default 60) each and prints, per target, executions,
# time and whether it crashed:   fuzz/run.sh [SECONDS] [TARGET...]
# Needs `cargo install cargo-fuzz`. Uses nightly with AddressSanitizer when available,
# otherwise stable without a sanitizer (-s none). cargo-fuzz builds in release with debug
# assertions (so the kernels' debug_assert! preconditions and overflow checks are live).
# New inputs go to fuzz/artifacts/corpus/TARGET (the checked-in seeds in fuzz/corpus/TARGET
# are read, never written); crashes land in fuzz/artifacts/TARGET/. Once a crash is fixed,
# copy its input into fuzz/corpus/TARGET/ so `cargo test --test fuzz_corpus` replays it.
# An input running past 60 s is a crash too (libFuzzer's -timeout; its default, 20 minutes,
# would stall a smoke run on a hang such as prepare's NaN chart in xatlas).
# Full logs: fuzz/artifacts/run-TARGET.log. Exits non-zero when any target crashed (CI's
# smoke run relies on it).
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-60}
shift || true
if rustup run nightly rustc --version >/dev/null 2>&1; then tc=(+nightly); san=(); else tc=(); san=(-s none); fi
# cargo-fuzz sets RUSTFLAGS, which hides .cargo/config.toml's: pass the AVX2 code path on.
if grep -q avx2 /proc/cpuinfo 2>/dev/null; then
    export RUSTFLAGS="${RUSTFLAGS:+$RUSTFLAGS }-C target-feature=+avx2,+fma"
fi
if [ $# -gt 0 ]; then targets=("$@"); else mapfile -t targets < <(cargo "${tc[@]}" fuzz list); fi
mkdir -p artifacts/corpus
crashed=()
for target in "${targets[@]}"; do
    mkdir -p "artifacts/corpus/$target"
    log="artifacts/run-$target.log"
    status=ok
    cargo "${tc[@]}" fuzz run "${san[@]}" "$target" "artifacts/corpus/$target" "corpus/$target" -- \
        -max_total_time="$seconds" -print_final_stats=1 -rss_limit_mb=4096 -timeout=60 >"$log" 2>&1 || { status=CRASH; crashed+=("$log"); }
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1 || true)
    secs=$(grep -o 'Done [0-9]* runs in [0-9]* second' "$log" | grep -o 'in [0-9]*' | grep -o '[0-9]*' | tail -1 || true)
    echo "$target: ${execs:-?} executions in ${secs:-?} s, $status (log: fuzz/$log)"
done
if [ ${#crashed[@]} -gt 0 ]; then
    grep -h -A3 "panicked at\|ERROR: AddressSanitizer\|ERROR: libFuzzer" "${crashed[@]}" | head -40 >&2 || true
    exit 1
fi
