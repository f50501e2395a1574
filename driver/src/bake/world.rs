//! Everything a gather ray can meet, shared read-only by every worker: the BVH in the
//! kernels' layout, per-triangle shading data, the analytic lights and the sky.
//!
//! The radiance a gather ray brings back from a hit ([`World::hit_radiance`]) is the hit's
//! emission (front faces only) plus its albedo/π times the direct irradiance there, connected
//! explicitly with shadow rays, plus indirect light by the bake's transport: in `series`
//! passes after the first, albedo/π × the previous pass's indirect irradiance at the hit
//! ([`PreviousPass`]); in `path` mode albedo × the radiance arriving along a cosine-sampled
//! direction, recursively, up to `bounces` vertices, with Russian roulette from the third.
//! A ray that leaves the scene sees the sky. Light kinds the scene lacks cost nothing: no
//! light, no shadow rays; a black sky, no lookups; a black surface, no continuation.

use glam::Vec3;
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
use guidebake_kernels::packet::{LANES, Ray, Ray8};
use guidebake_kernels::traverse::{
    BvhRef, intersect1, occluded1, occluded8, offset_origin, triangle_extent,
};
use wide::f32x8;

use super::settings::Transport;

use crate::bvh::{Bvh, BvhError, Preset};
use crate::scene::{self, Scene, Sky};
use crate::transport::lights::Light;
use crate::transport::rng::SampleRng;
use crate::transport::series::PreviousPass;
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
    corners: Vec<[Vec3; 3]>,
    surfaces: Vec<Surface>,
    lights: Vec<Light>,
    sky: Sky,
    sky_black: bool,
    transport: Transport,
    bounces: u32,
    previous: Option<PreviousPass>,
}

/// Where a gather ray hit: the primitive, the ray parameter and the barycentric weights of
/// the triangle's second and third vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// BVH primitive id (scene triangle index).
    pub prim: u32,
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weight of the second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
}

/// What [`World::hit_radiance`] brings back and what it cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Leaving {
    /// Radiance leaving the hit towards the gather ray's origin.
    pub radiance: Vec3,
    /// Shadow rays traced (next-event estimation at the path's vertices).
    pub shadow_rays: u32,
    /// Path continuation rays traced (`path` transport).
    pub path_rays: u32,
}

/// Path vertices from which Russian roulette may end a path (the first two always continue).
const ROULETTE_FROM: u32 = 3;

/// Shadow rays stop this fraction short of a light at a finite distance, so the light's own
/// geometry (a sphere light's surface) does not occlude it.
const SHADOW_SHORTEN: f32 = 1.0 - 1e-4;

impl World {
    /// Builds the BVH over the scene's triangles and gathers its lights.
    ///
    /// # Errors
    /// [`BvhError`] when the BVH cannot be built (a non-finite vertex).
    pub fn new(scene: &Scene, preset: Preset) -> Result<Self, BvhError> {
        let corners = scene.triangle_positions();
        let bvh = Bvh::build(&corners, preset)?;
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
            corners,
            surfaces,
            lights: lights_of(scene),
            sky_black: sky_is_black(&scene.sky),
            sky: scene.sky.clone(),
            transport: Transport::Series,
            bounces: 1,
            previous: None,
        })
    }

    /// Sets the transport at gather hits: `path` with at most `bounces` vertices, or
    /// `series` (whose indirect light comes from [`Self::set_previous_pass`]).
    pub fn set_transport(&mut self, transport: Transport, bounces: u32) {
        self.transport = transport;
        self.bounces = bounces.max(1);
    }

    /// The previous series pass, looked up at gather hits (`None` in the first pass).
    pub fn set_previous_pass(&mut self, previous: Option<PreviousPass>) {
        self.previous = previous;
    }

    /// The point of triangle `prim` closest to `p`, moved a thousandth of the way towards the
    /// triangle's centroid but never more than `max_shift`: a ray origin on the triangle, never
    /// exactly on an edge it shares with a neighbouring wall (where it could slip through the
    /// corner and see the sky), and never far from `p` on a huge triangle. `p` itself when
    /// `prim` is not a triangle of the scene.
    pub fn onto_triangle(&self, prim: u32, p: Vec3, max_shift: f32) -> Vec3 {
        let Some(&[a, b, c]) = self.corners.get(prim as usize) else {
            return p;
        };
        let q = closest_point_on_triangle(p, a, b, c);
        let shift = ((a + b + c) / 3.0 - q) * 1e-3;
        let length = shift.length();
        if length > max_shift && length > 0.0 {
            q + shift * (max_shift / length)
        } else {
            q + shift
        }
    }

    /// `p`, a point on triangle `prim`, offset off the surface towards `n` for a ray to leave
    /// from ([`offset_origin`]): by a few ulps of its coordinates and of the triangle's size
    /// seen from it, plus `travelled`, the length of the ray that computed `p` (0 for a point
    /// interpolated on the triangle), whose rounding grows with it.
    pub fn leave_surface(&self, prim: u32, p: Vec3, n: Vec3, travelled: f32) -> Vec3 {
        let extent = self
            .corners
            .get(prim as usize)
            .map_or(0.0, |c| triangle_extent(p, c));
        offset_origin(p, n, extent + travelled.max(0.0))
    }

    /// The geometric normal of triangle `prim` on the side of `toward` (for offsetting ray
    /// origins off the surface itself, not off a shading normal that may lie near its
    /// plane); `toward` when `prim` is not a triangle of the scene.
    pub fn facing_normal(&self, prim: u32, toward: Vec3) -> Vec3 {
        match self.surfaces.get(prim as usize) {
            Some(s) if s.normal.dot(toward) < 0.0 => -s.normal,
            Some(s) => s.normal,
            None => toward,
        }
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

    /// Radiance leaving `hit` of the gather ray from `origin` along `dir`, back towards
    /// `origin`, by the world's transport (module docs). `rng` is the sample's own stream.
    pub fn hit_radiance(
        &self,
        origin: Vec3,
        dir: Vec3,
        hit: SurfaceHit,
        rng: &mut SampleRng,
    ) -> Leaving {
        let mut out = Leaving::default();
        let (mut origin, mut dir, mut hit) = (origin, dir, hit);
        let mut throughput = Vec3::ONE;
        for vertex in 1.. {
            let Some(s) = self.surfaces.get(hit.prim as usize) else {
                break;
            };
            let front = s.normal.dot(dir) < 0.0;
            if front {
                out.radiance += throughput * s.emission;
            }
            if s.albedo == Vec3::ZERO {
                break;
            }
            let facing = if front { s.normal } else { -s.normal };
            let p = self.leave_surface(hit.prim, origin + dir * hit.t, facing, hit.t);
            let reflect = throughput * s.albedo;
            let mut irradiance = Vec3::ZERO;
            if !self.lights.is_empty() {
                let (direct, rays) = self.direct_irradiance(p, facing, rng.pair());
                irradiance += direct;
                out.shadow_rays += rays;
            }
            if let (Transport::Series, Some(previous)) = (self.transport, &self.previous) {
                irradiance += previous.irradiance(hit.prim, hit.u, hit.v);
            }
            out.radiance += reflect * core::f32::consts::FRAC_1_PI * irradiance;
            if self.transport != Transport::Path || vertex >= self.bounces {
                break;
            }
            // Continue: cosine-weighted direction, so the estimate's weight is the albedo.
            throughput = reflect;
            if vertex + 1 >= ROULETTE_FROM {
                let survive = throughput.max_element().clamp(0.05, 0.95);
                if rng.unit() >= survive {
                    break;
                }
                throughput /= survive;
            }
            let (tangent, bitangent) = orthonormal_basis(facing);
            let d = sample_cosine_hemisphere(rng.pair());
            let next = (tangent * d.x + bitangent * d.y + facing * d.z).normalize_or(facing);
            out.path_rays += 1;
            match intersect1(&self.bvh(), &Ray::new(p, next, 0.0, f32::INFINITY)) {
                None => {
                    out.radiance += throughput * self.sky(next);
                    break;
                }
                Some(h) => {
                    (origin, dir) = (p, next);
                    hit = SurfaceHit {
                        prim: h.prim,
                        t: h.t,
                        u: h.u,
                        v: h.v,
                    };
                }
            }
        }
        out
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

/// Closest point to `p` on triangle `abc` (Ericson, *Real-Time Collision Detection*, 5.1.5).
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    if !(v.is_finite() && w.is_finite()) {
        return a; // degenerate triangle
    }
    a + ab * v + ac * w
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
            scene::Light::Sphere {
                center,
                radius,
                radiance,
            } => Light::Sphere {
                center,
                radius,
                radiance,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_points_lie_on_the_triangle() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let near = |p: Vec3, want: Vec3| {
            let q = closest_point_on_triangle(p, a, b, c);
            assert!((q - want).length() < 1e-6, "{p:?} -> {q:?}, want {want:?}");
        };
        near(Vec3::new(0.2, 0.2, 5.0), Vec3::new(0.2, 0.2, 0.0));
        near(Vec3::new(-1.0, -1.0, 0.0), a);
        near(Vec3::new(0.5, -3.0, 1.0), Vec3::new(0.5, 0.0, 0.0));
        near(Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.5, 0.5, 0.0));
        near(Vec3::new(3.0, -1.0, 0.0), b);
        assert!(closest_point_on_triangle(Vec3::ONE, a, a, a).is_finite());
    }
}
