#!/usr/bin/env python3
"""The table of scripts/probes/equal-time.sh: OUT SCENE... -> markdown on stdout.

For each scene, seed and guided run: its gather seconds (the stats JSON beside the probe
file) and its MSE and relative MSE (compare.py) against the reference; the unguided runs
of the same seed, interpolated log-log in (seconds, error), give the unguided error at the
guided run's time; the ratio unguided / guided (above 1: guiding wins at equal time).
"""
import json
import math
import os
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))


def runs(dir):
    out = {}
    files = sorted(f for f in os.listdir(dir) if f.endswith(".probes") and f[:3] in ("on-", "off"))
    lines = subprocess.run([sys.executable, os.path.join(here, "compare.py"), os.path.join(dir, "ref.probes")]
                           + [os.path.join(dir, f) for f in files], capture_output=True, text=True,
                           check=True).stdout.splitlines()
    for f, line in zip(files, lines):
        guiding, spp, seed = f[:-len(".probes")].split("-")
        err = json.loads(line)
        stats = json.load(open(os.path.join(dir, f + ".json")))
        out[(guiding, int(spp), int(seed))] = (stats["seconds"]["gather"], err["mse"], err["rel_mse"])
    return out


def at_time(points, t, k):
    """Error k (1: mse, 2: rel_mse) of `points` [(seconds, mse, rel)] at time t, log-log."""
    pts = sorted(points)
    i = 0
    while i < len(pts) - 2 and t > pts[i + 1][0]:
        i += 1
    a, b = pts[i], pts[i + 1]
    x = (math.log(t) - math.log(a[0])) / (math.log(b[0]) - math.log(a[0]))
    return math.exp(math.log(a[k]) + x * (math.log(b[k]) - math.log(a[k])))


def main():
    root, scenes = sys.argv[1], sys.argv[2:]
    print("| scene | spp | seed | guided s | unguided s (same spp) | guided rel MSE | unguided rel MSE at equal time | ratio | guided MSE | unguided MSE at equal time | ratio |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for scene in scenes:
        r = runs(os.path.join(root, scene))
        for (guiding, spp, seed), (t, mse, rel) in sorted(r.items()):
            if guiding != "on":
                continue
            off = [v for (g, _, s), v in r.items() if g == "off" and s == seed]
            u_rel, u_mse = at_time(off, t, 2), at_time(off, t, 1)
            print(f"| {scene} | {spp} | {seed} | {t:.2f} | {r[('off', spp, seed)][0]:.2f} | {rel:.3e} | {u_rel:.3e} | "
                  f"{u_rel / rel:.2f}× | {mse:.3e} | {u_mse:.3e} | {u_mse / mse:.2f}× |")


if __name__ == "__main__":
    main()
