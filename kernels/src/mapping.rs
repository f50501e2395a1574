//! `mapping`: the primary sample space [0,1)² mapped to the cosine-weighted hemisphere, and
//! tangent frames from a normal.
//!
//! Sources: Silvennoinen & Sloan 2019, §2.2 — the guide lives in the primary sample space of
//! the unguided cosine-weighted sampler, so uniform density on the square *is* the baseline and
//! the guide learns radiance alone: p(ω) = p_square(u) · cos θ / π. The square goes to the
//! disk by Shirley & Chiu's concentric map (1997), then up to the hemisphere by Malley's
//! method (z = √(1 − r²)). Frames: Duff et al., *Building an Orthonormal Basis, Revisited*,
//! JCGT 6(1), 2017, listing 3 — no branch on the sign of n.z.
//!
//! The light probes' directions cover the whole sphere: Clarberg's equal-area octahedral map
//! ([`sample_sphere_equal_area`], its inverse, density [`SPHERE_PDF`]; scalar only — a probe's
//! packets are warped one lane at a time, docs/probes.md).
//!
//! Every hemisphere map is a triple (`sample_*`, `*_pdf`, `invert_*`), scalar and 8-wide. The scalar
//! versions are the readable reference; the 8-wide ones are branch-free (`select`) and run
//! the *same* floating-point operations in the same order — only +, −, ×, ÷ and √, all
//! correctly rounded in IEEE 754, never a fused multiply-add — so the two agree **bit for bit**
//! with or without AVX2/FMA. For that reason sin, cos and atan are our own polynomials
//! (shared by both through the private `Real` trait) rather than `libm`'s:
//! - sin/cos(π/4·t), t ∈ [−1, 1]: Taylor polynomials to degree 9 / 10 (truncation < 2·10⁻⁹);
//! - atan(z), z ∈ [−1, 1]: Cephes `atanf` (one range reduction at tan π/8, relative error
//!   ≈ 10⁻⁷).
//!
//! Deviation from the textbook map: the lift uses the square's own radius, z = √(1 − r²) with
//! r = max(|a|, |b|), instead of √(1 − x² − y²); it is the same value in exact arithmetic,
//! one rounding cheaper, and never negative under the root.

use core::f32::consts::{FRAC_1_PI, FRAC_PI_4};
use core::ops::{Add, Div, Mul, Sub};

use glam::Vec3;
use wide::f32x8;

use crate::sobol::ONE_MINUS_EPSILON;

/// The arithmetic the shared polynomials need: implemented by `f32` and `f32x8`, so one
/// formula serves the scalar reference and the 8-wide kernel.
trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    fn splat(x: f32) -> Self;
}

impl Real for f32 {
    #[inline(always)]
    fn splat(x: f32) -> Self {
        x
    }
}

impl Real for f32x8 {
    #[inline(always)]
    fn splat(x: f32) -> Self {
        f32x8::splat(x)
    }
}

/// (sin, cos) of π/4 · t for t ∈ [−1, 1], by Horner's rule in s² (no FMA).
#[inline(always)]
fn sin_cos_quarter_pi<T: Real>(t: T) -> (T, T) {
    let s = t * T::splat(FRAC_PI_4);
    let s2 = s * s;
    let sin_tail = T::splat(-1.0 / 6.0)
        + s2 * (T::splat(1.0 / 120.0)
            + s2 * (T::splat(-1.0 / 5040.0) + s2 * T::splat(1.0 / 362_880.0)));
    let sin = s + s * s2 * sin_tail;
    let cos_tail = T::splat(1.0 / 24.0)
        + s2 * (T::splat(-1.0 / 720.0)
            + s2 * (T::splat(1.0 / 40_320.0) + s2 * T::splat(-1.0 / 3_628_800.0)));
    let cos = T::splat(1.0) + s2 * (T::splat(-0.5) + s2 * cos_tail);
    (sin, cos)
}

/// Cephes' `atanf` polynomial: atan(w) for |w| ≤ tan(π/8).
#[inline(always)]
fn atan_small<T: Real>(w: T) -> T {
    let w2 = w * w;
    let p = ((T::splat(8.053_744_5e-2) * w2 - T::splat(1.387_768_6e-1)) * w2
        + T::splat(1.997_771_1e-1))
        * w2
        - T::splat(3.333_295e-1);
    p * w2 * w + w
}

/// tan(π/8): above it, atan(z) = π/4 + atan((z − 1)/(z + 1)).
const TAN_PI_8: f32 = 0.414_213_57;

/// atan(z) for z ∈ [0, 1] (the reference for [`atan_unit_x8`]).
#[inline]
fn atan_unit(z: f32) -> f32 {
    if z > TAN_PI_8 {
        FRAC_PI_4 + atan_small((z - 1.0) / (z + 1.0))
    } else {
        atan_small(z)
    }
}

/// [`atan_unit`] for eight lanes.
#[inline]
fn atan_unit_x8(z: f32x8) -> f32x8 {
    let big = z.simd_gt(f32x8::splat(TAN_PI_8));
    let one = f32x8::splat(1.0);
    let w = big.select((z - one) / (z + one), z);
    let base = big.select(f32x8::splat(FRAC_PI_4), f32x8::splat(0.0));
    // `0 + p` is exactly p (p is never −0 here: only for z = −0, which `abs` has removed).
    base + atan_small(w)
}

/// Maps u ∈ [0,1)² to a direction on the cosine-weighted hemisphere around +z (local frame,
/// z = the normal). Density [`cosine_hemisphere_pdf`]`(z)` per unit solid angle.
///
/// # Panics
/// Debug builds assert u ∈ [0,1)². Release: any finite u still gives a unit vector with
/// z ≥ 0 when u ∈ \[0,1\]² (outside it, |x| or |y| may exceed 1).
#[inline]
pub fn sample_cosine_hemisphere(u: [f32; 2]) -> Vec3 {
    debug_assert!(
        (0.0..1.0).contains(&u[0]) && (0.0..1.0).contains(&u[1]),
        "u = {u:?}"
    );
    // Shirley–Chiu: the square [-1,1]² in concentric squares to concentric circles.
    let a = 2.0 * u[0] - 1.0;
    let b = 2.0 * u[1] - 1.0;
    let (x, y, r) = if a == 0.0 && b == 0.0 {
        (0.0, 0.0, 0.0)
    } else if a.abs() > b.abs() {
        // Wedges around ±x: radius a, angle π/4 · b/a.
        let (s, c) = sin_cos_quarter_pi(b / a);
        (a * c, a * s, a)
    } else {
        // Wedges around ±y: radius b, angle π/2 − π/4 · a/b.
        let (s, c) = sin_cos_quarter_pi(a / b);
        (b * s, b * c, b)
    };
    // Malley: lift the disk to the hemisphere.
    let z = libm::sqrtf((1.0 - r * r).max(0.0));
    Vec3::new(x, y, z)
}

/// Solid-angle density of [`sample_cosine_hemisphere`]: cos θ / π, and 0 below the horizon
/// (and for NaN).
#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    if cos_theta > 0.0 {
        cos_theta * FRAC_1_PI
    } else {
        0.0
    }
}

/// The inverse of [`sample_cosine_hemisphere`]: the point of [0,1)² that maps to `w`.
///
/// Only w.x and w.y are used (the disk projection); `w` should be a unit vector with
/// z ≥ 0. The result is clamped into [0, 1 − 2⁻²⁴]², and NaN components come back as 0, so
/// it can be fed to a warp whatever `w` was.
#[inline]
pub fn invert_cosine_hemisphere(w: Vec3) -> [f32; 2] {
    let (x, y) = (w.x, w.y);
    let r = libm::sqrtf(x * x + y * y);
    let (a, b) = if r == 0.0 {
        (0.0, 0.0)
    } else if x.abs() >= y.abs() {
        // Wedges around ±x: radius a = ±r, b = a · atan(y/x) · 4/π.
        let a = libm::copysignf(r, x);
        let t = libm::copysignf(atan_unit((y / x).abs()), y / x) * (4.0 / core::f32::consts::PI);
        (a, a * t)
    } else {
        let b = libm::copysignf(r, y);
        let t = libm::copysignf(atan_unit((x / y).abs()), x / y) * (4.0 / core::f32::consts::PI);
        (b * t, b)
    };
    [clamp_unit((a + 1.0) * 0.5), clamp_unit((b + 1.0) * 0.5)]
}

/// Into [0, 1 − 2⁻²⁴]; NaN to 0.
#[inline]
fn clamp_unit(u: f32) -> f32 {
    if u >= 0.0 {
        u.min(ONE_MINUS_EPSILON)
    } else {
        0.0
    }
}

/// [`clamp_unit`] for eight lanes.
#[inline]
fn clamp_unit_x8(u: f32x8) -> f32x8 {
    let zero = f32x8::splat(0.0);
    let top = f32x8::splat(ONE_MINUS_EPSILON);
    let u = u.simd_ge(zero).select(u, zero);
    u.simd_gt(top).select(top, u)
}

/// [`sample_cosine_hemisphere`] for eight lanes: returns [x, y, z], bit-identical per lane.
///
/// # Panics
/// Never; the scalar version's debug assertion on u is not repeated here (release behaviour
/// is the same).
#[inline]
pub fn sample_cosine_hemisphere_x8(u: [f32x8; 2]) -> [f32x8; 3] {
    let (zero, one, two) = (f32x8::splat(0.0), f32x8::splat(1.0), f32x8::splat(2.0));
    let a = two * u[0] - one;
    let b = two * u[1] - one;
    let wedge_x = a.abs().simd_gt(b.abs());
    // Radius and the ratio's numerator / denominator for either wedge; a zero denominator
    // (only at a = b = 0, where the radius is 0 too) becomes 1 so no NaN is formed.
    let r = wedge_x.select(a, b);
    let num = wedge_x.select(b, a);
    let den = r.simd_eq(zero).select(one, r);
    let (s, c) = sin_cos_quarter_pi(num / den);
    let x = r * wedge_x.select(c, s);
    let y = r * wedge_x.select(s, c);
    let z = (one - r * r).max(zero).sqrt();
    [x, y, z]
}

/// [`cosine_hemisphere_pdf`] for eight lanes.
#[inline]
pub fn cosine_hemisphere_pdf_x8(cos_theta: f32x8) -> f32x8 {
    let zero = f32x8::splat(0.0);
    cos_theta
        .simd_gt(zero)
        .select(cos_theta * f32x8::splat(FRAC_1_PI), zero)
}

/// [`invert_cosine_hemisphere`] for eight lanes: w = [x, y, z] (z unused).
#[inline]
pub fn invert_cosine_hemisphere_x8(w: [f32x8; 3]) -> [f32x8; 2] {
    let (zero, one, half) = (f32x8::splat(0.0), f32x8::splat(1.0), f32x8::splat(0.5));
    let [x, y, _] = w;
    let r = (x * x + y * y).sqrt();
    let wedge_x = x.abs().simd_ge(y.abs());
    let num = wedge_x.select(y, x);
    let den = wedge_x.select(x, y);
    let den = den.simd_eq(zero).select(one, den);
    let ratio = num / den;
    let t = atan_unit_x8(ratio.abs()).copysign(ratio) * f32x8::splat(4.0 / core::f32::consts::PI);
    let radius = r.copysign(den);
    let is_zero = r.simd_eq(zero);
    let a = is_zero.select(zero, wedge_x.select(radius, radius * t));
    let b = is_zero.select(zero, wedge_x.select(radius * t, radius));
    [
        clamp_unit_x8((a + one) * half),
        clamp_unit_x8((b + one) * half),
    ]
}

/// Maps u ∈ [0,1)² to the unit sphere by Clarberg's equal-area octahedral map (*Fast
/// Equal-Area Mapping of the (Hemi)Sphere using SIMD*, JGT 13(3), 2008; as pbrt-v4's
/// `EqualAreaSquareToSphere`): every region of the square goes to a region of the sphere of
/// the same share of its area, so a density p on the square is p / 4π per unit solid angle.
/// The light probes' primary sample space (their guide lives on this square, as a texel's
/// lives on the cosine map's).
///
/// # Panics
/// Debug builds assert u ∈ [0,1)².
#[inline]
pub fn sample_sphere_equal_area(u: [f32; 2]) -> Vec3 {
    debug_assert!(
        (0.0..1.0).contains(&u[0]) && (0.0..1.0).contains(&u[1]),
        "u = {u:?}"
    );
    let (a, b) = (2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0);
    let (ap, bp) = (a.abs(), b.abs());
    let signed_distance = 1.0 - (ap + bp);
    let r = 1.0 - signed_distance.abs();
    // φ = π/4 · (1 + t), t = (|b| − |a|) / r ∈ [−1, 1].
    let t = if r == 0.0 {
        0.0
    } else {
        ((bp - ap) / r).clamp(-1.0, 1.0)
    };
    let (s, c) = sin_cos_quarter_pi(t);
    let half_root2 = core::f32::consts::FRAC_1_SQRT_2;
    let (cos_phi, sin_phi) = ((c - s) * half_root2, (c + s) * half_root2);
    let z = (1.0 - r * r).copysign(signed_distance);
    let lift = r * libm::sqrtf((2.0 - r * r).max(0.0));
    Vec3::new(cos_phi.copysign(a) * lift, sin_phi.copysign(b) * lift, z)
}

/// Solid-angle density of [`sample_sphere_equal_area`] under the uniform square: 1 / 4π.
pub const SPHERE_PDF: f32 = FRAC_1_PI / 4.0;

/// The inverse of [`sample_sphere_equal_area`]: the point of [0,1)² that maps to the unit
/// vector `w`, clamped into [0, 1 − 2⁻²⁴]² (NaN components come back as 0).
#[inline]
pub fn invert_sphere_equal_area(w: Vec3) -> [f32; 2] {
    let (x, y, z) = (w.x.abs(), w.y.abs(), w.z.abs());
    let r = libm::sqrtf((1.0 - z).max(0.0));
    let (big, small) = (x.max(y), x.min(y));
    let ratio = if big == 0.0 { 0.0 } else { small / big };
    let mut phi = atan_unit(ratio) * (2.0 * FRAC_1_PI);
    if x < y {
        phi = 1.0 - phi;
    }
    let mut v = phi * r;
    let mut u = r - v;
    if w.z < 0.0 {
        core::mem::swap(&mut u, &mut v);
        u = 1.0 - u;
        v = 1.0 - v;
    }
    let (u, v) = (u.copysign(w.x), v.copysign(w.y));
    [clamp_unit(0.5 * (u + 1.0)), clamp_unit(0.5 * (v + 1.0))]
}

/// A right-handed orthonormal basis (t, b) with t × b = n, for a unit normal `n` (Duff et
/// al. 2017, listing 3). The sign is that of n.z with −0 counted as +0, so the two zeros of
/// a wall facing sideways get the same frame. The frame still turns by 180° about n where
/// n.z crosses 0: a texel's frame that must agree with its neighbours' comes from
/// [`carried_frame`].
///
/// # Panics
/// Debug builds assert n is finite. Release: the frame is as accurate as n is unit.
#[inline]
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    debug_assert!(n.is_finite(), "n = {n}");
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let bt = Vec3::new(b, sign + n.y * n.y * a, -n.y);
    (t, bt)
}

/// The frame of a cluster — tangent `t` of the unit mean normal `m` — carried to the unit
/// normal `n` by the minimal rotation taking `m` to `n` (Rodrigues, about `m × n`); returns
/// `(t', b')` with `t' × b' = n`. Texels whose normals are close map a point of the square
/// to close directions, whatever the signs of their components. Needs `m · n > −1` (normals
/// of one cluster lie within 60° of their mean); the result is re-orthonormalized
/// (Gram–Schmidt against `n`).
#[inline]
pub fn carried_frame(t: Vec3, m: Vec3, n: Vec3) -> (Vec3, Vec3) {
    let c = m.dot(n);
    let k = m.cross(n);
    let rotate = |v: Vec3| v * c + k.cross(v) + k * (k.dot(v) / (1.0 + c));
    let t = if c > -0.999 { rotate(t) } else { t };
    let t = (t - n * n.dot(t)).normalize_or(orthonormal_basis(n).0);
    (t, n.cross(t))
}

/// [`orthonormal_basis`] for eight normals: returns ([tx, ty, tz], [bx, by, bz]).
#[inline]
pub fn orthonormal_basis_x8(n: [f32x8; 3]) -> ([f32x8; 3], [f32x8; 3]) {
    let [nx, ny, nz] = n;
    let one = f32x8::splat(1.0);
    let sign = nz.simd_ge(f32x8::ZERO).select(one, -one);
    let a = -one / (sign + nz);
    let b = nx * ny * a;
    let t = [one + sign * nx * nx * a, sign * b, -sign * nx];
    let bt = [b, sign + ny * ny * a, -ny];
    (t, bt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{Pcg32, chi_square};
    use std::vec::Vec;

    const EDGES: [f32; 8] = [
        0.0,
        ONE_MINUS_EPSILON,
        0.5,
        0.25,
        0.75,
        1e-7,
        0.5 - 3e-8,
        0.999,
    ];

    fn lane(v: f32x8, i: usize) -> f32 {
        v.to_array()[i]
    }

    /// Packs `count` (1..=8) points into lanes, padding with the last one.
    fn pack(us: &[[f32; 2]]) -> [f32x8; 2] {
        let pad = |k: usize| core::array::from_fn(|i| us[i.min(us.len() - 1)][k]);
        [f32x8::new(pad(0)), f32x8::new(pad(1))]
    }

    fn sample_inputs() -> Vec<[f32; 2]> {
        let mut rng = Pcg32::new(5, 9);
        let mut us: Vec<[f32; 2]> = Vec::new();
        for &a in &EDGES {
            for &b in &EDGES {
                us.push([a, b]);
            }
        }
        for _ in 0..20_000 {
            us.push([rng.next_f32(), rng.next_f32()]);
        }
        us
    }

    #[test]
    fn sample_x8_matches_scalar_bit_for_bit_for_every_lane_count() {
        let us = sample_inputs();
        for count in 1..=8 {
            for chunk in us.chunks(count) {
                let w8 = sample_cosine_hemisphere_x8(pack(chunk));
                let pdf8 = cosine_hemisphere_pdf_x8(w8[2]);
                for (i, &u) in chunk.iter().enumerate() {
                    let w = sample_cosine_hemisphere(u);
                    let got = [lane(w8[0], i), lane(w8[1], i), lane(w8[2], i)];
                    assert_eq!(
                        got.map(f32::to_bits),
                        w.to_array().map(f32::to_bits),
                        "u = {u:?}"
                    );
                    let pdf = cosine_hemisphere_pdf(w.z);
                    assert_eq!(lane(pdf8, i).to_bits(), pdf.to_bits());
                }
            }
        }
    }

    #[test]
    fn invert_x8_matches_scalar_bit_for_bit_for_every_lane_count() {
        let mut ws: Vec<Vec3> = sample_inputs()
            .into_iter()
            .map(sample_cosine_hemisphere)
            .collect();
        ws.extend([
            Vec3::X,
            -Vec3::X,
            Vec3::Y,
            -Vec3::Y,
            Vec3::Z,
            Vec3::new(0.6, 0.6, 0.52),
        ]);
        ws.extend([Vec3::new(f32::NAN, 0.0, 1.0), Vec3::new(-0.0, -0.0, 1.0)]);
        for count in 1..=8 {
            for chunk in ws.chunks(count) {
                let pad = |k: usize| {
                    f32x8::new(core::array::from_fn(|i| chunk[i.min(chunk.len() - 1)][k]))
                };
                let u8 = invert_cosine_hemisphere_x8([pad(0), pad(1), pad(2)]);
                for (i, &w) in chunk.iter().enumerate() {
                    let u = invert_cosine_hemisphere(w);
                    assert_eq!(
                        [lane(u8[0], i).to_bits(), lane(u8[1], i).to_bits()],
                        u.map(f32::to_bits),
                        "w = {w}"
                    );
                }
            }
        }
    }

    #[test]
    fn samples_are_unit_upper_hemisphere_and_finite() {
        for u in sample_inputs() {
            let w = sample_cosine_hemisphere(u);
            assert!(w.is_finite() && w.z >= 0.0, "u = {u:?}: {w}");
            assert!(
                (w.length() - 1.0).abs() < 4e-7,
                "u = {u:?}: |w| = {}",
                w.length()
            );
        }
        assert_eq!(sample_cosine_hemisphere([0.5, 0.5]), Vec3::Z);
        assert_eq!(
            sample_cosine_hemisphere([ONE_MINUS_EPSILON, 0.5]).z,
            libm::sqrtf(1.0 - (2.0 * ONE_MINUS_EPSILON - 1.0) * (2.0 * ONE_MINUS_EPSILON - 1.0))
        );
    }

    #[test]
    fn invert_undoes_sample() {
        let mut worst = 0.0f32;
        for u in sample_inputs() {
            let back = invert_cosine_hemisphere(sample_cosine_hemisphere(u));
            worst = worst
                .max((back[0] - u[0]).abs())
                .max((back[1] - u[1]).abs());
        }
        assert!(worst < 2e-6, "worst |invert(sample(u)) - u| = {worst}");
        // And the other way round, on directions: compare the disk projections (z is
        // ill-conditioned at the horizon, dz = r dr / z).
        let mut rng = Pcg32::new(8, 8);
        for _ in 0..10_000 {
            let w = sample_cosine_hemisphere([rng.next_f32(), rng.next_f32()]);
            let again = sample_cosine_hemisphere(invert_cosine_hemisphere(w));
            assert!((again - w).truncate().length() < 1e-6, "{w} -> {again}");
        }
        for w in [
            Vec3::new(f32::NAN, 0.5, 0.5),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, -3.0, 0.0),
        ] {
            let u = invert_cosine_hemisphere(w);
            assert!(u.iter().all(|c| (0.0..1.0).contains(c)), "{w} -> {u:?}");
        }
    }

    /// Chi-square of the sampled directions against the cosine pdf, binned in (cos θ, φ) with
    /// odd resolutions; expected counts integrate the pdf over each cell exactly:
    /// ∫ cos θ/π dω over [z0,z1]×[φ0,φ1] = (z1² − z0²)/2 · (φ1 − φ0)/π.
    /// Both the scalar and the 8-wide sampler are tested (Šidák over the two).
    #[test]
    fn chi_square_against_the_cosine_pdf() {
        const NZ: usize = 9;
        const NPHI: usize = 21;
        let n = 200_000usize;
        let bin = |w: Vec3| {
            let iz = ((w.z * NZ as f32) as usize).min(NZ - 1);
            let phi = libm::atan2f(w.y, w.x).rem_euclid(2.0 * core::f32::consts::PI);
            let ip = ((phi / (2.0 * core::f32::consts::PI) * NPHI as f32) as usize).min(NPHI - 1);
            iz * NPHI + ip
        };
        let mut expected = std::vec![0.0f64; NZ * NPHI];
        let mut total = 0.0;
        for iz in 0..NZ {
            let (z0, z1) = (iz as f64 / NZ as f64, (iz + 1) as f64 / NZ as f64);
            for ip in 0..NPHI {
                let p = (z1 * z1 - z0 * z0) / 2.0 * (2.0 / NPHI as f64);
                expected[iz * NPHI + ip] = p * n as f64;
                total += p;
            }
        }
        assert!((total - 1.0).abs() < 1e-12, "the pdf integrates to {total}");
        let mut rng = Pcg32::new(2019, 1);
        let mut scalar = std::vec![0.0f64; NZ * NPHI];
        let mut wide8 = std::vec![0.0f64; NZ * NPHI];
        for _ in 0..n / 8 {
            let us: [[f32; 2]; 8] = core::array::from_fn(|_| [rng.next_f32(), rng.next_f32()]);
            let w8 = sample_cosine_hemisphere_x8(pack(&us));
            for (i, &u) in us.iter().enumerate() {
                scalar[bin(sample_cosine_hemisphere(u))] += 1.0;
                let _ = u;
                wide8[bin(Vec3::new(lane(w8[0], i), lane(w8[1], i), lane(w8[2], i)))] += 1.0;
            }
        }
        // The x8 lanes saw the same u as the scalar ones, so feed it an independent stream too.
        let mut rng = Pcg32::new(2019, 2);
        let mut independent = std::vec![0.0f64; NZ * NPHI];
        for _ in 0..n / 8 {
            let us: [[f32; 2]; 8] = core::array::from_fn(|_| [rng.next_f32(), rng.next_f32()]);
            let w8 = sample_cosine_hemisphere_x8(pack(&us));
            for i in 0..8 {
                independent[bin(Vec3::new(lane(w8[0], i), lane(w8[1], i), lane(w8[2], i)))] += 1.0;
            }
        }
        assert_eq!(
            scalar, wide8,
            "scalar and 8-wide disagree on the same inputs"
        );
        for (name, hist) in [("scalar", &scalar), ("x8", &independent)] {
            let r = chi_square(hist, &expected, 5.0);
            if !r.passes(0.01, 2) {
                let path = dump_histogram(name, hist, &expected, NPHI);
                panic!("{name}: {r:?}; histogram and expectation in {path}");
            }
        }
        // The test can fail: a uniform-hemisphere sampler (z = u) must be rejected.
        let mut rng = Pcg32::new(2019, 3);
        let mut wrong = std::vec![0.0f64; NZ * NPHI];
        for _ in 0..n {
            let w = sample_cosine_hemisphere([rng.next_f32(), rng.next_f32()]);
            let z = rng.next_f32();
            let s = libm::sqrtf(1.0 - z * z) / libm::sqrtf(w.x * w.x + w.y * w.y).max(1e-12);
            wrong[bin(Vec3::new(w.x * s, w.y * s, z))] += 1.0;
        }
        assert!(!chi_square(&wrong, &expected, 5.0).passes(0.01, 1));
    }

    #[test]
    fn pdf_matches_the_sample_density_and_edge_values() {
        assert_eq!(cosine_hemisphere_pdf(1.0), FRAC_1_PI);
        assert_eq!(cosine_hemisphere_pdf(0.0), 0.0);
        assert_eq!(cosine_hemisphere_pdf(-0.5), 0.0);
        assert_eq!(cosine_hemisphere_pdf(f32::NAN), 0.0);
        let p8 = cosine_hemisphere_pdf_x8(f32x8::new([
            1.0,
            0.0,
            -0.5,
            f32::NAN,
            0.5,
            f32::INFINITY,
            -0.0,
            1e-30,
        ]));
        let want =
            [1.0, 0.0, -0.5, f32::NAN, 0.5, f32::INFINITY, -0.0, 1e-30].map(cosine_hemisphere_pdf);
        assert_eq!(p8.to_array().map(f32::to_bits), want.map(f32::to_bits));
        // Jacobian check: the map's area distortion is π / cos θ · ... i.e. p(ω) dω = du.
        // Estimate the solid angle of a small square's image and compare with du / pdf.
        let mut rng = Pcg32::new(1, 1);
        for _ in 0..200 {
            let u = [0.02 + 0.96 * rng.next_f32(), 0.02 + 0.96 * rng.next_f32()];
            let h = 1e-3f32;
            let w0 = sample_cosine_hemisphere(u);
            let wx = sample_cosine_hemisphere([u[0] + h, u[1]]);
            let wy = sample_cosine_hemisphere([u[0], u[1] + h]);
            let area = (wx - w0).cross(wy - w0).length();
            if w0.z < 0.05 {
                continue;
            }
            let want = h * h / cosine_hemisphere_pdf(w0.z);
            assert!(
                (area / want - 1.0).abs() < 0.02,
                "u {u:?}: {area} vs {want}"
            );
        }
    }

    /// Writes observed and expected counts (rows: cos θ bins, columns: φ bins) under
    /// `target/` so a person can look at a failing chi-square test.
    fn dump_histogram(
        name: &str,
        observed: &[f64],
        expected: &[f64],
        columns: usize,
    ) -> std::string::String {
        use std::fmt::Write;
        let mut text = std::string::String::from(
            "# observed / expected per cell; rows = cos theta bins, columns = phi bins\n",
        );
        for (row_o, row_e) in observed.chunks(columns).zip(expected.chunks(columns)) {
            for (o, e) in row_o.iter().zip(row_e) {
                let _ = write!(text, "{o:.0}/{e:.1} ");
            }
            text.push('\n');
        }
        let path = std::format!(
            "{}/../target/chi2_cosine_hemisphere_{name}.txt",
            env!("CARGO_MANIFEST_DIR")
        );
        let _ = std::fs::write(&path, text);
        path
    }

    fn check_basis(n: Vec3, t: Vec3, b: Vec3) {
        for (name, v) in [
            ("t.t", t.dot(t) - 1.0),
            ("b.b", b.dot(b) - 1.0),
            ("t.b", t.dot(b)),
            ("t.n", t.dot(n)),
            ("b.n", b.dot(n)),
        ] {
            assert!(v.abs() < 1e-6, "n = {n}: {name} off by {v}");
        }
        assert!(
            (t.cross(b) - n).length() < 1e-6,
            "n = {n}: not right-handed"
        );
    }

    #[test]
    fn basis_is_orthonormal_near_poles_and_for_random_normals() {
        let mut normals: Vec<Vec3> = Vec::new();
        for s in [1.0f32, -1.0] {
            normals.push(Vec3::new(0.0, 0.0, s));
            normals.push(Vec3::new(-0.0, 0.0, s));
            normals.push(Vec3::new(0.0, -0.0, -0.0 * s + s));
            for e in [1e-7f32, 1e-5, 1e-3, 3e-2] {
                normals.push(Vec3::new(e, -e, s).normalize());
                normals.push(Vec3::new(-e, 0.0, s).normalize());
                normals.push(Vec3::new(0.0, e, s).normalize());
            }
        }
        normals.push(Vec3::new(0.0, 0.0, -0.0).with_z(-0.0) + Vec3::X);
        normals.push(Vec3::new(0.0, 1.0, -0.0));
        let mut rng = Pcg32::new(3, 3);
        for _ in 0..10_000 {
            // Uniform on the sphere.
            let z = 2.0 * rng.next_f32() - 1.0;
            let phi = 2.0 * core::f32::consts::PI * rng.next_f32();
            let r = libm::sqrtf((1.0 - z * z).max(0.0));
            normals.push(Vec3::new(r * libm::cosf(phi), r * libm::sinf(phi), z).normalize());
        }
        for count in 1..=8 {
            for chunk in normals.chunks(count) {
                let pad = |k: usize| {
                    f32x8::new(core::array::from_fn(|i| chunk[i.min(chunk.len() - 1)][k]))
                };
                let (t8, b8) = orthonormal_basis_x8([pad(0), pad(1), pad(2)]);
                for (i, &n) in chunk.iter().enumerate() {
                    let (t, b) = orthonormal_basis(n);
                    check_basis(n, t, b);
                    let t_lane = [lane(t8[0], i), lane(t8[1], i), lane(t8[2], i)];
                    let b_lane = [lane(b8[0], i), lane(b8[1], i), lane(b8[2], i)];
                    assert_eq!(
                        t_lane.map(f32::to_bits),
                        t.to_array().map(f32::to_bits),
                        "n = {n}"
                    );
                    assert_eq!(
                        b_lane.map(f32::to_bits),
                        b.to_array().map(f32::to_bits),
                        "n = {n}"
                    );
                }
            }
        }
    }

    #[test]
    fn shared_polynomials_are_accurate() {
        let mut worst = [0.0f64; 3];
        for k in 0..=20_000 {
            let t = -1.0 + 2.0 * k as f32 / 20_000.0;
            let (s, c) = sin_cos_quarter_pi(t);
            let x = f64::from(t) * core::f64::consts::FRAC_PI_4;
            worst[0] = worst[0].max((f64::from(s) - x.sin()).abs());
            worst[1] = worst[1].max((f64::from(c) - x.cos()).abs());
            let z = k as f32 / 20_000.0;
            worst[2] = worst[2].max((f64::from(atan_unit(z)) - f64::from(z).atan()).abs());
            assert_eq!(
                atan_unit_x8(f32x8::splat(z)).to_array()[3].to_bits(),
                atan_unit(z).to_bits()
            );
        }
        assert!(
            worst[0] < 2e-7 && worst[1] < 2e-7 && worst[2] < 2e-7,
            "errors {worst:?}"
        );
    }

    #[test]
    fn both_zeros_of_n_z_give_one_frame() {
        for n in [Vec3::X, Vec3::new(0.6, 0.8, 0.0), Vec3::new(0.0, -1.0, 0.0)] {
            let minus = Vec3::new(n.x, n.y, -0.0);
            assert_eq!(orthonormal_basis(n), orthonormal_basis(minus), "{n}");
            let (t, b) = orthonormal_basis_x8([
                f32x8::splat(n.x),
                f32x8::splat(n.y),
                f32x8::new([0.0, -0.0, 0.0, -0.0, 0.0, -0.0, 0.0, -0.0]),
            ]);
            let (t0, b0) = orthonormal_basis(n);
            for a in [t, b].iter().zip([t0, b0]) {
                for (lane, want) in a.0.iter().zip([a.1.x, a.1.y, a.1.z]) {
                    assert!(lane.to_array().iter().all(|&v| v == want), "{n}");
                }
            }
        }
    }

    #[test]
    fn carried_frames_are_orthonormal_and_continuous() {
        let m = Vec3::new(1.0, 0.0, 0.0);
        let (t, _) = orthonormal_basis(m);
        for n in [
            m,
            Vec3::new(1.0, 0.0, 1e-7).normalize(),
            Vec3::new(1.0, 0.0, -1e-7).normalize(),
            Vec3::new(0.8, 0.0, 0.6),
            Vec3::new(0.8, 0.6, 0.0),
            Vec3::new(0.6, -0.5, -0.62).normalize(),
        ] {
            let (a, b) = carried_frame(t, m, n);
            assert!((a.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
            assert!(a.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5 && a.dot(b).abs() < 1e-5);
            assert!((a.cross(b) - n).length() < 1e-5, "right-handed about {n}");
            // The minimal rotation moves the tangent no more than the normal moved.
            let turned = m.angle_between(n);
            assert!(a.angle_between(t) <= turned + 1e-3, "{n}: {a} vs {t}");
        }
    }

    /// The equal-area map is uniform over the sphere: 8 bands of equal area in z (z is
    /// uniform on [−1, 1] for uniform directions) × 16 sectors in φ, chi-square against equal
    /// counts; and it inverts to the point it came from.
    #[test]
    fn the_equal_area_sphere_map_is_uniform_and_inverts() {
        let mut rng = Pcg32::new(7, 3);
        let (bands, sectors, n) = (8usize, 16usize, 200_000usize);
        let mut observed = std::vec![0.0f64; bands * sectors];
        for _ in 0..n {
            let u = [rng.next_f32(), rng.next_f32()];
            let w = sample_sphere_equal_area(u);
            assert!((w.length() - 1.0).abs() < 1e-5, "{u:?} -> {w}");
            let back = invert_sphere_equal_area(w);
            assert!(
                (back[0] - u[0]).abs() < 2e-4 && (back[1] - u[1]).abs() < 2e-4,
                "{u:?} -> {w} -> {back:?}"
            );
            let band = (((w.z + 1.0) * 0.5 * bands as f32) as usize).min(bands - 1);
            let phi = w.y.atan2(w.x) + core::f32::consts::PI;
            let sector =
                ((phi / core::f32::consts::TAU * sectors as f32) as usize).min(sectors - 1);
            observed[band * sectors + sector] += 1.0;
        }
        let expected = std::vec![n as f64 / (bands * sectors) as f64; bands * sectors];
        let test = chi_square(&observed, &expected, 5.0);
        assert!(test.passes(0.01, 1), "{test:?}");
        assert_eq!(
            sample_sphere_equal_area([0.5, 0.5]),
            Vec3::new(0.0, 0.0, 1.0)
        );
    }
}
