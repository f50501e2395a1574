//! What leaves a gather ray's hit, by the bake's transport (docs/bake.md):
//! the hit's emission, weighted by multiple importance sampling against the next-event
//! estimate of the point the ray left ([`super::direct`]), plus its albedo/π times the
//! irradiance arriving there: under `series` ([`super::series`]), the previous pass's total
//! irradiance (pass 1 reads the direct pass 0) where the hit is on the side its texels bake
//! and not within `NEAR_FIELD_TEXELS` of its texels of the ray's origin, else direct light by
//! next-event estimation plus the previous pass's gather-only irradiance. Where the gather's hit
//! reads neither layer — within `NEAR_PATH_TEXELS` of its texels of the ray's origin, or where
//! the texels cannot be read (a side no texel describes, padding or texels inside geometry,
//! texels that disagree beyond `SMOOTH_RATIO`) — its direct light is connected and the rest
//! carried one cosine-weighted bounce on, to a vertex that reads the pass before the previous
//! one by the same rules; a vertex there that cannot be read either (or a hit that cannot be
//! read without that pass) has a path traced on from it with as many bounces as the pass it
//! reads holds, as under `path` (docs/bake.md, "Where series reads the lightmap");
//! under `path`, direct light by next-event estimation plus a path continued with
//! cosine-weighted directions, next-event estimation and MIS at every vertex, and Russian
//! roulette from the third vertex. A ray that leaves the scene sees the sky.
//!
//! What a final-gather sample therefore contains, and the guide learns from (paper §2.2):
//! the emission its ray hits, times the MIS weight of the gather's density against
//! next-event estimation from the texel — so light an emitter sends straight to the texel
//! is found mostly by next-event estimation and weighs little in the records, except where
//! the gather samples it better (large emitters close by) — plus everything the hit
//! reflects, in which every emitter is connected explicitly or read from the previous pass. Records are therefore no
//! longer zero-or-huge under small emitters: the guide learns the indirect light, which
//! next-event estimation cannot find.

use glam::Vec3;
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
use guidebake_kernels::packet::Ray;
use guidebake_kernels::traverse::intersect1;

use super::direct::{Receiver, power_heuristic};
use super::emitters::EmittersAt;
use super::rng::SampleRng;
use super::settings::{EmitterSampling, Transport};
use super::world::{SurfaceHit, World};

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
    /// Reads of the previous series pass's total irradiance (next-event estimation skipped).
    pub totals_read: u32,
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
        // Series: the vertices a path traced from a vertex that could not be read may have
        // (the passes the pass it read holds, plus that vertex), once it is traced.
        let mut traced: Option<u32> = None;
        // The emitter selection at `from` when next-event estimation made it there (a path
        // vertex), for the MIS weight of the emission its ray hits; the gather's texel made
        // its own.
        let mut from_emitters: Option<EmittersAt<'_>> = None;
        for vertex in 1.. {
            let Some(s) = self.surfaces().get(hit.prim as usize) else {
                break;
            };
            let front = s.normal.dot(dir) < 0.0;
            if front && s.emission != Vec3::ZERO {
                let emitted =
                    throughput * s.emission * self.hit_weight(&from, from_emitters, dir, hit);
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
            let previous = match self.transport() {
                Transport::Series if traced.is_none() && vertex == 1 => self.previous_pass(),
                Transport::Series if traced.is_none() => self.earlier_pass(),
                Transport::Series | Transport::Path => None,
            };
            // Series: a side no texel describes (the other side of a thin wall, a triangle
            // without lightmap UVs) has no lightmap to read — the texels of its other side
            // hold the light of the space behind it — and neither has a point where no baked
            // texel lies (padding, texels inside geometry, whose values are the dilation's);
            // where the texels read disagree (a doorway, a shadow edge), their average is not
            // the light at the hit. The light there is computed another way (below).
            let lookup = previous
                .filter(|p| p.bakes_side(hit.prim, front))
                .map(|p| p.lookup(hit.prim, hit.u, hit.v))
                .filter(|l| l.baked);
            let far = previous.is_some_and(|p| p.reads_total(hit.prim, front, hit.t));
            let reads_total = far && lookup.is_some_and(|l| l.smooth);
            // So near the origin the texels a lookup interpolates lie as far from the hit as
            // the gathering point does: their gather-only light is the blur of the corner the
            // two make, not the light at the hit (docs/bake.md).
            let near = vertex == 1 && previous.is_some_and(|p| !p.reads_gathered(hit.prim, hit.t));
            let reads_gathered = lookup.is_some_and(|l| l.gathered_smooth) && !near;
            let read = reads_total || reads_gathered;
            // A gather's hit that reads neither layer has its direct light connected and the
            // rest carried one bounce on, where the pass before the previous one is read: one
            // noisy step, not a whole path (docs/bake.md). A vertex that cannot be read there,
            // or a hit that cannot be read without that pass, has a path traced from it with
            // as many bounces as the pass it reads holds, next-event estimation at every
            // vertex, as path transport does (in the first gather pass, whose previous pass
            // holds direct light alone, that path is the hit's next-event estimate).
            let carried = vertex == 1
                && previous.is_some()
                && !read
                && (near || self.earlier_pass().is_some());
            if let Some(p) = previous.filter(|_| !read && !carried) {
                traced = Some(p.pass() + vertex);
            }
            let continues = match (self.transport(), traced) {
                (Transport::Path, _) => vertex < self.bounces(),
                (Transport::Series, Some(depth)) => vertex < depth,
                (Transport::Series, None) => carried && self.earlier_pass().is_some(),
            };
            let cosine_pdf = |d: Vec3| facing.dot(d).max(0.0) * core::f32::consts::FRAC_1_PI;
            let at = Receiver {
                point: p,
                normal: facing,
                other: continues.then_some(&cosine_pdf as &dyn Fn(Vec3) -> f32),
            };
            let mut irradiance = Vec3::ZERO;
            let mut emitters_here = None;
            match lookup {
                Some(l) if reads_total => {
                    irradiance += l.total;
                    out.totals_read += 1;
                }
                _ => {
                    if self.has_direct_light() {
                        emitters_here = self.emitters().map(|e| e.at(p, facing));
                        let (direct, rays) = self.direct_irradiance_at(
                            &at,
                            emitters_here.as_ref(),
                            rng.pair(),
                            rng.unit(),
                        );
                        irradiance += direct;
                        out.shadow_rays += rays;
                    }
                    if let Some(l) = lookup.filter(|_| reads_gathered) {
                        irradiance += l.gathered;
                    }
                }
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
            match intersect1(&self.wide_bvh(), &Ray::new(p, next, 0.0, f32::INFINITY)) {
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
                    from_emitters = emitters_here;
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
    /// `at_from` is the emitter selection next-event estimation made at `from`, if any.
    fn hit_weight(
        &self,
        from: &Departure,
        at_from: Option<EmittersAt<'_>>,
        dir: Vec3,
        hit: SurfaceHit,
    ) -> f32 {
        let Some(emitters) = self.emitters() else {
            return 1.0;
        };
        match self.emitter_sampling() {
            EmitterSampling::Hits => 1.0,
            EmitterSampling::Nee => 0.0,
            EmitterSampling::Mis => {
                let nee = match at_from {
                    Some(at) => at.pdf(hit.prim, dir, hit.t),
                    None => emitters.pdf(from.point, from.normal, hit.prim, dir, hit.t),
                };
                power_heuristic(from.pdf, nee)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::Preset;
    use crate::scene::Sun;
    use crate::test_support::lightmapped_triangle;
    use crate::texels::{SEEN_FRONT, TriangleRecord};
    use crate::transport::series::{
        NEAR_FIELD_TEXELS, NEAR_PATH_TEXELS, PreviousPassWriter, SMOOTH_RATIO,
    };
    use glam::Vec2;

    /// A 4 m right triangle on z = 0 facing +z, albedo 0.5, under a sun of irradiance 2 from
    /// +z; its lightmap is a 4×4 page, so one texel is 1 m. The previous pass (pass 2) read 1
    /// (gather only) and 5 (total) everywhere, and baked the front side.
    fn lit_triangle(dir: &std::path::Path) -> World {
        let (mut scene, triangles, pages) = lightmapped_triangle(4.0, 0.5);
        scene.sun = Some(Sun {
            direction: Vec3::Z,
            angular_radius: 0.0,
            irradiance: Vec3::splat(2.0),
        });
        let mut image = PreviousPassWriter::create(&dir.join("pass.bin"), &pages).unwrap();
        for i in 0..16 {
            image.set(0, (i % 4, i / 4), [1.0; 3], [5.0; 3]);
        }
        let mut world = World::new(&scene, Preset::DEFAULT).unwrap();
        world.set_transport(Transport::Series, 3);
        world.set_previous_pass(Some(image.finish(&scene, &triangles).unwrap().of_pass(2)));
        world
    }

    /// What leaves the triangle at (1, 1, 0) towards a ray that left from `height` above
    /// (or below, when negative) it.
    fn leaving(world: &World, height: f32) -> Leaving {
        let from = Departure {
            point: Vec3::new(1.0, 1.0, height),
            normal: -Vec3::Z * height.signum(),
            pdf: 1.0,
        };
        let hit = SurfaceHit {
            prim: 0,
            t: height.abs(),
            u: 0.25,
            v: 0.25,
        };
        let dir = -Vec3::Z * height.signum();
        world.radiance_from_hit(&from, dir, hit, &mut SampleRng::new(1, 0, 0, 0))
    }

    /// Series from pass 1 (reading pass 0 or a later one): a far hit on the baked side reads
    /// the total (no shadow ray); a near one, within [`NEAR_FIELD_TEXELS`] texels, connects
    /// the sun and reads the gather-only layer; one on the other side reads nothing and traces
    /// one more bounce.
    #[test]
    fn a_series_hit_reads_the_total_only_far_away_on_the_baked_side() {
        let dir = tempfile::tempdir().unwrap();
        let world = lit_triangle(dir.path());
        let albedo_over_pi = 0.5 * core::f32::consts::FRAC_1_PI;
        let far = leaving(&world, 3.0 * NEAR_FIELD_TEXELS);
        assert_eq!((far.shadow_rays, far.totals_read), (0, 1));
        assert!(
            (far.reflected - Vec3::splat(5.0 * albedo_over_pi)).length() < 1e-5,
            "{far:?}"
        );
        let near = leaving(&world, 0.5 * NEAR_FIELD_TEXELS);
        assert_eq!((near.shadow_rays, near.totals_read), (1, 0));
        let want = Vec3::splat((2.0 + 1.0) * albedo_over_pi);
        assert!((near.reflected - want).length() < 1e-5, "{near:?}");
        // From below: the back, which no texel bakes and the sun does not reach. Its texels
        // hold the light of the front, so it is not read: a path is traced instead (up to
        // the 3 vertices pass 2's light has made), into the black sky under the triangle.
        let back = leaving(&world, -3.0 * NEAR_FIELD_TEXELS);
        assert_eq!((back.totals_read, back.path_rays), (0, 1));
        assert_eq!(back.reflected, Vec3::ZERO, "{back:?}");
        assert_eq!(far.emitted + near.emitted + back.emitted, Vec3::ZERO);
    }

    /// A hit within [`NEAR_PATH_TEXELS`] of its texels of the ray's origin reads neither
    /// layer: its sun is connected, and the rest of its light is carried one bounce on to
    /// where the pass before the previous one is read — here into the black sky above, so
    /// only the sun comes back. Without that pass (the bake's first gather pass, whose
    /// previous pass holds no gathered light), the sun alone. That the bounce reads the
    /// earlier pass, keeping the bake's bounce count, `driver/tests/unwrap.rs` checks in a
    /// closed room against the closed form.
    #[test]
    fn a_series_hit_within_a_texel_of_its_origin_is_carried_one_bounce_on() {
        let dir = tempfile::tempdir().unwrap();
        let mut world = lit_triangle(dir.path());
        let sun_only = Vec3::splat(2.0 * 0.5 * core::f32::consts::FRAC_1_PI);
        // Neither layer read, one shadow ray, `path_rays` bounces on, the sun alone back.
        let sun_alone = |l: Leaving, path_rays: u32| {
            assert_eq!(
                (l.totals_read, l.shadow_rays, l.path_rays),
                (0, 1, path_rays),
                "{l:?}"
            );
            assert!((l.reflected - sun_only).length() < 1e-5, "{l:?}");
        };
        sun_alone(leaving(&world, 0.5 * NEAR_PATH_TEXELS), 0);
        let (scene, triangles, pages) = lightmapped_triangle(4.0, 0.5);
        let earlier = PreviousPassWriter::create(&dir.path().join("earlier.bin"), &pages)
            .unwrap()
            .finish(&scene, &triangles)
            .unwrap()
            .of_pass(1);
        world.set_earlier_pass(Some(earlier));
        sun_alone(leaving(&world, 0.5 * NEAR_PATH_TEXELS), 1);
        let beyond = leaving(&world, 2.0 * NEAR_PATH_TEXELS);
        assert_eq!((beyond.shadow_rays, beyond.path_rays), (1, 0), "{beyond:?}");
    }

    /// A hit whose lookup is refused (here: the floor's texels disagree) reads neither layer.
    /// With the pass before the previous one in memory, it is carried one bounce on and that
    /// pass is read where the bounce lands (a ceiling 2 m up whose earlier-pass texels hold a
    /// gathered 7): the floor's albedo times the ceiling's light. Without that pass a path is
    /// traced, and in this world without lights or sky the path brings nothing back.
    #[test]
    fn a_refused_hit_reads_the_pass_before_one_bounce_on() {
        let dir = tempfile::tempdir().unwrap();
        let (mut scene, mut triangles, pages) = lightmapped_triangle(4.0, 0.5);
        let big = 1000.0;
        let mut ceiling = scene.triangles[0];
        // Facing down (-z), over the whole sky of the floor's hit.
        ceiling.positions = [
            Vec3::new(-big, -big, 2.0),
            Vec3::new(-big, 3.0 * big, 2.0),
            Vec3::new(3.0 * big, -big, 2.0),
        ];
        ceiling.normals = [-Vec3::Z; 3];
        ceiling.lightmap_uv = Some([Vec2::ZERO, Vec2::Y, Vec2::X]);
        scene.triangles.push(ceiling);
        scene.meshes[0].triangle_count = 2;
        let uv = [Vec2::ZERO, Vec2::new(0.0, 4.0), Vec2::new(4.0, 0.0)];
        triangles.push(TriangleRecord::lightmapped(0, uv, SEEN_FRONT));
        let image = |name: &str, value: &dyn Fn(u32) -> f32| {
            let mut w = PreviousPassWriter::create(&dir.path().join(name), &pages).unwrap();
            for i in 0..16 {
                w.set(0, (i % 4, i / 4), [value(i); 3], [value(i); 3]);
            }
            w.finish(&scene, &triangles).unwrap()
        };
        // Pass 2: columns 0 and 1 dark, 2 and 3 bright; pass 1: 7 everywhere.
        let previous = image("pass.bin", &|i| {
            if i % 4 < 2 { 1.0 } else { 10.0 * SMOOTH_RATIO }
        });
        let mut world = World::new(&scene, Preset::DEFAULT).unwrap();
        world.set_transport(Transport::Series, 3);
        world.set_previous_pass(Some(previous.of_pass(2)));
        // Between columns 1 and 2 of the floor, from far above: refused.
        let hit = SurfaceHit {
            prim: 0,
            t: 3.0 * NEAR_FIELD_TEXELS,
            u: 0.5,
            v: 0.125,
        };
        let from = Departure {
            point: Vec3::new(2.0, 0.5, hit.t),
            normal: -Vec3::Z,
            pdf: 1.0,
        };
        let leaving = |world: &World| {
            world.radiance_from_hit(&from, -Vec3::Z, hit, &mut SampleRng::new(1, 0, 0, 0))
        };
        let traced = leaving(&world);
        assert!(
            traced.totals_read == 0 && traced.path_rays >= 1,
            "{traced:?}"
        );
        assert_eq!(traced.reflected, Vec3::ZERO, "{traced:?}");
        world.set_earlier_pass(Some(image("earlier.bin", &|_| 7.0).of_pass(1)));
        let carried = leaving(&world);
        assert_eq!(carried.path_rays, 1, "{carried:?}");
        let want = Vec3::splat(0.5 * 0.5 * core::f32::consts::FRAC_1_PI * 7.0);
        assert!((carried.reflected - want).length() < 1e-4, "{carried:?}");
    }

    /// Where the texels a hit would read disagree by more than [`SMOOTH_RATIO`] (a shadow
    /// edge), neither layer is read: the sun is connected at the hit and the rest carried on
    /// (no earlier pass here: a path traced).
    #[test]
    fn a_hit_where_the_texels_disagree_is_traced_not_read() {
        let dir = tempfile::tempdir().unwrap();
        let (mut scene, triangles, pages) = lightmapped_triangle(4.0, 0.5);
        scene.sun = Some(Sun {
            direction: Vec3::Z,
            angular_radius: 0.0,
            irradiance: Vec3::splat(2.0),
        });
        let mut image = PreviousPassWriter::create(&dir.path().join("pass.bin"), &pages).unwrap();
        for i in 0..16 {
            // Columns 0 and 1 dark, 2 and 3 bright.
            let v = if i % 4 < 2 { 1.0 } else { 10.0 * SMOOTH_RATIO };
            image.set(0, (i % 4, i / 4), [v; 3], [v; 3]);
        }
        let mut world = World::new(&scene, Preset::DEFAULT).unwrap();
        world.set_transport(Transport::Series, 3);
        world.set_previous_pass(Some(image.finish(&scene, &triangles).unwrap().of_pass(2)));
        let read = |u: f32| {
            let from = Departure {
                point: Vec3::new(4.0 * u, 0.5, 3.0 * NEAR_FIELD_TEXELS),
                normal: -Vec3::Z,
                pdf: 1.0,
            };
            let hit = SurfaceHit {
                prim: 0,
                t: 3.0 * NEAR_FIELD_TEXELS,
                u,
                v: 0.125,
            };
            world.radiance_from_hit(&from, -Vec3::Z, hit, &mut SampleRng::new(1, 0, 0, 0))
        };
        // In column 0 (pixel x = 0.4): its taps, columns 0 and... 0 (clamped): agree, read.
        let smooth = read(0.1);
        assert_eq!(
            (smooth.totals_read, smooth.shadow_rays),
            (1, 0),
            "{smooth:?}"
        );
        // Between columns 1 and 2 (pixel x = 2.0): they disagree; the sun is connected.
        let edge = read(0.5);
        assert_eq!(edge.totals_read, 0, "{edge:?}");
        assert_eq!((edge.shadow_rays, edge.path_rays), (1, 1), "{edge:?}");
    }
}
