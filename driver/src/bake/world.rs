//! Everything a gather ray can meet, shared read-only by every worker: the BVH in the
//! kernels' layout, per-triangle shading data, the analytic lights and the sky.
//!
//! The radiance a gather ray brings back from a hit follows the paper's production setting
//! (series transport, first pass): the hit's emission (front faces only) plus its albedo/π
//! times the direct irradiance there, connected explicitly with shadow rays. A ray that
//! leaves the scene sees the sky. Light kinds the scene lacks cost nothing: no light, no
//! shadow rays; a black sky, no lookups.

use glam::Vec3;
use guidebake_kernels::packet::{LANES, Ray, Ray8};
use guidebake_kernels::traverse::{BvhRef, occluded1, occluded8, offset_origin};
use wide::f32x8;

use crate::bvh::{Bvh, BvhError, Preset};
use crate::scene::{self, Scene, Sky};
use crate::transport::lights::Light;
use crate::transport::sky::{sky_is_black, sky_radiance};

/// Shading data of one triangle, indexed by BVH primitive id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Unit geometric normal (winding order), the front side.
    pub normal: Vec3,
    /// Diffuse albedo.
    pub albedo: Vec3,
    /// Radiance emitted from the front side.
    pub emission: Vec3,
}

/// The scene as the bake sees it.
#[derive(Debug)]
pub struct World {
    bvh: Bvh,
    surfaces: Vec<Surface>,
    lights: Vec<Light>,
    sky: Sky,
    sky_black: bool,
}

/// Shadow rays stop this fraction short of a light at a finite distance, so the light's own
/// geometry (a sphere light's surface) does not occlude it.
const SHADOW_SHORTEN: f32 = 1.0 - 1e-4;

impl World {
    /// Builds the BVH over the scene's triangles and gathers its lights.
    ///
    /// # Errors
    /// [`BvhError`] when the BVH cannot be built (a non-finite vertex).
    pub fn new(scene: &Scene, preset: Preset) -> Result<Self, BvhError> {
        let bvh = Bvh::build(&scene.triangle_positions(), preset)?;
        let surfaces = scene
            .triangles
            .iter()
            .map(|t| {
                let m = &scene.materials[t.material as usize];
                Surface {
                    normal: t.geometric_normal(),
                    albedo: m.albedo,
                    emission: m.emission,
                }
            })
            .collect();
        Ok(Self {
            bvh,
            surfaces,
            lights: lights_of(scene),
            sky_black: sky_is_black(&scene.sky),
            sky: scene.sky.clone(),
        })
    }

    /// The BVH, for tracing.
    pub fn bvh(&self) -> BvhRef<'_> {
        self.bvh.view()
    }

    /// The BVH's build statistics source.
    pub fn bvh_owner(&self) -> &Bvh {
        &self.bvh
    }

    /// The analytic lights.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// Radiance of the sky along `dir` (zero without a lookup when the sky is black).
    pub fn sky(&self, dir: Vec3) -> Vec3 {
        if self.sky_black {
            Vec3::ZERO
        } else {
            sky_radiance(&self.sky, dir)
        }
    }

    /// Radiance leaving the hit of a ray along `dir` on primitive `prim` at point `p`, back
    /// towards the ray's origin: emission (front face) + albedo/π × direct irradiance.
    /// `u` drives the light samples. Returns the radiance and the shadow rays traced.
    pub fn hit_radiance(&self, prim: u32, p: Vec3, dir: Vec3, u: [f32; 2]) -> (Vec3, u32) {
        let Some(s) = self.surfaces.get(prim as usize) else {
            return (Vec3::ZERO, 0);
        };
        let front = s.normal.dot(dir) < 0.0;
        let emission = if front { s.emission } else { Vec3::ZERO };
        if self.lights.is_empty() || s.albedo == Vec3::ZERO {
            return (emission, 0);
        }
        let facing = if front { s.normal } else { -s.normal };
        let (direct, rays) = self.direct_irradiance(offset_origin(p, facing), facing, u);
        (
            emission + s.albedo * core::f32::consts::FRAC_1_PI * direct,
            rays,
        )
    }

    /// Direct irradiance at `p` (already offset from its surface) with normal `n`: one sample
    /// of every light, each with a single shadow ray. Returns it and the shadow rays traced.
    pub fn direct_irradiance(&self, p: Vec3, n: Vec3, u: [f32; 2]) -> (Vec3, u32) {
        let bvh = self.bvh();
        let (mut e, mut rays) = (Vec3::ZERO, 0);
        for light in &self.lights {
            if let Some(s) = light.sample(p, n, u) {
                rays += 1;
                if s.distance == 0.0 || !occluded1(&bvh, &shadow_ray(p, s.direction, s.distance)) {
                    e += s.weight;
                }
            }
        }
        (e, rays)
    }

    /// Direct irradiance for eight samples sharing origin `p` (offset) and normal `n`, light
    /// sample `u[lane]` each: shadow rays traced as packets, one packet per light. Adds into
    /// `out` and returns the shadow rays traced.
    pub fn direct_irradiance8(
        &self,
        p: Vec3,
        n: Vec3,
        u: &[[f32; 2]; LANES],
        out: &mut [Vec3; LANES],
    ) -> u32 {
        let bvh = self.bvh();
        let mut rays = 0;
        for light in &self.lights {
            let mut packet = Ray8::INACTIVE;
            let mut weights = [Vec3::ZERO; LANES];
            let mut unshadowed = 0u8;
            for lane in 0..LANES {
                let Some(s) = light.sample(p, n, u[lane]) else {
                    continue;
                };
                weights[lane] = s.weight;
                if s.distance == 0.0 {
                    unshadowed |= 1 << lane;
                } else {
                    packet.set_lane(lane, &shadow_ray(p, s.direction, s.distance));
                    rays += 1;
                }
            }
            let traced = lanes_traced(&packet);
            let blocked = if traced != 0 {
                occluded8(&bvh, &packet)
            } else {
                0
            };
            for lane in 0..LANES {
                let visible =
                    unshadowed & (1 << lane) != 0 || (traced & !blocked) & (1 << lane) != 0;
                if visible {
                    out[lane] += weights[lane];
                }
            }
        }
        rays
    }
}

fn lanes_traced(packet: &Ray8) -> u8 {
    let tmin = packet.tmin.to_array();
    (0..LANES).fold(0, |m, i| if tmin[i].is_finite() { m | 1 << i } else { m })
}

fn shadow_ray(p: Vec3, dir: Vec3, distance: f32) -> Ray {
    let tmax = if distance.is_finite() {
        distance * SHADOW_SHORTEN
    } else {
        f32::INFINITY
    };
    Ray::new(p, dir, 0.0, tmax)
}

/// The scene's punctual lights and sun as next-event estimation samplers.
pub fn lights_of(scene: &Scene) -> Vec<Light> {
    let mut lights: Vec<Light> = scene
        .lights
        .iter()
        .map(|l| match *l {
            scene::Light::Directional {
                direction,
                irradiance,
            } => Light::Sun {
                to_sun: -direction,
                angular_radius: 0.0,
                irradiance,
            },
            scene::Light::Point {
                position,
                intensity,
            } => Light::Point {
                position,
                intensity,
            },
            scene::Light::Spot {
                position,
                direction,
                intensity,
                inner_cone,
                outer_cone,
            } => Light::Spot {
                position,
                direction,
                intensity,
                cos_inner: inner_cone.cos(),
                cos_outer: outer_cone.cos(),
            },
        })
        .collect();
    if let Some(sun) = &scene.sun {
        lights.push(Light::Sun {
            to_sun: sun.direction,
            angular_radius: sun.angular_radius,
            irradiance: sun.irradiance,
        });
    }
    lights.retain(|l| power_of(l) > 0.0);
    lights
}

fn power_of(light: &Light) -> f32 {
    match *light {
        Light::Sun { irradiance: c, .. }
        | Light::Point { intensity: c, .. }
        | Light::Spot { intensity: c, .. }
        | Light::Sphere { radiance: c, .. } => c.max_element(),
    }
}

/// Lanes of a packet as an array (for per-lane shading after a packet trace).
pub fn lanes(v: f32x8) -> [f32; LANES] {
    v.to_array()
}
