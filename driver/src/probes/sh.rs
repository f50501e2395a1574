//! Order-2 (L2) real spherical harmonics of a light probe's incident radiance: nine
//! coefficients per colour channel, their irradiance, and optional de-ringing.
//!
//! The convention, stated once (docs/probes.md, "Spherical harmonics"):
//! - **what**: the coefficients project the *incident radiance* L(ω), ω the unit direction
//!   from the probe towards where the light comes from, in the scene's own axes (a glTF level
//!   is +Y up): `L_k = ∫ L(ω) Y_k(ω) dω`;
//! - **basis**: the real, orthonormal basis of Sloan's *Stupid Spherical Harmonics Tricks*
//!   (2008), index `k = l² + l + m`: Y₀ = 0.282095; Y₁ = 0.488603·y, Y₂ = 0.488603·z,
//!   Y₃ = 0.488603·x; Y₄ = 1.092548·xy, Y₅ = 1.092548·yz, Y₆ = 0.315392·(3z² − 1),
//!   Y₇ = 1.092548·xz, Y₈ = 0.546274·(x² − y²);
//! - **irradiance** at normal n: `E(n) = Σ Â_l L_k Y_k(n)`, Â₀ = π, Â₁ = 2π/3, Â₂ = π/4
//!   (Ramamoorthi & Hanrahan 2001); a diffuse surface of albedo ρ there leaves ρ·E(n)/π;
//! - **L1** is the first four coefficients of the same set (bands 0 and 1).
//!
//! De-ringing (`--probe-dering`) multiplies band l by the Lanczos σ-factor
//! sinc(l / (order + 1)) (Sloan, *Deringing Spherical Harmonics*, 2017, windowing): a bright
//! source no longer drives the irradiance negative on the far side, at the price of a blurrier
//! probe.

use glam::Vec3;

/// Coefficients of order 2: bands 0, 1 and 2.
pub const COEFFICIENTS: usize = 9;

/// The band of each coefficient.
pub const BAND: [usize; COEFFICIENTS] = [0, 1, 1, 1, 2, 2, 2, 2, 2];

/// Â_l: the clamped cosine's convolution factor of each band (irradiance from radiance).
pub const COSINE_LOBE: [f32; 3] = [
    std::f32::consts::PI,
    2.0 * std::f32::consts::PI / 3.0,
    std::f32::consts::PI / 4.0,
];

/// The basis at unit direction `d` (module docs for the order and constants).
#[inline]
#[must_use]
pub fn basis(d: Vec3) -> [f32; COEFFICIENTS] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282_095,
        0.488_603 * y,
        0.488_603 * z,
        0.488_603 * x,
        1.092_548 * x * y,
        1.092_548 * y * z,
        0.315_392 * (3.0 * z * z - 1.0),
        1.092_548 * x * z,
        0.546_274 * (x * x - y * y),
    ]
}

/// Nine RGB coefficients of incident radiance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sh9 {
    /// Coefficient k, RGB.
    pub c: [Vec3; COEFFICIENTS],
}

impl Sh9 {
    /// Adds the projection of `value` arriving from `d` (a sample's radiance over its
    /// density: the Monte Carlo estimate of the projection integral).
    #[inline]
    pub fn add(&mut self, d: Vec3, value: Vec3) {
        for (c, y) in self.c.iter_mut().zip(basis(d)) {
            *c += value * y;
        }
    }

    /// Every coefficient times `s`.
    #[must_use]
    pub fn scaled(&self, s: f32) -> Self {
        Self {
            c: self.c.map(|c| c * s),
        }
    }

    /// The sum of two projections.
    #[must_use]
    pub fn plus(&self, o: &Self) -> Self {
        let mut c = self.c;
        for (a, b) in c.iter_mut().zip(o.c) {
            *a += b;
        }
        Self { c }
    }

    /// The radiance the coefficients reconstruct from direction `d`.
    #[must_use]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        self.c.iter().zip(basis(d)).map(|(c, y)| *c * y).sum()
    }

    /// Irradiance on a surface of unit normal `n` facing the probe's light (module docs).
    #[must_use]
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        self.c
            .iter()
            .zip(basis(n))
            .zip(BAND)
            .map(|((c, y), band)| *c * (y * COSINE_LOBE[band]))
            .sum()
    }

    /// De-ringed: band l times the Lanczos σ-factor sinc(l / 3) (module docs).
    #[must_use]
    pub fn deringed(&self) -> Self {
        let mut c = self.c;
        for (k, c) in c.iter_mut().enumerate() {
            *c *= lanczos(BAND[k]);
        }
        Self { c }
    }

    /// Whether every coefficient is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.c.iter().all(|c| c.is_finite())
    }
}

/// The Lanczos σ-factor of band `l` for order 2: sinc(π l / 3).
fn lanczos(l: usize) -> f32 {
    if l == 0 {
        return 1.0;
    }
    let x = std::f32::consts::PI * l as f32 / 3.0;
    x.sin() / x
}

/// The 26 directions in which the probes' error is judged: the faces, edges and corners of a
/// cube (docs/probes.md, "How good the probes are").
#[must_use]
pub fn judged_directions() -> Vec<Vec3> {
    let mut out = Vec::with_capacity(26);
    for x in -1i32..=1 {
        for y in -1i32..=1 {
            for z in -1i32..=1 {
                if (x, y, z) != (0, 0, 0) {
                    out.push(Vec3::new(x as f32, y as f32, z as f32).normalize());
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::mapping::sample_sphere_equal_area;

    /// Integrates `f` over the sphere on a 512² grid of the equal-area square (each cell the
    /// same solid angle, 4π / 512²).
    fn integrate(f: impl Fn(Vec3) -> f64) -> f64 {
        let n = 512;
        let mut sum = 0.0;
        for i in 0..n {
            for j in 0..n {
                let u = [(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32];
                sum += f(sample_sphere_equal_area(u));
            }
        }
        sum * 4.0 * std::f64::consts::PI / (n * n) as f64
    }

    #[test]
    fn the_basis_is_orthonormal() {
        for a in 0..COEFFICIENTS {
            for b in a..COEFFICIENTS {
                let v = integrate(|d| f64::from(basis(d)[a]) * f64::from(basis(d)[b]));
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 2e-3, "<Y{a}, Y{b}> = {v}");
            }
        }
    }

    /// A constant radiance L projects onto Y₀ alone and gives E = πL in every direction.
    #[test]
    fn constant_radiance_gives_pi_l_everywhere() {
        let mut sh = Sh9::default();
        sh.c[0] = Vec3::splat(2.0 * (4.0 * std::f32::consts::PI).sqrt());
        for n in judged_directions() {
            let e = sh.irradiance(n);
            assert!((e.x - 2.0 * std::f32::consts::PI).abs() < 1e-3, "{n}: {e}");
        }
    }

    /// Radiance 1 from the upper hemisphere (z > 0) and 0 below: E(+z) = π, E(−z) = 0 and
    /// E(horizontal) = π/2 exactly; the L2 projection gets them within its known ringing
    /// (< 0.1 π: the clamped cosine's band-2 truncation).
    #[test]
    fn a_hemisphere_of_light_is_projected_within_the_truncation() {
        let mut sh = Sh9::default();
        for (k, c) in sh.c.iter_mut().enumerate() {
            let v = integrate(|d| {
                if d.z > 0.0 {
                    f64::from(basis(d)[k])
                } else {
                    0.0
                }
            });
            *c = Vec3::splat(v as f32);
        }
        let pi = std::f32::consts::PI;
        assert!((sh.irradiance(Vec3::Z).x - pi).abs() < 0.1 * pi);
        assert!(sh.irradiance(-Vec3::Z).x.abs() < 0.1 * pi);
        assert!((sh.irradiance(Vec3::X).x - pi / 2.0).abs() < 0.02 * pi);
        assert!((sh.radiance(Vec3::Z).x - 1.0).abs() < 0.3);
    }

    /// One small bright source: its L2 irradiance dips below zero on the far side; de-ringed,
    /// the dip is smaller and the irradiance towards the source is kept within 30 %.
    #[test]
    fn deringing_shrinks_the_negative_lobe() {
        let toward = Vec3::new(0.3, 0.4, 0.866).normalize();
        let mut sh = Sh9::default();
        sh.add(toward, Vec3::splat(10.0));
        let worst = |s: &Sh9| {
            judged_directions()
                .into_iter()
                .map(|n| s.irradiance(n).x)
                .fold(f32::INFINITY, f32::min)
        };
        let ringed = worst(&sh);
        let deringed = sh.deringed();
        assert!(ringed < 0.0, "{ringed}");
        assert!(
            worst(&deringed) > ringed,
            "{} vs {ringed}",
            worst(&deringed)
        );
        let (a, b) = (sh.irradiance(toward).x, deringed.irradiance(toward).x);
        assert!(b > 0.7 * a && b <= a, "{b} vs {a}");
    }
}
