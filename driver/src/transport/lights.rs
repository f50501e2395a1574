//! Next-event estimation for analytic lights: one sample of each light's irradiance at a
//! surface point, with the shadow ray it needs.
//!
//! Every sampler returns the Monte Carlo weight `L · cosθ / p(ω)` of one direction towards
//! the light, so that the mean over samples, times visibility, estimates the irradiance
//! `E = ∫ L cosθ dω` the light delivers to a surface with normal `n`. Units follow glTF's
//! `KHR_lights_punctual`: point and spot intensity in W/sr (radiometric here), the sun as
//! irradiance on a plane facing it.
//!
//! - **Sun**: a disk of angular radius α, sampled uniformly in its cone of directions; its
//!   radiance is `E_sun / (π sin²α)`, so a plane whose normal makes angle θ with the sun
//!   direction (cone wholly above its horizon) receives exactly `E_sun cosθ`. α = 0 is a
//!   delta light.
//! - **Point**: `E = I cosθ / d²`.
//! - **Spot**: a point light with glTF's smooth angular falloff between the inner and the
//!   outer cone: `t = clamp((cosφ − cos_outer) / (cos_inner − cos_outer), 0, 1)`, factor `t²`.
//! - **Sphere**: uniform sampling of the cone the sphere subtends (pbrt-v4's
//!   `SampleUniformCone` towards the centre); a point facing it at distance d receives
//!   `π L (r/d)²`. A point inside the sphere sees it in every direction: `E = π L`, with no
//!   shadow ray.

use glam::Vec3;

use crate::scene::{Scene, SceneLight};

/// An analytic light as next-event estimation samples it, in world space (from the scene's
/// [`SceneLight`]s and sun by [`analytic_lights`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnalyticLight {
    /// A distant disk: unit `to_sun` direction, half-angle `angular_radius` (radians), and
    /// `irradiance` on a plane facing it.
    Sun {
        /// Unit vector from the scene towards the sun.
        to_sun: Vec3,
        /// Half-angle of the sun's disk, radians, ≥ 0.
        angular_radius: f32,
        /// RGB irradiance on a plane facing the sun.
        irradiance: Vec3,
    },
    /// An isotropic point light.
    Point {
        /// Position.
        position: Vec3,
        /// RGB radiant intensity (W/sr).
        intensity: Vec3,
    },
    /// A spot light with a smooth falloff between two cones.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit direction the spot points along.
        direction: Vec3,
        /// RGB radiant intensity on the axis (W/sr).
        intensity: Vec3,
        /// Cosine of the inner cone's half-angle (full intensity inside).
        cos_inner: f32,
        /// Cosine of the outer cone's half-angle (dark outside).
        cos_outer: f32,
    },
    /// A sphere of uniform radiance.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius, > 0.
        radius: f32,
        /// RGB radiance of its surface.
        radiance: Vec3,
    },
}

/// One next-event sample: the direction to test for visibility and its weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit direction from the surface point towards the light.
    pub direction: Vec3,
    /// Distance along `direction` to the light: the shadow ray's `tmax`
    /// (`f32::INFINITY` for the sun; 0 when no shadow ray is needed).
    pub distance: f32,
    /// `L cosθ / p(ω)`, RGB, ≥ 0 and finite: the irradiance estimate if the ray is unoccluded.
    pub weight: Vec3,
}

impl AnalyticLight {
    /// Samples the light from surface point `p` with unit normal `n` using the random pair
    /// `u` ∈ [0,1)². Returns `None` when the light cannot reach the point's upper hemisphere
    /// (behind the surface, outside the spot cone, zero power) — no shadow ray is needed.
    pub fn sample(&self, p: Vec3, n: Vec3, u: [f32; 2]) -> Option<LightSample> {
        let sample = match *self {
            AnalyticLight::Sun {
                to_sun,
                angular_radius,
                irradiance,
            } => sample_sun(to_sun, angular_radius, irradiance, n, u),
            AnalyticLight::Point {
                position,
                intensity,
            } => sample_point(position, intensity, p, n),
            AnalyticLight::Spot {
                position,
                direction,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let s = sample_point(position, intensity, p, n)?;
                let falloff = spot_falloff(-s.direction.dot(direction), cos_inner, cos_outer);
                Some(LightSample {
                    weight: s.weight * falloff,
                    ..s
                })
            }
            AnalyticLight::Sphere {
                center,
                radius,
                radiance,
            } => sample_sphere(center, radius, radiance, p, n, u),
        }?;
        let usable = sample.weight.cmpgt(Vec3::ZERO).any() && sample.weight.is_finite();
        usable.then_some(sample)
    }

    /// The largest channel of the light's strength (irradiance, intensity or radiance):
    /// zero for a light that cannot light anything.
    pub fn power(&self) -> f32 {
        match *self {
            AnalyticLight::Sun { irradiance: c, .. }
            | AnalyticLight::Point { intensity: c, .. }
            | AnalyticLight::Spot { intensity: c, .. }
            | AnalyticLight::Sphere { radiance: c, .. } => c.max_element(),
        }
    }
}

/// The scene's declared lights and its sun as next-event estimation samplers; lights of no
/// power are dropped (they would cost shadow rays for nothing).
pub fn analytic_lights(scene: &Scene) -> Vec<AnalyticLight> {
    let mut lights: Vec<AnalyticLight> = scene
        .lights
        .iter()
        .map(|l| match *l {
            SceneLight::Directional {
                direction,
                irradiance,
            } => AnalyticLight::Sun {
                to_sun: -direction,
                angular_radius: 0.0,
                irradiance,
            },
            SceneLight::Point {
                position,
                intensity,
            } => AnalyticLight::Point {
                position,
                intensity,
            },
            SceneLight::Spot {
                position,
                direction,
                intensity,
                inner_cone,
                outer_cone,
            } => AnalyticLight::Spot {
                position,
                direction,
                intensity,
                cos_inner: inner_cone.cos(),
                cos_outer: outer_cone.cos(),
            },
            SceneLight::Sphere {
                center,
                radius,
                radiance,
            } => AnalyticLight::Sphere {
                center,
                radius,
                radiance,
            },
        })
        .collect();
    if let Some(sun) = &scene.sun {
        lights.push(AnalyticLight::Sun {
            to_sun: sun.direction,
            angular_radius: sun.angular_radius,
            irradiance: sun.irradiance,
        });
    }
    lights.retain(|l| l.power() > 0.0);
    lights
}

/// glTF `KHR_lights_punctual` spot falloff: `t²` with `t` linear in cosφ between the cones.
pub fn spot_falloff(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    let span = (cos_inner - cos_outer).max(1e-4);
    let t = ((cos_angle - cos_outer) / span).clamp(0.0, 1.0);
    t * t
}

fn sample_sun(
    to_sun: Vec3,
    alpha: f32,
    irradiance: Vec3,
    n: Vec3,
    u: [f32; 2],
) -> Option<LightSample> {
    if alpha <= 0.0 {
        let cos = n.dot(to_sun);
        return (cos > 0.0).then(|| LightSample {
            direction: to_sun,
            distance: f32::INFINITY,
            weight: irradiance * cos,
        });
    }
    let cos_max = alpha.cos();
    let direction = sample_uniform_cone(to_sun, cos_max, u);
    let cos = n.dot(direction);
    if cos <= 0.0 {
        return None;
    }
    // L = E / (π sin²α); p = 1 / (2π (1 − cos α)); weight = L cos / p.
    let sin2 = (1.0 - cos_max * cos_max).max(f32::MIN_POSITIVE);
    let weight = irradiance * (cos * 2.0 * (1.0 - cos_max) / sin2);
    Some(LightSample {
        direction,
        distance: f32::INFINITY,
        weight,
    })
}

fn sample_point(position: Vec3, intensity: Vec3, p: Vec3, n: Vec3) -> Option<LightSample> {
    let to_light = position - p;
    let d2 = to_light.length_squared();
    if !(d2 > 0.0 && d2.is_finite()) {
        return None;
    }
    let distance = d2.sqrt();
    let direction = to_light / distance;
    let cos = n.dot(direction);
    (cos > 0.0).then(|| LightSample {
        direction,
        distance,
        weight: intensity * (cos / d2),
    })
}

fn sample_sphere(
    center: Vec3,
    radius: f32,
    radiance: Vec3,
    p: Vec3,
    n: Vec3,
    u: [f32; 2],
) -> Option<LightSample> {
    let to_center = center - p;
    let d2 = to_center.length_squared();
    let r2 = radius * radius;
    if d2 <= r2 {
        // Inside the sphere: radiance from every direction of the hemisphere, E = πL.
        return Some(LightSample {
            direction: n,
            distance: 0.0,
            weight: radiance * core::f32::consts::PI,
        });
    }
    let d = d2.sqrt();
    let axis = to_center / d;
    let sin2_max = r2 / d2;
    let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
    let direction = sample_uniform_cone(axis, cos_max, u);
    let cos = n.dot(direction);
    if cos <= 0.0 {
        return None;
    }
    // Distance to the sphere's near surface along the sampled direction.
    let b = direction.dot(to_center);
    let distance = (b - (r2 - (d2 - b * b)).max(0.0).sqrt()).max(0.0);
    let solid_angle = 2.0 * core::f32::consts::PI * one_minus_cos(sin2_max, cos_max);
    Some(LightSample {
        direction,
        distance,
        weight: radiance * (cos * solid_angle),
    })
}

/// 1 − cos θ for a cone of sin²θ, without cancellation for tiny cones (far-away lights).
fn one_minus_cos(sin2: f32, cos: f32) -> f32 {
    if sin2 < 1e-3 {
        sin2 * 0.5 + sin2 * sin2 * 0.125
    } else {
        1.0 - cos
    }
}

/// A direction uniformly distributed in the cone around unit `axis` with half-angle
/// `acos(cos_max)` (pbrt-v4 `SampleUniformCone`, rotated to `axis`).
pub fn sample_uniform_cone(axis: Vec3, cos_max: f32, u: [f32; 2]) -> Vec3 {
    let cos = (1.0 - u[0]) + u[0] * cos_max;
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = u[1] * core::f32::consts::TAU;
    let (t, b) = axis.any_orthonormal_pair();
    (t * (sin * phi.cos()) + b * (sin * phi.sin()) + axis * cos).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::Pcg32;

    /// Mean and standard error of the light's irradiance estimate over `n` samples
    /// (accumulated in f64: an f32 running sum of 20 000 equal terms is biased by 1e-4).
    fn estimate(light: &AnalyticLight, p: Vec3, normal: Vec3, n: usize) -> (Vec3, Vec3) {
        let mut rng = Pcg32::new(11, 3);
        let (mut sum, mut sum2) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
        for _ in 0..n {
            if let Some(s) = light.sample(p, normal, [rng.next_f32(), rng.next_f32()]) {
                assert!(s.weight.is_finite() && s.weight.min_element() >= 0.0);
                assert!((s.direction.length() - 1.0).abs() < 1e-5);
                let w = s.weight.as_dvec3();
                sum += w;
                sum2 += w * w;
            }
        }
        let mean = sum / n as f64;
        let var = (sum2 / n as f64 - mean * mean).max(glam::DVec3::ZERO);
        (mean.as_vec3(), (var / n as f64).powf(0.5).as_vec3())
    }

    fn within_3_sigma(got: (Vec3, Vec3), want: Vec3) {
        let tol = got.1 * 3.0 + want.abs() * 1e-5;
        assert!(
            (got.0 - want).abs().cmple(tol).all(),
            "got {:?} ± {:?}, want {want:?}",
            got.0,
            got.1
        );
    }

    #[test]
    fn sun_obeys_the_cosine_law_for_any_angular_radius() {
        let irradiance = Vec3::new(3.0, 2.0, 1.0);
        let to_sun = Vec3::new(0.3, 0.2, 1.0).normalize();
        for alpha in [0.0f32, 0.00465, 0.05, 0.3] {
            for normal in [Vec3::Z, Vec3::new(0.5, -0.2, 1.0).normalize()] {
                let light = AnalyticLight::Sun {
                    to_sun,
                    angular_radius: alpha,
                    irradiance,
                };
                let want = irradiance * normal.dot(to_sun);
                within_3_sigma(estimate(&light, Vec3::ZERO, normal, 20_000), want);
            }
        }
    }

    #[test]
    fn point_light_follows_inverse_square_and_cosine() {
        let light = AnalyticLight::Point {
            position: Vec3::new(0.0, 3.0, 4.0),
            intensity: Vec3::splat(50.0),
        };
        let s = light.sample(Vec3::ZERO, Vec3::Z, [0.5, 0.5]).unwrap();
        let want = 50.0 * 0.8 / 25.0;
        assert!((s.weight - Vec3::splat(want)).abs().max_element() < 1e-5);
        assert!((s.distance - 5.0).abs() < 1e-5);
        assert!(
            light.sample(Vec3::ZERO, -Vec3::Z, [0.5, 0.5]).is_none(),
            "behind the surface"
        );
    }

    #[test]
    fn spot_light_falls_off_between_its_cones() {
        let (cos_inner, cos_outer) = (0.9f32, 0.7f32);
        let light = AnalyticLight::Spot {
            position: Vec3::new(0.0, 0.0, 2.0),
            direction: -Vec3::Z,
            intensity: Vec3::splat(8.0),
            cos_inner,
            cos_outer,
        };
        let on_axis = light.sample(Vec3::ZERO, Vec3::Z, [0.0; 2]).unwrap();
        assert!(
            (on_axis.weight.x - 2.0).abs() < 1e-5,
            "8 W/sr at 2 m facing it is 2"
        );
        let outside = Vec3::new(10.0, 0.0, 0.0);
        assert!(light.sample(outside, Vec3::Z, [0.0; 2]).is_none());
        assert!((spot_falloff(0.8, cos_inner, cos_outer) - 0.25).abs() < 1e-6);
        assert_eq!(spot_falloff(0.95, cos_inner, cos_outer), 1.0);
    }

    #[test]
    fn sphere_light_gives_pi_l_r_over_d_squared_facing_it() {
        let radiance = Vec3::new(10.0, 5.0, 1.0);
        for (radius, distance) in [(0.5f32, 4.0f32), (1.0, 1.5), (0.01, 100.0)] {
            let light = AnalyticLight::Sphere {
                center: Vec3::new(0.0, 0.0, distance),
                radius,
                radiance,
            };
            let want = radiance * core::f32::consts::PI * (radius / distance).powi(2);
            within_3_sigma(estimate(&light, Vec3::ZERO, Vec3::Z, 20_000), want);
        }
    }

    #[test]
    fn sphere_light_shadow_rays_stop_at_its_surface() {
        let light = AnalyticLight::Sphere {
            center: Vec3::new(0.0, 0.0, 5.0),
            radius: 1.0,
            radiance: Vec3::ONE,
        };
        let mut rng = Pcg32::new(5, 5);
        for _ in 0..1000 {
            let s = light
                .sample(Vec3::ZERO, Vec3::Z, [rng.next_f32(), rng.next_f32()])
                .unwrap();
            let hit = s.direction * s.distance;
            assert!(((hit - Vec3::new(0.0, 0.0, 5.0)).length() - 1.0).abs() < 1e-3);
        }
        let inside = light
            .sample(Vec3::new(0.0, 0.0, 5.2), Vec3::Z, [0.3, 0.3])
            .unwrap();
        assert_eq!(inside.distance, 0.0);
        assert!((inside.weight.x - core::f32::consts::PI).abs() < 1e-6);
    }

    #[test]
    fn far_off_points_and_extreme_powers_stay_finite() {
        let far = Vec3::splat(1e6);
        let sphere = AnalyticLight::Sphere {
            center: far + Vec3::new(0.0, 0.0, 3.0),
            radius: 0.5,
            radiance: Vec3::splat(1e5),
        };
        let point = AnalyticLight::Point {
            position: far + Vec3::Z,
            intensity: Vec3::splat(1e-4),
        };
        for light in [sphere, point] {
            let (mean, _) = estimate(&light, far, Vec3::Z, 1000);
            assert!(
                mean.is_finite() && mean.min_element() > 0.0,
                "{light:?}: {mean:?}"
            );
        }
        let coincident = AnalyticLight::Point {
            position: Vec3::ONE,
            intensity: Vec3::ONE,
        };
        assert!(coincident.sample(Vec3::ONE, Vec3::Z, [0.0; 2]).is_none());
    }
}
