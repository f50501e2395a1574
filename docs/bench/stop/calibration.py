#!/usr/bin/env python3
"""The stopping rule's calibration from docs/bench/stop/run.sh's runs: for each scene, cap
and method, the measured relative error (the square root of the bench's relative MSE, every
valid texel against the path reference) beside the method's --target-error — and, where the
runs were measured with --reference-noise, net of the reference's own noise (the bench's
`reference_noise` subtracted from the relative MSE) — the gather rays per texel over every
pass (the cap and the lookup passes' quarter of it, without the rule), the shadow rays per texel, the CPU
time, and the uniform unguided baseline's relative MSE and MSE at that CPU time over the
bake's (> 1: the rule's bake is ahead at equal time; the baseline's two rungs fitted by a
power law in the CPU time, `*` where read off outside them).

    docs/bench/stop/calibration.py OUT
"""
import csv
import json
import math
import re
import sys
from pathlib import Path

out = Path(sys.argv[1])
print("| scene | cap (spp) | method | target | measured √relMSE | measured ÷ target "
      "| net of the reference's noise | net ÷ target "
      "| gather rays / texel | shadow rays / texel | CPU s | rel. bias "
      "| baseline ÷ bake at equal CPU time: relMSE | MSE |")
print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for runs in sorted(out.glob("*/runs.csv")):
    scene = runs.parent.name
    summary = runs.parent / "summary.json"
    noise = (json.loads(summary.read_text()).get("reference_noise") or {}).get("rel_mse") \
        if summary.exists() else None
    rows = list(csv.DictReader(runs.open()))
    base = sorted((float(r["cpu_s"]), float(r["rel_mse"]), float(r["rmse"]) ** 2)
                  for r in rows if r["method"] == "off/average/-")
    (t0, e0, m0), (t1, e1, m1) = base[0], base[-1]
    slope = math.log(e1 / e0) / math.log(t1 / t0)
    mslope = math.log(m1 / m0) / math.log(t1 / t0)
    for r in rows:
        m = re.search(r"\+stop=(\d+)", r["method"])
        target = int(m.group(1)) / 1000 if m else None
        texels = int(r["texels"])
        err = math.sqrt(float(r["rel_mse"]))
        ratio = f"{err / target:.2f}" if target else ""
        net = math.sqrt(max(float(r["rel_mse"]) - noise, 0.0)) if noise is not None else None
        net_cols = (f"{net:.4f} | {net / target:.2f}" if target else f"{net:.4f} |") \
            if net is not None else " | "
        t = max(float(r["cpu_s"]), 1e-3)
        at = e0 * (t / t0) ** slope / float(r["rel_mse"])
        mat = m0 * (t / t0) ** mslope / float(r["rmse"]) ** 2
        outside = "*" if not t0 <= t <= t1 else ""
        print(f"| {scene} | {r['spp']} | `{r['method']}` | {target or ''} | {err:.4f} | {ratio} "
              f"| {net_cols} | {int(r['gather_rays']) / texels:.0f} "
              f"| {int(r['shadow_rays']) / texels:.0f} | {float(r['cpu_s']):.1f} "
              f"| {100 * float(r['rel_bias']):+.2f} % | {at:.2f}{outside} | {mat:.2f}{outside} |")
