//! One cluster's K learning iterations (paper §2.1–2.2): the cluster's frame, each
//! iteration gathered with the guide the last one learned (or cosine points, or the seed
//! the pass before kept), the stopping rule between iterations; and the direct pass's tile,
//! next-event estimation alone.

use std::time::Instant;

use glam::Vec3;
use guidebake_kernels::estimator::{cluster_weights, pooled};
use guidebake_kernels::guide::{self, Guide, GuideParams};
use guidebake_kernels::mapping::{carried_frame, orthonormal_basis};
use guidebake_kernels::presort::presorted;

use crate::bake::budget;
use crate::bake::grid::GridGuide;
use crate::bake::settings::{Budget, Combine, GuideTarget, Guiding, MAX_ITERATIONS};
use crate::bake::stopping::{self, Plan};
use crate::texels::{FLAG_PARTIAL, TexelRecord};

use super::*;

impl<'w> TileBaker<'w> {
    /// K learning iterations over one cluster; `members` index `self.valid`.
    pub(super) fn bake_cluster(
        &mut self,
        members: &[u32],
        texels: &[TexelRecord],
        first_texel: u64,
    ) {
        let Self {
            world,
            settings,
            orders,
            rotated,
            learning,
            nodes,
            sort_room,
            batches,
            weights,
            gathered,
            sh,
            valid,
            factors,
            unguided,
            counters,
            texel_direct,
            writes_guide_seeds,
            stream_seed,
            seeds,
            ..
        } = self;
        counters.clusters += 1;
        let iterations = settings.iterations;
        let mut guide: Option<Guide<'_>> = None;
        let mut grid: Option<GridGuide> = None;
        let frame = cluster_frame(members.iter().map(|&m| {
            let t = &texels[valid[m as usize] as usize];
            Vec3::from(t.normal)
        }));
        let params = GuideParams {
            min_records: settings.min_split,
            alpha: settings.smooth as f32 / 100.0,
            // With a mixture the cosine share is the defence: the guide's own floor drops.
            ambient: if settings.mix > 0 {
                MIXED_AMBIENT
            } else {
                guide::DEFAULT_AMBIENT
            },
            uniform: settings.uniform_share(),
            second_moment: settings.guide_target == GuideTarget::SecondMoment,
            ..GuideParams::default()
        };
        // Once the guide a cluster sampled shows too little gain (`--min-gain`), the cluster
        // gathers with cosine points for the rest of its iterations and stops learning.
        let mut stopped = false;
        // The stopping rule's last iteration, cut to the samples it still needs (`--target-error`).
        let mut cut: Option<u32> = None;
        let guides = matches!(settings.guiding, Guiding::Coherent | Guiding::Naive);
        // Where the pass before measured this cluster's light as flat, cosine points are
        // already (nearly) exact: no guide, seeded or learned (`--flat-below`).
        let flat = guides
            && world.reads_guide_seeds()
            && is_flat(
                members.iter().filter_map(|&m| {
                    world.seeding_result(first_texel + u64::from(valid[m as usize]))
                }),
                settings.flat_below,
            );
        counters.clusters_flat += u64::from(flat);
        // The pass before kept this cluster's seed: its first iteration samples a guide too.
        if world.reads_guide_seeds() && guides && !flat {
            let cells = members.iter().map(|&m| {
                let id = first_texel + u64::from(valid[m as usize]);
                world.guide_seed(id).unwrap_or(0.0)
            });
            let clock = Instant::now();
            guide = seeded_guide(cells, learning, &params, nodes);
            counters.clusters_seeded += u64::from(guide.is_some());
            counters.guide_build_ns += clock.elapsed().as_nanos() as u64;
        }
        let mut seed = writes_guide_seeds.then(|| SeedHistogram::new(members.len()));
        learning.pool.clear();
        // A flat cluster learns nothing from its iterations: it bakes them in one set of all
        // their samples, stratified over the whole hemisphere as the unguided bake's pass is
        // (docs/guiding-on-levels.md, "One set where the light is flat").
        // (Not under `--target-error`: its stopping rule judges between iterations.)
        let one_set = (flat && settings.target_error.is_none()).then(|| {
            (0..iterations)
                .map(|k| settings.samples_in_iteration(k))
                .sum()
        });
        if flat {
            counters.iterations_unguided_flat += u64::from(iterations - 1);
        }
        for k in 0..iterations {
            learning.clear();
            if stopped {
                counters.iterations_unguided_no_gain += 1;
            }
            let learns = !flat
                && !stopped
                && cut.is_none()
                && k + 1 < iterations
                && settings.guiding != Guiding::Off;
            let nominal =
                one_set.unwrap_or_else(|| cut.unwrap_or_else(|| settings.samples_in_iteration(k)));
            for &m in members {
                let i = valid[m as usize];
                let t = gather_texel(&texels[i as usize], first_texel + u64::from(i), frame);
                let learned = match (&guide, &grid) {
                    (Some(g), _) => Some(IterationGuide::Tree(g)),
                    (None, Some(g)) => Some(IterationGuide::Grid(g)),
                    (None, None) => None,
                };
                if learned.is_some() {
                    unguided[m as usize] = false;
                }
                let at = m as usize * iterations as usize + k as usize;
                let mut sinks = Sinks {
                    batch: &mut batches[at],
                    gathered: &mut gathered[m as usize],
                    sh: sh.get_mut(at),
                    learning: (learns || seed.is_some()).then_some(&mut *learning),
                };
                let ctx = IterationCtx {
                    texel_direct: *texel_direct,
                    seed: *stream_seed,
                    ..IterationCtx::new(world, settings, k, learned)
                };
                let n = budget::scaled(nominal, factors[m as usize]);
                match settings.guiding {
                    Guiding::Naive => ctx.gather_naive(&t, n, &mut sinks, counters),
                    Guiding::Off | Guiding::Coherent | Guiding::Grid => {
                        let order = orders.entry(n).or_insert_with(|| presorted(n));
                        ctx.gather_packets(&t, order, rotated, &mut sinks, counters);
                    }
                }
            }
            if let Some(seed) = &mut seed {
                seed.add(learning, params.second_moment);
            }
            if one_set.is_some() {
                break;
            }
            if cut.is_some() {
                counters.texel_iterations_stopped +=
                    members.len() as u64 * u64::from(iterations - k - 1);
                break;
            }
            if let Some(target) = settings
                .target_error
                .filter(|_| k > 0 && k + 1 < iterations)
            {
                let n = iterations as usize;
                // A texel that borrows its direct light holds it besides its samples.
                let borrowed = world.previous_pass().filter(|_| !*texel_direct);
                let rows = members.iter().map(|&m| {
                    let t = &texels[valid[m as usize] as usize];
                    let besides = borrowed.map_or(0.0, |p| {
                        p.direct_luminance_at(t.page, t.pixel.map(u32::from))
                    });
                    (
                        &batches[m as usize * n..(m as usize + 1) * n],
                        f64::from(besides),
                    )
                });
                let taken = (0..=k).map(|j| settings.samples_in_iteration(j)).sum();
                let next = settings.samples_in_iteration(k + 1);
                match stopping::plan(rows, k as usize, target, taken, next) {
                    Plan::Stop => {
                        counters.texel_iterations_stopped +=
                            members.len() as u64 * u64::from(iterations - k - 1);
                        break;
                    }
                    Plan::Last(n) => cut = Some(n),
                    Plan::Go => {}
                }
            }
            if learns {
                let clock = Instant::now();
                match settings.guiding {
                    Guiding::Off => {}
                    Guiding::Grid => {
                        grid = learn_grid(&learning.records, settings.uniform_share(), counters);
                    }
                    Guiding::Naive | Guiding::Coherent => {
                        // The guide this iteration sampled, judged by its own records: below
                        // `--min-gain` the cluster gathers with cosine points from now on.
                        let sampled = guide.is_some();
                        if sampled
                            && settings.min_gain > 0
                            && learning.gain() * 100.0 < f64::from(settings.min_gain)
                        {
                            guide = None;
                            stopped = true;
                        } else {
                            if params.second_moment {
                                learning.square_fluxes();
                            }
                            let records = learning.pooled(sampled);
                            guide = learn(records, &params, nodes, sort_room, counters);
                        }
                    }
                }
                counters.guide_build_ns += clock.elapsed().as_nanos() as u64;
            }
        }
        if let Some(seed) = seed {
            for (&m, cell) in members.iter().zip(seed.cells()) {
                seeds[m as usize] = cell;
            }
        }
        if settings.combine == Combine::Cluster {
            cluster_weights::<MAX_ITERATIONS>(members, batches, iterations as usize, weights);
        }
    }

    /// The direct pass over the tile's valid texels ([`Self::direct_only`]): each iteration's
    /// samples are next-event estimates alone, in the batch a gather's would fill; with
    /// `--target-error` the tile's texels stop together once their estimates are within it
    /// ([`stopping`]).
    pub(super) fn bake_direct(&mut self, texels: &[TexelRecord], first_texel: u64) {
        let settings = self.settings;
        let n = settings.iterations as usize;
        let targets: Vec<GatherTexel> = self
            .valid
            .iter()
            .map(|&i| {
                let record = &texels[i as usize];
                let frame = cluster_frame(std::iter::once(Vec3::from(record.normal)));
                gather_texel(record, first_texel + u64::from(i), frame)
            })
            .collect();
        let mut cut: Option<u32> = None;
        // The direct budget: the later half of the iterations by the earlier half's error.
        let pilot = (settings.budget != Budget::Uniform && settings.target_error.is_none())
            .then_some(n / 2)
            .filter(|&p| p > 0);
        let mut factors: Option<Vec<f32>> = None;
        for k in 0..n {
            let ctx = IterationCtx {
                seed: self.stream_seed,
                ..IterationCtx::new(self.world, &settings, k as u32, None)
            };
            let samples = cut.unwrap_or_else(|| settings.direct_samples_in_iteration(k as u32));
            for (m, t) in targets.iter().enumerate() {
                let batch = &mut self.batches[m * n + k];
                let own = factors
                    .as_ref()
                    .map_or(samples, |f| budget::scaled(samples, f[m]));
                ctx.direct_alone(t, own, batch, &mut self.counters);
            }
            if pilot == Some(k + 1) {
                factors = self.direct_budget(texels, k + 1);
            }
            let stop = match settings.target_error.filter(|_| k > 0 && k + 1 < n) {
                _ if cut.is_some() => Plan::Stop,
                None => Plan::Go,
                Some(target) => {
                    let target = stopping::share_of(target, settings.lightmap_borrows_direct());
                    let rows = self.batches.chunks_exact(n).map(|row| (row, 0.0));
                    let taken = (0..=k as u32)
                        .map(|j| settings.direct_samples_in_iteration(j))
                        .sum();
                    let next = settings.direct_samples_in_iteration(k as u32 + 1);
                    stopping::plan(rows, k, target, taken, next)
                }
            };
            match stop {
                Plan::Stop => {
                    self.counters.texel_iterations_stopped += (targets.len() * (n - k - 1)) as u64;
                    break;
                }
                Plan::Last(samples) => cut = Some(samples),
                Plan::Go => {}
            }
        }
    }

    /// The direct pass's factors for this tile's valid texels from their first `iterations`
    /// iterations (each texel's samples pooled: its per-sample variance and mean luminance),
    /// by the bake's `--budget` normalised over the tile ([`budget::tile_factors`]).
    fn direct_budget(&self, texels: &[TexelRecord], iterations: usize) -> Option<Vec<f32>> {
        let n = self.settings.iterations as usize;
        let measured: Vec<budget::Measured> = self
            .valid
            .iter()
            .enumerate()
            .map(|(m, &i)| {
                let record = &texels[i as usize];
                let pooled = pooled(&self.batches[m * n..m * n + iterations]);
                budget::Measured {
                    page: record.page,
                    pixel: record.pixel.map(u32::from),
                    variance: pooled.luminance_variance().unwrap_or(0.0),
                    mean: pooled.mean_luminance().unwrap_or(0.0),
                }
            })
            .collect();
        budget::tile_factors(self.settings.budget, &measured)
    }
}

/// A cluster's frame: its mean normal and that normal's tangent (the mean of unit normals
/// within 60° of each other is never zero; should it be, +z).
pub(super) fn cluster_frame(normals: impl Iterator<Item = Vec3>) -> (Vec3, Vec3) {
    let mean = normals.sum::<Vec3>().normalize_or(Vec3::Z);
    (mean, orthonormal_basis(mean).0)
}

/// The per-texel frame as it was before the cluster frame: the sign of n.z by `copysign`,
/// so −0 and +0 flip the frame (the test of the fix shows the flip).
#[cfg(test)]
pub(super) fn texel_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let bt = Vec3::new(b, sign + n.y * n.y * a, -n.y);
    (t, bt)
}

/// A texel of a cluster whose frame is `(mean normal, its tangent)`: the cluster's frame
/// carried to the texel's normal by the minimal rotation.
pub(super) fn gather_texel(t: &TexelRecord, id: u64, (mean, tangent): (Vec3, Vec3)) -> GatherTexel {
    let normal = Vec3::from(t.normal);
    let (tangent, bitangent) = carried_frame(tangent, mean, normal);
    GatherTexel {
        id,
        position: Vec3::from(t.position),
        normal,
        tangent,
        bitangent,
        dpdu: Vec3::from(t.dpdu),
        dpdv: Vec3::from(t.dpdv),
        jitter: t.flags & FLAG_PARTIAL == 0,
        triangle: t.triangle,
    }
}
