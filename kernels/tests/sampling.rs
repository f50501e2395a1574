//! Integration tests of the sampling pipeline a texel runs (paper §2.4): presorted order →
//! Sobol point → Cranley–Patterson rotation → f32 → cosine hemisphere, scalar against 8-wide,
//! and the packet coherence that README's figure reports.

use glam::Vec3;
use guidebake_kernels::mapping::{
    cosine_hemisphere_pdf, cosine_hemisphere_pdf_x8, orthonormal_basis, sample_cosine_hemisphere,
    sample_cosine_hemisphere_x8,
};
use guidebake_kernels::packet::LANES;
use guidebake_kernels::presort::coherence::{coherence_table, mean_spread_deg};
use guidebake_kernels::presort::{presorted, reorder_after_rotation_into};
use guidebake_kernels::sobol::{
    rotate, rotate_x8, rotation, sobol_2d, sobol_2d_x8, to_unit, to_unit_x8,
};
use guidebake_kernels::testing::Pcg32;
use wide::u32x8;

/// A texel's packets through the 8-wide path equal the scalar path bit for bit, for sample
/// counts whose last packet is short (inactive lanes padded with the packet's first index).
#[test]
fn packet_pipeline_x8_equals_scalar_for_any_n() {
    for n in [1u32, 5, 8, 13, 64, 100, 256, 1000] {
        let order = presorted(n);
        let mut reordered = vec![0; n as usize];
        for texel in [0u64, 1, 12_345, u64::MAX] {
            let r = rotation(42, texel, 2);
            reorder_after_rotation_into(&order, r, &mut reordered);
            for packet in reordered.chunks(LANES) {
                let lanes = std::array::from_fn(|i| packet[i.min(packet.len() - 1)]);
                let [x, y] = rotate_x8(sobol_2d_x8(u32x8::new(lanes)), r);
                let w8 = sample_cosine_hemisphere_x8([to_unit_x8(x), to_unit_x8(y)]);
                let pdf8 = cosine_hemisphere_pdf_x8(w8[2]);
                for (lane, &i) in packet.iter().enumerate() {
                    let u = rotate(sobol_2d(i), r).map(to_unit);
                    assert!(u.iter().all(|c| (0.0..1.0).contains(c)));
                    let w = sample_cosine_hemisphere(u);
                    let got = Vec3::new(
                        w8[0].to_array()[lane],
                        w8[1].to_array()[lane],
                        w8[2].to_array()[lane],
                    );
                    assert_eq!(
                        got.to_array().map(f32::to_bits),
                        w.to_array().map(f32::to_bits)
                    );
                    assert_eq!(pdf8.to_array()[lane], cosine_hemisphere_pdf(w.z));
                    assert!(w.is_finite() && (w.length() - 1.0).abs() < 1e-6);
                }
            }
        }
    }
}

/// Local directions brought to world space by the Duff frame stay unit and in the normal's
/// hemisphere.
#[test]
fn world_space_directions_stay_in_the_normals_hemisphere() {
    let mut rng = Pcg32::new(9, 9);
    let order = presorted(64);
    for _ in 0..500 {
        let n = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        )
        .normalize_or(Vec3::Z);
        let (t, b) = orthonormal_basis(n);
        let r = [rng.next_u32(), rng.next_u32()];
        for &i in &order {
            let l = sample_cosine_hemisphere(rotate(sobol_2d(i), r).map(to_unit));
            let w = t * l.x + b * l.y + n * l.z;
            assert!((w.length() - 1.0).abs() < 2e-6);
            assert!((w.dot(n) - l.z).abs() < 2e-6);
        }
    }
}

/// README's coherence figure, in small: after a random rotation, presorted packets are
/// several times tighter than unsorted ones, and the wrap reorder tightens them further.
/// The published table is `guidebake samples --coherence` (1000 rotations).
#[test]
fn presorted_packets_are_several_times_tighter_than_unsorted() {
    for row in coherence_table(&[64, 256, 1024], 40, 7) {
        // With 64 samples the 8 packets must tile the whole hemisphere: 2x is all there is.
        let several = if row.n >= 256 { 3.0 } else { 1.8 };
        let ratio = row.unsorted / row.reordered;
        assert!(
            ratio > several,
            "N {}: unsorted / reordered = {ratio:.2} ({row:?})",
            row.n
        );
        assert!(row.unsorted / row.hilbert > 1.4, "N {}: {row:?}", row.n);
        assert!(
            row.reordered < 0.8 * row.hilbert,
            "the wrap reorder must pay: {row:?}"
        );
        assert!(
            row.reordered < row.morton_reordered,
            "Hilbert children must beat Morton: {row:?}"
        );
        assert!(row.split_fraction > 0.0 && row.split_fraction < 1.0);
        // The full re-sort is the ideal the O(N) reorder approximates; allow 25%.
        assert!(row.reordered < 1.25 * row.resorted, "{row:?}");
    }
}

/// The spread metric sees the wrap: an off-grid rotation splits packets, and the reorder
/// repairs them. (A rotation by (½, ½) would not do: it cuts along the quadtree's first split,
/// where no packet of N = 256 straddles.)
#[test]
fn wrap_reorder_repairs_an_off_grid_rotation() {
    let order = presorted(256);
    let mut reordered = vec![0; 256];
    let unrotated = mean_spread_deg(&order, [0, 0]);
    let r = [0x4C00_0000, 0x9A00_0000];
    reorder_after_rotation_into(&order, r, &mut reordered);
    let (before, after) = (mean_spread_deg(&order, r), mean_spread_deg(&reordered, r));
    assert!(
        before > 1.3 * unrotated,
        "the wrap should hurt: {before} vs {unrotated}"
    );
    assert!(after < 0.8 * before, "{after} vs {before}");
    assert!(
        after < 1.3 * unrotated,
        "reordered {after}, unrotated {unrotated}"
    );
}
