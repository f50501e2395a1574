#!/usr/bin/env python3
"""Which texels guiding gains least at, and why: the default (`coherent`) and the unguided bake
(`off`) of where.sh (OUT/TRANSPORT-GUIDING-SEED.exr, seeds 1 and 2) against the mean of the
reference and its twin that run.sh's bench named in SUMMARY, relative MSE net of that mean's
noise (per texel: (reference − twin)² / 4), split by texel kind; and how much of each bake's
error is its variance (per texel: (seed 1 − seed 2)² / 2) and how much is left, a bias that
more samples do not take out. With --bias, each of the bakes NAME-1.exr and NAME-2.exr in
OUT alone: its error, variance and bias by texel kind (the variants of docs/series.md, "Guiding at equal time on a level (zdm2)", were throwaway builds baked so). Needs numpy and OpenEXR.
    where.py SUMMARY OUT TRANSPORT
    where.py --bias SUMMARY OUT NAME..."""
import os
import sys

import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "surfaces"))
sys.path.insert(0, os.path.join(here, "..", "borders"))
sys.path.insert(0, os.path.join(here, "..", "iterations"))
from borders import beside  # noqa: E402
from compare import reference_mean_at  # noqa: E402
from error_maps import rgb, texels  # noqa: E402

VALID, PARTIAL, INSIDE = 1, 2, 4


def kinds(t, x, y, shape, luminance):
    """Named masks over the valid texels (x, y) of texel file `t`, whose pages are `shape`."""
    baked, inside = np.zeros(shape, bool), np.zeros(shape, bool)
    baked[y, x] = True
    flags, px = t["flags"], t["px"]
    ins = flags & INSIDE != 0
    inside[px[ins, 1].astype(int), px[ins, 0].astype(int)] = True
    partial = (flags & PARTIAL != 0)[flags & VALID != 0]
    border = beside(~baked)[y, x]
    q = np.quantile(luminance, [0.1, 0.5, 0.9])
    return {
        "all": np.ones(len(x), bool),
        "partial (no triangle covers the centre)": partial,
        "centre covered": ~partial,
        "beside an unbaked texel": border,
        "beside a texel inside geometry": beside(inside)[y, x],
        "not beside an unbaked texel": ~border,
        "darkest tenth": luminance <= q[0],
        "10–50 %": (luminance > q[0]) & (luminance <= q[1]),
        "50–90 %": (luminance > q[1]) & (luminance <= q[2]),
        "brightest tenth": luminance > q[2],
    }


def setup(summary, out):
    """The texel file, the valid texels, the page shape, the reference mean at them, the
    denominator of the relative error, and the mean's noise per texel."""
    texel_path = os.path.join(out, "z.texels")
    a, b, x, y, shape, _ = reference_mean_at(summary, texel_path)
    t = texels(texel_path)
    r = (a + b) / 2
    den = r ** 2 + 1e-2 * r.mean() ** 2
    return t, x, y, shape, r, den, ((a - b) ** 2 / 4 / den).mean(-1)


def error_and_variance(out, name, x, y, r, den, noise):
    """Per texel, over NAME-1.exr and NAME-2.exr: the error net of the reference's noise,
    and the variance between the two."""
    p, q = (rgb(os.path.join(out, f"{name}-{k}.exr"))[y, x] for k in (1, 2))
    e = (((p - r) ** 2 + (q - r) ** 2) / 2 / den).mean(-1) - noise
    return e, ((p - q) ** 2 / 2 / den).mean(-1)


def bias_table(summary, out, names):
    t, x, y, shape, r, den, noise = setup(summary, out)
    ks = kinds(t, x, y, shape, r.mean(-1))
    print("| bake | texels | relative MSE (net) | variance | bias |")
    print("|---|---|---:|---:|---:|")
    for name in names:
        e, v = error_and_variance(out, name, x, y, r, den, noise)
        for k in ["all", "partial (no triangle covers the centre)", "centre covered"]:
            m = ks[k]
            print(f"| {name} | {k} | {e[m].mean():.3e} | {v[m].mean():.3e} | {e[m].mean() - v[m].mean():.2e} |")


def main():
    if sys.argv[1] == "--bias":
        bias_table(sys.argv[2], sys.argv[3], sys.argv[4:])
        return
    summary, out, transport = sys.argv[1:4]
    t, x, y, shape, r, den, noise = setup(summary, out)
    (off, off_var), (on, on_var) = (error_and_variance(out, f"{transport}-{g}", x, y, r, den, noise)
                                    for g in ("off", "coherent"))
    print(f"{len(x)} valid texels; relative MSE net of the reference's noise, 2 seeds, 256 spp; "
          "bias: the error less the variance between the seeds")
    print("| texels | share of the texels | unguided | its bias | default | its bias | unguided ÷ default "
          "| share of the default's error | of the unguided bake's |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, m in kinds(t, x, y, shape, r.mean(-1)).items():
        print(f"| {name} | {m.mean():.0%} | {off[m].mean():.3e} | {off[m].mean() - off_var[m].mean():.2e} "
              f"| {on[m].mean():.3e} | {on[m].mean() - on_var[m].mean():.2e} | {off[m].mean() / on[m].mean():.2f} "
              f"| {on[m].sum() / on.sum():.0%} | {off[m].sum() / off.sum():.0%} |")


if __name__ == "__main__":
    main()
