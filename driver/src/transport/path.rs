//! What leaves a gather ray's hit, by the bake's transport (docs/bake.md):
//! the hit's emission, weighted by multiple importance sampling against the next-event
//! estimate of the point the ray left ([`super::direct`]), plus its albedo/π times the
//! irradiance arriving there — direct light by next-event estimation, and indirect light
//! from the previous pass's lightmap (`series`, [`super::series`]) or from a path continued
//! with cosine-weighted directions, next-event estimation and MIS at every vertex, and
//! Russian roulette from the third vertex (`path`). A ray that leaves the scene sees the sky.
//!
//! What a final-gather sample therefore contains, and the guide learns from (paper §2.2):
//! the emission its ray hits, times the MIS weight of the gather's density against
//! next-event estimation from the texel — so light an emitter sends straight to the texel
//! is found mostly by next-event estimation and weighs little in the records, except where
//! the gather samples it better (large emitters close by) — plus everything the hit
//! reflects, in which every emitter is connected explicitly. Records are therefore no
//! longer zero-or-huge under small emitters: the guide learns the indirect light, which
//! next-event estimation cannot find.

use glam::Vec3;
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
use guidebake_kernels::packet::Ray;
use guidebake_kernels::traverse::intersect1;

use super::direct::{Receiver, power_heuristic};
use super::rng::SampleRng;
use crate::bake::settings::{EmitterSampling, Transport};
use crate::bake::world::{SurfaceHit, World};

/// Path vertices from which Russian roulette may end a path (the first two always continue).
const ROULETTE_FROM: u32 = 3;

/// Where a ray left from, as multiple importance sampling needs it: the point (offset), the
/// normal next-event estimation used there, and the solid-angle density of the ray's
/// direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Departure {
    /// The ray's origin.
    pub point: Vec3,
    /// The unit normal of the surface it left (the side it left from).
    pub normal: Vec3,
    /// The solid-angle density its direction was sampled with.
    pub pdf: f32,
}

/// What [`World::radiance_from_hit`] brings back and what it cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Leaving {
    /// The hit's own emission towards the ray, MIS-weighted: direct light from an emitter.
    pub emitted: Vec3,
    /// Everything else the hit sends back along the ray: reflected direct and indirect light.
    pub reflected: Vec3,
    /// Shadow rays traced (next-event estimation at the path's vertices).
    pub shadow_rays: u32,
    /// Path continuation rays traced (`path` transport).
    pub path_rays: u32,
}

impl World {
    /// Radiance leaving `hit` of the ray that left `from` along `dir`, back towards it, by
    /// the world's transport (module docs). `rng` is the sample's own stream.
    pub fn radiance_from_hit(
        &self,
        from: &Departure,
        dir: Vec3,
        hit: SurfaceHit,
        rng: &mut SampleRng,
    ) -> Leaving {
        let mut out = Leaving::default();
        let (mut from, mut dir, mut hit) = (*from, dir, hit);
        let mut throughput = Vec3::ONE;
        for vertex in 1.. {
            let Some(s) = self.surfaces().get(hit.prim as usize) else {
                break;
            };
            let front = s.normal.dot(dir) < 0.0;
            if front && s.emission != Vec3::ZERO {
                let emitted = throughput * s.emission * self.hit_weight(&from, dir, hit);
                if vertex == 1 {
                    out.emitted = emitted;
                } else {
                    out.reflected += emitted;
                }
            }
            let albedo = self.albedo_at(s, &hit);
            if albedo == Vec3::ZERO {
                break;
            }
            let facing = if front { s.normal } else { -s.normal };
            let p = self.leave_surface(hit.prim, from.point + dir * hit.t, facing, hit.t);
            let reflect = throughput * albedo;
            let continues = self.transport() == Transport::Path && vertex < self.bounces();
            let cosine_pdf = |d: Vec3| facing.dot(d).max(0.0) * core::f32::consts::FRAC_1_PI;
            let at = Receiver {
                point: p,
                normal: facing,
                other: continues.then_some(&cosine_pdf as &dyn Fn(Vec3) -> f32),
            };
            let mut irradiance = Vec3::ZERO;
            if self.has_direct_light() {
                let (direct, rays) = self.direct_irradiance(&at, rng.pair(), rng.unit());
                irradiance += direct;
                out.shadow_rays += rays;
            }
            if let (Transport::Series, Some(previous)) = (self.transport(), self.previous_pass()) {
                irradiance += previous.irradiance(hit.prim, hit.u, hit.v);
            }
            out.reflected += reflect * core::f32::consts::FRAC_1_PI * irradiance;
            if !continues {
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
                    out.reflected += throughput * self.sky(next);
                    break;
                }
                Some(h) => {
                    from = Departure {
                        point: p,
                        normal: facing,
                        pdf: cosine_pdf(next),
                    };
                    dir = next;
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

    /// The weight of emission that a ray from `from` along `dir` finds at `hit` (a front
    /// face): 1 when emitters are not sampled by next-event estimation, 0 when they are
    /// alone, else the power heuristic against the emitter sampling of `from`.
    fn hit_weight(&self, from: &Departure, dir: Vec3, hit: SurfaceHit) -> f32 {
        let Some(emitters) = self.emitters() else {
            return 1.0;
        };
        match self.emitter_sampling() {
            EmitterSampling::Hits => 1.0,
            EmitterSampling::Nee => 0.0,
            EmitterSampling::Mis => {
                let nee = emitters.pdf(from.point, from.normal, hit.prim, dir, hit.t);
                power_heuristic(from.pdf, nee)
            }
        }
    }
}
