#!/usr/bin/env bash
# Fetches Intel Open Image Denoise (the CPU device) for `--features oidn`: Debian has no
# package, so this takes the libraries out of PyPI's `pyoidn` wheel (pinned, checked by its
# SHA-256) into DIR/lib, with the unversioned symlink the linker needs, and prints on stdout
# the environment to build and run with:
#
#   eval "$(scripts/oidn/fetch.sh)"        # DIR defaults to ~/.cache/guidebake/oidn-2.5.1
#   cargo build --release -p guidebake --features oidn
#
# OIDN_DIR is what the `oidn` crate's build script links against (DIR/lib);
# LD_LIBRARY_PATH lets the binary find the libraries at run time. Exits non-zero, saying
# why on stderr, if the wheel cannot be downloaded or is not the pinned one.
set -euo pipefail

VERSION=2.5.1.0
WHEEL=pyoidn-$VERSION-py3-none-manylinux2014_x86_64.whl
SHA256=32ad13368f8de1ef63001942ad05b02a00cd732d1206d97f352d3a3f606d823e
DIR=${1:-${XDG_CACHE_HOME:-$HOME/.cache}/guidebake/oidn-2.5.1}
# The CPU device and what it needs (the GPU devices and SYCL runtime are left out).
LIBS=(libOpenImageDenoise.so.2.5.1 libOpenImageDenoise_core.so.2.5.1
      libOpenImageDenoise_device_cpu.so.2.5.1 libtbb.so.12.19)

say() { echo "oidn/fetch.sh: $*" >&2; }

if [[ $(uname -sm) != "Linux x86_64" ]]; then
    say "the pinned wheel is for Linux x86_64, not $(uname -sm)"
    exit 1
fi

if [[ ! -e $DIR/lib/libOpenImageDenoise_device_cpu.so.2.5.1 ]]; then
    download=$(mktemp -d)
    trap 'rm -rf "$download"' EXIT
    say "downloading $WHEEL from PyPI"
    # pip where it is installed, else the wheel's URL from PyPI's simple index with curl.
    if ! python3 -m pip download --quiet --no-deps --only-binary :all: \
            --platform manylinux2014_x86_64 --python-version 3.11 \
            -d "$download" "pyoidn==$VERSION" >&2 2>/dev/null; then
        url=$(curl -fsSL "https://pypi.org/simple/pyoidn/" |
            grep -o "href=\"[^\"]*/$WHEEL[^\"]*\"" | head -1 | sed 's/^href="//; s/[#"].*//') || true
        if [[ -z $url ]] || ! curl -fsSL -o "$download/$WHEEL" "$url"; then
            say "neither pip nor curl could download $WHEEL from PyPI"
            exit 1
        fi
    fi
    if ! echo "$SHA256  $download/$WHEEL" | sha256sum --check --status; then
        say "$WHEEL does not have the pinned SHA-256 $SHA256"
        exit 1
    fi
    # Unpack into a fresh folder and move it in place whole: never a half-written DIR.
    staging=$DIR.partial
    rm -rf "$staging"
    mkdir -p "$staging/lib"
    python3 - "$download/$WHEEL" "$staging/lib" "${LIBS[@]}" <<'PY'
import sys, zipfile, os
wheel, out, names = sys.argv[1], sys.argv[2], sys.argv[3:]
with zipfile.ZipFile(wheel) as z:
    for name in names:
        with z.open("pyoidn/oidn/lib/" + name) as src, open(os.path.join(out, name), "wb") as dst:
            dst.write(src.read())
PY
    ln -s libOpenImageDenoise.so.2.5.1 "$staging/lib/libOpenImageDenoise.so.2"
    ln -s libOpenImageDenoise.so.2 "$staging/lib/libOpenImageDenoise.so"
    ln -s libtbb.so.12.19 "$staging/lib/libtbb.so.12"
    rm -rf "$DIR"
    mv "$staging" "$DIR"
    say "libraries in $DIR/lib"
fi

echo "export OIDN_DIR=$DIR"
echo "export LD_LIBRARY_PATH=$DIR/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
