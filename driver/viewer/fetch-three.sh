#!/usr/bin/env bash
# Refreshes driver/viewer/three/ — the three.js files `guidebake view` serves (checked in, so
# nothing is fetched at build or run time) — from the npm registry at the pinned version,
# checking the tarball's SHA-256. Run from anywhere; needs npm and network.
#   driver/viewer/fetch-three.sh            # re-fetch and overwrite the checked-in files
# To move to another version: change VERSION and SHA256 (npm pack prints the tarball, sha256sum it),
# run this, then `cargo test -p guidebake --test viewer` (the browser test).
set -euo pipefail
VERSION=0.180.0
SHA256=ad66d724565ee29a2467277fa84daa5ed0211d6b8d446e9ef29f6bae0cd14144
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack --silent "three@$VERSION" >/dev/null)
echo "$SHA256  $work/three-$VERSION.tgz" | sha256sum -c --quiet
tar xzf "$work/three-$VERSION.tgz" -C "$work"
src="$work/package"
dst="$here/three"
rm -rf "$dst"
mkdir -p "$dst/addons/loaders" "$dst/addons/controls" "$dst/addons/utils" "$dst/addons/libs"
cp "$src/LICENSE" "$dst/LICENSE"
cp "$src/build/three.module.min.js" "$src/build/three.core.min.js" "$dst/"
cp "$src/examples/jsm/loaders/GLTFLoader.js" "$src/examples/jsm/loaders/EXRLoader.js" "$dst/addons/loaders/"
cp "$src/examples/jsm/controls/OrbitControls.js" "$dst/addons/controls/"
cp "$src/examples/jsm/utils/BufferGeometryUtils.js" "$dst/addons/utils/"
cp "$src/examples/jsm/libs/fflate.module.js" "$dst/addons/libs/"
echo "three@$VERSION" > "$dst/VERSION"
echo "driver/viewer/three: three@$VERSION"
