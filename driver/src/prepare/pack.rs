//! The one packer of `prepare` (docs/texels.md, "Lightmap UVs when a mesh has none"): a
//! skyline ("tetris") packer over each piece's column profile, the strategy xatlas's own
//! packer names as the better one and leaves undone (`findChartLocation`, "start stacking
//! large charts as if they were tetris pieces"; Jylänki 2010, "A thousand ways to pack the
//! bin", §4 skyline, bottom-left rule, here with a per-column profile instead of a
//! rectangle). The paper (Silvennoinen & Sloan 2019, §2.1) starts from lightmap texels, so
//! from a layout; this is where it comes from.
//!
//! It packs two kinds of piece:
//! - **Charts** ([`pack_charts`]), charted apart (one xatlas atlas per chunk,
//!   [`super::unwrap::Charted`]), into one atlas of free size.
//! - **Rectangles** ([`pack_rects`]): a mesh's own UV square in the per-mesh layout, a
//!   whole unwrapped atlas, onto pages of a fixed size.
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

/// A piece's footprint: per column, its lowest and highest texel row.
struct Profile {
    bottom: Vec<i32>,
    top: Vec<i32>,
    height: i32,
    /// Every column from row 0 to `height - 1`: a rectangle.
    flat: bool,
}

impl Profile {
    /// A `w`×`h` rectangle (each at least 1).
    fn rect(w: u32, h: u32) -> Self {
        let (w, h) = (w.max(1) as usize, h.max(1) as i32);
        Self {
            bottom: vec![0; w],
            top: vec![h - 1; w],
            height: h,
            flat: true,
        }
    }
}

/// Packs the charts: `chart[t]` is triangle `t`'s chart (`charts` of them, `u32::MAX` for
/// none), `uv[t]` its UVs at one texel per unit (each chart's minimum corner at the origin).
/// Every coordinate must be finite. `max_chart` ≥ 1.
#[must_use]
pub fn pack_charts(
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
    let mut area = 0.0f64;
    let mut narrowest_fit = 1i32;
    for e in extent.iter().filter(|e| e.is_finite()) {
        let (w, h) = (f64::from(e.x) + 2.0, f64::from(e.y) + 2.0);
        area += (w + f64::from(padding)) * (h + f64::from(padding));
        narrowest_fit = narrowest_fit.max(e.x.min(e.y) as i32 + 2);
    }
    let footprint = |c: usize, swap: bool| {
        let m = tris(c);
        (!m.is_empty() && extent[c].is_finite()).then(|| profile(m, &out, swap))
    };
    let best = free_atlas(
        &order,
        &footprint,
        &[false, true],
        area,
        narrowest_fit,
        padding as i32,
    );
    for p in &best.placed {
        let at = Vec2::new(p.x as f32, p.y as f32);
        for &t in tris(p.piece as usize) {
            let q = &mut out[t as usize];
            *q = q.map(|v| if p.swap { Vec2::new(v.y, v.x) } else { v } + at);
        }
    }
    Layout {
        width: best.width.max(0) as u32,
        height: best.height.max(0) as u32,
        uv: out,
    }
}

/// A rectangle's place: (page, x, y) of its corner inside the gutter.
pub type Place = (u32, u32, u32);

/// Packs `(width, height)` rectangles (a mesh's UV square, a whole atlas), each with a
/// `gutter` on every side, onto pages of `page` texels, by the same skyline and order as the
/// charts: largest perimeter first, each where its top is lowest, then leftmost, on the
/// first of the last few open pages where it fits, else on a new page. Rectangles are never
/// turned (a mesh's UVs are only scaled and shifted). With `compact`, rectangles that fit one
/// page together are packed about square first, as charts are, so a page cut down to what
/// was used is not a strip along the bottom. Returns per rectangle its place (`None` for
/// `None`) and the number of pages. A rectangle larger than a page gets a page of its own.
#[must_use]
pub fn pack_rects(
    rects: &[Option<(u32, u32)>],
    gutter: u32,
    page: (u32, u32),
    compact: bool,
) -> (Vec<Option<Place>>, u32) {
    let outer = |i: usize| rects[i].map(|(w, h)| (w + 2 * gutter, h + 2 * gutter));
    let mut order: Vec<usize> = (0..rects.len()).filter(|&i| rects[i].is_some()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(outer(i).map(|(w, h)| w + h)), i));
    let footprint = |i: usize, _swap: bool| outer(i).map(|(w, h)| Profile::rect(w, h));
    let (w, h) = (page.0 as i32, page.1 as i32);
    let mut placement = None;
    if compact {
        let area: f64 = order
            .iter()
            .filter_map(|&i| outer(i))
            .map(|(w, h)| f64::from(w) * f64::from(h))
            .sum();
        let widest = order
            .iter()
            .filter_map(|&i| outer(i))
            .map(|r| r.0 as i32)
            .max()
            .unwrap_or(1);
        let one = free_atlas(&order, &footprint, &[false], area, widest, 0);
        if one.width <= w && one.height <= h && one.placed.len() == order.len() {
            placement = Some(one);
        }
    }
    let placement = placement.unwrap_or_else(|| on_pages(&order, &footprint, w, h));
    let mut out = vec![None; rects.len()];
    let mut pages = 1;
    for p in &placement.placed {
        out[p.piece as usize] = Some((p.page, p.x as u32 + gutter, p.y as u32 + gutter));
        pages = pages.max(p.page + 1);
    }
    (out, pages)
}

/// Where the pieces went, and the extent of what they cover.
struct Placement {
    placed: Vec<Placed>,
    width: i32,
    height: i32,
}

/// One piece placed: at (x, y) of `page`, u and v swapped when `swap`.
struct Placed {
    piece: u32,
    page: u32,
    x: i32,
    y: i32,
    swap: bool,
}

/// One atlas of free height: a skyline whose width is first guessed from the pieces'
/// `area`, then tried again at the width that would have made the first atlas square; the
/// one of smaller longer side is kept. Never narrower than `narrowest_fit`.
fn free_atlas(
    order: &[usize],
    footprint: &dyn Fn(usize, bool) -> Option<Profile>,
    turns: &[bool],
    area: f64,
    narrowest_fit: i32,
    pad: i32,
) -> Placement {
    let first_width = (area.sqrt().ceil() as i32).max(narrowest_fit).max(1);
    let mut best = place(order, footprint, turns, first_width, pad);
    let square = (f64::from(best.width) * f64::from(best.height))
        .sqrt()
        .ceil() as i32;
    let second_width = square.max(narrowest_fit).max(1);
    if (second_width - first_width).abs() * 50 > first_width {
        let second = place(order, footprint, turns, second_width, pad);
        if second.width.max(second.height) < best.width.max(best.height) {
            best = second;
        }
    }
    best
}

/// Places the pieces (`footprint(c, swap)`: piece `c`'s profile, `None` to leave it out) in
/// `order` on one skyline `width` texels wide and of free height, each the way of `turns`
/// (as given, u and v swapped) whose top is lowest.
fn place(
    order: &[usize],
    footprint: &dyn Fn(usize, bool) -> Option<Profile>,
    turns: &[bool],
    width: i32,
    pad: i32,
) -> Placement {
    let mut sky = Skyline::new(width, pad);
    let mut result = Placement {
        placed: Vec::with_capacity(order.len()),
        width: 0,
        height: 0,
    };
    for &c in order {
        let mut best: Option<(i32, i32, i32, bool, Profile)> = None;
        for &swap in turns {
            let Some(p) = footprint(c, swap) else {
                break;
            };
            let bound = best.as_ref().map_or(i32::MAX, |b| b.2);
            if let Some((x, y)) = sky.lowest(&p, bound) {
                let top = y + p.height;
                if best.as_ref().is_none_or(|b| top < b.2) {
                    best = Some((x, y, top, swap, p));
                }
            }
        }
        let Some((x, y, top, swap, p)) = best else {
            continue;
        };
        sky.raise(&p, x, y);
        result.width = result.width.max(x + p.bottom.len() as i32);
        result.height = result.height.max(top);
        result.placed.push(Placed {
            piece: c as u32,
            page: 0,
            x,
            y,
            swap,
        });
    }
    result
}

/// Pages an open page stays a candidate for: a piece tries the last this many pages opened,
/// so the cost per piece stays bounded however many pages a world needs.
const OPEN_PAGES: usize = 4;

/// Places the pieces in `order`, never turned, on pages of `width`×`height`: each on the
/// first open page where its top stays inside, else on a new page (alone when it is larger
/// than a page).
fn on_pages(
    order: &[usize],
    footprint: &dyn Fn(usize, bool) -> Option<Profile>,
    width: i32,
    height: i32,
) -> Placement {
    let mut pages: Vec<Skyline> = Vec::new();
    let mut result = Placement {
        placed: Vec::with_capacity(order.len()),
        width: 0,
        height: 0,
    };
    for &c in order {
        let Some(p) = footprint(c, false) else {
            continue;
        };
        let open = pages.len().saturating_sub(OPEN_PAGES)..pages.len();
        let found = open
            .clone()
            .find_map(|k| Some((k, pages[k].lowest(&p, height + 1)?)));
        let (k, (x, y)) = found.unwrap_or_else(|| {
            pages.push(Skyline::new(width, 0));
            (pages.len() - 1, (0, 0))
        });
        if p.bottom.len() as i32 <= width {
            pages[k].raise(&p, x, y);
        } else {
            pages[k].sky.fill(i32::MAX / 2); // larger than a page: nothing else goes there
        }
        result.width = result.width.max(x + p.bottom.len() as i32);
        result.height = result.height.max(y + p.height);
        result.placed.push(Placed {
            piece: c as u32,
            page: k as u32,
            x,
            y,
            swap: false,
        });
    }
    result
}

/// Per atlas column, the row above the highest footprint texel placed there plus the
/// padding: where a piece may start.
struct Skyline {
    sky: Vec<i32>,
    pad: i32,
    /// Lowest footprint row within `pad` columns, per column of the piece being placed.
    scratch: Vec<i32>,
}

impl Skyline {
    fn new(width: i32, pad: i32) -> Self {
        Self {
            sky: vec![0; width.max(1) as usize],
            pad,
            scratch: Vec::new(),
        }
    }

    /// The lowest `y` (then the least `x`) at which `p` clears the skyline with `pad`
    /// texels to spare and its top `y + p.height` stays below `bound`; `None` when no place
    /// beats `bound` or `p` is wider than the skyline.
    fn lowest(&mut self, p: &Profile, bound: i32) -> Option<(i32, i32)> {
        let (cw, pad) = (p.bottom.len() as i32, self.pad);
        if cw > self.sky.len() as i32 {
            return None;
        }
        if p.flat {
            return lowest_flat(&self.sky, cw, pad, p.height, bound);
        }
        // Lowest footprint row within `pad` columns of each column k - pad.
        self.scratch.clear();
        self.scratch.extend((0..cw + 2 * pad).map(|k| {
            let (a, b) = ((k - 2 * pad).max(0), k.min(cw - 1));
            (a..=b)
                .map(|j| p.bottom[j as usize])
                .min()
                .unwrap_or(i32::MAX)
        }));
        lowest(&self.sky, &self.scratch, cw, pad, p.height, bound)
    }

    /// Raises the skyline over `p` placed at (`x`, `y`).
    fn raise(&mut self, p: &Profile, x: i32, y: i32) {
        for (j, &t) in p.top.iter().enumerate() {
            let s = &mut self.sky[x as usize + j];
            *s = (*s).max(y + t + 1 + self.pad);
        }
    }
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
    leftmost_lowest(w - cw, bound.saturating_sub(height), |x, limit| {
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
        y
    })
}

/// [`lowest`] for a rectangle (every column's footprint from row 0): `y` is the highest
/// skyline within `pad` columns of it, a sliding-window maximum, so one pass over the
/// skyline whatever the rectangle's width.
fn lowest_flat(sky: &[i32], cw: i32, pad: i32, height: i32, bound: i32) -> Option<(i32, i32)> {
    let w = sky.len() as i32;
    // Columns of the window, their skyline decreasing from front to back.
    let mut window = std::collections::VecDeque::new();
    let mut end = 0; // columns below `end` have entered the window
    leftmost_lowest(w - cw, bound.saturating_sub(height), |x, _| {
        let (a, b) = ((x - pad).max(0), (x + cw + pad).min(w));
        while end < b {
            while window
                .back()
                .is_some_and(|&j: &i32| sky[j as usize] <= sky[end as usize])
            {
                window.pop_back();
            }
            window.push_back(end);
            end += 1;
        }
        while window.front().is_some_and(|&j| j < a) {
            window.pop_front();
        }
        window.front().map_or(0, |&j| sky[j as usize].max(0))
    })
}

/// The least `y` below `limit` over `x` from 0 to `last` in order, then the least `x`;
/// `y_at(x, limit)` is `x`'s `y`, and may stop counting once it reaches the current `limit`.
/// Stops at the first `y` of 0.
fn leftmost_lowest(
    last: i32,
    mut limit: i32,
    mut y_at: impl FnMut(i32, i32) -> i32,
) -> Option<(i32, i32)> {
    let mut best = None;
    for x in 0..=last {
        let y = y_at(x, limit);
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
        flat: false,
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
            let l = pack_charts(&uv, &chart, charts, density, 4096, padding);
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
        let l = pack_charts(&uv, &[0], 1, 2.0, 4096, 2);
        let q = l.uv[0];
        let legs = [(q[1] - q[0]).length(), (q[2] - q[0]).length()];
        assert!(legs.iter().all(|&e| (e - 20.0).abs() < 1e-3), "{legs:?}");
        assert!(q.iter().all(|v| v.min_element() >= 0.5 - 1e-4), "{q:?}");
        assert_eq!((l.width, l.height), (21, 21));
        // Longer than the limit: scaled down below it.
        let l = pack_charts(&uv, &[0], 1, 2.0, 8, 2);
        assert!(l.width <= 9 && l.height <= 9, "{}x{}", l.width, l.height);
    }

    #[test]
    fn packing_is_deterministic_and_uses_the_area() {
        let (uv, chart) = random_charts(7, 300);
        let a = pack_charts(&uv, &chart, 300, 1.5, 4096, 2);
        let b = pack_charts(&uv, &chart, 300, 1.5, 4096, 2);
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

    /// Random `(w, h)` rectangles up to `max` texels a side, every seventh `None`.
    fn random_rects(seed: u64, count: usize, max: u32) -> Vec<Option<(u32, u32)>> {
        let mut s = seed;
        let mut rnd = |n: u32| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            1 + ((s >> 33) % u64::from(n)) as u32
        };
        (0..count)
            .map(|i| (i % 7 != 3).then(|| (rnd(max), rnd(max))))
            .collect()
    }

    /// Every rectangle placed, with its gutter inside its page and apart from every other's.
    fn assert_rects_apart(
        rects: &[Option<(u32, u32)>],
        places: &[Option<Place>],
        gutter: u32,
        page: (u32, u32),
    ) {
        let mut boxes = Vec::new();
        for (i, (r, p)) in rects.iter().zip(places).enumerate() {
            assert_eq!(r.is_some(), p.is_some(), "rectangle {i}");
            let (Some((w, h)), Some((pg, x, y))) = (r, p) else {
                continue;
            };
            let (x0, y0, x1, y1) = (x - gutter, y - gutter, x + w + gutter, y + h + gutter);
            if *w + 2 * gutter <= page.0 && *h + 2 * gutter <= page.1 {
                assert!(
                    x1 <= page.0 && y1 <= page.1,
                    "rectangle {i} at {x},{y} leaves {page:?}"
                );
            }
            boxes.push((i, *pg, x0, y0, x1, y1));
        }
        for (k, a) in boxes.iter().enumerate() {
            for b in &boxes[k + 1..] {
                let apart = a.1 != b.1 || a.4 <= b.2 || b.4 <= a.2 || a.5 <= b.3 || b.5 <= a.3;
                assert!(apart, "rectangles {} and {} overlap: {a:?} {b:?}", a.0, b.0);
            }
        }
    }

    #[test]
    fn rectangles_stay_on_their_pages_and_apart() {
        for (seed, count, max, page) in [
            (1, 200, 60, (256, 192)),
            (2, 50, 200, (256, 256)),
            (3, 400, 9, (64, 40)),
            (4, 1, 10, (64, 64)),
        ] {
            let rects = random_rects(seed, count, max);
            for compact in [false, true] {
                let (places, pages) = pack_rects(&rects, 2, page, compact);
                assert_rects_apart(&rects, &places, 2, page);
                let used = places.iter().flatten().map(|p| p.0 + 1).max().unwrap_or(1);
                assert_eq!(pages, used, "seed {seed}");
                // Pages hold area: no more than twice the pages the area alone needs.
                let area: u64 = rects
                    .iter()
                    .flatten()
                    .map(|&(w, h)| u64::from(w + 4) * u64::from(h + 4))
                    .sum();
                let least = area.div_ceil(u64::from(page.0 * page.1)) as u32;
                assert!(
                    pages <= 2 * least.max(1),
                    "seed {seed}: {pages} pages, {least} by area"
                );
            }
        }
    }

    #[test]
    fn rectangles_that_fit_one_page_pack_about_square_and_dense() {
        let rects = random_rects(5, 300, 40);
        let (places, pages) = pack_rects(&rects, 2, (4096, 4096), true);
        assert_eq!(pages, 1);
        assert_rects_apart(&rects, &places, 2, (4096, 4096));
        let (mut w, mut h, mut area) = (0u32, 0u32, 0u64);
        for (r, p) in rects.iter().zip(&places) {
            let (Some((rw, rh)), Some((_, x, y))) = (r, p) else {
                continue;
            };
            w = w.max(x + rw + 2);
            h = h.max(y + rh + 2);
            area += u64::from(rw + 4) * u64::from(rh + 4);
        }
        let fill = area as f64 / (f64::from(w) * f64::from(h));
        assert!(fill > 0.8, "fill {fill} of {w}x{h}");
        assert!(w.max(h) < 2 * w.min(h), "{w}x{h}");
        // Without `compact` the same rectangles lie along the page's bottom edge.
        let (places, _) = pack_rects(&rects, 2, (4096, 4096), false);
        let top = places.iter().flatten().map(|p| p.2).max().unwrap_or(0);
        assert!(top < h / 4, "{top}");
        // The same input, the same places.
        assert_eq!(
            pack_rects(&rects, 2, (4096, 4096), true).0,
            pack_rects(&rects, 2, (4096, 4096), true).0
        );
    }

    #[test]
    fn a_rectangle_larger_than_a_page_gets_a_page_of_its_own() {
        let rects = [Some((10, 10)), Some((100, 20)), Some((8, 8))];
        let (places, pages) = pack_rects(&rects, 2, (64, 64), false);
        assert_eq!(pages, 2);
        let big = places[1].unwrap();
        assert!(
            places
                .iter()
                .enumerate()
                .all(|(i, p)| i == 1 || p.unwrap().0 != big.0),
            "{places:?}"
        );
    }

    #[test]
    fn the_sliding_window_lowest_matches_the_column_walk() {
        let mut s = 9u64;
        let mut rnd = |n: i32| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 33) % n as u64) as i32
        };
        for _ in 0..2000 {
            let w = 1 + rnd(40);
            let sky: Vec<i32> = (0..w).map(|_| rnd(4) * rnd(12)).collect();
            let (cw, pad, height) = (1 + rnd(w), rnd(4), 1 + rnd(20));
            let bound = if rnd(3) == 0 { i32::MAX } else { rnd(60) };
            let low = vec![0; (cw + 2 * pad) as usize];
            assert_eq!(
                lowest_flat(&sky, cw, pad, height, bound),
                lowest(&sky, &low, cw, pad, height, bound),
                "sky {sky:?} cw {cw} pad {pad} height {height} bound {bound}"
            );
        }
    }
}
