//! Packet coherence (paper §2.4, Figure 3): how far apart the eight rays of a packet point,
//! measured on the cosine hemisphere, for the orders `presort` builds. `guidebake samples
//! --coherence` prints the table; the sampling tests assert its ordering.
//!
//! A measurement, not a hot path: it allocates.

use alloc::vec;
use alloc::vec::Vec;

use glam::Vec3;

use super::{
    CurveOrder, presort_with_into, quadtree_sort_by, reorder_after_rotation_into, wrap_quadrant,
};
use crate::mapping::sample_cosine_hemisphere;
use crate::packet::LANES;
use crate::sobol::{rotate, rotation, sobol_2d, to_unit};

/// One row of the coherence table: mean packet spread in degrees for one N.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoherenceRow {
    /// Sample count.
    pub n: u32,
    /// Sobol index order, rotated.
    pub unsorted: f64,
    /// Presorted by the Morton-order quadtree, rotated.
    pub morton: f64,
    /// Morton presort, then the O(N) wrap-quadrant reorder per rotation.
    pub morton_reordered: f64,
    /// Presorted by the Hilbert-order quadtree (the default), rotated.
    pub hilbert: f64,
    /// Hilbert presort, then the O(N) wrap-quadrant reorder per rotation.
    pub reordered: f64,
    /// The rotated points re-sorted by a full quadtree (O(N log N) per texel).
    pub resorted: f64,
    /// Hilbert presort without any rotation.
    pub unrotated: f64,
    /// Fraction of Hilbert-presorted packets whose points the wrap splits across quadrants.
    pub split_fraction: f64,
}

/// Mean angle in degrees between each direction and the packet's mean direction; 90° when
/// the directions cancel (no mean direction: every axis is as bad as a perpendicular one).
pub fn packet_spread_deg(dirs: &[Vec3]) -> f64 {
    let sum: Vec3 = dirs.iter().copied().sum();
    let Some(mean) = sum.try_normalize() else {
        return 90.0;
    };
    let total: f64 = dirs
        .iter()
        .map(|d| libm::acos(f64::from(d.dot(mean).clamp(-1.0, 1.0))))
        .sum();
    (total / dirs.len() as f64).to_degrees()
}

/// Mean over packets of [`packet_spread_deg`] when `order` is drawn with rotation `r`.
/// Packets of fewer than 2 rays (a short last packet) are skipped.
pub fn mean_spread_deg(order: &[u32], r: [u32; 2]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for packet in order.chunks(LANES).filter(|p| p.len() > 1) {
        let dirs: Vec<Vec3> = packet
            .iter()
            .map(|&i| direction(rotate(sobol_2d(i), r)))
            .collect();
        sum += packet_spread_deg(&dirs);
        count += 1;
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// The cosine-hemisphere direction of a (rotated) Sobol point: what a packet's ray would trace.
pub fn direction(p: [u32; 2]) -> Vec3 {
    sample_cosine_hemisphere(p.map(to_unit))
}

/// The coherence table: for each N, spreads averaged over `rotations` random rotations
/// (texels 0..rotations of `seed`).
pub fn coherence_table(ns: &[u32], rotations: u32, seed: u32) -> Vec<CoherenceRow> {
    ns.iter()
        .map(|&n| coherence_row(n, rotations, seed))
        .collect()
}

fn presort_order(n: u32, order: CurveOrder) -> Vec<u32> {
    let mut out = vec![0; n as usize];
    presort_with_into(n, order, &mut out);
    out
}

fn coherence_row(n: u32, rotations: u32, seed: u32) -> CoherenceRow {
    let unsorted: Vec<u32> = (0..n).collect();
    let morton = presort_order(n, CurveOrder::Morton);
    let hilbert = presort_order(n, CurveOrder::Hilbert);
    let mut scratch = vec![0; n as usize];
    let mut acc = [0.0f64; 7];
    for texel in 0..u64::from(rotations) {
        let r = rotation(seed, texel, 0);
        acc[0] += mean_spread_deg(&unsorted, r);
        acc[1] += mean_spread_deg(&morton, r);
        acc[2] += mean_spread_deg(&hilbert, r);
        reorder_after_rotation_into(&hilbert, r, &mut scratch);
        acc[3] += mean_spread_deg(&scratch, r);
        scratch.copy_from_slice(&unsorted);
        quadtree_sort_by(&mut scratch, CurveOrder::Hilbert, |i| {
            rotate(sobol_2d(i), r)
        });
        acc[4] += mean_spread_deg(&scratch, r);
        acc[5] += split_fraction(&hilbert, r);
        reorder_after_rotation_into(&morton, r, &mut scratch);
        acc[6] += mean_spread_deg(&scratch, r);
    }
    let k = f64::from(rotations);
    CoherenceRow {
        n,
        unsorted: acc[0] / k,
        morton: acc[1] / k,
        morton_reordered: acc[6] / k,
        hilbert: acc[2] / k,
        reordered: acc[3] / k,
        resorted: acc[4] / k,
        unrotated: mean_spread_deg(&hilbert, [0, 0]),
        split_fraction: acc[5] / k,
    }
}

/// Fraction of full packets of `order` whose points fall in more than one wrap quadrant.
fn split_fraction(order: &[u32], r: [u32; 2]) -> f64 {
    let packets = order.chunks_exact(LANES);
    let total = packets.len();
    let split = packets
        .filter(|p| {
            let q = wrap_quadrant(sobol_2d(p[0]), r);
            p.iter().any(|&i| wrap_quadrant(sobol_2d(i), r) != q)
        })
        .count();
    if total == 0 {
        0.0
    } else {
        split as f64 / total as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_of_identical_and_opposite_directions() {
        assert_eq!(packet_spread_deg(&[Vec3::Z; 8]), 0.0);
        let s = packet_spread_deg(&[Vec3::X, Vec3::Y]);
        assert!((s - 45.0).abs() < 1e-4, "{s}");
        assert_eq!(
            packet_spread_deg(&[Vec3::X, -Vec3::X]),
            90.0,
            "no mean direction"
        );
    }
}
