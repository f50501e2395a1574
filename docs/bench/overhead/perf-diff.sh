#!/bin/bash
# Where guiding's extra CPU time goes: perf profiles of one single-threaded bake unguided
# (`--guiding off --combine average`) and one with the defaults (coherent guiding), then the
# per-symbol difference in samples. Usage (from the repository root, after
# `cargo build --release -p guidebake`):
#   [TRANSPORT=path] docs/bench/overhead/perf-diff.sh SCENE.glb [SPP] [OUT_DIR]
# Needs `perf` (linux-perf). Prints the total samples of both runs and the 24 symbols whose
# sample count grew the most.
set -euo pipefail
scene=${1:?usage: perf-diff.sh SCENE.glb [SPP] [OUT_DIR]}
spp=${2:-256}
out=${3:-target/overhead-perf}
bin=${GUIDEBAKE:-target/release/guidebake}
mkdir -p "$out"
"$bin" prepare "$scene" -o "$out/scene.texels" --size 128x128 >/dev/null
for m in off coherent; do
    extra=()
    [ "$m" = off ] && extra=(--guiding off --combine average)
    perf record -q -F 2000 -g -o "$out/perf-$m.data" "$bin" bake "$out/scene.texels" \
        --scene "$scene" -o "$out/$m.exr" --spp "$spp" --seed 1 --threads 1 ${TRANSPORT:+--transport $TRANSPORT} "${extra[@]}" \
        >/dev/null 2>&1
done
python3 - "$out" <<'PY'
import re, subprocess, sys
out = sys.argv[1]
def load(m):
    text = subprocess.run(['perf', 'report', '-i', f'{out}/perf-{m}.data', '--no-children',
                           '--sort', 'symbol', '--stdio', '-n'],
                          capture_output=True, text=True).stdout
    d = {}
    for line in text.split('\n'):
        mm = re.match(r'\s+([\d.]+)%\s+(\d+)\s+\[\.\]\s+(\S+)', line)
        if mm:
            d[mm.group(3)] = d.get(mm.group(3), 0) + int(mm.group(2))
    return d
a, b = load('off'), load('coherent')
ta, tb = sum(a.values()), sum(b.values())
print(f'samples: off {ta}, coherent {tb}, ratio {tb / ta:.3f}')
print(f'{"extra":>7} {"% off":>6} {"off":>7} {"coh":>7}  symbol')
for k in sorted(set(a) | set(b), key=lambda k: -(b.get(k, 0) - a.get(k, 0)))[:24]:
    d = b.get(k, 0) - a.get(k, 0)
    print(f'{d:7d} {100 * d / ta:6.2f} {a.get(k, 0):7d} {b.get(k, 0):7d}  {k[:80]}')
PY
