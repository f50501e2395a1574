//! The L1 spherical harmonics a gather sample is projected on (`--directional sh-l1`): the
//! basis constants, one sample's projection, and the exact coefficients of a hemisphere of
//! constant radiance. Here, below the bake, because next-event estimation
//! ([`super::direct`]) projects its samples too; the directional file and its combination
//! are the bake's ([`crate::bake::directional`], which re-exports these).

use glam::Vec3;

/// `Y0 = 1 / (2√π)`.
pub const Y0: f32 = 0.282_094_8;
/// `√(3 / 4π)`: `Y1a(ω) = Y1 · ω_a`.
pub const Y1: f32 = 0.488_602_5;

/// The projection of one sample (or the sum of several): `[L0, L1x, L1y, L1z]`, RGB each.
pub type ShSample = [Vec3; 4];

/// `r · Y_i(ω)` for the four basis functions: the projection of radiance-over-density `r`
/// arriving from unit direction `dir`.
pub fn project(r: Vec3, dir: Vec3) -> ShSample {
    [r * Y0, r * (Y1 * dir.x), r * (Y1 * dir.y), r * (Y1 * dir.z)]
}

/// Adds to `sample` the projection of an irradiance estimate `e = L cosθ / p` of direction
/// `dir`, `cos` its cosine to the receiver's normal: `(e / cos) · Y_i(dir)`. Nothing for
/// `cos ≤ 0` or a projection that is not finite.
pub fn add_irradiance_sample(sample: &mut ShSample, e: Vec3, dir: Vec3, cos: f32) {
    if cos <= 0.0 {
        return;
    }
    let p = project(e / cos, dir);
    if p.iter().all(|v| v.is_finite()) {
        sample.iter_mut().zip(p).for_each(|(s, v)| *s += v);
    }
}

/// The exact coefficients of radiance `l` arriving from every direction of the hemisphere
/// around unit normal `n` (a receiver inside a sphere light): `L0 = √π l` and
/// `L1 = √(3/4π) π l n`.
pub fn hemisphere(l: Vec3, n: Vec3) -> ShSample {
    let pi = core::f32::consts::PI;
    let l1 = l * (Y1 * pi);
    [l * pi.sqrt(), l1 * n.x, l1 * n.y, l1 * n.z]
}
