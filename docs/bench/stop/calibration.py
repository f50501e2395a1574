#!/usr/bin/env python3
"""The stopping rule's calibration from docs/bench/stop/run.sh's runs: for each scene, cap
and method, the measured relative error (the square root of the bench's relative MSE, every
valid texel against the path reference) beside the method's --target-error, the gather rays
per texel per gather pass (the cap without the rule), the shadow rays per texel, and the CPU
time over the uniform default's where both ran.

    docs/bench/stop/calibration.py OUT [BOUNCES]     (BOUNCES: the bake's gather passes, 3)
"""
import csv
import math
import re
import sys
from pathlib import Path

out = Path(sys.argv[1])
bounces = int(sys.argv[2]) if len(sys.argv) > 2 else 3
print("| scene | cap (spp) | method | target | measured √relMSE | measured ÷ target "
      "| gather rays / texel / pass | shadow rays / texel | CPU s | rel. bias |")
print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
for runs in sorted(out.glob("*/runs.csv")):
    scene = runs.parent.name
    for r in csv.DictReader(runs.open()):
        m = re.search(r"\+stop=(\d+)", r["method"])
        target = int(m.group(1)) / 1000 if m else None
        texels = int(r["texels"])
        err = math.sqrt(float(r["rel_mse"]))
        ratio = f"{err / target:.2f}" if target else ""
        print(f"| {scene} | {r['spp']} | `{r['method']}` | {target or ''} | {err:.4f} | {ratio} "
              f"| {int(r['gather_rays']) / texels / bounces:.0f} "
              f"| {int(r['shadow_rays']) / texels:.0f} | {float(r['cpu_s']):.1f} "
              f"| {100 * float(r['rel_bias']):+.2f} % |")
