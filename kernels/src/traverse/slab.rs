//! # traverse::slab: the slack that keeps every slab test conservative
//!
//! The widened interval `[tmin · (1 − 2⁻¹⁸), far · (1 + 2⁻¹⁸) + 2⁻¹²⁶]` that
//! [`box1`](super::scalar::box1) and the 8-wide box tests share, and the two forms of the wide
//! walks' slab test (docs/traverse.md, "Wide layout", "The fused slab test"):
//!
//! - **fused** ([`slab`], [`slab8`]), for rays whose inverse direction is finite: `p·inv − c`,
//!   one multiply-subtract a plane, the offsets `c = o·inv` moved an ulp outwards;
//! - **exact** ([`exact`]), for rays with an infinite inverse direction component:
//!   [`box1`](super::scalar::box1)'s `(p − o)·inv` with the true `±∞`, bit for bit, so the
//!   wide walks keep every box the binary walk keeps. (A finite stand-in for `∞` culled hits
//!   beyond its reach.)
//!
//! [`slab_of`], [`plane8`] and [`met8`] take the form as a `const` parameter, so each walk is
//! compiled once per form and chooses once a ray (or packet). A module of its own because the
//! per-ray constants of the triangle test ([`super::triangle`]) and the walks
//! ([`super::scalar`], [`super::packet_walk`], [`super::wide`]) all need it, and none of them needs
//! the others for it.

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
/// One axis of the wide walks' fused slab test: the plane distances are `t = p·inv − c`, one fused
/// multiply-subtract per plane where [`box1`](super::scalar::box1)'s `(p − o)·inv` takes a
/// subtraction and a product (Embree's fast kernels precompute `o·inv` so; it saved a fifth of the
/// wide packet walk's lane test, docs/traverse.md, "What each kept change bought"). Returns
/// `[inv, c_near, c_far]`: `c_near = o·inv + s` and `c_far = o·inv − s`, `s` =
/// [`OFFSET_SLACK`]`·|o·inv|`, so the near distance never exceeds `(p − o)·inv` and the far
/// one never falls below it, but for the rounding of the result, which [`FAR_UP`] covers. The
/// test stays conservative at any origin; its boxes grow by one to two ulps of the origin's
/// coordinate (four unfused). Where `o·inv` overflows, `c_far` (or `c_near`) is NaN and the
/// axis culls nothing (the max and min keep the other operand), as in
/// [`box1`](super::scalar::box1) at `0·∞`.
///
/// For a finite `inv` only: a ray with an infinite inverse (a direction component ±0, or so
/// small that its inverse overflows) takes the exact test ([`exact`], [`plane8`]), since no
/// finite stand-in for `∞` can be exact — `(p − o)·∞` is unbounded for any `p ≠ o`, a finite
/// scale times a tiny `p − o` is not (a stand-in `2¹⁰⁰` with a slack `2⁶⁰` culled hits beyond
/// `(hi − o)·2¹⁰⁰ + 2⁶⁰`). Here an infinite `inv` gives NaN or infinite offsets.
#[inline(always)]
pub(super) fn slab(o: f32, inv: f32) -> [f32; 3] {
    let c = o * inv;
    let s = c.abs() * OFFSET_SLACK;
    [inv, c + s, c - s]
}

/// [`slab`] for eight rays, the same operations lane for lane.
#[inline(always)]
pub(super) fn slab8(o: f32x8, inv: f32x8) -> [f32x8; 3] {
    let c = o * inv;
    let s = c.abs() * f32x8::splat(OFFSET_SLACK);
    [inv, c + s, c - s]
}

/// Whether a ray whose inverse direction is `inv` takes the exact slab test: some component
/// is infinite. Such rays are rare in a bake (a sampled direction component is seldom ±0), so
/// the walks are monomorphised over the form (`const EXACT: bool`), chosen once a ray or
/// packet, and the fused form's code is what it was without the choice.
#[inline(always)]
pub(super) fn exact(inv: &[f32; 3]) -> bool {
    inv.iter().any(|i| i.abs() == f32::INFINITY)
}

/// One axis's constants for the slab test of the form `EXACT`: [`slab`]'s `[inv, c_near,
/// c_far]`, or for the exact form `[inv, o, o]`.
#[inline(always)]
pub(super) fn slab_of<const EXACT: bool>(o: f32, inv: f32) -> [f32; 3] {
    if EXACT { [inv, o, o] } else { slab(o, inv) }
}

/// The distances of eight planes `p` along one axis from the constants `inv`, `c` of
/// [`slab_of`]: fused `p·inv − c`, or exact `(p − o)·inv` ([`box1`](super::scalar::box1)'s
/// operations, so its values bit for bit: with `inv = ±∞`, `±∞` for `p ≠ o` and NaN at `p = o`,
/// which the walks' `fast_max`/`fast_min` (`maxps`/`minps`: the second operand where either
/// is NaN) pass over as `box1`'s `if t > near` does).
#[inline(always)]
pub(super) fn plane8<const EXACT: bool>(p: f32x8, inv: f32x8, c: f32x8) -> f32x8 {
    if EXACT {
        (p - c) * inv
    } else {
        p.mul_sub(inv, c)
    }
}

/// Whether the entry distances `near` lie within the widened far bounds `far`: fused
/// ([`widened8`]) in the fused form, unfused ([`widened`], `box1`'s rounding) in the exact one,
/// so that the exact form keeps exactly the boxes [`box1`](super::scalar::box1) keeps.
#[inline(always)]
pub(super) fn met8<const EXACT: bool>(near: f32x8, far: f32x8) -> f32x8 {
    let far = if EXACT {
        far * f32x8::splat(FAR_UP) + f32x8::splat(FAR_FLOOR)
    } else {
        widened8(far)
    };
    near.simd_le(far)
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
