//! Directional lightmaps (`--directional sh-l1`): per texel, the L1 spherical-harmonic
//! projection of the incident radiance, in world space, beside the irradiance
//! (docs/lightmaps.md, "Directional lightmaps", has the convention, the conversions to Unity's
//! and Unreal's encodings, the analytic test's derivation and the measurements).
//!
//! **Basis**: the real spherical harmonics of bands 0 and 1, orthonormal on the sphere, without
//! the Condon–Shortley phase, indexed by world axis: `Y0 = 1 / (2√π)` and
//! `Y1a(ω) = √(3 / 4π) · ω_a` for a = x, y, z. **Coefficients**: `L_i = ∫ L(ω) Y_i(ω) dω`
//! over the sphere, `L(ω)` the radiance arriving at the texel from direction ω — zero below
//! the texel's surface, whose hemisphere is all a texel gathers. The irradiance at any unit
//! normal n follows from the convolution with the clamped cosine (Ramamoorthi & Hanrahan
//! 2001): `E(n) ≈ π Y0 L0 + (2π/3) Y1(n)·L1 = (√π / 2) L0 + √(π / 3) (L1 · n)`, per colour.
//!
//! **Estimator**: every sample the irradiance gets contributes `(L / p) · Y_i(ω)`, `p` the
//! solid-angle density it was drawn with. The gather and next-event samples carry their
//! irradiance estimate `L cosθ / p`, so the projection divides by `cosθ` ([`ShSums::add`]); a
//! sample at `cosθ ≤ 0`, or whose projection is not finite, adds nothing (it has measure
//! zero), and a sample the irradiance's estimator rejects is not projected either. Each
//! iteration's sums become means, combined with exactly the per-iteration weights the
//! irradiance's combination gives that texel ([`guidebake_kernels::estimator::CombinationWeights`]:
//! plain average, Graybill–Deal's per-texel weights, the cluster's, Müller's global ones) and
//! scaled by the same ρ, so the coefficients are the same linear function of the same samples
//! as the irradiance: unbiased where it is, and `(√π/2) L0 + √(π/3) L1·n` at the texel's own
//! normal estimates the irradiance (exactly, for a hemisphere of constant radiance).
//!
//! **Files**: the last pass keeps one [`ShL1`] per texel (`directional.bin` in the work
//! directory), or K of them — the iterations' means — when `--combine global` combines the
//! iterations in the final pass; `finish` writes them as the EXR channels [`SH_CHANNELS`].

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use guidebake_kernels::estimator::{CombinationWeights, Welford};

pub use super::settings::Directional;
use super::settings::MAX_ITERATIONS;
use crate::output::result_file::{PerTexel, RecordFile};
pub use crate::transport::sh_l1::{ShSample, Y0, Y1, add_irradiance_sample, hemisphere, project};

/// The EXR channels of [`ShL1`], in its order: layer `SH0` (L0) and layers `SH1x`, `SH1y`,
/// `SH1z` (L1 by world axis), each R, G, B.
pub const SH_CHANNELS: [&str; 12] = [
    "SH0.R", "SH0.G", "SH0.B", "SH1x.R", "SH1x.G", "SH1x.B", "SH1y.R", "SH1y.G", "SH1y.B",
    "SH1z.R", "SH1z.G", "SH1z.B",
];

/// One texel's coefficients: `[L0, L1x, L1y, L1z]`, each R, G, B (index `3 · i + channel`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ShL1 {
    /// The coefficients.
    pub coefficients: [f32; 12],
}

impl PerTexel for ShL1 {
    const MAGIC: [u8; 8] = *b"GBSHL1\0\0";
    const VERSION: u32 = 1;
    const KIND: &'static str = "directional file";
}

/// The directional coefficients of every texel (`--directional sh-l1`): one [`ShL1`] per
/// texel, or K (the iterations' means) with `--combine global`. Declared here, beside its
/// record, so that the result-file module does not import the bake's modules.
pub type DirectionalFile = RecordFile<ShL1>;

impl ShL1 {
    /// The coefficients scaled by `s` (ρ), non-finite ones as zero.
    pub fn scaled(&self, s: f64) -> [f32; 12] {
        self.coefficients.map(|c| {
            let v = (f64::from(c) * s) as f32;
            if v.is_finite() { v } else { 0.0 }
        })
    }

    /// The irradiance these coefficients give a surface of unit normal `n`:
    /// `(√π/2) L0 + √(π/3) (L1 · n)`, per colour.
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        let c = &self.coefficients;
        let (a, b) = (
            core::f32::consts::PI.sqrt() / 2.0,
            (core::f32::consts::PI / 3.0).sqrt(),
        );
        Vec3::from_array(core::array::from_fn(|ch| {
            a * c[ch] + b * (c[3 + ch] * n.x + c[6 + ch] * n.y + c[9 + ch] * n.z)
        }))
    }
}

/// One iteration's sums of a texel's sample projections, in `f64` (as the irradiance's
/// [`Welford`] batches): divided by the batch's sample count they are the iteration's means.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShSums {
    sums: [f64; 12],
}

impl ShSums {
    /// Adds one sample's projection.
    pub fn add(&mut self, sample: &ShSample) {
        for (i, v) in sample.iter().enumerate() {
            for (c, x) in v.to_array().into_iter().enumerate() {
                self.sums[3 * i + c] += f64::from(x);
            }
        }
    }

    /// The mean over the batch's `count` samples (zero without samples).
    pub fn mean(&self, count: u64) -> ShL1 {
        let inv = if count > 0 { 1.0 / count as f64 } else { 0.0 };
        ShL1 {
            coefficients: self.sums.map(|s| (s * inv) as f32),
        }
    }
}

/// A texel's coefficients from its iterations' means, combined with the weights `weights`
/// gives its `batches` (the irradiance's combination); zero without samples.
pub fn combine(means: &[ShL1], batches: &[Welford], weights: &dyn CombinationWeights) -> ShL1 {
    let mut w = [0.0f64; MAX_ITERATIONS];
    let k = batches.len().min(w.len());
    if !weights.weights(&batches[..k], &mut w[..k]) {
        return ShL1::default();
    }
    let mut out = [0.0f64; 12];
    for (mean, w) in means.iter().zip(&w[..k]) {
        for (o, c) in out.iter_mut().zip(mean.coefficients) {
            *o += w * f64::from(c);
        }
    }
    ShL1 {
        coefficients: out.map(|c| c as f32),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::estimator::PlainAverage;
    use guidebake_kernels::testing::Pcg32;

    /// The basis is orthonormal: a Monte Carlo of `Y_i Y_j` over the sphere.
    #[test]
    fn the_basis_is_orthonormal() {
        let mut rng = Pcg32::new(5, 1);
        let n = 200_000;
        let mut gram = [[0.0f64; 4]; 4];
        for _ in 0..n {
            let z = 2.0 * rng.next_f32() - 1.0;
            let phi = core::f32::consts::TAU * rng.next_f32();
            let r = (1.0 - z * z).max(0.0).sqrt();
            let dir = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            let y = project(Vec3::ONE, dir).map(|v| f64::from(v.x));
            for i in 0..4 {
                for j in 0..4 {
                    gram[i][j] += y[i] * y[j] * 4.0 * std::f64::consts::PI / f64::from(n);
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, g) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((g - want).abs() < 0.02, "<Y{i}, Y{j}> = {g}");
            }
        }
    }

    /// A hemisphere of constant radiance L: its coefficients give back E = πL at its normal,
    /// and E(−n) = 0 (the L1 reconstruction of a hemisphere is exact at both poles).
    #[test]
    fn a_constant_hemisphere_reconstructs_pi_l() {
        let n = Vec3::new(0.6, 0.0, 0.8);
        let [a, b, c, d] = hemisphere(Vec3::splat(2.0), n);
        let mut sh = ShL1::default();
        for (i, v) in [a, b, c, d].iter().enumerate() {
            sh.coefficients[3 * i..3 * i + 3].copy_from_slice(&v.to_array());
        }
        let e = sh.irradiance(n);
        assert!((e.x - 2.0 * core::f32::consts::PI).abs() < 1e-5, "{e}");
        assert!(sh.irradiance(-n).x.abs() < 1e-5);
    }

    #[test]
    fn grazing_and_non_finite_samples_add_nothing() {
        let mut s = ShSample::default();
        add_irradiance_sample(&mut s, Vec3::ONE, Vec3::X, 0.0);
        add_irradiance_sample(&mut s, Vec3::splat(f32::MAX), Vec3::X, 1e-30);
        assert_eq!(s, ShSample::default());
        add_irradiance_sample(&mut s, Vec3::ONE, Vec3::Z, 0.5);
        assert_eq!(s[3], Vec3::splat(2.0 * Y1));
    }

    #[test]
    fn iterations_combine_with_the_irradiance_weights() {
        let mut batches = [Welford::new(); 2];
        (0..3).for_each(|_| batches[0].push([1.0; 3]));
        batches[1].push([1.0; 3]);
        let means = [
            ShL1 {
                coefficients: [1.0; 12],
            },
            ShL1 {
                coefficients: [5.0; 12],
            },
        ];
        // Plain average: 3 samples at 1, one at 5.
        let c = combine(&means, &batches, &PlainAverage);
        assert_eq!(c.coefficients, [2.0; 12]);
        assert_eq!(
            combine(&means, &[Welford::new(); 2], &PlainAverage),
            ShL1::default()
        );
    }
}
