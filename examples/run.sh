#!/usr/bin/env bash
# Builds the C and C++ embedding examples against both libraries of guidebake-kernels-capi
# (static libguidebake_capi.a and shared libguidebake_capi.so), runs them, and checks that
# each prints exactly what the Rust example (kernels/examples/embed.rs) prints. The examples
# themselves check their estimates against the analytic irradiance (exit 1 if outside 3σ).
# Needs cc and c++ (C11, C++17) besides cargo. Run from anywhere: bash examples/run.sh
set -euo pipefail
cd "$(dirname "$0")/.."
out=target/examples
mkdir -p "$out"
cargo build -p guidebake-kernels-capi
lib=target/debug
# What rustc says a static Rust library needs from the system (`--print native-static-libs`).
native=(-lgcc_s -lutil -lrt -lpthread -lm -ldl)
# No FMA contraction: the examples' own float arithmetic must round as Rust's does.
cflags=(-O2 -Wall -Wextra -Werror -ffp-contract=off -Icapi/include)

cargo run -q -p guidebake-kernels --example embed > "$out/rust.txt"
cc -std=c11 "${cflags[@]}" examples/c/embed.c "$lib/libguidebake_capi.a" "${native[@]}" -o "$out/embed-c-static"
cc -std=c11 "${cflags[@]}" examples/c/embed.c -L"$lib" -lguidebake_capi -lm -Wl,-rpath,"$PWD/$lib" -o "$out/embed-c-shared"
c++ -std=c++17 "${cflags[@]}" examples/cpp/embed.cpp "$lib/libguidebake_capi.a" "${native[@]}" -o "$out/embed-cpp-static"
c++ -std=c++17 "${cflags[@]}" examples/cpp/embed.cpp -L"$lib" -lguidebake_capi -Wl,-rpath,"$PWD/$lib" -o "$out/embed-cpp-shared"
# The shared builds really load the .so (not a static copy). Not `grep -q`: it exits at the
# first match, and ldd, still writing, dies of SIGPIPE, which pipefail turns into a silent
# failure of this script (about 1 run in 600; it failed CI once).
for exe in embed-c-shared embed-cpp-shared; do
    if ! ldd "$out/$exe" | grep libguidebake_capi.so >/dev/null; then
        echo "examples/run.sh: $out/$exe does not load libguidebake_capi.so" >&2
        exit 1
    fi
done

for exe in embed-c-static embed-c-shared embed-cpp-static embed-cpp-shared; do
    "$out/$exe" > "$out/$exe.txt"
    diff -u "$out/rust.txt" "$out/$exe.txt"
    echo "$exe: same output as the Rust example"
done
cat "$out/rust.txt"
