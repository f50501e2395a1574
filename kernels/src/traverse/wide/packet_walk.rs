//! The wide tree's packet walk (paper §2.4: eight rays): each live lane's slab test
//! against a node's eight boxes ([`boxes8`]), the children sorted by their nearest entry
//! ([`sort8_descending`], a sorting network), a shared stack of slots with their lanes
//! ([`Stack8`]), and the [`Visitor`] that says what a walk does at a leaf (the binary
//! tree's packet walk, [`crate::traverse::packet_walk`], implements it too).

use super::*;
use crate::packet::{LANES, mask_of, set_lanes};
use crate::traverse::slab::{met8, plane8};
use crate::traverse::triangle::{ROWS, RowTri, TriAt};
use crate::traverse::{LEAF, Pre8};
use wide::{f32x8, u32x8};

/// The box-test constants of a packet's lanes, read from its [`Pre8`], by lane (lane `i` at
/// index `i`), so a lane's test loads each of them with one scaled index; in the slab test's
/// form `EXACT` ([`crate::traverse::slab`]), the same for every lane.
pub(super) struct Lanes<const EXACT: bool> {
    /// [`crate::traverse::slab::slab_of`]'s constants per axis.
    inv: [[f32; LANES]; 3],
    c_near: [[f32; LANES]; 3],
    c_far: [[f32; LANES]; 3],
    /// Byte offsets within a [`WideNode`] of the rows of each lane's near and far planes per
    /// axis, `32·row` (`lo` x, y, z rows 0–2, `hi` rows 3–5): only [`Lanes::new`] writes
    /// them, and [`Lanes::row`] relies on them being such offsets.
    near: [[u32; LANES]; 3],
    far: [[u32; LANES]; 3],
    tmin_down: [f32; LANES],
}

/// Bytes of one row of a [`WideNode`]: the eight `lo` or `hi` values of one axis.
pub(super) const ROW_BYTES: u32 = 4 * WIDTH as u32;

impl<const EXACT: bool> Lanes<EXACT> {
    pub(super) fn new(pre: &Pre8) -> Self {
        let offsets = |far: bool| {
            [0, 1, 2].map(|a| {
                // 1 in the lanes whose direction has the sign bit set (near plane `hi`).
                let neg = bytemuck::cast::<f32x8, u32x8>(pre.neg[a]) >> 31;
                let hi = if far { u32x8::ONE - neg } else { neg };
                (u32x8::splat(a as u32) + hi * u32x8::splat(3)) * u32x8::splat(ROW_BYTES)
            })
        };
        let (inv, c_near, c_far) = if EXACT {
            (pre.inv, pre.org, pre.org)
        } else {
            (pre.slab_inv, pre.c_near, pre.c_far)
        };
        Self {
            inv: inv.map(f32x8::to_array),
            c_near: c_near.map(f32x8::to_array),
            c_far: c_far.map(f32x8::to_array),
            near: offsets(false).map(u32x8::to_array),
            far: offsets(true).map(u32x8::to_array),
            tmin_down: pre.tmin_down.to_array(),
        }
    }

    /// The row of `node` at the byte offset `off`, one of [`Lanes::near`] or [`Lanes::far`].
    /// (Indexing the rows by row number took an `and` and a shift per plane and lane: 12 of
    /// the 70 instructions of a lane's test, docs/traverse.md, "What each kept change bought".)
    #[inline(always)]
    fn row(node: &WideNode, off: u32) -> f32x8 {
        debug_assert!(off.is_multiple_of(ROW_BYTES) && off < 6 * ROW_BYTES);
        // SAFETY: `off` is `32·row` with `row < 6` (`Lanes::new` writes no other values), so
        // the 32 bytes read lie inside the 256-byte node; `[f32; 8]` needs the alignment of
        // `f32` only, which `off` (a multiple of 4) keeps.
        f32x8::from(unsafe {
            core::ptr::from_ref(node)
                .cast::<u8>()
                .add(off as usize)
                .cast::<[f32; WIDTH]>()
                .read()
        })
    }
}

/// `u32x8::splat(1 << i)` for lane `i`, as one load.
pub(super) const LANE_BIT: [[u32; WIDTH]; LANES] = {
    let mut bits = [[0; WIDTH]; LANES];
    let mut i = 0;
    while i < LANES {
        bits[i] = [1 << i; WIDTH];
        i += 1;
    }
    bits
};

/// The slab test of `node`'s eight slots for each lane of `live`, lane by lane (one `f32x8`
/// test per lane, [`Ray1x8::boxes`]' operations): per slot, the mask of lanes that meet it
/// (`u32` lanes) and the nearest of their entry distances (+∞ where none does).
#[inline(always)]
pub(super) fn boxes8<const EXACT: bool>(
    node: &WideNode,
    lanes: &Lanes<EXACT>,
    live: u8,
    tmax: &[f32; LANES],
) -> (u32x8, f32x8) {
    let inf = f32x8::splat(f32::INFINITY);
    let mut met = u32x8::ZERO;
    let mut nearest = inf;
    let mut test = |i: usize| {
        let mut near = f32x8::splat(lanes.tmin_down[i]);
        let mut far = f32x8::splat(tmax[i]);
        for axis in 0..3 {
            let pn = Lanes::<EXACT>::row(node, lanes.near[axis][i]);
            let pf = Lanes::<EXACT>::row(node, lanes.far[axis][i]);
            let inv = f32x8::splat(lanes.inv[axis][i]);
            near = plane8::<EXACT>(pn, inv, f32x8::splat(lanes.c_near[axis][i])).fast_max(near);
            far = plane8::<EXACT>(pf, inv, f32x8::splat(lanes.c_far[axis][i])).fast_min(far);
        }
        let m = met8::<EXACT>(near, far);
        nearest = m.select(near, inf).fast_min(nearest);
        met |= bytemuck::cast::<f32x8, u32x8>(m) & u32x8::from(LANE_BIT[i]);
    };
    // A node that all eight lanes reach is tested without the loop over set lanes, whose exit the
    // branch predictor misses once a node (city gather 0.90–0.94× → 0.97–1.00× Embree,
    // docs/traverse.md, "What each kept change bought"; the same for six or more lanes, the dead
    // ones tested with `tmax = −∞`, was no faster).
    if live == 0xff {
        for i in 0..LANES {
            test(i);
        }
    } else {
        for i in set_lanes(live) {
            test(i & 7);
        }
    }
    (met, nearest)
}

/// What a packet walk (the binary tree's, `crate::traverse::packet_walk`, and the wide one below) does at a
/// leaf.
pub(in crate::traverse) trait Visitor<'a> {
    /// The live lanes at most from which the wide walk finishes the subtree of an inner
    /// node lane by lane ([`Visitor::alone`]); 0: never. (The closest-hit walk never does:
    /// Embree's hybrid switch was measured and dropped there four times, docs/traverse.md,
    /// "Measured and dropped".)
    const ALONE: u32 = 0;

    /// Walks the subtree of the wide entry `entry` (`child | meta << 32`) for each lane of
    /// `lanes` alone; returns the packet's new `tmax`.
    fn alone(&mut self, _bvh: &WideRef<'a>, _lanes: u8, _entry: u64) -> f32x8 {
        unreachable!("ALONE is 0")
    }

    /// Tests a leaf's triangles for the packet, eight lanes per test; returns the packet's
    /// new `tmax` (−∞ in finished lanes).
    fn leaf8<T: TriAt>(&mut self, leaf: impl Iterator<Item = T>) -> f32x8;

    /// Tests the wide leaf of `n` triangles whose rows start at `rows[0]` for each lane of
    /// `lanes`, eight triangles per pass; returns the packet's new `tmax`.
    fn rows1(&mut self, rows: &'a [f32], n: usize, lanes: u8) -> f32x8;
}

/// Depth-first walk of a packet: a shared stack ([`Stack8`]) of slots, each with the lanes
/// whose interval met its box when it was pushed; the children a node's live lanes meet are
/// sorted by the nearest entry distance among their lanes ([`sort8_descending`]), the
/// nearest visited next and the others pushed farthest first. A node is tested lane by lane,
/// eight slots at a time ([`boxes8`]): only the live lanes are tested, and a packet's lanes
/// drift apart deeper in the tree. (Measured against testing slot by slot, eight lanes at a
/// time, against one frustum test for a shared-origin packet, and against a frustum test
/// choosing the slots then tested eight lanes at a time: docs/traverse.md,
/// "Measured and dropped".) A popped inner node that at most [`Visitor::ALONE`] live lanes reach is
/// handed to [`Visitor::alone`] (any-hit walks only: docs/traverse.md, "Wide layout").
pub(in crate::traverse) fn walk8<'a, V: Visitor<'a>>(
    bvh: &WideRef<'a>,
    pre: &Pre8,
    tmax: f32x8,
    visitor: &mut V,
) {
    // A packet with a lane that needs the exact slab test takes it in every lane (lanes of a
    // packet are tested alike; the exact test keeps a subset of the fused one's boxes, and
    // both keep every box `box1` keeps).
    if pre.exact != 0 {
        walk8_with::<V, true>(bvh, pre, tmax, visitor);
    } else {
        walk8_with::<V, false>(bvh, pre, tmax, visitor);
    }
}

/// [`walk8`] in the slab test's form `EXACT`.
pub(super) fn walk8_with<'a, V: Visitor<'a>, const EXACT: bool>(
    bvh: &WideRef<'a>,
    pre: &Pre8,
    mut tmax: f32x8,
    visitor: &mut V,
) {
    let lanes = Lanes::<EXACT>::new(pre);
    let mut stack = Stack8::new();
    let mut alive = pre.traced;
    let mut index = 0usize;
    let mut live = alive;
    let mut far = widened_largest(tmax, alive);
    loop {
        let node = &bvh.nodes[index];
        let (met, nearest) = boxes8(node, &lanes, live, tmax.as_array());
        // The slots met sorted farthest first without a branch: the first `n − 1` pushed,
        // the nearest visited next. (Sorted by insertion, the sort's and the pushes' branches
        // were two fifths of the walk's mispredictions on the city: callgrind's model,
        // docs/traverse.md, "What each kept change bought".)
        let hit = !met.simd_eq(u32x8::ZERO);
        let n = hit.to_bitmask().count_ones() as usize;
        let mut next = (n > 0).then(|| {
            let rows = [
                u32x8::from(node.child),
                u32x8::from(node.meta),
                bytemuck::cast(nearest),
                met,
            ];
            let (next, pushed) = stack.push_sorted(sorted_rows(nearest, hit, rows), n);
            // The nearest entry pushed is prefetched: the walk comes back to it after the
            // nearest subtree (docs/traverse.md).
            prefetch_entry(bvh, pushed.entry());
            next
        });
        loop {
            let e = match next.take() {
                Some(e) => e,
                None => {
                    let Some(e) = stack.pop() else {
                        return;
                    };
                    // Beyond every live lane's widened `tmax`: the slab tests repeated
                    // would all fail.
                    if e.dist > far {
                        continue;
                    }
                    e
                }
            };
            let (child, meta) = (e.child, e.meta);
            live = e.lanes & alive;
            if live == 0 {
                continue;
            }
            tmax = if meta != 0 {
                let n = (meta & !LEAF) as usize;
                let rows = bvh.leaf_rows(child);
                if rows_for(live, meta) {
                    visitor.rows1(rows, n, live)
                } else {
                    let leaf = &rows[..ROWS * n];
                    visitor.leaf8((0..n).map(|i| RowTri::new(leaf, n, i)))
                }
            } else if live.count_ones() <= V::ALONE {
                visitor.alone(bvh, live, e.entry())
            } else {
                index = child as usize;
                break;
            };
            alive = pre.tmin.simd_le(tmax).to_bitmask() as u8;
            if alive == 0 {
                return;
            }
            far = widened_largest(tmax, alive);
        }
    }
}

/// Whether the packet walk tests the leaf `meta` for the lanes `live` lane by lane, eight
/// triangles per pass on its rows: when that takes fewer passes than triangle by triangle,
/// eight lanes per test on its [`Tri`]s.
#[inline(always)]
pub(super) fn rows_for(live: u8, meta: u32) -> bool {
    let n = (meta & !LEAF) as usize;
    live.count_ones() as usize * n.div_ceil(8) < n
}

/// The widened far bound of the largest `tmax` among the lanes of `alive`, without a branch:
/// a branch per lane on `alive` mispredicted wherever lanes finish at random, as shadow lanes
/// do (the room's shadow packets 1.00× → 1.21–1.23× Embree, docs/traverse.md,
/// "What each kept change bought").
#[inline(always)]
pub(super) fn widened_largest(tmax: f32x8, alive: u8) -> f32 {
    let t = mask_of(alive)
        .select(tmax, f32x8::splat(f32::NEG_INFINITY))
        .to_array();
    // Without `f32::max`'s NaN handling: an alive lane's `tmax` is never NaN.
    let max = |x: f32, y: f32| if x > y { x } else { y };
    let [a, b, c, d] = [0, 1, 2, 3].map(|i| max(t[i], t[i + 4]));
    crate::traverse::widened(max(max(a, c), max(b, d)))
}

#[cfg(test)]
mod tests {

    use super::*;

    /// The sorting network sorts every 0–1 input (so, by the 0–1 principle, every input)
    /// and random keys with ties, as `sort` does.
    #[test]
    fn the_network_sorts_eight_keys_descending() {
        let check = |keys: [u32; WIDTH]| {
            let mut want = keys;
            want.sort_unstable_by(|a, b| b.cmp(a));
            assert_eq!(
                sort8_descending(u32x8::from(keys)).to_array(),
                want,
                "{keys:?}"
            );
        };
        for bits in 0..=255u32 {
            check(core::array::from_fn(|i| bits >> i & 1));
        }
        let mut rng = crate::testing::Pcg32::new(7, 1);
        for _ in 0..10_000 {
            let range = [4, 1 << 16, u32::MAX][rng.next_u32() as usize % 3];
            check(core::array::from_fn(|_| rng.next_u32() % range));
        }
    }

    #[test]
    fn permute_takes_each_lanes_index() {
        let v = u32x8::from([10, 11, 12, 13, 14, 15, 16, 17]);
        let idx = [7, 0, 3, 3, 9, 1, 6, 2];
        let want = idx.map(|i| 10 + (i & 7));
        assert_eq!(permute(v, u32x8::from(idx)).to_array(), want);
    }
}
