//! # traverse::scalar: the conservative slab test and the single-ray walk of the binary tree
//!
//! [`box1`] is the reference slab test, which the binary tree's walks reproduce (8-wide in
//! [`super::packet`]); the wide tree's walks ([`super::bvh8`]) test their boxes in the fused
//! form [`slab`] sets up, as conservative as [`box1`] and a few ulps looser. [`walk1`] is the
//! scalar reference traversal of the binary layout.

use super::triangle::Pre;
use super::{BvhRef, Node, STACK, Tri};
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
/// and 12 % more nodes visited on the 1M-triangle city, docs/traverse.md, session 19.)
/// Unfused (no FMA), the rounding of `p·inv` adds up to an ulp of `o·inv` again.
#[cfg(all(target_feature = "avx", target_feature = "fma"))]
const OFFSET_SLACK: f32 = 1.0 / (1u32 << 24) as f32 + 1.0 / (1u32 << 30) as f32;
#[cfg(not(all(target_feature = "avx", target_feature = "fma")))]
const OFFSET_SLACK: f32 = 1.0 / (1u32 << 22) as f32;
/// Stand-in for an infinite inverse direction (a direction component of ±0, or so small that
/// its inverse overflows): `p·2¹⁰⁰ − o·2¹⁰⁰` has the sign of `p − o`, and `o·2¹⁰⁰` is exact
/// for `|o| < 2²⁸`.
const INV_HUGE: f32 = (1u128 << 100) as f32;
/// Offset slack on such an axis, `2⁻⁴⁰·2¹⁰⁰`: a ray lying in a box face's plane (`p = o`, even
/// at `o = 0`, where `o·inv` has no ulp to move by) is kept, as [`box1`] keeps it
/// (`(p − o)·∞` is NaN there).
const HUGE_SLACK: f32 = (1u64 << 60) as f32;

/// One axis of the wide walks' fused slab test: the plane distances are `t = p·inv − c`, one
/// fused multiply-subtract per plane where [`box1`]'s `(p − o)·inv` takes a subtraction and a
/// product (Embree's fast kernels precompute `o·inv` so; it saved a fifth of the wide packet
/// walk's lane test, docs/traverse.md, session 19). Returns `[inv, c_near, c_far]`:
/// `c_near = o·inv + s` and `c_far = o·inv − s`, `s` = [`OFFSET_SLACK`]`·|o·inv|`, so the near
/// distance never exceeds `(p − o)·inv` and the far one never falls below it, but for the
/// rounding of the result, which [`FAR_UP`] covers. The test stays conservative at any origin;
/// its boxes grow by one to two ulps of the origin's coordinate (four unfused). An infinite
/// `inv` becomes ±[`INV_HUGE`] with [`HUGE_SLACK`] added to `s`; where `o·inv` overflows,
/// `c_near` or `c_far` is NaN and the axis culls nothing (the max and min keep the other
/// operand), as in [`box1`] at `0·∞`.
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

/// Entry distance of slot `slot` if the ray's `[tmin, tmax]` meets its box.
///
/// Slab planes are taken in the order of the direction's sign bits (near plane first) and a
/// plane whose distance is NaN (`0 · ∞`: the ray runs inside that plane) does not constrain the
/// interval, so rays along a box face are kept. `if t > near` keeps `near` for NaN `t`, as
/// `_mm256_max_ps(t, near)` does in [`Pre8::box8`].
pub(super) fn box1(node: &Node, slot: usize, pre: &Pre, tmax: f32) -> Option<f32> {
    let lo = [0, 1, 2].map(|axis| node.lo[axis][slot]);
    let hi = [0, 1, 2].map(|axis| node.hi[axis][slot]);
    box1_at((lo, hi), pre, tmax)
}

/// [`box1`] for the box `(lo, hi)`.
pub(super) fn box1_at((lo, hi): ([f32; 3], [f32; 3]), pre: &Pre, tmax: f32) -> Option<f32> {
    let mut near = pre.tmin * NEAR_DOWN;
    let mut far = tmax;
    for axis in 0..3 {
        let (lo, hi) = (lo[axis], hi[axis]);
        let (pn, pf) = if pre.inv[axis].is_sign_negative() {
            (hi, lo)
        } else {
            (lo, hi)
        };
        let tn = (pn - pre.org[axis]) * pre.inv[axis];
        let tf = (pf - pre.org[axis]) * pre.inv[axis];
        near = if tn > near { tn } else { near };
        far = if tf < far { tf } else { far };
    }
    (near <= widened(far)).then_some(near)
}

/// Depth-first walk of one ray through the binary tree, nearer child first. `visit` tests a
/// leaf's triangles and returns the ray's new `tmax` (−∞ stops the walk).
pub(super) fn walk1<'a>(
    bvh: &BvhRef<'a>,
    pre: &Pre,
    mut visit: impl FnMut(&'a [Tri]) -> f32,
) -> f32 {
    let mut tmax = visit(&[]);
    let mut stack = [(0u32, 0u32); STACK];
    let mut sp = 1;
    while sp > 0 {
        sp -= 1;
        let (child, meta) = stack[sp];
        if meta != 0 {
            tmax = visit(bvh.leaf(child, meta));
            if tmax == f32::NEG_INFINITY {
                break;
            }
            continue;
        }
        let node = &bvh.nodes[child as usize];
        let entry = |slot: usize| (node.child[slot], node.meta[slot]);
        match (box1(node, 0, pre, tmax), box1(node, 1, pre, tmax)) {
            (Some(n0), Some(n1)) => {
                let (near, far) = if n1 < n0 { (1, 0) } else { (0, 1) };
                stack[sp] = entry(far);
                stack[sp + 1] = entry(near);
                sp += 2;
            }
            (Some(_), None) => {
                stack[sp] = entry(0);
                sp += 1;
            }
            (None, Some(_)) => {
                stack[sp] = entry(1);
                sp += 1;
            }
            (None, None) => {}
        }
    }
    tmax
}
