#!/usr/bin/env bash
# Runs every fuzz target for SECONDS (default 60) each and prints executions and crashes.
# Needs `cargo install cargo-fuzz`. Uses nightly with AddressSanitizer when available,
# otherwise stable without a sanitizer (-s none). New crashes land in fuzz/artifacts/;
# once fixed, copy each into fuzz/corpus/TARGET/ so `cargo test` replays it.
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-60}
if rustup run nightly rustc --version >/dev/null 2>&1; then tc=(+nightly); san=(); else tc=(); san=(-s none); fi
for target in $(cargo "${tc[@]}" fuzz list); do
    echo "=== $target (${seconds}s)"
    cargo "${tc[@]}" fuzz run "${san[@]}" "$target" "corpus/$target" -- \
        -max_total_time="$seconds" -print_final_stats=1 2>&1 | grep -E 'stat::number_of_executed_units|crash|ERROR' || true
done
