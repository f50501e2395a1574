#!/bin/bash
# Where guiding's extra work goes, counted in instructions: one single-threaded bake unguided
# (`--guiding off`, the bake's defaults otherwise) and one with the defaults (coherent
# guiding), each under callgrind, then each function's inclusive instruction count in both
# and the difference. Instructions do not move with the machine's other load, as CPU time and
# perf's samples do (docs/BENCHMARKS.md, "Figure-5 overhead"); they are not time (a cache
# miss costs more than an add), so read them beside a paired CPU-time figure. Usage (from the
# repository root, after `cargo build --release -p guidebake`):
#   docs/bench/overhead/instructions.sh SCENE.glb [SIZE] [SPP] [OUT_DIR]
# (defaults 128, 256, target/overhead-instructions). Needs valgrind; about 50× the bake's
# time (two minutes for the Cornell box at 128², 256 spp). Prints both totals, their ratio,
# and the 20 of the bake's functions whose inclusive count grew or fell the most, in % of
# the unguided total.
set -euo pipefail
scene=${1:?usage: instructions.sh SCENE.glb [SIZE] [SPP] [OUT_DIR]}
size=${2:-128}
spp=${3:-256}
out=${4:-target/overhead-instructions}
bin=${GUIDEBAKE:-target/release/guidebake}
mkdir -p "$out"
"$bin" prepare "$scene" -o "$out/scene.texels" --size "${size}x${size}" >/dev/null
for m in off coherent; do
    valgrind -q --tool=callgrind --callgrind-out-file="$out/callgrind-$m.out" "$bin" bake \
        "$out/scene.texels" --scene "$scene" -o "$out/$m.exr" --spp "$spp" --seed 1 \
        --threads 1 --guiding "$m" >/dev/null 2>&1
done
python3 - "$out" <<'PY'
import re, subprocess, sys
out = sys.argv[1]
def load(m):
    """Inclusive instructions per function (call counts and file names stripped), and the total."""
    text = subprocess.run(['callgrind_annotate', '--inclusive=yes', '--threshold=100',
                           f'{out}/callgrind-{m}.out'], capture_output=True, text=True).stdout
    d, total = {}, None
    for line in text.split('\n'):
        mm = re.match(r'\s*([\d,]+) \(\s*[\d.]+%\)\s+(.*)$', line)
        if not mm:
            continue
        n, name = int(mm.group(1).replace(',', '')), mm.group(2)
        if 'PROGRAM TOTALS' in name:
            total = n
            continue
        name = re.sub(r' \[[^]]*\]$', '', name)
        name = re.sub(r' \([\d,]+x\)$', '', name)
        name = name.split(':', 1)[1] if ':' in name else name
        if 'guidebake' in name and "'" not in name:  # the bake's own, not threads' frames
            d[name] = max(d.get(name, 0), n)
    return d, total
(a, ta), (b, tb) = load('off'), load('coherent')
print(f'instructions: off {ta / 1e9:.3f} G, coherent {tb / 1e9:.3f} G, ratio {tb / ta:.3f}')
print(f'{"change":>8} {"off":>9} {"coherent":>9}  function (inclusive; % of the unguided total)')
for k in sorted(set(a) | set(b), key=lambda k: -abs(b.get(k, 0) - a.get(k, 0)))[:20]:
    d = b.get(k, 0) - a.get(k, 0)
    print(f'{100 * d / ta:+7.2f}% {100 * a.get(k, 0) / ta:8.2f}% {100 * b.get(k, 0) / ta:8.2f}%  {k[:90]}')
PY
