#!/usr/bin/env python3
"""Equal-time ratios of `local` against `power` emitter selection from `guidebake bench` runs
(docs/bake.md, "Next-event estimation on the bidir room"): for every pair of methods that
differ only by `+select=power`, at 256 spp, the means over seeds of the time, the squared
error (RMSE²) and the relative MSE; `power` over `local`, so > 1 means `local` wins.

    docs/bench/nee/ratios.py RUN_DIR...     (directories holding runs.csv)

The time is the process's CPU time (`cpu_s`, one thread) by default: on a machine shared with
other work, wall time (`TCOL=gather_s`) measures the neighbours as much as the bake."""
import csv
import os
import statistics as st
import sys

PAIRS = [
    ("series guided (default)", "coherent/cluster/rho", "coherent/cluster/rho+select=power"),
    ("path guided", "coherent/cluster/rho+transport=path",
     "coherent/cluster/rho+transport=path+select=power"),
    ("path unguided", "off/average/-+transport=path", "off/average/-+transport=path+select=power"),
    ("path unguided TREE", "off/average/-+transport=path+select=tree",
     "off/average/-+transport=path+select=power"),
]
TCOL = os.environ.get("TCOL", "cpu_s")

for d in sys.argv[1:]:
    rows = list(csv.DictReader(open(os.path.join(d, "runs.csv"))))

    def agg(method):
        r = [x for x in rows if x["method"] == method and x["spp"] == "256"]
        if not r:
            return None
        return (st.mean(float(x[TCOL]) for x in r),
                st.mean(float(x["rmse"]) ** 2 for x in r),
                st.mean(float(x["rel_mse"]) for x in r))

    print(os.path.basename(d.rstrip("/")))
    for label, local, power in PAIRS:
        a, b = agg(local), agg(power)
        if not a or not b:
            continue
        print(f"   {label}: time x{a[0] / b[0]:.2f}, MSE/sample {b[1] / a[1]:.2f}x less, "
              f"MSE equal time {b[1] * b[0] / (a[1] * a[0]):.2f}x, "
              f"relMSE equal time {b[2] * b[0] / (a[2] * a[0]):.2f}x")
