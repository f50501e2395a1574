#!/usr/bin/env python3
"""Where a guided bake loses to the unguided one by MSE on a level: per-texel squared error
(and relative squared error) of each bake against a reference, broken down by the reference's
brightness deciles, partial / whole texels, the share of direct light in the reference, the
properties of the guide's cluster a texel belongs to (recomputed here exactly as
kernels/src/cluster.rs splits a tile's valid texels), the sample count the bake gave the texel
(aux channel `samples`), and the fireflies (top 0.1 % of the texels by squared error).

    where_guiding_loses.py TEXELS REF.exr DIRECT.exr BASE.exr NAME=BAKE.exr [NAME=BAKE.exr ...]
        [--ref2 REF2.exr] [--sky SKY.exr] [--sky-radiance R,G,B] [--json OUT.json]

REF.exr: an unbiased reference (path transport, >= 16x the samples); DIRECT.exr: a bake of the
direct light alone (`--bounces 0`, many samples); BASE.exr: the unguided bake; each NAME=BAKE.exr
a bake compared with it at equal samples (BAKE.exr may be a comma-separated list of seeds:
their squared errors are averaged; BASE.exr too); SKY.exr: the black level under the sky alone (its
irradiance over pi x the sky's radiance is the texel's sky view). Every bake's error is measured against REF (or the
mean of REF and REF2). The reference's own noise adds the same expected amount to every bake's
MSE, so the *differences* of MSE per group (the "loss" columns) are net of it; ratios are
pulled towards 1 by it. MSE and relative MSE are over the valid texels and the three
channels; relative MSE uses the bench's denominator r^2 + 1e-2 * mean(r)^2 (per channel).
A group's "contribution" is its texels' summed error over all valid texels: the groups'
contributions add up to the whole MSE. Needs numpy and OpenEXR (pip install numpy OpenEXR).
"""
import json
import struct
import sys

import numpy as np
import OpenEXR

VALID, PARTIAL = 1, 2
SKY = np.array([0.45, 0.55, 0.7])  # the recipe's --sky (complex); --sky-radiance for another
MAX_TEXELS, COS_MAX = 64, np.float32(np.cos(np.radians(60.0)))


def read_texels(path):
    b = open(path, "rb").read()
    count, tiles = struct.unpack_from("<QQ", b, 24)
    texels_off, tiles_off = struct.unpack_from("<QQ", b, 72)
    rec = np.dtype([("pos", "<f4", 3), ("n", "<f4", 3), ("du", "<f4", 3), ("dv", "<f4", 3),
                    ("page", "<u4"), ("px", "<u2", 2), ("tri", "<u4"), ("flags", "<u4")])
    trec = np.dtype([("page", "<u4"), ("x", "<u4"), ("y", "<u4"), ("w", "<u4"), ("h", "<u4"),
                     ("count", "<u4"), ("first", "<u8")])
    t = np.frombuffer(b, dtype=rec, count=count, offset=texels_off)
    tl = np.frombuffer(b, dtype=trec, count=tiles, offset=tiles_off)
    return t, tl


def channels(path):
    ch = OpenEXR.File(path).channels()
    out = {k: np.asarray(v.pixels, dtype=np.float64) for k, v in ch.items()}
    return out


def unit(v):
    return v / np.sqrt((v * v).sum(-1, keepdims=True))


def midpoint_partition(idx, key):
    v = key[idx]
    lo, hi = v.min(0), v.max(0)
    ext = hi - lo
    axis = 0 if (ext[0] >= ext[1] and ext[0] >= ext[2]) else (1 if ext[1] >= ext[2] else 2)
    if ext[axis] <= 0:
        return None
    mid = np.float32(lo[axis] + np.float32(0.5) * ext[axis])
    left = v[:, axis] < mid
    if left.all():
        return None
    return idx[left], idx[~left]


def cone_within(nu, idx):
    s = nu[idx].sum(0)
    ln = np.sqrt((s * s).sum())
    if ln <= 1e-6 * len(idx):
        return False
    return bool(((nu[idx] @ (s / ln)) >= COS_MAX).all())


def clusters_of_tile(pos, nu):
    """kernels/src/cluster.rs build_clusters with the default parameters: lists of indices."""
    out, stack = [], [np.arange(len(pos))]
    while stack:
        idx = stack.pop()
        small = len(idx) <= MAX_TEXELS
        if len(idx) == 1 or (small and cone_within(nu, idx)):
            out.append(idx)
            continue
        order = ((nu, pos) if small else (pos, nu))
        parts = midpoint_partition(idx, order[0]) or midpoint_partition(idx, order[1])
        if parts is None:
            h = len(idx) // 2
            parts = (idx[:h], idx[h:])
        stack.extend(parts)
    return out


def islands(px):
    """4-connected components of a set of atlas pixels (a proxy for the charts a cluster spans)."""
    s = {(int(x), int(y)): i for i, (x, y) in enumerate(px)}
    seen, n = set(), 0
    for p in s:
        if p in seen:
            continue
        n += 1
        todo = [p]
        seen.add(p)
        while todo:
            x, y = todo.pop()
            for q in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
                if q in s and q not in seen:
                    seen.add(q)
                    todo.append(q)
    return n


def cluster_table(t, tiles, lum_ref):
    """Per valid texel (in file order of the valid texels): its cluster's id, size, islands,
    distinct triangles, world diagonal over the texel footprint, and the max/min ratio of the
    reference luminance within it; plus the tile's islands and triangles."""
    valid = (t["flags"] & VALID) != 0
    vindex = -np.ones(len(t), np.int64)
    vindex[valid] = np.arange(valid.sum())
    nv = int(valid.sum())
    cols = {k: np.zeros(nv) for k in ("cid", "size", "islands", "tris", "diag", "spread",
                                      "tile_islands", "tile_tris", "tile_texels")}
    foot = np.sqrt(np.linalg.norm(t["du"], axis=1) * np.linalg.norm(t["dv"], axis=1))
    cid = 0
    for tile in tiles:
        a = int(tile["first"])
        rows = np.arange(a, a + int(tile["count"]))
        rows = rows[valid[rows]]
        if len(rows) == 0:
            continue
        pos = t["pos"][rows].astype(np.float32)
        nu = unit(t["n"][rows].astype(np.float32))
        vi = vindex[rows]
        ti, tt = islands(t["px"][rows]), len(np.unique(t["tri"][rows]))
        cols["tile_islands"][vi], cols["tile_tris"][vi], cols["tile_texels"][vi] = ti, tt, len(rows)
        for c in clusters_of_tile(pos, nu):
            r = rows[c]
            v = vi[c]
            d = np.linalg.norm(pos[c].max(0) - pos[c].min(0)) / max(np.median(foot[r]), 1e-9)
            l = lum_ref[v]
            cols["cid"][v] = cid
            cols["size"][v] = len(c)
            cols["islands"][v] = islands(t["px"][r])
            cols["tris"][v] = len(np.unique(t["tri"][r]))
            cols["diag"][v] = d
            cols["spread"][v] = (l.max() + 1e-6) / (l.min() + 1e-6)
            cid += 1
    return cols


def fmt(x):
    return f"{x:.3e}"


def main():
    args = [a for a in sys.argv[1:]]
    ref2 = jpath = None
    if "--ref2" in args:
        i = args.index("--ref2"); ref2 = args[i + 1]; del args[i:i + 2]
    sky_path = None
    if "--sky" in args:
        i = args.index("--sky"); sky_path = args[i + 1]; del args[i:i + 2]
    global SKY
    if "--sky-radiance" in args:
        i = args.index("--sky-radiance")
        SKY = np.array([float(v) for v in args[i + 1].split(",")]); del args[i:i + 2]
    if "--json" in args:
        i = args.index("--json"); jpath = args[i + 1]; del args[i:i + 2]
    texels_path, ref_path, direct_path, base_path = args[:4]
    named = [("unguided", base_path)] + [tuple(a.split("=", 1)) for a in args[4:]]

    t, tiles = read_texels(texels_path)
    valid = (t["flags"] & VALID) != 0
    x, y = t["px"][valid, 0].astype(int), t["px"][valid, 1].astype(int)
    partial = (t["flags"][valid] & PARTIAL) != 0
    ref = channels(ref_path)["RGB"][y, x]
    noise = np.zeros_like(ref)
    if ref2:
        other = channels(ref2)["RGB"][y, x]
        noise = (ref - other) ** 2 / 4  # per texel and channel: the mean's expected error
        ref = (ref + other) / 2
    direct = channels(direct_path)["RGB"][y, x]
    # SKY.exr: the black level lit by the sky alone, no sun: E / (pi L_sky) is the sky view
    sky = None
    if sky_path:
        e = channels(sky_path)["RGB"][y, x]
        sky = e.sum(-1) / (np.pi * SKY.sum())
    den = ref ** 2 + 1e-2 * ref.mean(0) ** 2
    lum = ref.mean(-1)
    n = len(lum)
    bakes, aux = {}, {}
    for name, paths in named:
        se = rse = 0
        for p in paths.split(","):  # several seeds: their squared errors averaged
            ch = channels(p)
            v = ch["RGB"][y, x]
            se = se + ((v - ref) ** 2).mean(-1)
            rse = rse + ((v - ref) ** 2 / den).mean(-1)
        k = len(paths.split(","))
        bakes[name] = (se / k, rse / k)
        aux[name] = {c: ch[c][y, x] for c in ch if c != "RGB" and ch[c].ndim == 2}
    print(f"valid texels {n}, partial {partial.mean():.1%}; aux channels "
          f"{sorted(aux['unguided'])}")
    cols = cluster_table(t, tiles, lum)
    dfrac = direct.mean(-1) / np.maximum(lum, 1e-9)
    names = [k for k, _ in named]
    result = {"texels": n, "bakes": {}}

    print(f"\nreference mean's own noise: MSE {fmt(noise.mean())}, relative MSE "
          f"{fmt((noise / den).mean())} (in every bake's error below; differences are net of it)")
    print("\n## Totals\n")
    print("| bake | MSE | RMSE | relative MSE | top 0.1 % texels' share of SE | of rel. SE |")
    print("|---|---:|---:|---:|---:|---:|")
    k = max(1, n // 1000)
    for nm in names:
        se, rse = bakes[nm]
        top = np.sort(se)[-k:].sum() / se.sum()
        rtop = np.sort(rse)[-k:].sum() / rse.sum()
        result["bakes"][nm] = dict(mse=se.mean(), rel=rse.mean(), top_se=top, top_rse=rtop)
        print(f"| {nm} | {fmt(se.mean())} | {np.sqrt(se.mean()):.4f} | {fmt(rse.mean())} | "
              f"{top:.1%} | {rtop:.1%} |")

    def table(title, groups):
        print(f"\n## {title}\n")
        hdr = "| group | texels | unguided MSE contrib. |"
        for nm in names[1:]:
            hdr += f" {nm}: MSE contrib. | its loss (share) | rel. MSE gain (share) |"
        print(hdr)
        print("|---|---:|---:|" + "---:|---:|---:|" * (len(names) - 1))
        rows = []
        base_se, base_rse = bakes["unguided"]
        for label, m in groups:
            line = f"| {label} | {m.mean():.1%} | {fmt(base_se[m].sum() / n)} |"
            row = {"group": label, "texels": float(m.mean())}
            for nm in names[1:]:
                se, rse = bakes[nm]
                loss = (se[m].sum() - base_se[m].sum()) / n
                tot = (se.sum() - base_se.sum()) / n
                gain = (base_rse[m].sum() - rse[m].sum()) / n
                gtot = (base_rse.sum() - rse.sum()) / n
                line += (f" {fmt(se[m].sum() / n)} | {fmt(loss)} ({loss / tot:+.0%}) |"
                         f" {fmt(gain)} ({gain / gtot:+.0%}) |")
                row[nm] = dict(mse=se[m].sum() / n, loss=loss, rel_gain=gain,
                               ratio=float(se[m].sum() / max(base_se[m].sum(), 1e-30)))
            rows.append(row)
            print(line)
        result[title] = rows

    # deciles by rank (a fifth of the texels share one value, pi x the sky: ties are split)
    dec = np.empty(n, int)
    dec[np.argsort(lum, kind="stable")] = np.arange(n) * 10 // n
    q = [lum[dec == d].min() for d in range(10)] + [lum.max()]
    table("Reference brightness deciles",
          [(f"decile {d + 1} ({q[d]:.3g}–{q[d + 1]:.3g})", dec == d) for d in range(10)])
    if sky is not None:
        table("Sky view (the share of the cosine-weighted hemisphere that sees the sky)",
              [("0 (indoors)", sky < 0.01), ("0.01–0.2", (sky >= 0.01) & (sky < 0.2)),
               ("0.2–0.6", (sky >= 0.2) & (sky < 0.6)), ("0.6–0.95", (sky >= 0.6) & (sky < 0.95)),
               ("≥ 0.95 (open sky)", sky >= 0.95)])
    table("Partial or whole texels", [("partial", partial), ("whole", ~partial)])
    table("Share of the reference that is direct light (sun + unoccluded sky)",
          [("< 10 % (lit indirectly)", dfrac < 0.1), ("10–50 %", (dfrac >= 0.1) & (dfrac < 0.5)),
           ("50–90 %", (dfrac >= 0.5) & (dfrac < 0.9)), ("≥ 90 % (sees sun or sky)", dfrac >= 0.9)])
    bright = lum > q[9]
    table("Brightest tenth by direct share",
          [("brightest tenth, direct < 50 %", bright & (dfrac < 0.5)),
           ("brightest tenth, direct ≥ 50 %", bright & (dfrac >= 0.5)),
           ("other 90 %", ~bright)])
    c = cols
    table("Cluster size (texels)", [("1–8", c["size"] <= 8), ("9–32", (c["size"] > 8) & (c["size"] <= 32)),
                                    ("33–64", c["size"] > 32)])
    table("Atlas islands (chart pieces) in the cluster",
          [("1", c["islands"] == 1), ("2", c["islands"] == 2), ("3–4", (c["islands"] >= 3) & (c["islands"] <= 4)),
           ("5+", c["islands"] >= 5)])
    table("Triangles in the cluster",
          [("1–2", c["tris"] <= 2), ("3–8", (c["tris"] > 2) & (c["tris"] <= 8)), ("9+", c["tris"] > 8)])
    table("Cluster's world diagonal (in texel footprints)",
          [("< 8", c["diag"] < 8), ("8–16", (c["diag"] >= 8) & (c["diag"] < 16)),
           ("16–64", (c["diag"] >= 16) & (c["diag"] < 64)), ("≥ 64", c["diag"] >= 64)])
    table("Reference luminance max/min within the cluster",
          [("< 2", c["spread"] < 2), ("2–10", (c["spread"] >= 2) & (c["spread"] < 10)),
           ("10–100", (c["spread"] >= 10) & (c["spread"] < 100)), ("≥ 100", c["spread"] >= 100)])
    table("Atlas islands in the 32×32 tile",
          [("1–4", c["tile_islands"] <= 4), ("5–16", (c["tile_islands"] > 4) & (c["tile_islands"] <= 16)),
           ("17+", c["tile_islands"] > 16)])
    for nm in names[1:]:
        s = aux[nm].get("samples")
        s0 = aux["unguided"].get("samples")
        if s is None or s0 is None:
            continue
        f = s / np.maximum(s0, 1)
        table(f"Samples given by {nm} over the unguided bake's",
              [("< 0.7×", f < 0.7), ("0.7–1.4×", (f >= 0.7) & (f < 1.4)), ("≥ 1.4×", f >= 1.4)])
        # where do samples go, by brightness
        print(f"\n{nm}: mean samples / unguided samples per reference decile: " +
              ", ".join(f"{(s[dec == d].sum() / s0[dec == d].sum()):.2f}" for d in range(10)))
    if jpath:
        json.dump(result, open(jpath, "w"), indent=1, default=float)


if __name__ == "__main__":
    main()
