#!/usr/bin/env bash
# The guide seed (docs/guiding-levers.md, "The seed guide"): the guiding targets' measure (docs/bench/reference-noise/run.sh:
# the three converted Bitterli scenes, 4 seeds, one thread, net of the path references' own noise)
# with the default, the default without its seed (`+seed=off`) and the unguided bake side by side
# in one run; net.py prints each against the unguided bake, and compare.py the default against
# the default without the seed at equal samples and at equal time.
#   docs/bench/guide-seed/run.sh SCENES_DIR OUT [SIZE]      (default size: 256)
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}; size=${3:-256}
here=$(dirname "$0")
mkdir -p "$out"
METHODS=off/average/-,coherent/cluster/rho,coherent/cluster/rho+seed=off \
  "$here/../reference-noise/run.sh" "$scenes" "$out" "$size" | tee "$out/net.md"
python3 "$here/compare.py" "$out" | tee "$out/compare.md"
