//! Next-event estimation: direct irradiance at a shading point from every analytic light
//! ([`super::lights`]) and from one sampled emitter ([`super::emitters`]), each with one
//! shadow ray; the emitter's sample weighted against the point's other strategy by multiple
//! importance sampling (Veach 1997, power heuristic).
//!
//! An emitter can be found two ways from a shading point: by next-event estimation, and by
//! the direction the point samples anyway — the final gather's (cosine or guided) at a
//! texel, the cosine continuation at a path vertex. Under [`EmitterSampling::Mis`] the two
//! estimates are weighted `w_nee = p_nee² / (p_nee² + p_other²)` and `w_hit = 1 − w_nee`
//! (the latter applied by [`super::path`] where a ray hits an emitter), so every light path
//! counts once. Where no ray will leave the point (a series hit, a path's last vertex), the
//! point has no other strategy and next-event estimation weighs 1.
//! [`EmitterSampling::Nee`] and [`EmitterSampling::Hits`] keep one strategy alone (the
//! latter is the bake before emitters were lights); they are unbiased too and serve as
//! comparators.

use glam::Vec3;
use guidebake_kernels::packet::{LANES, Ray, Ray8, set_lanes};
use guidebake_kernels::traverse::{WideRef, occluded1, occluded8};

use super::emitters::{EmitterSample, EmittersAt};
use super::settings::EmitterSampling;
use super::sh_l1::{ShSample, add_irradiance_sample, hemisphere};
use super::world::World;

/// Shadow rays stop this fraction short of a light at a finite distance, so the light's own
/// geometry (a sphere light's surface) does not occlude it.
const SHADOW_SHORTEN: f32 = 1.0 - 1e-4;

/// The power heuristic's weight of a strategy of density `a` against one of density `b`
/// (β = 2). An infinite `a` (a delta) weighs 1; two zero densities weigh 0.
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    if a == f32::INFINITY {
        return 1.0;
    }
    let (a2, b2) = (a * a, b * b);
    let w = a2 / (a2 + b2);
    if w.is_finite() { w } else { 0.0 }
}

/// A shading point as next-event estimation sees it.
#[derive(Clone, Copy)]
pub struct Receiver<'a> {
    /// The point, already offset off its surface.
    pub point: Vec3,
    /// Its unit normal (the side being lit).
    pub normal: Vec3,
    /// The solid-angle density of the point's other strategy for a direction: the final
    /// gather's at a texel, the path's continuation at a vertex; `None` when no ray leaves
    /// the point.
    pub other: Option<&'a dyn Fn(Vec3) -> f32>,
}

/// The other strategy's solid-angle densities for the directions of the lanes in a mask.
pub type Densities8<'a> = dyn Fn(&[Vec3; LANES], u8) -> [f32; LANES] + 'a;

/// The receiver of a packet's eight next-event samples ([`World::direct_irradiance8`]): one
/// point and normal, and the other strategy's solid-angle densities for eight directions at
/// once (lanes outside the mask are not looked at and may hold anything), so a guided
/// gather's density is looked up 8-wide.
pub struct Receiver8<'a> {
    /// The point, already offset off its surface.
    pub point: Vec3,
    /// Its unit normal (the side being lit).
    pub normal: Vec3,
    /// The other strategy's densities for directions `dirs` in the lanes of `mask`.
    pub other: Option<&'a Densities8<'a>>,
}

impl World {
    /// Weight of a next-event sample of an emitter at density `pdf` from `at`.
    fn nee_weight(&self, at: &Receiver<'_>, direction: Vec3, pdf: f32) -> f32 {
        match (self.emitter_sampling(), at.other) {
            (EmitterSampling::Mis, Some(other)) => power_heuristic(pdf, other(direction)),
            _ => 1.0,
        }
    }

    /// Direct irradiance at `at`: one sample of every analytic light (`u`) and of one
    /// emitter (`pick` chooses it, `u` the point on it), each with a single shadow ray.
    /// Returns it and the shadow rays traced.
    pub fn direct_irradiance(&self, at: &Receiver<'_>, u: [f32; 2], pick: f32) -> (Vec3, u32) {
        let emitters = self.emitters().map(|e| e.at(at.point, at.normal));
        self.direct_irradiance_at(at, emitters.as_ref(), u, pick)
    }

    /// [`Self::direct_irradiance`] with the emitter selection at `at` already made
    /// ([`super::emitters::Emitters::at`] at `at`'s point and normal; `None` when the world samples no
    /// emitter), so that the MIS density of the ray that leaves `at` reuses it.
    pub fn direct_irradiance_at(
        &self,
        at: &Receiver<'_>,
        emitters: Option<&EmittersAt<'_>>,
        u: [f32; 2],
        pick: f32,
    ) -> (Vec3, u32) {
        debug_assert!(emitters.is_none_or(|e| e.point() == at.point && e.normal() == at.normal));
        let bvh = self.wide_bvh();
        let (p, n) = (at.point, at.normal);
        let (mut e, mut rays) = (Vec3::ZERO, 0);
        for light in self.lights() {
            if let Some(s) = light.sample(p, n, u) {
                rays += 1;
                if s.distance == 0.0 || !occluded1(&bvh, &shadow_ray(p, s.direction, s.distance)) {
                    e += s.weight;
                }
            }
        }
        if let Some(s) = emitters.and_then(|e| e.sample(pick, u)) {
            rays += 1;
            if !occluded1(&bvh, &self.emitter_shadow_ray(p, &s)) {
                e += self.emitter_weight(at, &s);
            }
        }
        (e, rays)
    }

    /// Direct irradiance for eight samples sharing `at`, light sample `u[lane]` and emitter
    /// choice `pick[lane]` each: shadow rays traced as packets, one packet per light and one
    /// for the emitters. Adds into `out` and returns the shadow rays traced.
    pub fn direct_irradiance8(
        &self,
        at: &Receiver8<'_>,
        u: &[[f32; 2]; LANES],
        pick: &[f32; LANES],
        out: &mut [Vec3; LANES],
    ) -> u32 {
        self.direct_irradiance8_projected(at, u, pick, out, None)
    }

    /// [`Self::direct_irradiance8`], also adding each visible sample's spherical-harmonic
    /// projection (`L / p · Y_i(ω)`, [`crate::bake::directional`]) into `sh` when given:
    /// the directional lightmap's share of next-event estimation, from the same samples.
    pub fn direct_irradiance8_projected(
        &self,
        at: &Receiver8<'_>,
        u: &[[f32; 2]; LANES],
        pick: &[f32; LANES],
        out: &mut [Vec3; LANES],
        mut sh: Option<&mut [ShSample; LANES]>,
    ) -> u32 {
        let tree = self.wide_bvh();
        let (p, n) = (at.point, at.normal);
        let mut rays = 0;
        for light in self.lights() {
            let mut packet = Ray8::INACTIVE;
            let mut weights = [Vec3::ZERO; LANES];
            let mut directions = [Vec3::ZERO; LANES];
            let mut unshadowed = 0u8;
            for lane in 0..LANES {
                let Some(s) = light.sample(p, n, u[lane]) else {
                    continue;
                };
                weights[lane] = s.weight;
                directions[lane] = s.direction;
                if s.distance == 0.0 {
                    unshadowed |= 1 << lane;
                } else {
                    packet.set_lane(lane, &shadow_ray(p, s.direction, s.distance));
                }
            }
            let (visible, traced) = visible_lanes(&tree, &packet, unshadowed);
            for lane in set_lanes(visible) {
                out[lane] += weights[lane];
                if let Some(sh) = sh.as_deref_mut() {
                    if unshadowed >> lane & 1 == 1 {
                        // Inside a sphere light: radiance E/π from the whole hemisphere.
                        let l = weights[lane] * core::f32::consts::FRAC_1_PI;
                        let h = hemisphere(l, n);
                        sh[lane].iter_mut().zip(h).for_each(|(s, v)| *s += v);
                    } else {
                        let cos = n.dot(directions[lane]);
                        add_irradiance_sample(&mut sh[lane], weights[lane], directions[lane], cos);
                    }
                }
            }
            rays += traced;
        }
        if let Some(emitters) = self.emitters() {
            // One selection for the eight lanes: they share the receiver.
            let emitters = emitters.at(p, n);
            let mut packet = Ray8::INACTIVE;
            let mut samples = [None; LANES];
            for lane in 0..LANES {
                if let Some(s) = emitters.sample(pick[lane], u[lane]) {
                    packet.set_lane(lane, &self.emitter_shadow_ray(p, &s));
                    samples[lane] = Some(s);
                }
            }
            // The weight (and its MIS density, a guide lookup when the gather is guided) only
            // for the lanes that see their emitter, as in the scalar version: the same bits.
            let (visible, traced) = visible_lanes(&tree, &packet, 0);
            let live = set_lanes(visible)
                .fold(0u8, |m, lane| m | u8::from(samples[lane].is_some()) << lane);
            let others = self.other_densities8(at, &samples, live);
            for lane in set_lanes(live) {
                if let Some(s) = &samples[lane] {
                    let w = others[lane].map_or(1.0, |other| power_heuristic(s.pdf, other));
                    let e = emitter_irradiance(at.normal, s, w);
                    out[lane] += e;
                    if let Some(sh) = sh.as_deref_mut() {
                        let cos = at.normal.dot(s.direction);
                        add_irradiance_sample(&mut sh[lane], e, s.direction, cos);
                    }
                }
            }
            rays += traced;
        }
        rays
    }

    /// The other strategy's densities at the sampled directions of the lanes of `live`, for
    /// the MIS weight ([`Self::nee_weight`], 8-wide): `None` where no weighting applies.
    fn other_densities8(
        &self,
        at: &Receiver8<'_>,
        samples: &[Option<EmitterSample>; LANES],
        live: u8,
    ) -> [Option<f32>; LANES] {
        let (EmitterSampling::Mis, Some(other), true) =
            (self.emitter_sampling(), at.other, live != 0)
        else {
            return [None; LANES];
        };
        let dirs = core::array::from_fn(|lane| samples[lane].map_or(Vec3::Z, |s| s.direction));
        let densities = other(&dirs, live);
        core::array::from_fn(|lane| (live >> lane & 1 == 1).then_some(densities[lane]))
    }

    /// `L cosθ / p · w_nee`: the emitter sample's irradiance if unoccluded.
    fn emitter_weight(&self, at: &Receiver<'_>, s: &EmitterSample) -> Vec3 {
        emitter_irradiance(at.normal, s, self.nee_weight(at, s.direction, s.pdf))
    }

    /// The shadow ray from `p` to an emitter sample. It stops short of the sampled point by
    /// a ten-thousandth of the distance ([`SHADOW_SHORTEN`], as for the analytic lights) plus
    /// a few ulps of the coordinates divided by the cosine at the emitter — the rounding of
    /// the emitter's own intersection along a grazing ray — so the emitter never shadows
    /// itself, near or far from the origin.
    fn emitter_shadow_ray(&self, p: Vec3, s: &EmitterSample) -> Ray {
        let d = (s.point - p).dot(s.direction);
        let cos_emitter = (-s.normal.dot(s.direction)).max(1e-3);
        let scale = p.abs().max_element().max(s.point.abs().max_element());
        let rounding = 8.0 * f32::EPSILON * scale / cos_emitter;
        let tmax = (d * SHADOW_SHORTEN - rounding).max(0.5 * d);
        Ray::new(p, s.direction, 0.0, tmax)
    }
}

/// `L cosθ / p · w`: an emitter sample's irradiance at a receiver of unit normal `normal`
/// if unoccluded, with MIS weight `w`.
fn emitter_irradiance(normal: Vec3, s: &EmitterSample, w: f32) -> Vec3 {
    let cos = normal.dot(s.direction);
    s.radiance * (cos / s.pdf * w)
}

/// Traces `packet`'s live lanes for occlusion: the mask of visible lanes (the unoccluded
/// traced lanes and every lane of `unshadowed`) and the lanes traced.
fn visible_lanes(tree: &WideRef<'_>, packet: &Ray8, unshadowed: u8) -> (u8, u32) {
    let traced = lanes_traced(packet);
    let blocked = if traced != 0 {
        occluded8(tree, packet)
    } else {
        0
    };
    (unshadowed | (traced & !blocked), traced.count_ones())
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

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec2};
    use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
    use guidebake_kernels::testing::Pcg32;
    use guidebake_kernels::traverse::intersect1;

    use super::*;
    use crate::bvh::Preset;
    use crate::scene::{Material, Scene, Triangle};
    use crate::transport::emitters::EmitterSelection;
    use crate::transport::path::Departure;
    use crate::transport::rng::SampleRng;
    use crate::transport::world::SurfaceHit;

    /// Irradiance at `p` (normal `n`) from a Lambertian polygon of radiance `l` (Lambert's
    /// formula, `E = L/2 · Σ γᵢ n·(rᵢ × rᵢ₊₁)/|rᵢ × rᵢ₊₁|`), after clipping the polygon to
    /// the receiver's upper half-space.
    fn lambert(p: Vec3, n: Vec3, polygon: &[Vec3], l: f32) -> f64 {
        let (p, n) = (p.as_dvec3(), n.as_dvec3());
        let clipped = clip_above(polygon.iter().map(|v| v.as_dvec3() - p).collect(), n);
        let mut sum = 0.0;
        for i in 0..clipped.len() {
            let (a, b) = (
                clipped[i].normalize(),
                clipped[(i + 1) % clipped.len()].normalize(),
            );
            let cross = a.cross(b);
            if cross.length() > 0.0 {
                sum += a.dot(b).clamp(-1.0, 1.0).acos() * n.dot(cross.normalize());
            }
        }
        f64::from(l) * 0.5 * sum.abs()
    }

    /// Sutherland–Hodgman against the plane through the origin with normal `n`.
    fn clip_above(polygon: Vec<DVec3>, n: DVec3) -> Vec<DVec3> {
        let mut out = Vec::new();
        for i in 0..polygon.len() {
            let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            let (da, db) = (a.dot(n), b.dot(n));
            if da >= 0.0 {
                out.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                out.push(a + (b - a) * (da / (da - db)));
            }
        }
        out
    }

    /// A world holding one emissive quad (`corners` in order, front face `(b−a)×(c−a)`) of
    /// radiance `l`, albedo 0, black sky.
    fn lamp(corners: [Vec3; 4], l: f32, sampling: EmitterSampling, sel: EmitterSelection) -> World {
        let [a, b, c, d] = corners;
        let tri = |positions: [Vec3; 3]| Triangle {
            positions,
            normals: [(b - a).cross(c - a).normalize(); 3],
            lightmap_uv: Some([Vec2::ZERO; 3]),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        let material = Material {
            name: "lamp".into(),
            base_color_texture: None,
            albedo: Vec3::ZERO,
            emission: Vec3::splat(l),
        };
        let scene =
            Scene::of_triangles("lamp", vec![tri([a, b, c]), tri([a, c, d])], vec![material]);
        let mut world = World::new(&scene, Preset::DEFAULT).unwrap();
        world.set_emitters(sampling, sel);
        world
    }

    /// Mean and standard error of `n` samples of `f`.
    fn estimate(n: usize, mut f: impl FnMut(usize) -> f64) -> (f64, f64) {
        let (mut sum, mut sum2) = (0.0, 0.0);
        for i in 0..n {
            let x = f(i);
            assert!(x.is_finite() && x >= 0.0, "sample {i}: {x}");
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / n as f64;
        (
            mean,
            ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt(),
        )
    }

    /// One sample of the irradiance at `(p, n)` from `world`'s emitters by next-event
    /// estimation (weighted against cosine gathering when `mis`) and by a cosine-sampled
    /// ray that may hit one (weighted by the world's emitter sampling).
    fn sample(world: &World, p: Vec3, n: Vec3, rng: &mut Pcg32, i: usize) -> (f64, f64) {
        let cosine = |d: Vec3| n.dot(d).max(0.0) * core::f32::consts::FRAC_1_PI;
        let at = Receiver {
            point: p,
            normal: n,
            other: Some(&cosine),
        };
        let u = [rng.next_f32(), rng.next_f32()];
        let (nee, _) = world.direct_irradiance(&at, u, rng.next_f32());
        let (t, b) = orthonormal_basis(n);
        let d = sample_cosine_hemisphere([rng.next_f32(), rng.next_f32()]);
        let dir = (t * d.x + b * d.y + n * d.z).normalize();
        let hit = intersect1(&world.wide_bvh(), &Ray::new(p, dir, 0.0, f32::INFINITY));
        let hit_e = hit.map_or(0.0, |h| {
            let from = Departure {
                point: p,
                normal: n,
                pdf: cosine(dir),
            };
            let hit = SurfaceHit {
                prim: h.prim,
                t: h.t,
                u: h.u,
                v: h.v,
            };
            let mut rng = SampleRng::new(1, 0, 0, i as u32);
            let leaving = world.radiance_from_hit(&from, dir, hit, &mut rng);
            assert_eq!(
                leaving.reflected,
                Vec3::ZERO,
                "a black lamp reflects nothing"
            );
            f64::from(leaving.emitted.x) * core::f64::consts::PI
        });
        (f64::from(nee.x), hit_e)
    }

    #[test]
    fn an_emissive_quad_gives_lamberts_irradiance_by_nee_hits_and_mis() {
        let l = 7.0;
        // A 1 m square 1 m above the origin, facing down.
        let quad = [
            Vec3::new(-0.5, -0.5, 1.0),
            Vec3::new(-0.5, 0.5, 1.0),
            Vec3::new(0.5, 0.5, 1.0),
            Vec3::new(0.5, -0.5, 1.0),
        ];
        let cases = [
            ("facing it", Vec3::ZERO, Vec3::Z),
            (
                "at a slant",
                Vec3::new(0.7, 0.2, 0.0),
                Vec3::new(-0.5, 0.1, 1.0).normalize(),
            ),
            (
                "partly below the horizon",
                Vec3::new(0.1, 0.0, 0.6),
                Vec3::new(1.0, 0.0, 0.3).normalize(),
            ),
            // Far enough to be sampled by area rather than by solid angle.
            ("far below", Vec3::new(0.3, 0.2, -4.0), Vec3::Z),
        ];
        let n = 40_000;
        let selections = [
            EmitterSelection::Power,
            EmitterSelection::Tree,
            EmitterSelection::Local,
        ];
        for ((what, p, normal), sel) in cases.into_iter().flat_map(|c| selections.map(|s| (c, s))) {
            let what = format!("{what} ({sel})");
            let want = lambert(p, normal, &quad, l);
            assert!(want > 0.02, "{what}: {want}");
            let nee_alone = lamp(quad, l, EmitterSampling::Nee, sel);
            let hits_alone = lamp(quad, l, EmitterSampling::Hits, sel);
            let mis = lamp(quad, l, EmitterSampling::Mis, sel);
            let mut rng = Pcg32::new(7, 1);
            let nee = estimate(n, |i| sample(&nee_alone, p, normal, &mut rng, i).0);
            let hits = estimate(n, |i| sample(&hits_alone, p, normal, &mut rng, i).1);
            let both = estimate(n, |i| {
                let (a, b) = sample(&mis, p, normal, &mut rng, i);
                a + b
            });
            // The strategies that are off contribute nothing.
            let mut rng = Pcg32::new(8, 1);
            assert_eq!(
                estimate(1000, |i| sample(&nee_alone, p, normal, &mut rng, i).1).0,
                0.0
            );
            assert_eq!(
                estimate(1000, |i| sample(&hits_alone, p, normal, &mut rng, i).0).0,
                0.0
            );
            for (name, (mean, se)) in [("nee", nee), ("hits", hits), ("mis", both)] {
                assert!(
                    (mean - want).abs() <= 3.0 * se + 1e-4 * want,
                    "{what}, {name}: {mean} ± {se}, Lambert {want}"
                );
            }
            assert!(
                nee.1 < hits.1 && both.1 < hits.1,
                "{what}: {nee:?} {hits:?} {both:?}"
            );
        }
    }

    #[test]
    fn an_emitter_seen_from_behind_gives_nothing() {
        // The quad faces up (+z).
        let quad = [
            Vec3::new(-0.5, -0.5, 0.0),
            Vec3::new(0.5, -0.5, 0.0),
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(-0.5, 0.5, 0.0),
        ];
        let world = lamp(quad, 5.0, EmitterSampling::Mis, EmitterSelection::Power);
        let (p, n) = (Vec3::new(0.0, 0.0, -1.0), Vec3::Z);
        let mut rng = Pcg32::new(3, 3);
        let (mean, _) = estimate(2000, |i| {
            let (a, b) = sample(&world, p, n, &mut rng, i);
            a + b
        });
        assert_eq!(mean, 0.0, "from below, only the back is seen");
        let (p, n) = (Vec3::new(0.0, 0.0, 1.0), -Vec3::Z);
        let (mean, _) = estimate(2000, |i| {
            let (a, b) = sample(&world, p, n, &mut rng, i);
            a + b
        });
        assert!(mean > 0.0, "from above, the front is seen");
    }

    /// Many emitters of mixed power and orientation, some facing away, some behind the
    /// receiver: the irradiance by next-event estimation is the same whichever selection
    /// picks them (both unbiased), and MIS with hits agrees with it.
    #[test]
    fn power_and_tree_selection_agree_on_many_emitters() {
        let mut rng = Pcg32::new(42, 7);
        let mut tris = Vec::new();
        let mut materials = Vec::new();
        for i in 0..60 {
            let c = Vec3::new(
                rng.next_f32() * 6.0 - 3.0,
                rng.next_f32() * 6.0 - 3.0,
                rng.next_f32() * 3.0 - 0.5,
            );
            let e1 = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
            let e2 = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
            let n = e1.cross(e2).normalize();
            tris.push(Triangle {
                positions: [c, c + e1, c + e2],
                normals: [n; 3],
                lightmap_uv: Some([Vec2::ZERO; 3]),
                texture_uv: None,
                colour: None,
                mesh: 0,
                material: i,
            });
            materials.push(Material {
                name: format!("e{i}"),
                base_color_texture: None,
                albedo: Vec3::ZERO,
                emission: Vec3::splat(10f32.powf(rng.next_f32() * 3.0 - 1.0)),
            });
        }
        let scene = Scene::of_triangles("many", tris, materials);
        let (p, normal) = (
            Vec3::new(0.2, -0.1, 0.0),
            Vec3::new(0.1, 0.2, 1.0).normalize(),
        );
        let n = 200_000;
        let mut results = Vec::new();
        for (sampling, sel) in [
            (EmitterSampling::Nee, EmitterSelection::Power),
            (EmitterSampling::Nee, EmitterSelection::Tree),
            (EmitterSampling::Mis, EmitterSelection::Tree),
            (EmitterSampling::Nee, EmitterSelection::Local),
            (EmitterSampling::Mis, EmitterSelection::Local),
        ] {
            let mut world = World::new(&scene, Preset::DEFAULT).unwrap();
            world.set_emitters(sampling, sel);
            let mut rng = Pcg32::new(9, 9);
            let est = estimate(n, |i| {
                let (a, b) = sample(&world, p, normal, &mut rng, i);
                a + b
            });
            results.push((format!("{sampling}/{sel}"), est));
        }
        let (_, (m0, s0)) = results[0].clone();
        assert!(m0 > 0.0);
        for (what, (m, s)) in &results[1..] {
            let tol = 3.0 * (s * s + s0 * s0).sqrt();
            assert!(
                (m - m0).abs() <= tol,
                "{what}: {m} ± {s} vs nee/power {m0} ± {s0}"
            );
        }
    }

    /// A lamp and its receiver moved 10⁶ sideways (coordinates with ulps of 6 cm) and a lamp
    /// of radiance 10⁵ next to one of 10⁻⁴: every sample finite, the emitter never shadows
    /// itself (every sample that reaches it counts), and the mean within the geometry's
    /// rounding of Lambert's value.
    #[test]
    fn far_off_and_extreme_emitters_stay_finite() {
        let far = Vec3::new(1e6, -1e6, 0.0);
        let quad = [
            Vec3::new(-2.0, -2.0, 2.0),
            Vec3::new(-2.0, 2.0, 2.0),
            Vec3::new(2.0, 2.0, 2.0),
            Vec3::new(2.0, -2.0, 2.0),
        ];
        let cases = [(Vec3::ZERO, 1e5, 0.01), (far, 1e-4, 0.06)];
        let selections = [EmitterSelection::Tree, EmitterSelection::Local];
        for ((offset, l, tolerance), sel) in
            cases.into_iter().flat_map(|c| selections.map(|s| (c, s)))
        {
            let world = lamp(quad.map(|v| v + offset), l, EmitterSampling::Nee, sel);
            let p = offset + Vec3::new(0.3, 0.0, 0.0);
            let want = lambert(p, Vec3::Z, &quad.map(|v| v + offset), l);
            let mut rng = Pcg32::new(4, 4);
            let (mut reached, n) = (0, 20_000);
            let (mean, _) = estimate(n, |i| {
                let e = sample(&world, p, Vec3::Z, &mut rng, i).0;
                reached += usize::from(e > 0.0);
                e
            });
            assert_eq!(
                reached, n,
                "{offset}: an emitter facing the point is always reached"
            );
            assert!(
                (mean - want).abs() <= tolerance * want,
                "{offset}: {mean} vs Lambert {want}"
            );
        }
    }

    /// Skip what the scene doesn't need: a black lamp is no emitter, so no table, no tree,
    /// no shadow ray.
    #[test]
    fn a_world_without_emitters_samples_none() {
        let quad = [Vec3::ZERO, Vec3::X, Vec3::X + Vec3::Y, Vec3::Y];
        for sel in [
            EmitterSelection::Power,
            EmitterSelection::Tree,
            EmitterSelection::Local,
        ] {
            let dark = lamp(quad, 0.0, EmitterSampling::Mis, sel);
            assert!(dark.emitters().is_none() && !dark.has_direct_light());
            assert_eq!(dark.emitter_sampling(), EmitterSampling::Hits);
            let at = Receiver {
                point: Vec3::new(0.5, 0.5, -1.0),
                normal: Vec3::Z,
                other: None,
            };
            assert_eq!(dark.direct_irradiance(&at, [0.5; 2], 0.5), (Vec3::ZERO, 0));
            let lit = lamp(quad, 1.0, EmitterSampling::Mis, sel);
            assert_eq!(lit.emitters().map(|e| e.len()), Some(2));
        }
    }

    #[test]
    fn the_power_heuristic_weighs_in_zero_to_one() {
        assert_eq!(power_heuristic(f32::INFINITY, 3.0), 1.0);
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
        assert_eq!(power_heuristic(2.0, 2.0), 0.5);
        assert!((power_heuristic(1.0, 3.0) - 0.1).abs() < 1e-7);
        assert!((power_heuristic(3.0, 1.0) + power_heuristic(1.0, 3.0) - 1.0).abs() < 1e-7);
    }
}
