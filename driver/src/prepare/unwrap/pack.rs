//! Packs charts charted apart (one xatlas atlas per chunk, [`super::Charted`]) into one
//! atlas: a skyline ("tetris") packer over each chart's column profile, the strategy
//! xatlas's own packer names as the better one and leaves undone (`findChartLocation`, "start
//! stacking large charts as if they were tetris pieces"; Jylänki 2010, "A thousand ways to
//! pack the bin", §4 skyline, bottom-left rule, here with a per-column profile instead of a
//! rectangle).
//!
//! Per chart, as xatlas's `AtlasPacker::packCharts` does: scale to the density, scale down
//! to `max_chart` texels when longer, stretch each side to whole texels less 1e-4, shift
//! by half a texel. Then, largest perimeter first, place it (as given or with u and v
//! swapped, as xatlas does) where its top is lowest, then leftmost.
//!
//! **Gutter.** Each chart's footprint is the set of texels its triangles touch (conservative,
//! with a 1e-3-texel margin); per column it is taken as solid from its lowest to its highest
//! texel. The skyline holds, per atlas column, the row above the highest footprint texel
//! placed plus `padding`; a chart goes where every footprint texel is more than `padding`
//! rows above the skyline of every column within `padding` columns. So the texels of two
//! charts are more than `padding` texels apart (Chebyshev): at least `padding` empty texels
//! lie between them, on every side.
//!
//! Deterministic: one thread, fixed order, ties broken by chart index.

use glam::Vec2;

/// Margin (texels) by which the footprint rasterisation widens each triangle.
const MARGIN: f32 = 1e-3;

/// One packed atlas: its size and, per triangle, its UVs in texels.
pub struct Layout {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Per input triangle: its UVs in atlas texels (zeros for a triangle in no chart).
    pub uv: Vec<[Vec2; 3]>,
}

/// A chart's footprint: per column, its lowest and highest texel row.
struct Profile {
    bottom: Vec<i32>,
    top: Vec<i32>,
    height: i32,
}

/// Packs the charts: `chart[t]` is triangle `t`'s chart (`charts` of them, `u32::MAX` for
/// none), `uv[t]` its UVs at one texel per unit (each chart's minimum corner at the origin).
/// Every coordinate must be finite. `max_chart` ≥ 1.
#[must_use]
pub fn pack(
    uv: &[[Vec2; 3]],
    chart: &[u32],
    charts: u32,
    texels_per_unit: f32,
    max_chart: u32,
    padding: u32,
) -> Layout {
    let n = charts as usize;
    // Triangles by chart (counting sort: ascending triangle order within a chart).
    let mut first = vec![0u32; n + 1];
    for &c in chart {
        if (c as usize) < n {
            first[c as usize + 1] += 1;
        }
    }
    for c in 0..n {
        first[c + 1] += first[c];
    }
    let mut members = vec![0u32; first[n] as usize];
    let mut next = first.clone();
    for (t, &c) in chart.iter().enumerate() {
        if (c as usize) < n {
            members[next[c as usize] as usize] = t as u32;
            next[c as usize] += 1;
        }
    }
    drop(next);
    let tris = |c: usize| &members[first[c] as usize..first[c + 1] as usize];

    // Scale each chart as xatlas does; `out` holds chart-local texel UVs, later placed.
    let mut out = vec![[Vec2::ZERO; 3]; uv.len()];
    let mut extent = vec![Vec2::ZERO; n];
    let limit = max_chart.max(1) as f32;
    for (c, extent) in extent.iter_mut().enumerate() {
        let mut lo = Vec2::INFINITY;
        let mut hi = Vec2::NEG_INFINITY;
        for &t in tris(c) {
            for v in uv[t as usize] {
                lo = lo.min(v * texels_per_unit);
                hi = hi.max(v * texels_per_unit);
            }
        }
        if !(lo.is_finite() && hi.is_finite()) {
            *extent = Vec2::NAN; // not placed (the caller keeps such charts out)
            continue;
        }
        let mut ext = hi - lo;
        let mut scale = Vec2::splat(texels_per_unit);
        if ext.max_element() > limit {
            let s = limit / (ext.max_element() + 1.0);
            scale *= s;
            ext *= s;
        }
        // Stretch to whole texels (xatlas: "use the entire texel area available").
        let whole = ext.ceil();
        let stretch = Vec2::select(
            ext.cmpgt(Vec2::ZERO),
            (whole - 1e-4) / ext.max(Vec2::splat(f32::MIN_POSITIVE)),
            Vec2::ONE,
        );
        let origin = lo / texels_per_unit;
        for &t in tris(c) {
            out[t as usize] = uv[t as usize].map(|v| (v - origin) * scale * stretch + 0.5);
        }
        *extent = Vec2::select(ext.cmpgt(Vec2::ZERO), whole, Vec2::ZERO);
    }

    // Largest perimeter first, as xatlas sorts.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        let pa = extent[a].x + extent[a].y;
        let pb = extent[b].x + extent[b].y;
        pb.total_cmp(&pa).then(a.cmp(&b))
    });

    // Skyline width: about square, and wide enough for every chart's shorter side.
    let pad = padding as i32;
    let mut area = 0.0f64;
    let mut narrowest_fit = 1i32;
    for e in extent.iter().filter(|e| e.is_finite()) {
        let (w, h) = (f64::from(e.x) + 2.0, f64::from(e.y) + 2.0);
        area += (w + f64::from(padding)) * (h + f64::from(padding));
        narrowest_fit = narrowest_fit.max(e.x.min(e.y) as i32 + 2);
    }
    // The skyline's width from the area is a first guess; a second pass at the width that
    // would have made the first atlas square, and the one of smaller longer side is kept.
    let charts = |c: usize| {
        let m = tris(c);
        (!m.is_empty() && extent[c].is_finite()).then_some(m)
    };
    let first_width = (area.sqrt().ceil() as i32).max(narrowest_fit).max(1);
    let mut best = place(&order, &charts, &out, first_width, pad);
    let square = (f64::from(best.width) * f64::from(best.height))
        .sqrt()
        .ceil() as i32;
    let second_width = square.max(narrowest_fit).max(1);
    if (second_width - first_width).abs() * 50 > first_width {
        let second = place(&order, &charts, &out, second_width, pad);
        if second.width.max(second.height) < best.width.max(best.height) {
            best = second;
        }
    }
    for &(c, x, y, swap) in &best.placed {
        let at = Vec2::new(x as f32, y as f32);
        for &t in tris(c as usize) {
            let q = &mut out[t as usize];
            *q = q.map(|v| if swap { Vec2::new(v.y, v.x) } else { v } + at);
        }
    }
    Layout {
        width: best.width.max(0) as u32,
        height: best.height.max(0) as u32,
        uv: out,
    }
}

/// Where the charts went: per chart placed (chart, x, y, u and v swapped), and the extent.
struct Placement {
    placed: Vec<(u32, i32, i32, bool)>,
    width: i32,
    height: i32,
}

/// Places the charts (`charts(c)`: chart `c`'s triangles, `None` to leave it out) in
/// `order` on a skyline `width` texels wide.
fn place<'a>(
    order: &[usize],
    charts: &dyn Fn(usize) -> Option<&'a [u32]>,
    out: &[[Vec2; 3]],
    width: i32,
    pad: i32,
) -> Placement {
    let mut sky = vec![0i32; width as usize];
    let mut result = Placement {
        placed: Vec::with_capacity(order.len()),
        width: 0,
        height: 0,
    };
    let mut scratch = Vec::new();
    for &c in order {
        let Some(members) = charts(c) else {
            continue;
        };
        let mut best: Option<(i32, i32, i32, bool, Profile)> = None;
        for swap in [false, true] {
            let p = profile(members, out, swap);
            let cw = p.bottom.len() as i32;
            if cw > width {
                continue;
            }
            // Lowest footprint row within `pad` columns of each column k - pad.
            scratch.clear();
            scratch.extend((0..cw + 2 * pad).map(|k| {
                let (a, b) = ((k - 2 * pad).max(0), k.min(cw - 1));
                (a..=b)
                    .map(|j| p.bottom[j as usize])
                    .min()
                    .unwrap_or(i32::MAX)
            }));
            let bound = best.as_ref().map_or(i32::MAX, |b| b.2);
            if let Some((x, y)) = lowest(&sky, &scratch, cw, pad, p.height, bound) {
                let top = y + p.height;
                if best.as_ref().is_none_or(|b| top < b.2) {
                    best = Some((x, y, top, swap, p));
                }
            }
        }
        let Some((x, y, top, swap, p)) = best else {
            continue;
        };
        for (j, &t) in p.top.iter().enumerate() {
            let s = &mut sky[x as usize + j];
            *s = (*s).max(y + t + 1 + pad);
        }
        result.width = result.width.max(x + p.bottom.len() as i32);
        result.height = result.height.max(top);
        result.placed.push((c as u32, x, y, swap));
    }
    result
}

/// The lowest `y` (then the least `x`) at which a chart of footprint width `cw`, whose
/// lowest row within `pad` columns of its column `k - pad` is `low[k]`, clears the skyline
/// (`y + low[k] ≥ sky[x + k - pad]` for every atlas column in range), and whose top
/// `y + height` is below `bound`; `None` when no place beats `bound`.
fn lowest(
    sky: &[i32],
    low: &[i32],
    cw: i32,
    pad: i32,
    height: i32,
    bound: i32,
) -> Option<(i32, i32)> {
    let w = sky.len() as i32;
    let mut best: Option<(i32, i32)> = None;
    let mut limit = bound.saturating_sub(height); // y must stay below this
    for x in 0..=(w - cw) {
        let mut y = 0i32;
        let k0 = (pad - x).max(0);
        let k1 = (w - x + pad).min(cw + 2 * pad);
        for k in k0..k1 {
            let need = sky[(x + k - pad) as usize] - low[k as usize];
            if need > y {
                y = need;
                if y >= limit {
                    break;
                }
            }
        }
        if y < limit {
            limit = y;
            best = Some((x, y));
            if y == 0 {
                break;
            }
        }
    }
    best
}

/// The footprint of a chart's triangles (chart-local texel UVs, u and v swapped when
/// `swap`): per column from 0 to the rightmost touched, the lowest and highest touched row.
fn profile(members: &[u32], uv: &[[Vec2; 3]], swap: bool) -> Profile {
    let get = |v: Vec2| if swap { Vec2::new(v.y, v.x) } else { v };
    let mut cols = 0i32;
    for &t in members {
        for v in uv[t as usize] {
            cols = cols.max((get(v).x + MARGIN).floor() as i32 + 1);
        }
    }
    let cols = cols.max(1) as usize;
    let mut bottom = vec![i32::MAX; cols];
    let mut top = vec![i32::MIN; cols];
    for &t in members {
        let p = uv[t as usize].map(get);
        let lo = p.iter().fold(f32::INFINITY, |a, v| a.min(v.x));
        let hi = p.iter().fold(f32::NEG_INFINITY, |a, v| a.max(v.x));
        let c0 = ((lo - MARGIN).floor() as i32).max(0);
        let c1 = ((hi + MARGIN).floor() as i32).min(cols as i32 - 1);
        for c in c0..=c1 {
            let (x0, x1) = (c as f32 - MARGIN, c as f32 + 1.0 + MARGIN);
            let (y0, y1) = strip_range(p, x0, x1);
            if y0 > y1 {
                continue;
            }
            let r0 = ((y0 - MARGIN).floor() as i32).max(0);
            let r1 = ((y1 + MARGIN).floor() as i32).max(0);
            bottom[c as usize] = bottom[c as usize].min(r0);
            top[c as usize] = top[c as usize].max(r1);
        }
    }
    // A column no triangle touches (only possible between triangles of a chart that is not
    // connected in UV): solid from the neighbours' rows, so the profile has no gap.
    let mut last = (0, 0);
    for c in 0..cols {
        if bottom[c] == i32::MAX {
            bottom[c] = last.0;
            top[c] = last.1;
        } else {
            last = (bottom[c], top[c]);
        }
    }
    let height = top.iter().copied().max().unwrap_or(0) + 1;
    Profile {
        bottom,
        top,
        height,
    }
}

/// The range of y the triangle `p` covers within the vertical strip `x0 ≤ x ≤ x1`
/// (empty: `lo > hi`).
fn strip_range(p: [Vec2; 3], x0: f32, x1: f32) -> (f32, f32) {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut add = |y: f32| {
        lo = lo.min(y);
        hi = hi.max(y);
    };
    for i in 0..3 {
        let (a, b) = (p[i], p[(i + 1) % 3]);
        if a.x >= x0 && a.x <= x1 {
            add(a.y);
        }
        if a.x != b.x {
            for x in [x0, x1] {
                let s = (x - a.x) / (b.x - a.x);
                if (0.0..=1.0).contains(&s) {
                    add(a.y + s * (b.y - a.y));
                }
            }
        }
    }
    (lo, hi)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Texels a triangle touches, by brute force: the texel square (grown by `MARGIN`)
    /// and the triangle overlap (separating axes).
    pub(crate) fn touches(p: [Vec2; 3], x: i32, y: i32) -> bool {
        let lo = Vec2::new(x as f32, y as f32) - MARGIN * 0.5;
        let hi = lo + 1.0 + MARGIN;
        let corners = [lo, Vec2::new(hi.x, lo.y), hi, Vec2::new(lo.x, hi.y)];
        let tlo = p[0].min(p[1]).min(p[2]);
        let thi = p[0].max(p[1]).max(p[2]);
        if tlo.x > hi.x || tlo.y > hi.y || thi.x < lo.x || thi.y < lo.y {
            return false;
        }
        for i in 0..3 {
            let e = p[(i + 1) % 3] - p[i];
            let n = Vec2::new(-e.y, e.x);
            let side = n.dot(p[(i + 2) % 3] - p[i]);
            if side == 0.0 {
                continue;
            }
            if corners.iter().all(|&c| n.dot(c - p[i]) * side < 0.0) {
                return false;
            }
        }
        true
    }

    /// The texels each chart's triangles touch ([`touches`]): no texel is touched by two
    /// charts, and every texel of one chart is more than `padding` texels (Chebyshev) from
    /// another chart's. `triangles` are (chart, atlas UVs); `label` prefixes the messages.
    pub(crate) fn assert_charts_apart(
        triangles: impl IntoIterator<Item = (u32, [Vec2; 3])>,
        padding: u32,
        label: &str,
    ) {
        let mut owner = std::collections::HashMap::<(i32, i32), u32>::new();
        for (c, q) in triangles {
            let lo = q[0].min(q[1]).min(q[2]).floor().as_ivec2() - 1;
            let hi = q[0].max(q[1]).max(q[2]).floor().as_ivec2() + 1;
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    if touches(q, x, y) {
                        let o = *owner.entry((x, y)).or_insert(c);
                        assert_eq!(o, c, "{label}: charts {o} and {c} share texel ({x},{y})");
                    }
                }
            }
        }
        let r = padding as i32;
        for (&(x, y), &c) in &owner {
            for dy in -r..=r {
                for dx in -r..=r {
                    if let Some(&d) = owner.get(&(x + dx, y + dy)) {
                        assert_eq!(d, c, "{label}: charts {c} and {d} at ({x},{y})+({dx},{dy})");
                    }
                }
            }
        }
    }

    /// Charts of random triangles: small fans around random centres, at one texel per unit.
    fn random_charts(seed: u64, count: usize) -> (Vec<[Vec2; 3]>, Vec<u32>) {
        let mut s = seed;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32) / (1u64 << 24) as f32
        };
        let (mut uv, mut chart) = (Vec::new(), Vec::new());
        for c in 0..count {
            let size = 0.2 + 12.0 * rnd() * rnd();
            let k = 1 + (rnd() * 4.0) as usize;
            let centre = Vec2::splat(size);
            let mut tris = Vec::new();
            for _ in 0..k {
                let a = centre + Vec2::new(rnd() - 0.5, rnd() - 0.5) * size;
                let b = centre + Vec2::new(rnd() - 0.5, rnd() - 0.5) * size;
                tris.push([centre, a, b]);
            }
            let lo = tris.iter().flatten().fold(Vec2::INFINITY, |m, &v| m.min(v));
            for t in tris {
                uv.push(t.map(|v| v - lo));
                chart.push(c as u32);
            }
            // A triangle in no chart between charts.
            if c % 5 == 0 {
                uv.push([Vec2::ZERO; 3]);
                chart.push(u32::MAX);
            }
        }
        (uv, chart)
    }

    #[test]
    fn charts_keep_more_than_the_padding_between_them_and_stay_inside() {
        for (seed, density, padding) in [(1, 1.0, 2), (2, 3.0, 2), (3, 0.5, 1), (4, 2.0, 0)] {
            let (uv, chart) = random_charts(seed, 120);
            let charts = 120;
            let l = pack(&uv, &chart, charts, density, 4096, padding);
            for (t, (q, &c)) in l.uv.iter().zip(&chart).enumerate() {
                if c == u32::MAX {
                    continue;
                }
                for v in q {
                    assert!(v.x >= 0.0 && v.y >= 0.0, "{seed}: triangle {t} at {v}");
                    assert!(
                        v.x <= l.width as f32 && v.y <= l.height as f32,
                        "{seed}: {v}"
                    );
                }
            }
            // Every texel of one chart is more than `padding` texels from another chart's.
            let placed = l.uv.iter().zip(&chart).filter(|(_, c)| **c != u32::MAX);
            assert_charts_apart(
                placed.map(|(q, &c)| (c, *q)),
                padding,
                &format!("seed {seed}"),
            );
        }
    }

    #[test]
    fn a_chart_keeps_its_shape_at_the_density() {
        // A right triangle of legs 10 (one unit per texel): at 2 texels per unit, legs of
        // 20 texels, stretched to whole texels less 1e-4 and shifted by half a texel.
        let uv = vec![[Vec2::ZERO, Vec2::new(10.0, 0.0), Vec2::new(0.0, 10.0)]];
        let l = pack(&uv, &[0], 1, 2.0, 4096, 2);
        let q = l.uv[0];
        let legs = [(q[1] - q[0]).length(), (q[2] - q[0]).length()];
        assert!(legs.iter().all(|&e| (e - 20.0).abs() < 1e-3), "{legs:?}");
        assert!(q.iter().all(|v| v.min_element() >= 0.5 - 1e-4), "{q:?}");
        assert_eq!((l.width, l.height), (21, 21));
        // Longer than the limit: scaled down below it.
        let l = pack(&uv, &[0], 1, 2.0, 8, 2);
        assert!(l.width <= 9 && l.height <= 9, "{}x{}", l.width, l.height);
    }

    #[test]
    fn packing_is_deterministic_and_uses_the_area() {
        let (uv, chart) = random_charts(7, 300);
        let a = pack(&uv, &chart, 300, 1.5, 4096, 2);
        let b = pack(&uv, &chart, 300, 1.5, 4096, 2);
        assert_eq!((a.width, a.height), (b.width, b.height));
        assert_eq!(a.uv, b.uv);
        // Roughly square, and not mostly empty: the charts' boxes fill a fair share.
        let boxes: f64 = (0..300u32)
            .map(|c| {
                let (lo, hi) =
                    a.uv.iter()
                        .zip(&chart)
                        .filter(|(_, k)| **k == c)
                        .flat_map(|(q, _)| *q)
                        .fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(l, h), v| {
                            (l.min(v), h.max(v))
                        });
                f64::from((hi - lo).x * (hi - lo).y)
            })
            .sum();
        let fill = boxes / f64::from(a.width * a.height);
        assert!(fill > 0.3, "fill {fill}, {}x{}", a.width, a.height);
        let aspect = f64::from(a.width.max(a.height)) / f64::from(a.width.min(a.height));
        assert!(aspect < 2.0, "{}x{}", a.width, a.height);
    }
}
