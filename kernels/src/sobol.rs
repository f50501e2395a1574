//! `sobol`: the first two dimensions of the Sobol sequence as 32-bit integers, Cranley–Patterson
//! rotation, and conversion to `f32` strictly below 1.
//!
//! Source: Silvennoinen & Sloan 2019, §2.4 — every texel draws the same N two-dimensional
//! Sobol points, decorrelated per texel and learning iteration by a Cranley–Patterson
//! rotation (a toroidal shift). Dimension 0 is the van der Corput radical inverse (bit
//! reversal of the index); dimension 1 uses the generator matrix of the primitive polynomial
//! x + 1 (direction numbers v₁ = 2³¹, vₖ = vₖ₋₁ ⊕ (vₖ₋₁ ≫ 1), Joe & Kuo's second dimension),
//! as in Kollig & Keller 2002, evaluated without a loop over the index bits: the matrix is
//! Pascal's triangle mod 2, so a five-step superset transform and a bit reversal compute it
//! (see `sobol_dim1`). The first 2^k points of these two dimensions form a
//! (0, k, 2)-net in base 2: every elementary interval of area 2^-k holds exactly one point.
//!
//! The rotation is a wrapping `u32` add per axis — the toroidal shift in fixed point, exact and
//! free of the f32 rounding that `fract(u + r)` would add. Its offset comes from a 64-bit
//! integer hash (the SplitMix64 / Stafford "Mix13" finalizer, a bijection) of
//! (seed, texel id, iteration).
//!
//! Deviation: the paper does not say how the rotation offsets are drawn; we hash instead of
//! storing a random table so that any texel of any world gets its offset without state, and a
//! bake is bit-identical for any tile order or shard split (docs/ARCHITECTURE.md, "Invariants").
//!
//! Scalar and 8-wide versions compute the same integers, so they agree bit for bit; `to_unit`
//! and `to_unit_x8` are exact (24-bit integer times a power of two).

use wide::{f32x8, i32x8, u32x8};

/// Direction numbers of the second Sobol dimension: `V[k] = V[k-1] ^ (V[k-1] >> 1)`,
/// `V[0] = 1 << 31`. Bit k of the index contributes `V[k]`. Kept as the definition the fast
/// evaluation below is tested against.
#[cfg(test)]
const DIRECTIONS_1: [u32; 32] = {
    let mut v = [0u32; 32];
    v[0] = 1 << 31;
    let mut k = 1;
    while k < 32 {
        v[k] = v[k - 1] ^ (v[k - 1] >> 1);
        k += 1;
    }
    v
};

/// The masks of the superset transform: bit j is set iff bit `b` of j is clear.
const SUPERSET_MASKS: [(u32, u32); 5] = [
    (1, 0x5555_5555),
    (2, 0x3333_3333),
    (4, 0x0F0F_0F0F),
    (8, 0x00FF_00FF),
    (16, 0x0000_FFFF),
];

/// The largest `f32` below 1: 1 − 2⁻²⁴.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - 1.0 / 16_777_216.0;

/// The Sobol point `index` in its first two dimensions, as 32-bit fixed point in [0, 1).
///
/// Defined for every `index` below 2³²; point 0 is (0, 0).
#[inline]
pub fn sobol_2d(index: u32) -> [u32; 2] {
    [index.reverse_bits(), sobol_dim1(index)]
}

/// Dimension 1. By definition it is the XOR of the direction numbers `V[k]` of the index's
/// set bits k, and `V[k]` holds binary digit j (weight 2^-(j+1)) iff C(k, j) is odd — by
/// Lucas' theorem iff j ⊆ k as bit sets (the Pascal matrix mod 2). So digit j of the result is
/// the XOR of index bits k over all supersets k ⊇ j: a superset transform over the 5-bit
/// positions, done in five shift-mask-XOR steps, then the digits are bit-reversed into place.
#[inline]
fn sobol_dim1(index: u32) -> u32 {
    let mut x = index;
    for (shift, mask) in SUPERSET_MASKS {
        x ^= (x >> shift) & mask;
    }
    x.reverse_bits()
}

/// Eight Sobol points at once: lane i is [`sobol_2d`] of lane i of `index`.
#[inline]
pub fn sobol_2d_x8(index: u32x8) -> [u32x8; 2] {
    [reverse_bits_x8(index), sobol_dim1_x8(index)]
}

/// Bit reversal by swapping halves, then quarters, … (five mask-and-shift steps).
#[inline]
fn reverse_bits_x8(x: u32x8) -> u32x8 {
    let swap = |x: u32x8, mask: u32, shift: u32| {
        let m = u32x8::splat(mask);
        ((x >> shift) & m) | ((x & m) << shift)
    };
    let x = swap(x, 0x5555_5555, 1);
    let x = swap(x, 0x3333_3333, 2);
    let x = swap(x, 0x0F0F_0F0F, 4);
    let x = swap(x, 0x00FF_00FF, 8);
    (x >> 16) | (x << 16)
}

/// [`sobol_dim1`] for eight lanes: the same five steps and bit reversal.
#[inline]
fn sobol_dim1_x8(index: u32x8) -> u32x8 {
    let mut x = index;
    for (shift, mask) in SUPERSET_MASKS {
        x ^= (x >> shift) & u32x8::splat(mask);
    }
    reverse_bits_x8(x)
}

/// The Cranley–Patterson offset of (`seed`, `texel`, `iteration`): two hashed 32-bit shifts.
///
/// For a fixed seed and iteration, distinct texels get distinct 64-bit hashes (the mix is a
/// bijection), and likewise for distinct iterations of one texel.
#[inline]
pub fn rotation(seed: u32, texel: u64, iteration: u32) -> [u32; 2] {
    let key = (u64::from(seed) << 32) | u64::from(iteration);
    let h = mix64(mix64(texel ^ 0x9E37_79B9_7F4A_7C15) ^ key);
    [h as u32, (h >> 32) as u32]
}

/// Stafford's "Mix13" 64-bit finalizer (used by SplitMix64): a bijection with full avalanche.
#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Cranley–Patterson rotation: the toroidal shift of `p` by `r`, a wrapping add per axis.
#[inline]
pub fn rotate(p: [u32; 2], r: [u32; 2]) -> [u32; 2] {
    [p[0].wrapping_add(r[0]), p[1].wrapping_add(r[1])]
}

/// [`rotate`] for eight points sharing one offset (one texel's packet).
#[inline]
pub fn rotate_x8(p: [u32x8; 2], r: [u32; 2]) -> [u32x8; 2] {
    // wide's `+` on u32x8 wraps.
    [p[0] + u32x8::splat(r[0]), p[1] + u32x8::splat(r[1])]
}

/// 32-bit fixed point to `f32` in [0, 1): the top 24 bits times 2⁻²⁴, so the result is exact
/// and at most [`ONE_MINUS_EPSILON`] (rounding all 32 bits could give 1.0).
#[inline]
pub fn to_unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// [`to_unit`] for eight lanes, bit-identical to it.
#[inline]
pub fn to_unit_x8(x: u32x8) -> f32x8 {
    // Below 2²⁴, so the signed conversion is exact.
    let top: i32x8 = bytemuck::cast(x >> 8);
    f32x8::from_i32x8(top) * f32x8::splat(1.0 / 16_777_216.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;
    use std::vec;

    /// (0,2)-sequence property: for N = 2^k, every elementary interval of area 1/N, of every
    /// shape 2^-a × 2^-(k-a), holds exactly one of the first N points.
    #[test]
    fn first_2k_points_are_0_2_stratified() {
        for k in 1..=16u32 {
            let n = 1u32 << k;
            let points: vec::Vec<[u32; 2]> = (0..n).map(sobol_2d).collect();
            for a in 0..=k {
                let b = k - a;
                let mut count = vec![0u8; n as usize];
                for p in &points {
                    let cx = if a == 0 { 0 } else { p[0] >> (32 - a) };
                    let cy = if b == 0 { 0 } else { p[1] >> (32 - b) };
                    count[((cx << b) | cy) as usize] += 1;
                }
                assert!(
                    count.iter().all(|&c| c == 1),
                    "N = 2^{k}, intervals 2^-{a} x 2^-{b}"
                );
            }
        }
    }

    /// The superset-transform evaluation equals the definition (XOR of direction numbers).
    #[test]
    fn fast_dimension_1_equals_the_direction_number_definition() {
        let by_definition = |index: u32| {
            (0..32)
                .filter(|k| index >> k & 1 == 1)
                .fold(0, |x, k| x ^ DIRECTIONS_1[k])
        };
        let mut rng = Pcg32::new(1, 1);
        for i in (0..70_000)
            .chain((0..70_000).map(|_| rng.next_u32()))
            .chain([u32::MAX, 1 << 31])
        {
            assert_eq!(sobol_dim1(i), by_definition(i), "index {i}");
        }
    }

    /// Against an independent generator: Antonov–Saleev's Gray-code recursion produces point
    /// `gray(i) = i ^ (i >> 1)` by flipping one direction number per step.
    #[test]
    fn matches_gray_code_recursion_and_known_values() {
        let mut v = [0u32; 32];
        let mut d = 1u32 << 31;
        for slot in v.iter_mut() {
            *slot = d;
            d ^= d >> 1;
        }
        let (mut x, mut y) = (0u32, 0u32);
        for i in 0u32..100_000 {
            assert_eq!(sobol_2d(i ^ (i >> 1)), [x, y], "gray index of {i}");
            let c = (i + 1).trailing_zeros();
            x ^= 1 << (31 - c);
            y ^= v[c as usize];
        }
        // The first points as SciPy's unscrambled `qmc.Sobol` lists them (Gray-code order).
        let expected = [
            [0.0, 0.0],
            [0.5, 0.5],
            [0.75, 0.25],
            [0.25, 0.75],
            [0.375, 0.375],
            [0.875, 0.875],
            [0.625, 0.125],
            [0.125, 0.625],
        ];
        for (i, &e) in expected.iter().enumerate() {
            let gray = (i ^ (i >> 1)) as u32;
            assert_eq!(
                sobol_2d(gray).map(to_unit),
                e,
                "point {i} in Gray-code order"
            );
        }
        // The last index: all bits set.
        assert_eq!(sobol_2d(u32::MAX)[0], u32::MAX);
        assert_eq!(sobol_2d(u32::MAX)[1], v.iter().fold(0, |a, &b| a ^ b));
    }

    #[test]
    fn x8_matches_scalar_bit_for_bit() {
        let mut rng = Pcg32::new(2, 7);
        let edges = [
            0,
            1,
            2,
            7,
            8,
            0x7FFF_FFFF,
            0x8000_0000,
            u32::MAX - 1,
            u32::MAX,
        ];
        let check = |lanes: [u32; 8]| {
            let [x, y] = sobol_2d_x8(u32x8::new(lanes));
            for (i, &l) in lanes.iter().enumerate() {
                assert_eq!([x.to_array()[i], y.to_array()[i]], sobol_2d(l), "index {l}");
            }
            let r = rotation(3, u64::from(lanes[0]), 1);
            let [rx, ry] = rotate_x8([x, y], r);
            let (ux, uy) = (to_unit_x8(rx).to_array(), to_unit_x8(ry).to_array());
            for (i, &l) in lanes.iter().enumerate() {
                let p = rotate(sobol_2d(l), r);
                assert_eq!(ux[i].to_bits(), to_unit(p[0]).to_bits());
                assert_eq!(uy[i].to_bits(), to_unit(p[1]).to_bits());
            }
        };
        for chunk in edges.windows(8) {
            check(chunk.try_into().unwrap());
        }
        for _ in 0..10_000 {
            check(core::array::from_fn(|_| rng.next_u32()));
        }
        for base in (0..4096u32).step_by(8) {
            check(core::array::from_fn(|i| base + i as u32));
        }
    }

    #[test]
    fn to_unit_is_exact_and_below_one() {
        assert_eq!(to_unit(0), 0.0);
        assert_eq!(to_unit(u32::MAX), ONE_MINUS_EPSILON);
        assert!(to_unit(u32::MAX) < 1.0);
        assert_eq!(to_unit(1 << 31), 0.5);
        assert_eq!(
            to_unit(0xFF),
            0.0,
            "bits below 2^-24 are dropped, never rounded up"
        );
        let lanes = to_unit_x8(u32x8::new([
            0,
            u32::MAX,
            1 << 31,
            0xFF,
            0x100,
            3 << 30,
            1,
            0,
        ]));
        assert_eq!(lanes.to_array()[1], ONE_MINUS_EPSILON);
        assert_eq!(lanes.to_array()[4], 1.0 / 16_777_216.0);
        assert_eq!(lanes.to_array()[5], 0.75);
    }

    /// The rotation is a torus shift: the rotated first N points still put exactly one point
    /// into every elementary interval shifted by r (mod 1), checked in f64 arithmetic rather
    /// than by undoing the integer add.
    #[test]
    fn rotation_keeps_stratification_modulo_the_torus_wrap() {
        for (k, texel) in [(4u32, 0u64), (8, 17), (10, 1 << 40), (12, u64::MAX)] {
            let n = 1u32 << k;
            let r = rotation(0xC0FFEE, texel, 3);
            let shift = [
                f64::from(r[0]) / 4_294_967_296.0,
                f64::from(r[1]) / 4_294_967_296.0,
            ];
            for a in [0, k / 2, k] {
                let b = k - a;
                let mut count = vec![0u8; n as usize];
                for i in 0..n {
                    let q = rotate(sobol_2d(i), r);
                    let coord = |axis: usize, bits: u32| {
                        let u = f64::from(q[axis]) / 4_294_967_296.0 - shift[axis];
                        let u = if u < 0.0 { u + 1.0 } else { u };
                        (u * f64::from(1u32 << bits)) as u32
                    };
                    count[((coord(0, a) << b) | coord(1, b)) as usize] += 1;
                }
                assert!(count.iter().all(|&c| c == 1), "k {k}, a {a}, texel {texel}");
            }
        }
    }

    /// The hash decorrelates: offsets are deterministic, differ between neighbouring texels,
    /// iterations and seeds, and each output bit is set about half the time.
    #[test]
    fn rotation_offsets_are_deterministic_distinct_and_balanced() {
        assert_eq!(rotation(1, 2, 3), rotation(1, 2, 3));
        let mut seen = std::collections::HashSet::new();
        let mut ones = [0u32; 64];
        let trials = 4096u32;
        for t in 0..u64::from(trials) / 4 {
            for (seed, it) in [(0, 0), (0, 1), (1, 0), (u32::MAX, 7)] {
                let r = rotation(seed, t, it);
                assert!(seen.insert(r), "collision at texel {t}");
                let h = (u64::from(r[1]) << 32) | u64::from(r[0]);
                for (bit, count) in ones.iter_mut().enumerate() {
                    *count += ((h >> bit) & 1) as u32;
                }
            }
        }
        // Binomial(4096, 1/2): sd = 32; 6 sd either side fails with probability ~1e-9 per bit.
        for (bit, &c) in ones.iter().enumerate() {
            assert!(
                c.abs_diff(trials / 2) < 192,
                "bit {bit} set {c} times of {trials}"
            );
        }
    }
}
