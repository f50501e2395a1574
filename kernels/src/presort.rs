//! `presort`: presorted coherent packets of 8 (Silvennoinen & Sloan 2019, §2.4, Figure 3).
//!
//! For a fixed sample count N, the first N Sobol points ([`crate::sobol`]) are ordered by a
//! quadtree over [0,1)² whose leaves hold fewer than 8 points, leaves in traversal order.
//! Consecutive groups of 8 then lie close together in the square and so map to directionally
//! coherent rays: these are the packets. The order is built once per N and reused by every
//! texel after its rotation.
//!
//! How: we sort the point indices by a space-filling-curve key of the points' 32-bit fixed
//! point coordinates. The keys of a quadtree's depth-d cells are the keys' top 2d bits, so the
//! sorted order visits the cells of *any* quadtree over the points — in particular the one
//! whose leaves hold fewer than 8 — in traversal order, and orders each leaf's points by its
//! finer sub-cells (the paper leaves the order inside a leaf open). The tests rebuild the
//! quadtree explicitly and check this.
//!
//! Deviations, measured (see `docs/sampling.md`, `guidebake samples --coherence`):
//! - Children are visited in Hilbert-curve order by default ([`CurveOrder::Hilbert`]), not
//!   the Morton (Z) order a plain recursive quadtree gives: consecutive Hilbert leaves always
//!   share an edge, so a packet that spans two leaves stays tight. Morton stays available.
//! - The Cranley–Patterson rotation that decorrelates texels is a torus shift: it cuts the
//!   square once per axis, and a packet straddling a cut is split into two far-apart halves
//!   (mapped to opposite sides of the hemisphere). [`reorder_after_rotation_into`] repairs
//!   this in O(N) per texel without sorting: a stable partition of the presorted order into the
//!   four wrap quadrants, emitted in an order where consecutive quadrants are neighbours in
//!   the rotated square.

use wide::{f32x8, u32x8};

use crate::packet::LANES;
use crate::sobol::{rotate_x8, sobol_2d, sobol_2d_x8, to_unit_x8};

#[cfg(feature = "alloc")]
pub mod coherence;

/// The order in which a quadtree node's four children are visited.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurveOrder {
    /// Z order: (0,0), (1,0), (0,1), (1,1) at every level.
    Morton,
    /// Hilbert order: consecutive cells share an edge at every level (the default).
    Hilbert,
}

impl CurveOrder {
    /// The 64-bit sort key of a point in 32-bit fixed point.
    #[inline]
    pub fn key(self, p: [u32; 2]) -> u64 {
        match self {
            CurveOrder::Morton => morton_key(p),
            CurveOrder::Hilbert => hilbert_key(p),
        }
    }
}

/// Interleaves the bits: y in the odd positions, x in the even ones.
fn morton_key(p: [u32; 2]) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = u64::from(v);
        v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        (v | (v << 1)) & 0x5555_5555_5555_5555
    }
    (spread(p[1]) << 1) | spread(p[0])
}

/// Distance along the Hilbert curve of order 32 (the classic `xy2d`, one level per bit).
fn hilbert_key(p: [u32; 2]) -> u64 {
    let [mut x, mut y] = p;
    let mut d = 0u64;
    for level in (0..32).rev() {
        let s = 1u32 << level;
        let rx = u64::from(x & s != 0);
        let ry = u64::from(y & s != 0);
        d += (1u64 << (2 * level)) * ((3 * rx) ^ ry);
        // Rotate the sub-square so that the curve's entry is at its origin.
        if ry == 0 {
            if rx == 1 {
                x = !x;
                y = !y;
            }
            core::mem::swap(&mut x, &mut y);
        }
    }
    d
}

/// Writes the presorted order of the first `n` Sobol points into `out`: a permutation of
/// `0..n`; consecutive groups of [`LANES`] indices are the packets (the last one short when
/// `n` is not a multiple of 8).
///
/// Uses [`CurveOrder::Hilbert`]. Not a hot path: call once per sample count.
///
/// # Panics
/// If `out.len() != n` (debug and release: a wrong buffer is a programming error, and this
/// runs once per N).
pub fn presort_into(n: u32, out: &mut [u32]) {
    presort_with_into(n, CurveOrder::Hilbert, out);
}

/// [`presort_into`] with a chosen child order.
///
/// # Panics
/// If `out.len() != n`.
pub fn presort_with_into(n: u32, order: CurveOrder, out: &mut [u32]) {
    assert_eq!(
        out.len() as u64,
        u64::from(n),
        "presort buffer length must equal n"
    );
    for (slot, i) in out.iter_mut().zip(0..n) {
        *slot = i;
    }
    quadtree_sort_by(out, order, sobol_2d);
}

/// Orders `indices` by the quadtree over the points `point(i)` (in 32-bit fixed point), leaves
/// in `order`'s traversal order. Ties (equal points) keep no particular order.
///
/// This is also the reference "ordered after rotation" ordering: pass the rotated points.
pub fn quadtree_sort_by(indices: &mut [u32], order: CurveOrder, point: impl Fn(u32) -> [u32; 2]) {
    indices.sort_unstable_by_key(|&i| order.key(point(i)));
}

/// The presorted order of the first `n` Sobol points (see [`presort_into`]).
#[cfg(feature = "alloc")]
pub fn presorted(n: u32) -> alloc::vec::Vec<u32> {
    let mut out = alloc::vec![0; n as usize];
    presort_into(n, &mut out);
    out
}

/// Which wrap quadrant the rotation by `r` sends `p` to, numbered in the order
/// [`reorder_after_rotation_into`] emits them.
///
/// After the torus shift, points whose x wrapped lie left of the cut (rotated x < r.x), the
/// others right of it; likewise in y. The emitted order is a U through the rotated square:
/// bottom-left (both wrapped), top-left, top-right (none wrapped), bottom-right — each
/// quadrant shares an edge with the next.
#[inline]
pub fn wrap_quadrant(p: [u32; 2], r: [u32; 2]) -> usize {
    let wx = p[0].checked_add(r[0]).is_none();
    let wy = p[1].checked_add(r[1]).is_none();
    match (wx, wy) {
        (true, true) => 0,
        (true, false) => 1,
        (false, false) => 2,
        (false, true) => 3,
    }
}

/// Reorders a presorted order for one texel's rotation `r` so that packets stay coherent
/// after the torus wrap: a stable partition of `order` by [`wrap_quadrant`] into `out`.
///
/// Inside each quadrant the presorted order is kept, and a quadrant of the original square is
/// one contiguous rectangle in the rotated square, so only the (at most three) packets that
/// straddle a quadrant boundary in the output can mix distant points. O(N), two passes, no
/// allocation; `order` may be any permutation of Sobol indices.
///
/// # Panics
/// If `out.len() != order.len()`.
pub fn reorder_after_rotation_into(order: &[u32], r: [u32; 2], out: &mut [u32]) {
    assert_eq!(
        order.len(),
        out.len(),
        "reorder buffer length must equal the order's"
    );
    let mut start = [0usize; 4];
    for &i in order {
        let q = wrap_quadrant(sobol_2d(i), r);
        // Count into the slot after q, so that the prefix sum below gives each start.
        if q < 3 {
            start[q + 1] += 1;
        }
    }
    for q in 1..4 {
        start[q] += start[q - 1];
    }
    for &i in order {
        let q = wrap_quadrant(sobol_2d(i), r);
        out[start[q]] = i;
        start[q] += 1;
    }
}

/// One packet's points in the primary sample space: lane i is the Sobol point `packet[i]`
/// rotated by `r`, as `f32` in [0, 1) — what the 8-wide warp and
/// [`crate::mapping::sample_cosine_hemisphere_x8`] take.
///
/// `packet` holds 1 to 8 indices (a chunk of a presorted or reordered order); lanes past its
/// end repeat its last index, so they carry valid samples that the caller masks off.
///
/// # Panics
/// Debug builds assert 1 ≤ `packet.len()` ≤ 8. Release: an empty packet gives lanes of
/// point 0, extra indices are ignored.
#[inline]
pub fn packet_u_x8(packet: &[u32], r: [u32; 2]) -> [f32x8; 2] {
    debug_assert!(
        (1..=LANES).contains(&packet.len()),
        "packet of {} indices",
        packet.len()
    );
    let last = packet.len().min(LANES).saturating_sub(1);
    let lanes: [u32; LANES] =
        core::array::from_fn(|i| packet.get(i.min(last)).copied().unwrap_or(0));
    let [x, y] = rotate_x8(sobol_2d_x8(u32x8::new(lanes)), r);
    [to_unit_x8(x), to_unit_x8(y)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sobol::rotate;
    use crate::testing::Pcg32;
    use std::vec::Vec;

    /// Shadows the `alloc`-only [`super::presorted`] so these tests also run without `alloc`.
    fn presorted(n: u32) -> Vec<u32> {
        let mut out = std::vec![0; n as usize];
        presort_into(n, &mut out);
        out
    }

    /// Reference: the explicit recursive quadtree whose leaves hold fewer than 8 points; its
    /// leaves as sets of indices, in Morton or Hilbert traversal order.
    fn quadtree_leaves(points: &[(u32, [u32; 2])], order: CurveOrder) -> Vec<Vec<u32>> {
        fn recurse(
            pts: Vec<(u32, [u32; 2])>,
            level: u32,
            order: CurveOrder,
            leaves: &mut Vec<Vec<u32>>,
        ) {
            if pts.len() < LANES {
                if !pts.is_empty() {
                    leaves.push(pts.iter().map(|p| p.0).collect());
                }
                return;
            }
            let bit = 1u32 << (level - 1);
            let mut kids: [Vec<(u32, [u32; 2])>; 4] = Default::default();
            for p in pts {
                let c = usize::from(p.1[0] & bit != 0) | (usize::from(p.1[1] & bit != 0) << 1);
                kids[c].push(p);
            }
            // Order the children by the curve key's bits at this level (shared by all points
            // of a child): that is the traversal order.
            let mut keyed: Vec<(u64, usize)> = Vec::new();
            for (c, kid) in kids.iter().enumerate() {
                if let Some(p) = kid.first() {
                    keyed.push((order.key(p.1) >> (2 * (level - 1)), c));
                }
            }
            keyed.sort();
            for &(_, c) in &keyed {
                let kid = core::mem::take(&mut kids[c]);
                recurse(kid, level - 1, order, leaves);
            }
        }
        let mut leaves = Vec::new();
        recurse(points.to_vec(), 32, order, &mut leaves);
        leaves
    }

    fn check_matches_explicit_quadtree(n: u32, order: CurveOrder) {
        let mut out = std::vec![0; n as usize];
        presort_with_into(n, order, &mut out);
        let points: Vec<(u32, [u32; 2])> = (0..n).map(|i| (i, sobol_2d(i))).collect();
        let leaves = quadtree_leaves(&points, order);
        let mut pos = 0;
        for leaf in &leaves {
            assert!(leaf.len() < LANES);
            let mut got = out[pos..pos + leaf.len()].to_vec();
            let mut want = leaf.clone();
            got.sort_unstable();
            want.sort_unstable();
            assert_eq!(got, want, "n {n} {order:?}: leaf at {pos} out of order");
            pos += leaf.len();
        }
        assert_eq!(pos, n as usize);
    }

    #[test]
    fn output_is_a_permutation_for_any_n() {
        for n in (0..300).chain([511, 512, 1000, 1024, 4097]) {
            for order in [CurveOrder::Hilbert, CurveOrder::Morton] {
                let mut out = std::vec![u32::MAX; n as usize];
                presort_with_into(n, order, &mut out);
                let mut seen = std::vec![false; n as usize];
                for &i in &out {
                    assert!(
                        i < n && !seen[i as usize],
                        "n {n}: {i} repeated or out of range"
                    );
                    seen[i as usize] = true;
                }
            }
        }
        #[cfg(feature = "alloc")]
        assert_eq!(super::presorted(100), presorted(100));
    }

    #[test]
    fn leaves_of_the_quadtree_are_contiguous_and_in_traversal_order() {
        for n in [1, 7, 8, 9, 63, 64, 100, 256, 333, 1024] {
            check_matches_explicit_quadtree(n, CurveOrder::Hilbert);
            check_matches_explicit_quadtree(n, CurveOrder::Morton);
        }
    }

    #[test]
    fn packet_u_x8_matches_the_scalar_pipeline_for_every_lane_count() {
        use crate::sobol::to_unit;
        let order = presorted(203);
        let r = crate::sobol::rotation(4, 99, 1);
        for count in 1..=LANES {
            for packet in order.chunks(count) {
                let [x, y] = packet_u_x8(packet, r);
                for lane in 0..LANES {
                    let i = packet[lane.min(packet.len() - 1)];
                    let u = rotate(sobol_2d(i), r).map(to_unit);
                    assert_eq!([x.to_array()[lane], y.to_array()[lane]], u, "lane {lane}");
                }
            }
        }
    }

    #[test]
    fn hilbert_keys_step_to_edge_neighbours() {
        // On a 2^4 x 2^4 grid of cell corners, consecutive Hilbert keys are edge neighbours.
        let shift = 28;
        let mut cells: Vec<(u64, [u32; 2])> = Vec::new();
        for x in 0..16u32 {
            for y in 0..16u32 {
                let p = [x << shift, y << shift];
                cells.push((hilbert_key(p) >> (2 * shift), [x, y]));
            }
        }
        cells.sort();
        for (k, w) in cells.windows(2).enumerate() {
            assert_eq!(w[0].0 as usize, k);
            let d = w[0].1[0].abs_diff(w[1].1[0]) + w[0].1[1].abs_diff(w[1].1[1]);
            assert_eq!(d, 1, "{:?} -> {:?}", w[0].1, w[1].1);
        }
        assert_eq!(morton_key([1, 0]), 1);
        assert_eq!(morton_key([0, 1]), 2);
        assert_eq!(morton_key([u32::MAX, u32::MAX]), u64::MAX);
    }

    #[test]
    fn reorder_after_rotation_is_a_stable_partition_by_wrap_quadrant() {
        let mut rng = Pcg32::new(11, 3);
        for n in [8u32, 64, 100, 256, 1024] {
            let order = presorted(n);
            for _ in 0..20 {
                let r = [rng.next_u32(), rng.next_u32()];
                let mut out = std::vec![0; n as usize];
                reorder_after_rotation_into(&order, r, &mut out);
                // Quadrants appear in non-decreasing order ...
                let quads: Vec<usize> =
                    out.iter().map(|&i| wrap_quadrant(sobol_2d(i), r)).collect();
                assert!(quads.windows(2).all(|w| w[0] <= w[1]));
                // ... and within a quadrant the presorted order is kept (stable).
                for q in 0..4 {
                    let want: Vec<u32> = order
                        .iter()
                        .copied()
                        .filter(|&i| wrap_quadrant(sobol_2d(i), r) == q)
                        .collect();
                    let got: Vec<u32> = out
                        .iter()
                        .copied()
                        .filter(|&i| wrap_quadrant(sobol_2d(i), r) == q)
                        .collect();
                    assert_eq!(got, want);
                }
                // Each quadrant is one rectangle of the rotated square.
                for (&i, &q) in out.iter().zip(&quads) {
                    let p = rotate(sobol_2d(i), r);
                    assert_eq!(q == 0 || q == 1, p[0] < r[0], "x side of {i}");
                    assert_eq!(q == 0 || q == 3, p[1] < r[1], "y side of {i}");
                }
            }
        }
        // No rotation: nothing wraps, the order is unchanged.
        let order = presorted(64);
        let mut out = std::vec![0; 64];
        reorder_after_rotation_into(&order, [0, 0], &mut out);
        assert_eq!(out, order);
    }
}
