//! Sky radiance for gather rays that leave the scene.
//!
//! An equirectangular map is looked up with +Y up: row 0 is the zenith, the longitude
//! `φ = atan2(x, −z)` runs from the map's left edge (φ = −π) to its right (φ = π), so the
//! map's centre column looks along −Z (the glTF forward axis). Nearest-pixel lookup: the map
//! is sampled by many gather rays per texel, which filters it. The sun is never part of the
//! sky: it is connected by next-event estimation ([`super::lights`]).

use glam::Vec3;

use crate::scene::Sky;

/// Radiance arriving along `-dir` from the sky, i.e. seen by a ray travelling along unit `dir`.
pub fn sky_radiance(sky: &Sky, dir: Vec3) -> Vec3 {
    match sky {
        Sky::None => Vec3::ZERO,
        Sky::Constant(l) => *l,
        Sky::Equirect {
            width,
            height,
            pixels,
            ..
        } => {
            let (w, h) = (*width as usize, *height as usize);
            let phi = dir.x.atan2(-dir.z);
            let theta = dir.y.clamp(-1.0, 1.0).acos();
            let u = (phi / core::f32::consts::TAU + 0.5).clamp(0.0, 1.0);
            let v = (theta / core::f32::consts::PI).clamp(0.0, 1.0);
            let x = ((u * w as f32) as usize).min(w - 1);
            let y = ((v * h as f32) as usize).min(h - 1);
            pixels.get(y * w + x).copied().unwrap_or(Vec3::ZERO)
        }
    }
}

/// Whether any direction of the sky carries radiance (so a bake can skip sky lookups).
pub fn sky_is_black(sky: &Sky) -> bool {
    match sky {
        Sky::None => true,
        Sky::Constant(l) => *l == Vec3::ZERO,
        Sky::Equirect { pixels, .. } => pixels.iter().all(|p| *p == Vec3::ZERO),
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    #[test]
    fn equirect_lookup_follows_the_documented_axes() {
        // 4×2 map: top row zenith-side, bottom row nadir-side; columns by longitude.
        let pixels: Vec<Vec3> = (0..8).map(|i| Vec3::splat(i as f32)).collect();
        let sky = Sky::Equirect {
            path: PathBuf::new(),
            width: 4,
            height: 2,
            pixels,
        };
        let up_forward = Vec3::new(0.0, 0.5, -1.0).normalize();
        assert_eq!(
            sky_radiance(&sky, up_forward),
            Vec3::splat(2.0),
            "centre column, top row"
        );
        let down_back_left = Vec3::new(-0.01, -0.5, 1.0).normalize();
        assert_eq!(
            sky_radiance(&sky, down_back_left),
            Vec3::splat(4.0),
            "left edge, bottom row"
        );
        // At the zenith the longitude is arbitrary; the lookup must stay on the top row.
        for zenith in [
            Vec3::Y,
            Vec3::new(0.0, 1.0, -1e-7),
            Vec3::new(-0.0, 1.0, 0.0),
        ] {
            assert!(
                sky_radiance(&sky, zenith).x < 4.0,
                "{zenith:?} looks at the top row"
            );
        }
        assert!(sky_radiance(&sky, Vec3::new(f32::NAN, 0.0, 1.0)).is_finite());
    }

    #[test]
    fn black_skies_are_recognised() {
        assert!(sky_is_black(&Sky::None));
        assert!(sky_is_black(&Sky::Constant(Vec3::ZERO)));
        assert!(!sky_is_black(&Sky::Constant(Vec3::X)));
    }
}
