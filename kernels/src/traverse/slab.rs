//! # traverse::slab: the slack that keeps every slab test conservative
//!
//! The widened interval `[tmin · (1 − 2⁻¹⁸), far · (1 + 2⁻¹⁸) + 2⁻¹²⁶]` that
//! [`box1`](super::scalar::box1) and the 8-wide box tests share, and the fused form's per-ray
//! constants ([`slab`], [`slab8`]): the plane offsets `o·(1/d)` moved an ulp outwards
//! (docs/traverse.md, "Wide layout", "The fused slab test"). A module of its own because the
//! per-ray constants of the triangle test ([`super::triangle`]) and the walks ([`super::scalar`],
//! [`super::packet`], [`super::bvh8`]) all need it, and none of them needs the others for it.

use wide::f32x8;

/// Slack of the conservative slab test: the box interval is widened to
/// `[tmin · (1 − 2⁻¹⁸), min(far, tmax) · (1 + 2⁻¹⁸)]`. pbrt-v4's `1 + 2γ₃` (§6.8.2, about 3 ulps)
/// covers the slab arithmetic; the triangle test's own rounding of `t` can put a hit that the
/// oracle accepts at `t = tmax` (or `tmin`) a few ulps beyond a box face, so we keep 32 ulps.
pub(super) const SLACK: f32 = 1.0 / (1u32 << 18) as f32;
pub(super) const FAR_UP: f32 = 1.0 + SLACK;
pub(super) const NEAR_DOWN: f32 = 1.0 - SLACK;
/// Absolute slack added to the widened far bound: a relative one is nothing at `far = ±0`,
/// where a box entered at a subnormal distance (an origin of 10⁻⁴³ against a box face at 0)
/// was culled although its triangle's test rounds the hit to `t = 0` (found by the
/// `traverse` fuzz target: a closest hit at `t = −0` hid another at `t = +0` with a smaller
/// primitive id, which the tie rule prefers).
pub(super) const FAR_FLOOR: f32 = f32::MIN_POSITIVE;

/// Slack of [`slab`]'s plane offsets, relative to `|o·inv|`. With a fused multiply-subtract
/// the only error beyond the result's own rounding is that of `o·inv`, half an ulp of it: a
/// shade over half an ulp moves each offset by one ulp. (`2⁻²¹` left gather origins, lifted
/// 2–4 ulps off a box face by `offset_origin`, inside the box they leave: 2 % more slots met
/// and 12 % more nodes visited on the 1M-triangle city, docs/traverse.md, "Measured and dropped".)
/// Unfused (no FMA), the rounding of `p·inv` adds up to an ulp of `o·inv` again.
#[cfg(all(target_feature = "avx", target_feature = "fma"))]
const OFFSET_SLACK: f32 = 1.0 / (1u32 << 24) as f32 + 1.0 / (1u32 << 30) as f32;
#[cfg(not(all(target_feature = "avx", target_feature = "fma")))]
const OFFSET_SLACK: f32 = 1.0 / (1u32 << 22) as f32;
/// Stand-in for an infinite inverse direction (a direction component of ±0, or so small that
/// its inverse overflows): `p·2¹⁰⁰ − o·2¹⁰⁰` has the sign of `p − o`, and `o·2¹⁰⁰` is exact
/// for `|o| < 2²⁸`.
const INV_HUGE: f32 = (1u128 << 100) as f32;
/// Offset slack on such an axis, `2⁻⁴⁰·2¹⁰⁰`: a ray lying in a box face's plane (`p = o`, even at
/// `o = 0`, where `o·inv` has no ulp to move by) is kept, as [`box1`](super::scalar::box1) keeps it
/// (`(p − o)·∞` is NaN there).
const HUGE_SLACK: f32 = (1u64 << 60) as f32;

/// One axis of the wide walks' fused slab test: the plane distances are `t = p·inv − c`, one fused
/// multiply-subtract per plane where [`box1`](super::scalar::box1)'s `(p − o)·inv` takes a
/// subtraction and a product (Embree's fast kernels precompute `o·inv` so; it saved a fifth of the
/// wide packet walk's lane test, docs/traverse.md, "What each kept change bought"). Returns
/// `[inv, c_near, c_far]`: `c_near = o·inv + s` and `c_far = o·inv − s`, `s` =
/// [`OFFSET_SLACK`]`·|o·inv|`, so the near distance never exceeds `(p − o)·inv` and the far one never falls below it, but for
/// the rounding of the result, which [`FAR_UP`] covers. The test stays conservative at any origin;
/// its boxes grow by one to two ulps of the origin's coordinate (four unfused). An infinite `inv`
/// becomes ±[`INV_HUGE`] with [`HUGE_SLACK`] added to `s`; where `o·inv` overflows, `c_near` or
/// `c_far` is NaN and the axis culls nothing (the max and min keep the other operand), as in
/// [`box1`](super::scalar::box1) at `0·∞`.
#[inline(always)]
pub(super) fn slab(o: f32, inv: f32) -> [f32; 3] {
    let infinite = inv.abs() == f32::INFINITY;
    let inv = if infinite {
        INV_HUGE.copysign(inv)
    } else {
        inv
    };
    let c = o * inv;
    let s = c.abs() * OFFSET_SLACK + if infinite { HUGE_SLACK } else { 0.0 };
    [inv, c + s, c - s]
}

/// [`slab`] for eight rays, the same operations lane for lane.
#[inline(always)]
pub(super) fn slab8(o: f32x8, inv: f32x8) -> [f32x8; 3] {
    let infinite = inv.abs().simd_eq(f32x8::splat(f32::INFINITY));
    let inv = infinite.select(f32x8::splat(INV_HUGE).copysign(inv), inv);
    let c = o * inv;
    let s = c.abs() * f32x8::splat(OFFSET_SLACK) + (infinite & f32x8::splat(HUGE_SLACK));
    [inv, c + s, c - s]
}

/// The far end of the conservative slab interval: `far · (1 + 2⁻¹⁸) + 2⁻¹²⁶`.
#[inline(always)]
pub(super) fn widened(far: f32) -> f32 {
    far * FAR_UP + FAR_FLOOR
}

/// [`widened`] for eight far bounds, fused (the 8-wide slab tests' form; a fused `far · (1 +
/// 2⁻¹⁸) + 2⁻¹²⁶` rounds once, well inside the slack).
#[inline(always)]
pub(super) fn widened8(far: f32x8) -> f32x8 {
    far.mul_add(f32x8::splat(FAR_UP), f32x8::splat(FAR_FLOOR))
}
