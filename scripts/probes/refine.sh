#!/usr/bin/env bash
# Does refining the probe lattice where the direct light changes lower the error of probes
# interpolated in open air? (docs/probes.md, "Where light changes")
#
#   scripts/probes/refine.sh SCENES_DIR OUT
#     Env: N (random points, default 2000), SPACINGS (finest spacings, default "auto 9.5 9
#     8.5"; auto: the level's longest side / 24, 36 units), SPP (lattice probes, default
#     1024), REF_SPP (reference probes, default 4096), GUIDEBAKE (default
#     target/release/guidebake).
#
# zdm2 under its sun and sky (docs/bench/surfaces/zdm2-scene.sh), probes by path transport:
# the lattice with `--refine geometry` and with `--refine light`; N random points in the
# level's bounds as reference probes (those inside geometry are skipped by `probes`); then
# scripts/probes/refine.py interpolates each lattice at the reference's points.
set -euo pipefail
scenes=${1:?scenes dir (../shared/scenes)}; out=${2:?output dir}
g=$(realpath "${GUIDEBAKE:-target/release/guidebake}")
here=$(dirname "$(realpath "$0")")
mkdir -p "$out/src"
"$here/../../docs/bench/surfaces/zdm2-scene.sh" "$scenes" "$out/src"
scene=$out/src/zdm2.toml
[ -f "$out/scene.texels" ] || "$g" prepare "$scene" -o "$out/scene.texels" --size 768x768 --unwrap always -q
common=("$out/scene.texels" --scene "$scene" --transport path --volume off --quiet)
lattices=()
for spacing in ${SPACINGS:-auto 9.5 9 8.5}; do
  at=(); [ "$spacing" != auto ] && at=(--spacing "$spacing")
  for refine in geometry light; do
    "$g" probes "${common[@]}" "${at[@]}" --refine "$refine" --spp "${SPP:-1024}" --seed 1 \
      -o "$out/$refine-$spacing.probes"
    lattices+=("$out/$refine-$spacing.probes")
  done
done
python3 "$here/refine.py" "${lattices[0]}" "${N:-2000}" 7 > "$out/points.txt"
"$g" probes "${common[@]}" --placement points --points "$out/points.txt" --spp "${REF_SPP:-4096}" \
  --seed 1000 -o "$out/ref.probes"
(cd "$here" && python3 refine.py "$out/ref.probes" "${lattices[@]}") | tee "$out/refine.json"
