//! The wide tree's single-ray walks (paper §2.4's traversal, one ray): the eight child
//! boxes of a node in one 8-lane slab test ([`Ray1x8`]), the leaf's triangles eight at a
//! time from their rows; the any-hit walk of a subtree lane by lane for the packet walk
//! ([`occluded_alone`], Embree's hybrid switch), and unrelated rays walked interleaved
//! with prefetching ([`walk_interleaved_any`]).

use super::*;
use crate::packet::{LANES, mask_of, set_lanes};
use crate::traverse::slab::{exact, met8, plane8, slab_of};
use crate::traverse::triangle::{Pre1x8, occludes_rows};
use crate::traverse::{LEAF, NEAR_DOWN, Pre, Pre8};
use core::mem::MaybeUninit;
use wide::{f32x8, u32x8};

/// One ray's box-test constants ([`crate::traverse::slab`]) splatted over the eight children of a node,
/// for the slab test's fused form (`EXACT = false`) or its exact one (a ray with an infinite
/// inverse direction component, [`crate::traverse::slab::exact`]).
pub(in crate::traverse) struct Ray1x8<const EXACT: bool> {
    inv: [f32x8; 3],
    c_near: [f32x8; 3],
    c_far: [f32x8; 3],
    /// Axes whose near plane is `hi` (direction sign bit set). A branch per axis: picking
    /// the planes by row index, as the packet walk's lanes do, made the single-ray walks
    /// 10 % slower (docs/traverse.md, "Measured and dropped").
    neg: [bool; 3],
    tmin_down: f32x8,
}

impl<const EXACT: bool> Ray1x8<EXACT> {
    pub(in crate::traverse) fn new(pre: &Pre) -> Self {
        debug_assert!(
            EXACT || !exact(&pre.inv),
            "an infinite inverse takes the exact form"
        );
        let axes = [0, 1, 2].map(|a| slab_of::<EXACT>(pre.org[a], pre.inv[a]).map(f32x8::splat));
        Self {
            inv: axes.map(|[inv, _, _]| inv),
            c_near: axes.map(|[_, near, _]| near),
            c_far: axes.map(|[_, _, far]| far),
            neg: pre.inv.map(f32::is_sign_negative),
            tmin_down: f32x8::splat(pre.tmin * NEAR_DOWN),
        }
    }

    /// [`Ray1x8::new`] of lane `i` of a packet (traced), from the packet's constants, which
    /// equal the lane's scalar ones bit for bit ([`crate::traverse::slab8`]): no divisions.
    #[inline(always)]
    pub(in crate::traverse) fn lane(pre: &Pre8, i: usize) -> Self {
        debug_assert!(
            EXACT || pre.exact >> i & 1 == 0,
            "an infinite inverse: exact"
        );
        let at = |v: &f32x8| f32x8::splat(v.as_array()[i]);
        let (inv, c_near, c_far) = if EXACT {
            (&pre.inv, &pre.org, &pre.org)
        } else {
            (&pre.slab_inv, &pre.c_near, &pre.c_far)
        };
        Self {
            inv: inv.each_ref().map(at),
            c_near: c_near.each_ref().map(at),
            c_far: c_far.each_ref().map(at),
            neg: pre.neg.map(|m| m.to_bitmask() >> i & 1 == 1),
            tmin_down: at(&pre.tmin_down),
        }
    }

    /// The slab test ([`crate::traverse::slab`]) of the eight slots of `node` at once, the far bound
    /// widened ([`crate::traverse::slab::met8`]): the mask of slots met and their entry distances. In
    /// the exact form, [`box1`](crate::traverse::scalar::box1)'s slots and distances bit for bit.
    #[inline(always)]
    pub(super) fn boxes(&self, node: &WideNode, tmax: f32) -> (u8, f32x8) {
        let mut near = self.tmin_down;
        let mut far = f32x8::splat(tmax);
        for axis in 0..3 {
            let (lo, hi) = (f32x8::from(node.lo[axis]), f32x8::from(node.hi[axis]));
            let (pn, pf) = if self.neg[axis] { (hi, lo) } else { (lo, hi) };
            let tn = plane8::<EXACT>(pn, self.inv[axis], self.c_near[axis]);
            let tf = plane8::<EXACT>(pf, self.inv[axis], self.c_far[axis]);
            near = tn.fast_max(near);
            far = tf.fast_min(far);
        }
        (met8::<EXACT>(near, far).to_bitmask() as u8, near)
    }
}

/// [`walk1_with`] for the ray `pre`, in the slab test's form it needs
/// ([`crate::traverse::slab::exact`]): the closest-hit walk of a single ray.
pub(in crate::traverse) fn walk1<'a>(
    bvh: &WideRef<'a>,
    pre: &Pre,
    visit: impl FnMut(&'a [f32], usize) -> f32,
) -> f32 {
    if exact(&pre.inv) {
        walk1_with(bvh, &Ray1x8::<true>::new(pre), visit)
    } else {
        walk1_with(bvh, &Ray1x8::<false>::new(pre), visit)
    }
}

/// [`walk1_any_with`] for the ray `pre` from the root, in the slab test's form it needs
/// ([`crate::traverse::slab::exact`]): the any-hit walk of a single ray.
pub(in crate::traverse) fn walk1_any<'a>(
    bvh: &WideRef<'a>,
    pre: &Pre,
    tmax: f32,
    blocked: impl FnMut(&'a [f32], usize) -> bool,
) -> bool {
    if exact(&pre.inv) {
        walk1_any_with(bvh, &Ray1x8::<true>::new(pre), tmax, 0, blocked)
    } else {
        walk1_any_with(bvh, &Ray1x8::<false>::new(pre), tmax, 0, blocked)
    }
}

/// Depth-first walk of one ray, nearest child first. `visit` tests the leaf of `n` triangles
/// whose rows start at `rows[0]` and returns the ray's new `tmax` (−∞ stops the walk).
///
/// The stack ([`Stack8`]) holds each slot's child and meta with its entry distance beside
/// it, so a pop never reads the parent node again; a popped entry whose entry distance lies
/// beyond the widened `tmax` is skipped: exactly the slab test repeated with the new `tmax`.
pub(in crate::traverse) fn walk1_with<'a, const EXACT: bool>(
    bvh: &WideRef<'a>,
    ray: &Ray1x8<EXACT>,
    mut visit: impl FnMut(&'a [f32], usize) -> f32,
) -> f32 {
    let mut tmax = visit(&[], 0);
    let mut stack = Stack8::new();
    let mut index = 0;
    loop {
        let node = &bvh.nodes[index];
        let (bits, near) = ray.boxes(node, tmax);
        let n = bits.count_ones() as usize;
        // The nearest slot met is visited next; the others are pushed farthest first, sorted
        // as the packet walk sorts them (+4–8 % on single gather rays,
        // docs/traverse.md, "What each kept change bought").
        let mut next = match n {
            0 => None,
            1 => {
                let slot = bits.trailing_zeros() as usize;
                Some((node.child[slot], node.meta[slot]))
            }
            _ => {
                let hit = bytemuck::cast(mask_of(bits));
                let rows = [
                    u32x8::from(node.child),
                    u32x8::from(node.meta),
                    bytemuck::cast(near),
                    u32x8::ZERO,
                ];
                let (next, pushed) = stack.push_sorted(sorted_rows(near, hit, rows), n);
                // The nearest slot pushed is prefetched (every slot pushed, as before the sorting
                // network: +4–5 % on the city's single rays, −1 % in cache on the room).
                prefetch_entry(bvh, pushed.entry());
                Some((next.child, next.meta))
            }
        };
        loop {
            let (child, meta) = match next.take() {
                Some(e) => e,
                None => {
                    let Some(e) = stack.pop() else {
                        return tmax;
                    };
                    if e.dist > crate::traverse::widened(tmax) {
                        continue;
                    }
                    (e.child, e.meta)
                }
            };
            if meta == 0 {
                index = child as usize;
                break;
            }
            tmax = visit(bvh.leaf_rows(child), (meta & !LEAF) as usize);
            if tmax == f32::NEG_INFINITY {
                return tmax;
            }
        }
    }
}

/// Depth-first walk of one ray for any hit (occlusion) through the subtree of the entry
/// `start` (`child | meta << 32`; 0 for the whole tree): `blocked` tests the leaf of `n`
/// triangles whose rows start at `rows[0]`; the walk ends at the first leaf that blocks.
/// The slots met are taken in storage order, without a sort and without entry distances
/// on the stack: `tmax` never shrinks, so a popped entry is always still met (Embree's
/// any-hit traversal, `traverseAnyHit`). Returns whether a leaf blocked the ray.
pub(in crate::traverse) fn walk1_any_with<'a, const EXACT: bool>(
    bvh: &WideRef<'a>,
    ray: &Ray1x8<EXACT>,
    tmax: f32,
    start: u64,
    mut blocked: impl FnMut(&'a [f32], usize) -> bool,
) -> bool {
    let mut stack = Stack::<u64>::new();
    // The entry visited next: `start` first.
    let mut e = start;
    loop {
        let (child, meta) = (e as u32, (e >> 32) as u32);
        if meta == 0 {
            let node = &bvh.nodes[child as usize];
            let (bits, _) = ray.boxes(node, tmax);
            if bits != 0 {
                // [`slots_any_hit`] written out: through it (a closure pushing), the lanes of
                // the room's shadow packets walked 5 % slower (docs/traverse.md,
                // "Measured and dropped").
                let entry = |slot: u32| {
                    u64::from(node.child[slot as usize]) | u64::from(node.meta[slot as usize]) << 32
                };
                let leaves = !u32x8::from(node.meta).simd_eq(u32x8::ZERO).to_bitmask() as u8;
                let mut last = None;
                for group in [bits & !leaves, bits & leaves] {
                    let mut rest = group;
                    while rest != 0 {
                        let pushed = entry(rest.trailing_zeros());
                        rest &= rest - 1;
                        if let Some(p) = last.replace(pushed) {
                            prefetch_entry(bvh, p);
                            stack.push(p);
                        }
                    }
                }
                e = last.unwrap();
                continue;
            }
        } else if blocked(bvh.leaf_rows(child), (meta & !LEAF) as usize) {
            return true;
        }
        match stack.pop() {
            Some(next) => e = next,
            None => return false,
        }
    }
}

/// The lanes `lanes` of a packet as single rays looking for any hit ([`walk1_any_with`]), one
/// after another, each from the entry `entry` (`child | meta << 32`; 0 for the root), each in
/// the slab test's form it needs as a single ray ([`Pre8::exact`]): the lanes blocked.
pub(in crate::traverse) fn occluded_alone(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    lanes: u8,
    entry: u64,
) -> u8 {
    set_lanes(lanes).fold(0, |blocked, i| {
        let end = if pre.exact >> i & 1 == 1 {
            lane_any::<true>(bvh, pre, tmax, i, entry)
        } else {
            lane_any::<false>(bvh, pre, tmax, i, entry)
        };
        blocked | u8::from(end) << i
    })
}

/// Lane `i` of a packet as a single ray looking for any hit from the entry `entry`, in the
/// slab test's form `EXACT`: whether it is blocked.
#[inline(always)]
pub(super) fn lane_any<const EXACT: bool>(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    i: usize,
    entry: u64,
) -> bool {
    let pre1 = Pre1x8::lane(pre, i);
    let tmax = tmax.as_array()[i];
    walk1_any_with(
        bvh,
        &Ray1x8::<EXACT>::lane(pre, i),
        tmax,
        entry,
        |rows, n| occludes_rows(|| pre.lane(i), &pre1, rows, n, tmax),
    )
}

/// The slots `bits` (one or more) of `node` in the order an any-hit walk takes them: inner
/// nodes pushed first, then leaves (so a leaf is popped, and may end the walk, before another
/// subtree is opened), each group in storage order. `push` takes the entries
/// `child | meta << 32` but the last, which is returned: the one visited next.
#[inline(always)]
pub(super) fn slots_any_hit(node: &WideNode, bits: u8, mut push: impl FnMut(u64)) -> u64 {
    let entry = |slot: u32| {
        u64::from(node.child[slot as usize]) | u64::from(node.meta[slot as usize]) << 32
    };
    let leaves = !u32x8::from(node.meta).simd_eq(u32x8::ZERO).to_bitmask() as u8;
    let mut last = None;
    for group in [bits & !leaves, bits & leaves] {
        let mut rest = group;
        while rest != 0 {
            let pushed = entry(rest.trailing_zeros());
            rest &= rest - 1;
            if let Some(p) = last.replace(pushed) {
                push(p);
            }
        }
    }
    last.unwrap()
}

/// Layout size ([`WideRef::bytes`]) from which [`crate::traverse::occluded8`] interleaves the
/// single-ray walks of a packet whose lanes do not share an origin: 1 MiB, a core's L2 on the
/// measuring machine. Measured on two trees only (docs/traverse.md, "What falls
/// short"): on the Veach room (0.27 MB, in cache) interleaving costs 30–37 %, on the 1M-triangle
/// city (59 MB) it gains 1.9×.
pub const INTERLEAVE_BYTES: usize = 1 << 20;

/// The lanes `lanes` of a packet as single rays looking for any hit (occlusion), walked
/// interleaved: each round advances every unfinished lane by one node or leaf and prefetches
/// what that lane visits next, so the cache misses of the independent walks overlap (a single
/// walk waits for each node in turn). Each lane's walk is [`walk1_any`]'s: the slots met in
/// storage order, leaves first. `blocked(lane, pre, rows, n)` tests a leaf for one lane;
/// the lanes it blocks are returned as a bit mask. All lanes take the exact slab test when
/// one needs it ([`Pre8::exact`]), the fused one otherwise.
pub(in crate::traverse) fn walk_interleaved_any(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    lanes: u8,
    blocked: impl FnMut(usize, &Pre1x8, &[f32], usize) -> bool,
) -> u8 {
    if pre.exact & lanes != 0 {
        interleaved_any::<true>(bvh, pre, tmax, lanes, blocked)
    } else {
        interleaved_any::<false>(bvh, pre, tmax, lanes, blocked)
    }
}

/// [`walk_interleaved_any`] in the slab test's form `EXACT`.
pub(super) fn interleaved_any<const EXACT: bool>(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    lanes: u8,
    mut blocked: impl FnMut(usize, &Pre1x8, &[f32], usize) -> bool,
) -> u8 {
    let ray: [Option<(Ray1x8<EXACT>, Pre1x8)>; LANES] = core::array::from_fn(|i| {
        (lanes >> i & 1 == 1).then(|| (Ray1x8::lane(pre, i), Pre1x8::lane(pre, i)))
    });
    let tmax = tmax.to_array();
    let mut stacks: [[MaybeUninit<u64>; STACK]; LANES] =
        [const { [const { MaybeUninit::uninit() }; STACK] }; LANES];
    let mut sp = [0usize; LANES];
    // The entry each lane visits next (`child | meta << 32`): the root first.
    let mut next = [0u64; LANES];
    let mut active = lanes;
    let mut hit = 0;
    while active != 0 {
        for i in set_lanes(active) {
            let Some((r, consts)) = &ray[i] else {
                continue;
            };
            let (child, meta) = (next[i] as u32, (next[i] >> 32) as u32);
            let mut go = None;
            if meta == 0 {
                let node = &bvh.nodes[child as usize];
                let (bits, _) = r.boxes(node, tmax[i]);
                if bits != 0 {
                    go = Some(slots_any_hit(node, bits, |p| {
                        stacks[i][sp[i]].write(p);
                        sp[i] += 1;
                    }));
                }
            } else if blocked(i, consts, bvh.leaf_rows(child), (meta & !LEAF) as usize) {
                hit |= 1 << i;
                active &= !(1 << i);
                continue;
            }
            let e = go.or_else(|| {
                sp[i] = sp[i].checked_sub(1)?;
                // SAFETY: every entry below the previous `sp[i]` was written above.
                Some(unsafe { stacks[i][sp[i]].assume_init() })
            });
            let Some(e) = e else {
                active &= !(1 << i);
                continue;
            };
            prefetch_entry(bvh, e);
            next[i] = e;
        }
    }
    hit
}
