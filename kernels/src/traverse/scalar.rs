//! # traverse::scalar: the conservative slab test and the single-ray walk of the binary tree
//!
//! [`box1`] is the reference slab test, which the binary tree's walks reproduce (8-wide in
//! [`super::packet_walk`]); the wide tree's walks ([`super::wide`]) test their boxes in the fused
//! form [`slab`](super::slab::slab) sets up, as conservative as [`box1`] and a few ulps looser.
//! [`walk1`] is the scalar reference traversal of the binary layout. The slab test's slack
//! lives in [`super::slab`].

use super::slab::{NEAR_DOWN, widened};
use super::triangle::Pre;
use super::{BinaryNode, BvhRef, STACK, Tri};

/// Entry distance of slot `slot` if the ray's `[tmin, tmax]` meets its box.
///
/// Slab planes are taken in the order of the direction's sign bits (near plane first) and a
/// plane whose distance is NaN (`0 · ∞`: the ray runs inside that plane) does not constrain the
/// interval, so rays along a box face are kept. `if t > near` keeps `near` for NaN `t`, as
/// `_mm256_max_ps(t, near)` does in [`Pre8::box8`].
pub(super) fn box1(node: &BinaryNode, slot: usize, pre: &Pre, tmax: f32) -> Option<f32> {
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
