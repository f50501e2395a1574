//! # traverse::packet_walk: the 8-lane slab test and the packet walk of the binary tree
//!
//! One shared stack of `(child, meta)` entries with the mask of lanes that met each entry's
//! box; when both children are met, the lanes meeting both vote with their entry distances for
//! the one visited first. Leaves are tested by a [`Visitor`] (closest hit or occlusion), which
//! the wide walk ([`super::wide`], whose packet walk holds the trait: its any-hit switch hands
//! a subtree to the wide single-ray walk) shares.

use super::slab::widened8;
use super::triangle::{
    Best8, Pre1x8, Pre8, TriAt, closest_rows, closest8, occludes_rows, occludes8, set_lane,
};
use super::wide::{Visitor, WideRef};
use super::{BinaryNode, BvhRef, STACK};
use crate::packet::{Ray8, mask_of, set_lanes};
use wide::f32x8;

impl Pre8 {
    /// Lanes whose interval meets slot `slot`'s box, and their entry distances: [`box1`] for
    /// eight lanes, near planes picked once per packet when all lanes share the direction
    /// signs (a coherent packet), per lane otherwise.
    #[inline(always)]
    pub(super) fn box8(&self, node: &BinaryNode, slot: usize, tmax: f32x8) -> (f32x8, f32x8) {
        let lo = [0, 1, 2].map(|axis| node.lo[axis][slot]);
        let hi = [0, 1, 2].map(|axis| node.hi[axis][slot]);
        self.box8_at(lo, hi, tmax)
    }

    /// [`Pre8::box8`] for the box `lo`, `hi`.
    #[inline(always)]
    pub(super) fn box8_at(&self, lo: [f32; 3], hi: [f32; 3], tmax: f32x8) -> (f32x8, f32x8) {
        let mut near = self.tmin_down;
        let mut far = tmax;
        for axis in 0..3 {
            let (lo, hi) = (lo[axis], hi[axis]);
            let (pn, pf) = match self.octant {
                Some(neg) if neg[axis] => (f32x8::splat(hi), f32x8::splat(lo)),
                Some(_) => (f32x8::splat(lo), f32x8::splat(hi)),
                None => {
                    let (lo, hi) = (f32x8::splat(lo), f32x8::splat(hi));
                    (
                        self.neg[axis].bitselect(hi, lo),
                        self.neg[axis].bitselect(lo, hi),
                    )
                }
            };
            let tn = (pn - self.org[axis]) * self.inv[axis];
            let tf = (pf - self.org[axis]) * self.inv[axis];
            // fast_max(a, b) is maxps(a, b): `b` when either is NaN, like `box1`.
            near = tn.fast_max(near);
            far = tf.fast_min(far);
        }
        (near.simd_le(widened8(far)), near)
    }

    /// Whether every traced lane has the same origin (bit for bit), as a texel's gather or
    /// next-event packet does.
    pub(super) fn shared_origin(&self) -> bool {
        let lead = self.traced.trailing_zeros().min(7) as usize;
        self.org.iter().all(|o| {
            let bits: wide::u32x8 = bytemuck::cast(*o);
            let same = bits.simd_eq(wide::u32x8::splat(bits.as_array()[lead]));
            let same: f32x8 = bytemuck::cast(same);
            same.to_bitmask() as u8 & self.traced == self.traced
        })
    }
}

/// Closest-hit visitor.
pub(super) struct Closest<'p> {
    pub(super) pre: &'p Pre8,
    pub(super) best: Best8,
}

impl<'a> Visitor<'a> for Closest<'_> {
    #[inline(always)]
    fn leaf8<T: TriAt>(&mut self, leaf: impl Iterator<Item = T>) -> f32x8 {
        for tri in leaf {
            closest8(self.pre, tri, &mut self.best);
        }
        self.best.t
    }

    #[inline(always)]
    fn rows1(&mut self, rows: &'a [f32], n: usize, lanes: u8) -> f32x8 {
        for i in set_lanes(lanes) {
            let mut best = self.best.lane(i);
            closest_rows(
                || self.pre.lane(i),
                &Pre1x8::lane(self.pre, i),
                rows,
                n,
                &mut best,
            );
            set_lane(&mut self.best, i, &best);
        }
        self.best.t
    }
}

/// Occlusion visitor: a blocked lane's `tmax` becomes −∞.
pub(super) struct Occlusion<'p> {
    pub(super) pre: &'p Pre8,
    pub(super) tmax: f32x8,
    pub(super) blocked: u8,
}

impl<'a> Visitor<'a> for Occlusion<'_> {
    /// Two: the room's shadow packets of unrelated lanes ran at 1.20–1.22× Embree's
    /// `rtcOccluded8` with the switch at two lanes and at 1.18–1.19× without it; T = 1, 3, 4
    /// came within 0.02 of two (docs/traverse.md, "What each kept change bought").
    const ALONE: u32 = 2;

    #[inline(always)]
    fn alone(&mut self, bvh: &WideRef<'a>, lanes: u8, entry: u64) -> f32x8 {
        let blocked = super::wide::occluded_alone(bvh, self.pre, self.tmax, lanes, entry);
        self.blocked |= blocked;
        self.tmax = mask_of(blocked).bitselect(f32x8::splat(f32::NEG_INFINITY), self.tmax);
        self.tmax
    }

    #[inline(always)]
    fn leaf8<T: TriAt>(&mut self, leaf: impl Iterator<Item = T>) -> f32x8 {
        for tri in leaf {
            let bits = occludes8(self.pre, tri, self.tmax);
            if bits != 0 {
                self.blocked |= bits;
                self.tmax = mask_of(bits).bitselect(f32x8::splat(f32::NEG_INFINITY), self.tmax);
                if self.blocked == self.pre.traced {
                    break;
                }
            }
        }
        self.tmax
    }

    #[inline(always)]
    fn rows1(&mut self, rows: &'a [f32], n: usize, lanes: u8) -> f32x8 {
        for i in set_lanes(lanes) {
            let tmax = self.tmax.as_array()[i];
            if occludes_rows(
                || self.pre.lane(i),
                &Pre1x8::lane(self.pre, i),
                rows,
                n,
                tmax,
            ) {
                self.blocked |= 1 << i;
                self.tmax.as_mut_array()[i] = f32::NEG_INFINITY;
            }
        }
        self.tmax
    }
}

/// Depth-first walk of a packet through the binary tree: a shared stack of `(child, meta)`
/// entries with `lanes`, the bit mask of lanes whose interval met the entry's box when it was
/// pushed. When both children are met, the lanes meeting both vote with their entry
/// distances for the one visited first.
pub(super) fn walk8<'a>(
    bvh: &BvhRef<'a>,
    pre: &Pre8,
    mut tmax: f32x8,
    visitor: &mut impl Visitor<'a>,
) {
    // Entries as `child | meta << 32` and lane masks in two plain arrays: zeroing them is a
    // short memset (a tuple array with padding cost ~10% of the walk in stores).
    let mut stack = [0u64; STACK];
    let mut lanes_of = [0u8; STACK];
    lanes_of[0] = pre.traced;
    let mut sp = 1;
    let mut alive = pre.traced;
    while sp > 0 {
        sp -= 1;
        let (child, meta, lanes) = (stack[sp] as u32, (stack[sp] >> 32) as u32, lanes_of[sp]);
        if meta != 0 {
            tmax = visitor.leaf8(bvh.leaf(child, meta).iter());
            alive = pre.tmin.simd_le(tmax).to_bitmask() as u8;
            if alive == 0 {
                return;
            }
            continue;
        }
        if lanes & alive == 0 {
            continue;
        }
        let node = &bvh.nodes[child as usize];
        let (m0, n0) = pre.box8(node, 0, tmax);
        let (m1, n1) = pre.box8(node, 1, tmax);
        let (b0, b1) = (m0.to_bitmask() as u8, m1.to_bitmask() as u8);
        let entry = |slot: usize| u64::from(node.child[slot]) | u64::from(node.meta[slot]) << 32;
        match (b0 != 0, b1 != 0) {
            (true, true) => {
                let closer1 = (n1.simd_lt(n0) & m0 & m1).to_bitmask().count_ones();
                let (near, far) = if 2 * closer1 > (b0 & b1).count_ones() {
                    (1, 0)
                } else {
                    (0, 1)
                };
                let bits = [b0, b1];
                stack[sp] = entry(far);
                lanes_of[sp] = bits[far];
                stack[sp + 1] = entry(near);
                lanes_of[sp + 1] = bits[near];
                sp += 2;
            }
            (true, false) => {
                stack[sp] = entry(0);
                lanes_of[sp] = b0;
                sp += 1;
            }
            (false, true) => {
                stack[sp] = entry(1);
                lanes_of[sp] = b1;
                sp += 1;
            }
            (false, false) => {}
        }
    }
}

/// A packet's constants and its starting `tmax` (`min(tmax, f32::MAX)`, −∞ in lanes not
/// traced), or `None` when no lane is traced. Inlined with [`Pre8::new`], so the constants
/// (about 800 bytes) are built in place rather than returned through memory: 2–4 % more room
/// gather and shadow packets a second (docs/traverse.md, "What each kept change bought").
#[inline(always)]
pub(super) fn start8(rays: &Ray8) -> Option<(Pre8, f32x8)> {
    let pre = Pre8::new(rays);
    if pre.traced == 0 {
        return None;
    }
    let tmax = mask_of(pre.traced).bitselect(
        rays.tmax.fast_min(f32x8::splat(f32::MAX)),
        f32x8::splat(f32::NEG_INFINITY),
    );
    Some((pre, tmax))
}
