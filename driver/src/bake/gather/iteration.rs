//! One iteration's gather over one texel (paper §2.4): its rays, from presorted packets
//! rotated per texel and warped 8-wide (`coherent`), or one point at a time (`naive`), or
//! the grid comparator's bins, traced as packets or single rays; next-event estimation at
//! the texel; each sample's estimate, learning record and spherical-harmonic projection
//! ([`IterationCtx`], [`Sinks`]).

use std::time::Instant;

use glam::Vec3;
use guidebake_kernels::estimator::{Welford, luminance_f32};
use guidebake_kernels::guide::Record;
use guidebake_kernels::mapping::{
    invert_cosine_hemisphere_x8, sample_cosine_hemisphere, sample_cosine_hemisphere_x8,
};
use guidebake_kernels::packet::{LANES, NO_HIT, Ray, Ray8};
use guidebake_kernels::presort::reorder_after_rotation_into;
use guidebake_kernels::sobol::{
    rotate, rotate_x8, rotation, sobol_2d, sobol_2d_x8, to_unit, to_unit_x8,
};
use guidebake_kernels::traverse::{intersect1, intersect8};
use guidebake_kernels::warp;
use wide::{f32x8, u32x8};

use crate::bake::directional::{self, ShSample, ShSums};
use crate::bake::settings::BakeSettings;
use crate::transport::direct::Receiver8;
use crate::transport::path::{Departure, Leaving};
use crate::transport::rng::SampleRng;
use crate::transport::world::{SurfaceHit, World};

use super::*;

/// Where one texel's samples go in one iteration.
pub(super) struct Sinks<'a> {
    /// The texel's estimator of this iteration (gathered + direct irradiance).
    pub(super) batch: &'a mut Welford,
    /// Its samples' spherical-harmonic projections in this iteration, if kept.
    pub(super) sh: Option<&'a mut ShSums>,
    /// The texel's gather-only samples over all iterations.
    pub(super) gathered: &'a mut Welford,
    /// The cluster's learning records, when this iteration learns.
    pub(super) learning: Option<&'a mut GuideRecords>,
}

/// What one iteration's gather needs, borrowed.
pub(super) struct IterationCtx<'a> {
    pub(super) world: &'a World,
    /// The seed every random number of the iteration derives from: the settings' `--seed`,
    /// or the baker's own stream ([`TileBaker::stream_seed`]).
    pub(super) seed: u32,
    pub(super) k: u32,
    /// The guide this iteration samples; it holds the defensive mixture with the cosine
    /// baseline ([`GuideParams::uniform`]), so its density is the mixture's.
    pub(super) guide: Option<IterationGuide<'a>>,
    /// Whether samples include the texel's next-event estimate ([`TileBaker::texel_direct`]).
    pub(super) texel_direct: bool,
}

impl<'a> IterationCtx<'a> {
    pub(super) fn new(
        world: &'a World,
        settings: &'a BakeSettings,
        k: u32,
        guide: Option<IterationGuide<'a>>,
    ) -> Self {
        Self {
            world,
            seed: settings.seed,
            k,
            guide,
            texel_direct: true,
        }
    }

    /// The clock of packet `j`'s warp, if the iteration warps and the packet is one of the
    /// timed ones ([`GatherCounters::warp_ns`]).
    fn warp_clock(&self, j: u32) -> Option<Instant> {
        (self.guide.is_some() && j.is_multiple_of(WARP_TIMED_EVERY)).then(Instant::now)
    }

    /// The density on the primary sample square this iteration's gather samples with, at
    /// `u`: the guide's (the mixture's, [`GuideParams::uniform`]); 1 without a guide.
    #[cfg(test)]
    fn guide_pdf(&self, u: [f32; 2]) -> f32 {
        match self.guide {
            Some(IterationGuide::Tree(g)) => warp::pdf(g, u),
            Some(IterationGuide::Grid(g)) => g.pdf(u),
            None => 1.0,
        }
    }

    /// The density on the primary sample square that this iteration's gather at texel `t`
    /// sampled the world direction `dir` with (the point is the inverse cosine map of `dir`
    /// in the texel's frame): the solid-angle pdf is this × cosθ/π ([`Self::gather_pdf`]).
    /// 0 below the horizon. The scalar reference of [`Self::gather_pdf8`].
    #[cfg(test)]
    pub(super) fn sampled_density(&self, t: &GatherTexel, dir: Vec3) -> f32 {
        let local = Vec3::new(dir.dot(t.tangent), dir.dot(t.bitangent), dir.dot(t.normal));
        if local.z <= 0.0 {
            return 0.0;
        }
        if self.guide.is_none() {
            return 1.0;
        }
        let u = guidebake_kernels::mapping::invert_cosine_hemisphere(local.normalize());
        self.guide_pdf(u)
    }

    /// The origin of packet `packet`: a point of the texel's footprint (its centre for
    /// partly covered texels), brought back onto the texel's triangle and off its edges so
    /// no origin lies past a wall's corner, then offset from the surface.
    fn origin(&self, t: &GatherTexel, packet: u32) -> Vec3 {
        let mut p = t.position;
        if t.jitter {
            let r = rotation(self.seed ^ ORIGIN_SALT, t.id, self.k << 20 | packet);
            p += t.dpdu * (to_unit(r[0]) - 0.5) + t.dpdv * (to_unit(r[1]) - 0.5);
        }
        // Off the triangle's own plane, on the texel's side: a shading normal near the
        // tangent plane would lift the origin too little. The centroid nudge stays within a
        // hundredth of the texel.
        let footprint = t.dpdu.length() + t.dpdv.length();
        let on = self.world.onto_triangle(t.triangle, p, 0.01 * footprint);
        let n = self.world.facing_normal(t.triangle, t.normal);
        self.world.leave_surface(t.triangle, on, n, 0.0)
    }

    pub(super) fn to_world(&self, t: &GatherTexel, d: Vec3) -> Vec3 {
        (t.tangent * d.x + t.bitangent * d.y + t.normal * d.z).normalize_or(t.normal)
    }

    /// The iteration's points, one presorted Sobol set rotated per texel, traced as
    /// packets of eight; warped 8-wide through the guide when the iteration samples one.
    /// The guide holds the defensive mixture with the cosine baseline
    /// ([`GuideParams::uniform`]), so every packet is drawn from the mixture and the set
    /// stays whole: no packets are set aside for the baseline, whose few points would spread
    /// over the whole hemisphere and cost the packet walk its coherence.
    pub(super) fn gather_packets(
        &self,
        t: &GatherTexel,
        order: &[u32],
        rotated: &mut Vec<u32>,
        sinks: &mut Sinks<'_>,
        counters: &mut GatherCounters,
    ) {
        let rot = rotation(self.seed, t.id, self.k);
        let light_rot = rotation(self.seed ^ LIGHT_SALT, t.id, self.k);
        rotated.resize(order.len(), 0);
        reorder_after_rotation_into(order, rot, rotated);
        let tree = self.world.wide_bvh();
        for (j, chunk) in rotated.chunks_exact(LANES).enumerate() {
            let j = j as u32;
            let index = u32x8::new(chunk.try_into().expect("packets of 8"));
            let [sx, sy] = rotate_x8(sobol_2d_x8(index), rot);
            let (x, y) = (to_unit_x8(sx), to_unit_x8(sy));
            let clock = self.warp_clock(j);
            let (wx, wy, q) = match self.guide {
                Some(IterationGuide::Tree(g)) => {
                    let w = warp::sample8(g, x, y);
                    (w.x, w.y, w.pdf)
                }
                Some(IterationGuide::Grid(g)) => grid_sample8(g, x, y),
                None => (x, y, f32x8::ONE),
            };
            count_warp(clock, counters);
            let [dx, dy, dz] = sample_cosine_hemisphere_x8([wx, wy]);
            let (dx, dy, dz, wx, wy, q) = (
                dx.to_array(),
                dy.to_array(),
                dz.to_array(),
                wx.to_array(),
                wy.to_array(),
                q.to_array(),
            );
            let dirs: [Vec3; LANES] =
                core::array::from_fn(|i| self.to_world(t, Vec3::new(dx[i], dy[i], dz[i])));
            let origin = self.origin(t, j);
            let packet = Ray8::from_origin(origin, &dirs, 0.0, f32::INFINITY);
            let mut hits = guidebake_kernels::packet::Hit8::NONE;
            intersect8(&tree, &packet, &mut hits);
            counters.gather_rays += LANES as u64;
            let (ht, hprim) = (hits.t.to_array(), hits.prim.to_array());
            let (hu, hv) = (hits.u.to_array(), hits.v.to_array());
            let lu = rotate_x8(sobol_2d_x8(index), light_rot);
            let (lx, ly) = (to_unit_x8(lu[0]).to_array(), to_unit_x8(lu[1]).to_array());
            let light_u: [[f32; 2]; LANES] = core::array::from_fn(|i| [lx[i], ly[i]]);
            let samples: [u32; LANES] = core::array::from_fn(|i| chunk[i]);
            let mut direct_sh = [ShSample::default(); LANES];
            let sh = sinks.sh.is_some().then_some(&mut direct_sh);
            let direct = self.direct8(t, origin, &samples, &light_u, sh, true, counters);
            for lane in 0..LANES {
                let hit = (hprim[lane] != NO_HIT).then(|| SurfaceHit {
                    prim: hprim[lane],
                    t: ht[lane],
                    u: hu[lane],
                    v: hv[lane],
                });
                let from = Departure {
                    point: origin,
                    normal: t.normal,
                    pdf: q[lane] * dz[lane] * core::f32::consts::FRAC_1_PI,
                };
                let l = self.incoming(t.id, chunk[lane], &from, dirs[lane], hit, counters);
                let direct = (direct[lane], &direct_sh[lane]);
                let dir = (dirs[lane], dz[lane]);
                self.record(l, [wx[lane], wy[lane]], q[lane], dir, direct, sinks);
            }
        }
    }

    /// `n` unsorted points in index order, scalar warp, single rays: the naive comparator.
    pub(super) fn gather_naive(
        &self,
        t: &GatherTexel,
        n: u32,
        sinks: &mut Sinks<'_>,
        counters: &mut GatherCounters,
    ) {
        let rot = rotation(self.seed, t.id, self.k);
        let light_rot = rotation(self.seed ^ LIGHT_SALT, t.id, self.k);
        let bvh = self.world.wide_bvh();
        for j in 0..n / LANES as u32 {
            let origin = self.origin(t, j);
            let mut light_u = [[0.0; 2]; LANES];
            let mut samples = [(Leaving::default(), [0.0f32; 2], 1.0f32); LANES];
            let mut dirs = [(Vec3::Z, 1.0f32); LANES];
            // The packet's eight scalar warps first, timed together (the stats' warp time).
            let clock = self.warp_clock(j);
            let warped: [([f32; 2], f32); LANES] = core::array::from_fn(|lane| {
                let p = rotate(sobol_2d(j * LANES as u32 + lane as u32), rot);
                let u = [to_unit(p[0]), to_unit(p[1])];
                match self.guide {
                    Some(IterationGuide::Tree(g)) => {
                        let s = warp::sample(g, u);
                        (s.u, s.pdf)
                    }
                    Some(IterationGuide::Grid(g)) => g.sample(u),
                    None => (u, 1.0),
                }
            });
            count_warp(clock, counters);
            for (lane, &(w, q)) in warped.iter().enumerate() {
                let index = j * LANES as u32 + lane as u32;
                let local = sample_cosine_hemisphere(w);
                let dir = self.to_world(t, local);
                let hit = intersect1(&bvh, &Ray::new(origin, dir, 0.0, f32::INFINITY)).map(|h| {
                    SurfaceHit {
                        prim: h.prim,
                        t: h.t,
                        u: h.u,
                        v: h.v,
                    }
                });
                counters.gather_rays += 1;
                let from = Departure {
                    point: origin,
                    normal: t.normal,
                    pdf: q * local.z * core::f32::consts::FRAC_1_PI,
                };
                let l = self.incoming(t.id, index, &from, dir, hit, counters);
                let lp = rotate(sobol_2d(index), light_rot);
                light_u[lane] = [to_unit(lp[0]), to_unit(lp[1])];
                samples[lane] = (l, w, q);
                dirs[lane] = (dir, local.z);
            }
            let indices: [u32; LANES] = core::array::from_fn(|lane| j * LANES as u32 + lane as u32);
            let mut direct_sh = [ShSample::default(); LANES];
            let sh = sinks.sh.is_some().then_some(&mut direct_sh);
            let direct = self.direct8(t, origin, &indices, &light_u, sh, true, counters);
            for lane in 0..LANES {
                let (l, w, q) = samples[lane];
                let direct = (direct[lane], &direct_sh[lane]);
                self.record(l, w, q, dirs[lane], direct, sinks);
            }
        }
    }

    /// The direct pass's samples of this iteration at texel `t` into `batch`: next-event
    /// estimates alone, weighing 1 (no gather ray leaves the texel to weigh them against), from
    /// the origins and light samples the gather's packet `j` would use, sample `i` of the
    /// iteration taking the light sample of Sobol point `i`; `samples` of them: the
    /// iteration's share of `--direct-spp` ([`BakeSettings::direct_samples_in_iteration`]), or
    /// fewer where the stopping rule cut the iteration short ([`stopping::plan`]).
    pub(super) fn direct_alone(
        &self,
        t: &GatherTexel,
        samples: u32,
        batch: &mut Welford,
        counters: &mut GatherCounters,
    ) {
        let light_rot = rotation(self.seed ^ LIGHT_SALT, t.id, self.k);
        for j in 0..samples / LANES as u32 {
            let samples: [u32; LANES] = core::array::from_fn(|lane| j * LANES as u32 + lane as u32);
            let lu = rotate_x8(sobol_2d_x8(u32x8::new(samples)), light_rot);
            let (lx, ly) = (to_unit_x8(lu[0]).to_array(), to_unit_x8(lu[1]).to_array());
            let light_u: [[f32; 2]; LANES] = core::array::from_fn(|i| [lx[i], ly[i]]);
            let origin = self.origin(t, j);
            let direct = self.direct8(t, origin, &samples, &light_u, None, false, counters);
            for d in direct {
                batch.push(d.to_array());
            }
        }
    }

    /// Next-event estimation at the texel for one packet's eight samples (shared origin,
    /// sample indices `samples`), weighted against the gather's own density by MIS when `mis`
    /// (else weighing 1), counting the shadow rays.
    #[allow(clippy::too_many_arguments)]
    fn direct8(
        &self,
        t: &GatherTexel,
        origin: Vec3,
        samples: &[u32],
        light_u: &[[f32; 2]; LANES],
        sh: Option<&mut [ShSample; LANES]>,
        mis: bool,
        counters: &mut GatherCounters,
    ) -> [Vec3; LANES] {
        let mut direct = [Vec3::ZERO; LANES];
        if !self.world.has_direct_light() || !self.texel_direct {
            return direct;
        }
        let pick: [f32; LANES] = core::array::from_fn(|lane| {
            let seed = self.seed ^ EMITTER_SALT;
            SampleRng::new(seed, t.id, self.k, samples[lane]).unit()
        });
        let gather_pdf8 = |dirs: &[Vec3; LANES], live: u8| self.gather_pdf8(t, dirs, live);
        let at = Receiver8 {
            point: origin,
            normal: t.normal,
            other: mis.then_some(&gather_pdf8 as _),
        };
        let rays = self
            .world
            .direct_irradiance8_projected(&at, light_u, &pick, &mut direct, sh);
        counters.shadow_rays += u64::from(rays);
        direct
    }

    /// The solid-angle density with which this iteration's gather at texel `t` samples the
    /// world direction `dir`: [`Self::sampled_density`] (the mixture's density on the
    /// primary sample square at the point the cosine map sends to `dir`; 1 unguided) times
    /// `cosθ / π`.
    #[cfg(test)]
    pub(super) fn gather_pdf(&self, t: &GatherTexel, dir: Vec3) -> f32 {
        let cos = dir.dot(t.normal);
        if cos <= 0.0 {
            return 0.0;
        }
        self.sampled_density(t, dir) * cos * core::f32::consts::FRAC_1_PI
    }

    /// [`Self::gather_pdf`] for the directions of the lanes of `live` (the others are 0),
    /// the same bits: the inverse cosine map and the guide lookup run 8-wide
    /// (`invert_cosine_hemisphere_x8`, `warp::pdf8`), the rest per lane as in the scalar
    /// version.
    pub(super) fn gather_pdf8(
        &self,
        t: &GatherTexel,
        dirs: &[Vec3; LANES],
        live: u8,
    ) -> [f32; LANES] {
        let local: [Vec3; LANES] = core::array::from_fn(|lane| {
            let d = dirs[lane];
            let l = Vec3::new(d.dot(t.tangent), d.dot(t.bitangent), d.dot(t.normal));
            if live >> lane & 1 == 1 && l.z > 0.0 {
                l
            } else {
                Vec3::ZERO
            }
        });
        let q: [f32; LANES] = match self.guide {
            None => [1.0; LANES],
            Some(guide) => {
                let unit = local.map(|l| if l.z > 0.0 { l.normalize() } else { Vec3::Z });
                let w = [0, 1, 2].map(|axis| f32x8::new(unit.map(|u| u[axis])));
                let [x, y] = invert_cosine_hemisphere_x8(w);
                match guide {
                    IterationGuide::Tree(g) => warp::pdf8(g, x, y).to_array(),
                    IterationGuide::Grid(g) => {
                        let (x, y) = (x.to_array(), y.to_array());
                        core::array::from_fn(|lane| g.pdf([x[lane], y[lane]]))
                    }
                }
            }
        };
        core::array::from_fn(|lane| {
            let cos = dirs[lane].dot(t.normal);
            if local[lane].z <= 0.0 || cos <= 0.0 {
                return 0.0;
            }
            q[lane] * cos * core::f32::consts::FRAC_1_PI
        })
    }

    /// What arrives along `dir` at the ray's origin `from`: the sky on a miss, else what
    /// leaves the hit.
    fn incoming(
        &self,
        texel: u64,
        sample: u32,
        from: &Departure,
        dir: Vec3,
        hit: Option<SurfaceHit>,
        counters: &mut GatherCounters,
    ) -> Leaving {
        match hit {
            None => Leaving {
                reflected: self.world.sky(dir),
                ..Leaving::default()
            },
            Some(hit) => {
                let mut rng = SampleRng::new(self.seed, texel, self.k, sample);
                let leaving = self.world.radiance_from_hit(from, dir, hit, &mut rng);
                counters.shadow_rays += u64::from(leaving.shadow_rays);
                counters.path_rays += u64::from(leaving.path_rays);
                counters.series_totals_read += u64::from(leaving.totals_read);
                leaving
            }
        }
    }

    /// One sample into the texel's estimator (irradiance `L π / q` + direct light), its
    /// gather-only channel (what series passes look up: the light the hit sends, without the
    /// direct light of emitters that next-event estimation connects at the hits) and the
    /// cluster's learning records (point and flux `lum(L) / q`). `(dir, cos)`: the gather
    /// direction and its cosine to the texel's normal; `direct`: the next-event estimate and
    /// its projection, for the directional coefficients (only of a sample the batch accepts).
    fn record(
        &self,
        l: Leaving,
        w: [f32; 2],
        q: f32,
        (dir, cos): (Vec3, f32),
        (direct, direct_sh): (Vec3, &ShSample),
        sinks: &mut Sinks<'_>,
    ) {
        let scale = core::f32::consts::PI / q;
        let indirect = if self.world.emitters().is_some() {
            l.reflected
        } else {
            l.reflected + l.emitted
        };
        sinks.gathered.push((indirect * scale).to_array());
        let radiance = l.emitted + l.reflected;
        // Without the texel's next-event estimate, the emission its rays hit (weighted
        // against it) is left out too: the sample is the gathered light alone.
        let sample = if self.texel_direct {
            radiance * scale + direct
        } else {
            indirect * scale
        };
        sinks.batch.push(sample.to_array());
        if let Some(sh) = sinks.sh.as_deref_mut()
            && sample.is_finite()
        {
            let mut projected = *direct_sh;
            directional::add_irradiance_sample(&mut projected, radiance * scale, dir, cos);
            sh.add(&projected);
        }
        // The guide learns what the sample estimates: without the texel's next-event
        // estimate, the emission the rays hit is not part of it, and sampling towards it
        // would be wasted.
        let learned = if self.texel_direct {
            radiance
        } else {
            indirect
        };
        let flux = luminance_f32(learned.to_array()) / q;
        if let Some(learning) = sinks.learning.as_deref_mut()
            && flux.is_finite()
        {
            learning.push(Record { u: w, flux }, q);
        }
    }
}
