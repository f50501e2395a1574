//! `warp`: hierarchical sample warping through the learned guide (Clarberg, Jarosz,
//! Akenine-Möller & Jensen, *Wavelet Importance Sampling*, SIGGRAPH 2005, §4 "hierarchical
//! sample warping"; Silvennoinen & Sloan 2019, §2.4).
//!
//! A point `u` of the primary sample square descends the [`Guide`]'s quadtree. At each
//! interior node it picks the x-half by the marginal `px` (left if `x < px`), then the y-half
//! by the conditional `py[half]`, rescales the coordinate it used into [0,1) again, and
//! continues in the chosen child; in the leaf the remaining coordinates place the point
//! uniformly in the leaf's square. The density of the result on the square is the product of
//! `4 · P(x-half) · P(y-half | x-half)` over the path, which is the leaf's mass over its area.
//!
//! The triple: [`sample`] (u → warped point and its pdf), [`pdf`] (point → density on the
//! square) and [`invert`] (warped point → u). [`sample8`] is the 8-wide packet version on
//! `wide::f32x8`: a presorted packet (paper §2.4, Figure 3) mostly walks one path, so it runs
//! a **uniform fast path** with the node's values splatted while all lanes sit in the same
//! node, and switches to **per-lane** node indices (gathered loads, masked updates) from the
//! first node where the lanes part.
//!
//! # One kernel, two widths
//! The arithmetic of a level is written once ([`descend`]) over a small [`Value`] trait
//! implemented by `f32` and `f32x8` (as Mitsuba templates its warps on a scalar-or-packet
//! type); the scalar and 8-wide versions differ only in how they walk the tree. Both use the
//! same IEEE operations in the same order (no fused multiply-add), so they agree **bit for
//! bit**; the tests check it on every build, with and without AVX2.
//!
//! # Staying inside [0,1)
//! Rescaling `x / px` can round up to exactly 1 when `x` is just below `px`, and
//! `origin + x·size` can round up onto the leaf's upper edge (at depth ≥ 2 the leaf's
//! resolution is finer than the f32 spacing near 1). Both are clamped: a rescaled
//! coordinate to [`ONE_MINUS_EPS`], the largest f32 below 1, and the final point to the
//! largest f32 below the leaf's upper edge. The clamp keeps the warped point in [0,1) *and*
//! in the leaf that produced it, so `pdf(sample(u).u) == sample(u).pdf` exactly. It moves a
//! point by at most one ulp, a bias far below f32 sampling resolution.
//!
//! # Preconditions
//! Inputs must lie in [0,1)² (`debug_assert!`). In release builds a negative or NaN
//! coordinate is treated as 0 and one ≥ 1 as [`ONE_MINUS_EPS`], in both widths alike.
//!
//! # Deviation
//! Clarberg et al. warp a wavelet-defined image; we warp a quadtree whose per-node
//! probabilities are precomputed by [`crate::guide::build`]. [`invert`] has no 8-wide
//! version: nothing on the hot path needs it.

use crate::guide::{Guide, Node};
use core::ops::{Add, Div, Mul, Sub};
use wide::{f32x8, i32x8};

/// The largest f32 below 1 (1 − 2⁻²⁴).
pub const ONE_MINUS_EPS: f32 = f32::from_bits(0x3f7f_ffff);

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

/// The state of a descent: the point in the current node's frame, the node's square and the
/// density accumulated so far.
#[derive(Clone, Copy, Debug)]
struct State<V> {
    x: V,
    y: V,
    ox: V,
    oy: V,
    size: V,
    pdf: V,
}

impl<V: Value> State<V> {
    #[inline(always)]
    fn new(x: V, y: V) -> Self {
        let one = V::splat(1.0);
        let zero = V::splat(0.0);
        State {
            x: to_unit(x),
            y: to_unit(y),
            ox: zero,
            oy: zero,
            size: one,
            pdf: one,
        }
    }

    /// The warped point: the leaf's origin plus the rescaled point times its side, kept below
    /// the leaf's upper edge (module docs).
    #[inline(always)]
    fn finish(&self) -> (V, V) {
        let wx = (self.ox + self.x * self.size).min_of((self.ox + self.size).prev_float());
        let wy = (self.oy + self.y * self.size).min_of((self.oy + self.size).prev_float());
        (wx, wy)
    }
}

/// Maps NaN and negatives to 0 and values ≥ 1 to [`ONE_MINUS_EPS`].
#[inline(always)]
fn to_unit<V: Value>(v: V) -> V {
    V::select(v.ge(V::splat(0.0)), v, V::splat(0.0)).min_of(V::splat(ONE_MINUS_EPS))
}

/// One level of hierarchical warping (Clarberg et al. 2005), the kernel both widths share.
///
/// Readable form:
/// ```text
/// right = x >= px;          x = right ? (x - px) / (1 - px) : x / px
/// py = right ? py1 : py0
/// upper = y >= py;          y = upper ? (y - py) / (1 - py) : y / py
/// pdf *= 4 · P(x-half) · P(y-half | x-half);   size /= 2;   origin += (right, upper) · size
/// ```
/// The divisor is never zero for the half actually taken: `x < px` implies `px > 0`, and
/// `px ≤ x < 1` implies `1 − px > 0`.
#[inline(always)]
fn descend<V: Value>(s: &mut State<V>, px: V, py0: V, py1: V) -> (V::Mask, V::Mask) {
    let (one, zero) = (V::splat(1.0), V::splat(0.0));
    let right = s.x.ge(px);
    let fx = V::select(right, one - px, px);
    let x0 = V::select(right, px, zero);
    s.x = ((s.x - x0) / fx).min_of(V::splat(ONE_MINUS_EPS));
    let py = V::select(right, py1, py0);
    let upper = s.y.ge(py);
    let fy = V::select(upper, one - py, py);
    let y0 = V::select(upper, py, zero);
    s.y = ((s.y - y0) / fy).min_of(V::splat(ONE_MINUS_EPS));
    s.size = s.size * V::splat(0.5);
    s.ox = s.ox + V::select(right, s.size, zero);
    s.oy = s.oy + V::select(upper, s.size, zero);
    s.pdf = s.pdf * (fx * fy * V::splat(4.0));
    (right, upper)
}

#[inline(always)]
fn child_of(n: &Node, right: bool, upper: bool) -> usize {
    usize::from(n.child) + usize::from(right) + 2 * usize::from(upper)
}

/// Warps `u` ∈ [0,1)² through the guide: the scalar reference.
#[inline]
pub fn sample(guide: &Guide<'_>, u: [f32; 2]) -> Warped {
    debug_assert!(in_square(u), "sample point {u:?} outside [0,1)^2");
    let nodes = guide.nodes();
    let mut s = State::<f32>::new(u[0], u[1]);
    let mut n = &nodes[0];
    while n.child != 0 {
        let (right, upper) = descend(&mut s, n.px, n.py[0], n.py[1]);
        n = &nodes[child_of(n, right, upper)];
    }
    let (x, y) = s.finish();
    Warped {
        u: [x, y],
        pdf: s.pdf,
    }
}

/// The guide's density on the square at `w` ∈ [0,1)²; equals the `pdf` that [`sample`]
/// returns for the point it produces, bit for bit.
#[inline]
pub fn pdf(guide: &Guide<'_>, w: [f32; 2]) -> f32 {
    debug_assert!(in_square(w), "point {w:?} outside [0,1)^2");
    let nodes = guide.nodes();
    let (wx, wy) = (to_unit(w[0]), to_unit(w[1]));
    let (mut ox, mut oy, mut size, mut pdf) = (0f32, 0f32, 1f32, 1f32);
    let mut n = &nodes[0];
    while n.child != 0 {
        size *= 0.5;
        let right = wx >= ox + size;
        let fx = if right { 1.0 - n.px } else { n.px };
        let py = n.py[usize::from(right)];
        let upper = wy >= oy + size;
        let fy = if upper { 1.0 - py } else { py };
        ox += if right { size } else { 0.0 };
        oy += if upper { size } else { 0.0 };
        pdf *= fx * fy * 4.0;
        n = &nodes[child_of(n, right, upper)];
    }
    pdf
}

/// The inverse of [`sample`]: the `u` that warps to `w` (up to rounding, which grows with
/// the depth of `w`'s leaf; the tests bound it).
pub fn invert(guide: &Guide<'_>, w: [f32; 2]) -> [f32; 2] {
    debug_assert!(in_square(w), "point {w:?} outside [0,1)^2");
    let nodes = guide.nodes();
    let (wx, wy) = (to_unit(w[0]), to_unit(w[1]));
    // u = a + b·t, with t the point in the current node's frame.
    let (mut ax, mut ay, mut bx, mut by) = (0f32, 0f32, 1f32, 1f32);
    let (mut ox, mut oy, mut size) = (0f32, 0f32, 1f32);
    let mut n = &nodes[0];
    while n.child != 0 {
        size *= 0.5;
        let right = wx >= ox + size;
        if right {
            ax += bx * n.px;
            bx *= 1.0 - n.px;
            ox += size;
        } else {
            bx *= n.px;
        }
        let py = n.py[usize::from(right)];
        let upper = wy >= oy + size;
        if upper {
            ay += by * py;
            by *= 1.0 - py;
            oy += size;
        } else {
            by *= py;
        }
        n = &nodes[child_of(n, right, upper)];
    }
    let ux = ax + bx * ((wx - ox) / size);
    let uy = ay + by * ((wy - oy) / size);
    [to_unit(ux), to_unit(uy)]
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
    let mut s = State::<f32x8>::new(x, y);
    let mut n = &nodes[0];
    // Uniform fast path: every lane in node `n`, its values splatted.
    while n.child != 0 {
        let (px, py0, py1) = (
            f32x8::splat(n.px),
            f32x8::splat(n.py[0]),
            f32x8::splat(n.py[1]),
        );
        let (right, upper) = descend(&mut s, px, py0, py1);
        let (r, u) = (right.to_bitmask(), upper.to_bitmask());
        if (r == 0 || r == 0xff) && (u == 0 || u == 0xff) {
            n = &nodes[child_of(n, r != 0, u != 0)];
        } else {
            let idx = core::array::from_fn(|l| child_of(n, r >> l & 1 != 0, u >> l & 1 != 0));
            return per_lane(nodes, s, idx);
        }
    }
    let (x, y) = s.finish();
    Warped8 { x, y, pdf: s.pdf }
}

/// The divergent part of [`sample8`]: each lane has its own node; lanes that reached a leaf
/// keep their state (masked updates) while the others descend.
#[inline(never)]
fn per_lane(nodes: &[Node], mut s: State<f32x8>, mut idx: [usize; 8]) -> Warped8 {
    loop {
        let lane = |l: usize| &nodes[idx[l]];
        let active = f32x8::new(core::array::from_fn(|l| {
            if lane(l).child != 0 {
                f32::from_bits(u32::MAX)
            } else {
                0.0
            }
        }));
        if active.to_bitmask() == 0 {
            break;
        }
        let px = f32x8::new(core::array::from_fn(|l| lane(l).px));
        let py0 = f32x8::new(core::array::from_fn(|l| lane(l).py[0]));
        let py1 = f32x8::new(core::array::from_fn(|l| lane(l).py[1]));
        let before = s;
        let (right, upper) = descend(&mut s, px, py0, py1);
        s = State {
            x: active.select(s.x, before.x),
            y: active.select(s.y, before.y),
            ox: active.select(s.ox, before.ox),
            oy: active.select(s.oy, before.oy),
            size: active.select(s.size, before.size),
            pdf: active.select(s.pdf, before.pdf),
        };
        let (a, r, u) = (active.to_bitmask(), right.to_bitmask(), upper.to_bitmask());
        for (l, i) in idx.iter_mut().enumerate() {
            if a >> l & 1 != 0 {
                *i = child_of(&nodes[*i], r >> l & 1 != 0, u >> l & 1 != 0);
            }
        }
    }
    let (x, y) = s.finish();
    Warped8 { x, y, pdf: s.pdf }
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

    fn learned(storage: &mut [Node]) -> Guide<'_> {
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
        let mut st = [Node::default(); 1];
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
        let mut st = [Node::default(); 1024];
        let g = learned(&mut st);
        assert!(g.nodes().len() > 20);
        let mut rng = Pcg32::new(5, 9);
        let edge = [0.0, ONE_MINUS_EPS, 0.5, f32::from_bits(0x3effffff)];
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
        let mut st = [Node::default(); 1024];
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
    fn prev_float_agrees_across_widths() {
        for v in [1.0f32, 0.5, 0.75, 2f32.powi(-16), 0.3] {
            let p8 = f32x8::splat(v).prev_float().to_array();
            assert_eq!(p8[3], v.prev_float());
            assert!(v.prev_float() < v && v.prev_float().to_bits() + 1 == v.to_bits());
        }
    }
}
