//! `warp`: hierarchical sample warping through the learned guide (Clarberg, Jarosz,
//! Akenine-Möller & Jensen, *Wavelet Importance Sampling*, SIGGRAPH 2005, §4 "hierarchical
//! sample warping"; Silvennoinen & Sloan 2019, §2.4).
//!
//! A point `u` of the primary sample square descends the [`Guide`]'s quadtree. At each
//! interior node it picks the x-half by the marginal `px` (left if `x < px`), then the y-half
//! by the conditional `py[half]`, rescales the coordinate it used into [0,1) again, and
//! continues in the chosen child; in the leaf the remaining coordinates place the point
//! uniformly in the leaf's square. The density of the result on the square is the product of
//! `4 · P(x-half) · P(y-half | x-half)` over the path: the leaf's mass over its area.
//!
//! # Rescaling folded into the tree (deviation, same warp)
//! The composition of the per-level rescalings is affine on each node: a node receives
//! exactly the points of one rectangle `[lo, hi)` of primary sample space (its *source
//! rectangle*), and its split "x < px in the node's rescaled frame" is `u.x < lo.x +
//! (hi.x − lo.x)·px` in the original one. [`crate::guide::build`] computes these thresholds
//! once (in f64, rounded to f32, children inheriting the rounded values so the rectangles
//! tile the square exactly), so the descent is compare-only and `u` is rescaled once, in the
//! leaf: `w = origin + (u − lo)/(hi − lo) · size`. It is the same map as rescaling at every
//! level, with less rounding (one division instead of one per level) and no arithmetic on
//! the descent's critical path. The leaf's density is stored as the area of its source
//! rectangle over the area of its square, so it is exactly the density of the map as
//! rounded.
//!
//! The triple: [`sample`] (u → warped point and its pdf), [`pdf`] (point → density on the
//! square) and [`invert`] (warped point → u). [`sample`] is the readable scalar reference:
//! it descends from the root.
//!
//! [`sample8`] is the 8-wide packet version on `wide::f32x8`. Presorted packets (paper §2.4,
//! Figure 3) share only the top of their paths on a realistic guide (the leaves' source
//! rectangles are mass-balanced, so a 64-sample texel's packet spans 1/8 of the square and
//! meets many of them), so what pays is to make the per-lane part cheap:
//! - **start table and shortcuts**: each lane looks up the cell of `u` in the guide's
//!   [`Guide::start_table`] — the deepest node that every point of that cell of a 32 × 32
//!   grid over the primary sample square passes through (exact: the thresholds are in
//!   primary sample space) — takes one step there and jumps to the cell's **shortcut** for
//!   the quadrant it took: the deepest node every point of the cell in that quadrant
//!   passes through. A cell that straddles a shallow threshold would otherwise send its
//!   lanes down the whole subtree below it: on the bench's learned guide the lanes need
//!   1.16 levels below the start node on average and the deepest of four 2.47; after the
//!   shortcut 0.76 and 1.43;
//! - **interleaved per-lane descent in two halves of four**: lanes 0–3, then lanes 4–7,
//!   descend in lockstep rounds, branch-free, so their load → compare → load chains overlap
//!   where the scalar warp waits on one, and a half waits only for the deepest of its four
//!   lanes, not of eight (a half whose lanes are all in leaves skips its rounds). The step
//!   `link + right + 2·upper` is the child for an interior node and the node itself for a
//!   leaf (the node's `link`), and the node's `inner_kids` bits say whether the lane just
//!   reached a leaf, so a half stops in the round its deepest lane arrives;
//! - the leaves' placement fields (the first 32 bytes of each 64-byte node) are loaded as
//!   one row per lane, transposed, and the points placed 8-wide.
//!
//! Without a start table (the uniform guide, or a tree that filled its storage) it runs a
//! **uniform fast path** — one 8-wide compare per axis against the node's splatted
//! thresholds — while all lanes sit in the same node, and the per-lane descent from the
//! node where they part. Measurements of these and of the alternatives that did not pay
//! are in `docs/guide.md`.
//!
//! # One kernel, two widths
//! The arithmetic — the final placement (`place`) and the input clamp — is written once
//! over a small [`Value`] trait implemented by `f32` and `f32x8` (as Mitsuba templates its
//! warps on a scalar-or-packet type); the descent is comparisons only. Both widths use the
//! same IEEE operations in the same order (no fused multiply-add), so they agree **bit for
//! bit**; the tests check it on every build, with and without AVX2.
//!
//! # Staying inside [0,1)
//! `(u − lo)/(hi − lo)` can round up to exactly 1 when `u` is just below `hi`, and
//! `origin + t·size` can round up onto the leaf's upper edge (at depth ≥ 2 the leaf's
//! resolution is finer than the f32 spacing near 1). Both are clamped: the rescaled
//! coordinate to [`ONE_MINUS_EPSILON`], the largest f32 below 1, and the point to the largest f32
//! below the leaf's upper edge. The clamp keeps the warped point in [0,1) *and* in the leaf
//! that produced it, so `pdf(sample(u).u) == sample(u).pdf` exactly. It moves a point by at
//! most one ulp, far below the sampling resolution.
//!
//! # Preconditions
//! Inputs must lie in [0,1)² (`debug_assert!`). In release builds a negative or NaN
//! coordinate is treated as 0 and one ≥ 1 as [`ONE_MINUS_EPSILON`], in both widths alike.
//!
//! # Deviation
//! Clarberg et al. warp a wavelet-defined image; we warp a quadtree built by
//! [`crate::guide::build`]. [`pdf8`] is the 8-wide [`pdf`] (interleaved per-lane descent
//! by the squares' midpoints; the start table indexes primary sample space, not the warped
//! square, so it does not apply). [`invert`] has no 8-wide version: nothing on the hot path
//! needs it.

use crate::guide::{Guide, GuideNode, START_GRID};
use core::ops::{Add, Div, Mul, Sub};
use wide::{f32x8, i32x8};

use crate::sobol::ONE_MINUS_EPSILON;

/// A warped point of the square and its density there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Warped {
    /// The warped point, in [0,1)².
    pub u: [f32; 2],
    /// Its density on the square (`pdf(u)`).
    pub pdf: f32,
}

/// Eight warped points in structure-of-arrays form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Warped8 {
    /// x coordinates, in [0,1).
    pub x: f32x8,
    /// y coordinates, in [0,1).
    pub y: f32x8,
    /// Densities on the square.
    pub pdf: f32x8,
}

/// Arithmetic the level step needs, for `f32` (one lane) and `f32x8` (eight lanes).
pub trait Value:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    /// A per-lane condition.
    type Mask: Copy;
    /// Every lane set to `v`.
    fn splat(v: f32) -> Self;
    /// `self >= o` per lane (false for NaN).
    fn ge(self, o: Self) -> Self::Mask;
    /// `if m { a } else { b }` per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// The next f32 below `self` (positive, normal inputs).
    fn prev_float(self) -> Self;
    /// `if self < o { self } else { o }` per lane.
    fn min_of(self, o: Self) -> Self;
}

impl Value for f32 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f32) -> f32 {
        v
    }
    #[inline(always)]
    fn ge(self, o: f32) -> bool {
        self >= o
    }
    #[inline(always)]
    fn select(m: bool, a: f32, b: f32) -> f32 {
        if m { a } else { b }
    }
    #[inline(always)]
    fn prev_float(self) -> f32 {
        f32::from_bits(self.to_bits() - 1)
    }
    #[inline(always)]
    fn min_of(self, o: f32) -> f32 {
        if self < o { self } else { o }
    }
}

impl Value for f32x8 {
    type Mask = f32x8;
    #[inline(always)]
    fn splat(v: f32) -> f32x8 {
        f32x8::splat(v)
    }
    #[inline(always)]
    fn ge(self, o: f32x8) -> f32x8 {
        self.simd_ge(o)
    }
    #[inline(always)]
    fn select(m: f32x8, a: f32x8, b: f32x8) -> f32x8 {
        m.select(a, b)
    }
    #[inline(always)]
    fn prev_float(self) -> f32x8 {
        let bits: i32x8 = bytemuck::cast(self);
        bytemuck::cast(bits - i32x8::splat(1))
    }
    #[inline(always)]
    fn min_of(self, o: f32x8) -> f32x8 {
        self.simd_lt(o).select(self, o)
    }
}

/// Maps NaN and negatives to 0 and values ≥ 1 to [`ONE_MINUS_EPSILON`].
#[inline(always)]
fn to_unit<V: Value>(v: V) -> V {
    V::select(v.ge(V::splat(0.0)), v, V::splat(0.0)).min_of(V::splat(ONE_MINUS_EPSILON))
}

/// The fields of a leaf the final step reads, per lane.
#[derive(Clone, Copy, Debug)]
struct LeafData<V> {
    lo: [V; 2],
    hi: [V; 2],
    origin: [V; 2],
    size: V,
    pdf: V,
}

impl LeafData<f32> {
    #[inline(always)]
    fn of(n: &GuideNode) -> Self {
        LeafData {
            lo: n.lo,
            hi: n.hi,
            origin: n.origin,
            size: n.size,
            pdf: n.pdf,
        }
    }
}

impl LeafData<f32x8> {
    /// Gathers the leaves of eight lanes: each leaf's eight fields are the first 32 bytes of
    /// its (64-byte aligned) node, one row load per lane, transposed into field vectors.
    #[inline(always)]
    fn gather(nodes: &[GuideNode], idx: &[usize; 8]) -> Self {
        let rows = idx.map(|i| f32x8::from(nodes[i].leaf_row()));
        let [lo0, lo1, hi0, hi1, o0, o1, size, pdf] = f32x8::transpose(rows);
        LeafData {
            lo: [lo0, lo1],
            hi: [hi0, hi1],
            origin: [o0, o1],
            size,
            pdf,
        }
    }

    /// One leaf in every lane.
    #[inline(always)]
    fn splat(n: &GuideNode) -> Self {
        let s = |v: [f32; 2]| [f32x8::splat(v[0]), f32x8::splat(v[1])];
        LeafData {
            lo: s(n.lo),
            hi: s(n.hi),
            origin: s(n.origin),
            size: f32x8::splat(n.size),
            pdf: f32x8::splat(n.pdf),
        }
    }
}

/// The last step of the warp, shared by both widths: rescale `u` from the leaf's source
/// rectangle to [0,1) and place it in the leaf's square.
///
/// Readable form: `t = (u − lo) / (hi − lo)`, `w = origin + t · size`, both clamped (module
/// docs). `u ≥ lo` holds because the descent compared `u` against exactly these bounds.
#[inline(always)]
fn place<V: Value>(leaf: &LeafData<V>, u: [V; 2]) -> ([V; 2], V) {
    let axis = |a: usize| {
        let t =
            ((u[a] - leaf.lo[a]) / (leaf.hi[a] - leaf.lo[a])).min_of(V::splat(ONE_MINUS_EPSILON));
        let top = (leaf.origin[a] + leaf.size).prev_float();
        (leaf.origin[a] + t * leaf.size).min_of(top)
    };
    ([axis(0), axis(1)], leaf.pdf)
}

/// One level of the descent: the child of interior node `n` that `u` falls in.
///
/// This is Clarberg et al.'s step — x-half by the marginal, y-half by the conditional given
/// the x-half — with the rescaling of `u` folded into the thresholds `n.t` at build time.
#[inline(always)]
fn child(n: &GuideNode, x: f32, y: f32) -> usize {
    let right = x >= n.t[0];
    let upper = y >= n.t[1 + usize::from(right)];
    usize::from(n.child) + usize::from(right) + 2 * usize::from(upper)
}

/// Descends from node `i` to the leaf containing `(x, y)`.
#[inline(always)]
fn leaf_from(nodes: &[GuideNode], mut i: usize, x: f32, y: f32) -> usize {
    while nodes[i].child != 0 {
        i = child(&nodes[i], x, y);
    }
    i
}

/// Warps `u` ∈ [0,1)² through the guide: the scalar reference.
#[inline]
pub fn sample(guide: &Guide<'_>, u: [f32; 2]) -> Warped {
    debug_assert!(in_square(u), "sample point {u:?} outside [0,1)^2");
    let nodes = guide.nodes();
    let (x, y) = (to_unit(u[0]), to_unit(u[1]));
    let leaf = &nodes[leaf_from(nodes, 0, x, y)];
    let (w, pdf) = place(&LeafData::of(leaf), [x, y]);
    Warped { u: w, pdf }
}

/// The guide's density on the square at `w` ∈ [0,1)²: the density of the leaf whose square
/// holds `w`. Equals the `pdf` that [`sample`] returns with the point it produces, bit for bit.
#[inline]
pub fn pdf(guide: &Guide<'_>, w: [f32; 2]) -> f32 {
    guide.nodes()[leaf_at(guide, w)].pdf
}

/// [`pdf`] for eight points: lane `i` equals `pdf(guide, [x[i], y[i]])` bit for bit (the
/// same comparisons against the same midpoints). The eight descents run interleaved and
/// branch-free, as in [`sample8`], until no lane moved.
#[inline]
pub fn pdf8(guide: &Guide<'_>, x: f32x8, y: f32x8) -> f32x8 {
    debug_assert!(
        (0..8).all(|i| in_square([x.to_array()[i], y.to_array()[i]])),
        "packet outside [0,1)^2"
    );
    let nodes = guide.nodes();
    let (xs, ys) = (to_unit(x).to_array(), to_unit(y).to_array());
    let mut idx = [0usize; 8];
    loop {
        let mut moved = 0;
        for l in 0..8 {
            let n = &nodes[idx[l]];
            let half = n.size * 0.5;
            let right = xs[l] >= n.origin[0] + half;
            let upper = ys[l] >= n.origin[1] + half;
            let next = usize::from(n.child) + usize::from(right) + 2 * usize::from(upper);
            moved |= n.child;
            idx[l] = if n.child == 0 { idx[l] } else { next };
        }
        if moved == 0 {
            break;
        }
    }
    f32x8::new(idx.map(|i| nodes[i].pdf))
}

/// The leaf whose square holds `w` (descending by the squares' midpoints).
fn leaf_at(guide: &Guide<'_>, w: [f32; 2]) -> usize {
    debug_assert!(in_square(w), "point {w:?} outside [0,1)^2");
    let nodes = guide.nodes();
    let (wx, wy) = (to_unit(w[0]), to_unit(w[1]));
    let mut i = 0;
    while let Some(c) = nodes[i].first_child() {
        let n = &nodes[i];
        let half = n.size * 0.5;
        let right = wx >= n.origin[0] + half;
        let upper = wy >= n.origin[1] + half;
        i = c + usize::from(right) + 2 * usize::from(upper);
    }
    i
}

/// The inverse of [`sample`]: the `u` that warps to `w`, up to rounding. The warped point is
/// an f32 (spacing ≤ 2⁻²⁴) in a leaf of side 2^-d whose source rectangle has side
/// `hi − lo`, so `u` is recovered to about 2^(d−24)·(hi − lo) per axis.
pub fn invert(guide: &Guide<'_>, w: [f32; 2]) -> [f32; 2] {
    let n = &guide.nodes()[leaf_at(guide, w)];
    let axis = |a: usize| {
        let t = (to_unit(w[a]) - n.origin[a]) / n.size;
        let u = n.lo[a] + t * (n.hi[a] - n.lo[a]);
        // Stay in the source rectangle, so `sample(invert(w))` lands in the same leaf.
        let top = if n.hi[a] > n.lo[a] {
            n.hi[a].prev_float()
        } else {
            n.lo[a]
        };
        to_unit(u.max(n.lo[a]).min(top))
    };
    [axis(0), axis(1)]
}

fn in_square(u: [f32; 2]) -> bool {
    (0.0..1.0).contains(&u[0]) && (0.0..1.0).contains(&u[1])
}

/// Warps a packet of eight points; lane `i` equals `sample(guide, [x[i], y[i]])` bit for bit.
#[inline]
pub fn sample8(guide: &Guide<'_>, x: f32x8, y: f32x8) -> Warped8 {
    debug_assert!(
        (0..8).all(|i| in_square([x.to_array()[i], y.to_array()[i]])),
        "packet outside [0,1)^2"
    );
    let nodes = guide.nodes();
    let (x, y) = (to_unit(x), to_unit(y));
    let table = guide.start_table();
    if table.is_empty() {
        return from_root(nodes, x, y);
    }
    // Each lane starts at the deepest node its start-table cell shares (⌊u·G⌋ is exact:
    // G is a power of two and u ∈ [0, 1−ε]), takes one step there and goes on to the
    // cell's shortcut for that quadrant (the deepest node the cell's part there shares).
    let g = f32x8::splat(START_GRID as f32);
    let cell = (x * g).trunc_int() + (y * g).trunc_int() * i32x8::splat(START_GRID as i32);
    let cell = cell.to_array();
    let shortcuts = guide.shortcuts();
    let (xs, ys) = (x.to_array(), y.to_array());
    let idx = core::array::from_fn(|l| {
        let c = cell[l] as usize;
        let n = &nodes[usize::from(table[c])];
        let right = xs[l] >= n.t[0];
        let upper = ys[l] >= n.t[1 + usize::from(right)];
        usize::from(shortcuts[c][usize::from(right) + 2 * usize::from(upper)])
    });
    descend_lanes(nodes, idx, x, y)
}

/// [`sample8`] without a start table (the uniform guide, or a tree that filled its storage):
/// the uniform fast path — one 8-wide compare per axis against the node's splatted
/// thresholds — while all lanes sit in the same node, per-lane descent from where they part.
#[inline(never)]
fn from_root(nodes: &[GuideNode], x: f32x8, y: f32x8) -> Warped8 {
    let mut i = 0;
    while let Some(c) = nodes[i].first_child() {
        let n = &nodes[i];
        let r = x.simd_ge(f32x8::splat(n.t[0])).to_bitmask();
        if r != 0 && r != 0xff {
            return descend_lanes(nodes, [i; 8], x, y);
        }
        let right = usize::from(r != 0);
        let u = y.simd_ge(f32x8::splat(n.t[1 + right])).to_bitmask();
        if u != 0 && u != 0xff {
            return descend_lanes(nodes, [i; 8], x, y);
        }
        i = c + right + 2 * usize::from(u != 0);
    }
    let ([wx, wy], pdf) = place(&LeafData::splat(&nodes[i]), [x, y]);
    Warped8 { x: wx, y: wy, pdf }
}

/// Quadrant `q`'s bit in a node's `inner_kids`.
const QUADRANT_BIT: [u8; 4] = [1, 2, 4, 8];

/// The per-lane descent of [`sample8`]: lane `l` starts at node `idx[l]` (which its point
/// reaches) and descends on its own. Lanes 0–3 and then lanes 4–7 descend in lockstep
/// rounds, the four descents of a half interleaved so that their load → compare → load
/// chains overlap; a half's rounds run as often as its deepest lane needs (four lanes wait
/// for the deepest of four, not of eight), none if all four are in leaves already. The
/// step is branch-free and the same for every lane: `link + right + 2·upper` is the child
/// for an interior node and the node itself for a leaf (its `link` is its index − 3, its
/// thresholds 0), and the node's `inner_kids` says whether the lane just arrived in a
/// leaf, so the rounds stop in the round that brings the last lane to its leaf instead of
/// one round later. The leaves are then gathered (one 32-byte row per lane, transposed)
/// and placed 8-wide.
#[inline(always)]
fn descend_lanes(nodes: &[GuideNode], mut idx: [usize; 8], x: f32x8, y: f32x8) -> Warped8 {
    let (xs, ys) = (x.to_array(), y.to_array());
    for half in [0..4, 4..8] {
        if half.clone().fold(0, |m, l| m | nodes[idx[l]].child) == 0 {
            continue;
        }
        loop {
            let mut live = 0;
            for l in half.clone() {
                let n = &nodes[idx[l]];
                let right = xs[l] >= n.t[0];
                let upper = ys[l] >= n.t[1 + usize::from(right)];
                let q = usize::from(right) + 2 * usize::from(upper);
                live |= n.inner_kids & QUADRANT_BIT[q];
                idx[l] = n.link.wrapping_add(q as u32) as usize;
            }
            if live == 0 {
                break;
            }
        }
    }
    let ([wx, wy], pdf) = place(&LeafData::gather(nodes, &idx), [x, y]);
    Warped8 { x: wx, y: wy, pdf }
}

/// [`sample8`] for a packet of `lanes` ≤ 8 points (the tail of a texel's samples): lanes
/// `lanes..8` are ignored (they follow lane 0, so they never break the uniform path) and
/// come back unchanged with pdf 0.
///
/// # Panics
/// In debug builds if `lanes` is 0 or above 8; release builds treat it as `lanes.clamp(1, 8)`.
#[inline]
pub fn sample8_lanes(guide: &Guide<'_>, x: f32x8, y: f32x8, lanes: usize) -> Warped8 {
    debug_assert!((1..=8).contains(&lanes), "lane count {lanes} not in 1..=8");
    let lanes = lanes.clamp(1, 8);
    if lanes == 8 {
        return sample8(guide, x, y);
    }
    let live = f32x8::new(core::array::from_fn(|l| {
        if l < lanes {
            f32::from_bits(u32::MAX)
        } else {
            0.0
        }
    }));
    let (x0, y0) = (f32x8::splat(x.to_array()[0]), f32x8::splat(y.to_array()[0]));
    let w = sample8(guide, live.select(x, x0), live.select(y, y0));
    Warped8 {
        x: live.select(w.x, x),
        y: live.select(w.y, y),
        pdf: live.select(w.pdf, f32x8::splat(0.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::guide::{GuideParams, Record, build};
    use crate::testing::Pcg32;

    fn learned(storage: &mut [GuideNode]) -> Guide<'_> {
        // A bright disk on a dim background, learned from uniform samples.
        let mut rng = Pcg32::new(11, 2);
        let mut r: [Record; 400] = core::array::from_fn(|_| {
            let u = [rng.next_f32(), rng.next_f32()];
            let d2 = (u[0] - 0.7) * (u[0] - 0.7) + (u[1] - 0.2) * (u[1] - 0.2);
            Record {
                u,
                flux: if d2 < 0.01 { 50.0 } else { 0.5 },
            }
        });
        build(&mut r, &GuideParams::default(), storage).0
    }

    #[test]
    fn uniform_guide_is_the_identity() {
        let mut st = [GuideNode::default(); 1];
        let g = Guide::uniform(&mut st);
        let mut rng = Pcg32::new(1, 1);
        for _ in 0..1000 {
            let u = [rng.next_f32(), rng.next_f32()];
            let w = sample(&g, u);
            assert_eq!(w, Warped { u, pdf: 1.0 });
            assert_eq!(invert(&g, u), u);
        }
    }

    #[test]
    fn sample_pdf_matches_pdf_and_points_stay_in_square() {
        let mut st = [GuideNode::default(); 1024];
        let g = learned(&mut st);
        assert!(g.nodes().len() > 20);
        let mut rng = Pcg32::new(5, 9);
        let edge = [0.0, ONE_MINUS_EPSILON, 0.5, f32::from_bits(0x3effffff)];
        for k in 0..20_000 {
            let u = if k < 16 {
                [edge[k % 4], edge[k / 4]]
            } else {
                [rng.next_f32(), rng.next_f32()]
            };
            let w = sample(&g, u);
            assert!(in_square(w.u), "{u:?} -> {w:?}");
            assert_eq!(w.pdf.to_bits(), pdf(&g, w.u).to_bits(), "{u:?} -> {w:?}");
            assert!(w.pdf > 0.0 && w.pdf.is_finite());
        }
    }

    #[test]
    fn sample8_matches_scalar_bit_for_bit() {
        let mut st = [GuideNode::default(); 1024];
        let g = learned(&mut st);
        let mut rng = Pcg32::new(8, 3);
        for p in 0..2000 {
            // Alternate incoherent packets and coherent ones (a small square).
            let (cx, cy, r) = if p % 2 == 0 {
                (0.0, 0.0, 1.0)
            } else {
                (rng.next_f32() * 0.97, rng.next_f32() * 0.97, 0.03)
            };
            let xs: [f32; 8] = core::array::from_fn(|_| cx + r * rng.next_f32());
            let ys: [f32; 8] = core::array::from_fn(|_| cy + r * rng.next_f32());
            let w = sample8(&g, f32x8::new(xs), f32x8::new(ys));
            for l in 0..8 {
                let s = sample(&g, [xs[l], ys[l]]);
                assert_eq!(w.x.to_array()[l].to_bits(), s.u[0].to_bits());
                assert_eq!(w.y.to_array()[l].to_bits(), s.u[1].to_bits());
                assert_eq!(w.pdf.to_array()[l].to_bits(), s.pdf.to_bits());
            }
        }
    }

    #[test]
    fn pdf8_matches_scalar_pdf_bit_for_bit() {
        let mut st = [GuideNode::default(); 1024];
        let g = learned(&mut st);
        let mut rng = Pcg32::new(4, 12);
        let edge = [0.0, ONE_MINUS_EPSILON, 0.5, f32::from_bits(0x3effffff)];
        for p in 0..2000 {
            let xs: [f32; 8] =
                core::array::from_fn(|l| if p == 0 { edge[l % 4] } else { rng.next_f32() });
            let ys: [f32; 8] = core::array::from_fn(|l| {
                if p == 0 {
                    edge[l / 2 % 4]
                } else {
                    rng.next_f32()
                }
            });
            let d = pdf8(&g, f32x8::new(xs), f32x8::new(ys)).to_array();
            for l in 0..8 {
                assert_eq!(d[l].to_bits(), pdf(&g, [xs[l], ys[l]]).to_bits());
            }
            // At the warped points it returns the warp's own pdf.
            let w = sample8(&g, f32x8::new(xs), f32x8::new(ys));
            assert_eq!(pdf8(&g, w.x, w.y).to_array(), w.pdf.to_array());
        }
    }

    #[test]
    fn prev_float_agrees_across_widths() {
        for v in [1.0f32, 0.5, 0.75, 2f32.powi(-16), 0.3] {
            let p8 = f32x8::splat(v).prev_float().to_array();
            assert_eq!(p8[3], v.prev_float());
            assert!(v.prev_float() < v && v.prev_float().to_bits() + 1 == v.to_bits());
        }
    }
}
