//! The guided final gather of one tile (paper §2.1–2.5): cluster its texels, run K learning
//! iterations per cluster, combine each texel's iterations.
//!
//! For every cluster, iteration 0 gathers with the unguided cosine-weighted baseline; after
//! each iteration the cluster's samples (point u on the primary sample square, flux
//! `L / q(u)`) build the guide the next iteration samples from. A gather sample at a texel
//! with normal n estimates its irradiance as `L · π / q(u)`: the square maps to the
//! hemisphere with density `cosθ/π`, so a guide density `q` on the square gives
//! `p(ω) = q(u) cosθ/π` and `L cosθ / p(ω) = L π / q(u)`. Next-event estimation of the
//! analytic lights is added to each sample with its own stratified light sample.
//!
//! Direction modes ([`Guiding`]):
//! - `off` and `coherent`: each texel's presorted Sobol packets (paper §2.4, Figure 3),
//!   rotated per texel and iteration and reordered so the wrap keeps packets coherent; warped
//!   8-wide (`coherent`), traced as packets sharing one origin.
//! - `naive`: the same guide, sampled one point at a time from the Sobol points in index
//!   order, warped by the scalar warp and traced as single rays.
//!
//! A cluster whose learning saw no energy, or whose learned guide is uniform, keeps the
//! unguided baseline (no warping cost), and the skip is counted. Every random number derives
//! from (seed, texel id, iteration, sample index), so a tile's bits never depend on the thread
//! that baked it.

use std::collections::HashMap;

use glam::Vec3;
use guidebake_kernels::cluster::{ClusterParams, ClusterRange, build_clusters};
use guidebake_kernels::estimator::Welford;
use guidebake_kernels::guide::GuideNode;
use guidebake_kernels::presort::presorted;

use super::budget;
use super::directional::{Directional, ShL1, ShSums};
use super::grid::{self as grid_guide};
use super::pipeline::{TileBaked, TileBuffer};
use super::settings::{BakeSettings, Combine, Guiding};
use crate::output::journal::TileRecord;
use crate::output::result_file::TexelResult;
use crate::texels::{FLAG_INSIDE as TEXEL_INSIDE, FLAG_VALID as TEXEL_VALID, TexelRecord};
use crate::transport::world::World;

mod cluster;
mod combine;
mod counters;
mod iteration;
mod learning;
#[cfg(test)]
mod tests;

pub use counters::GatherCounters;

#[cfg(test)]
use cluster::texel_basis;
use counters::{WARP_TIMED_EVERY, count_warp};
use iteration::{IterationCtx, Sinks};
use learning::{
    GuideRecords, IterationGuide, SeedHistogram, grid_sample8, is_flat, learn, learn_grid,
    seeded_guide,
};

/// Guide nodes per cluster: enough for a 64-texel cluster's records at the default split rule.
pub const GUIDE_CAPACITY: usize = 4096;
/// The guide's ambient floor when a defensive mixture samples it (`--mix` > 0): the cosine
/// share already bounds every sample's weight, so the guide need not spend a tenth of its
/// mass on directions where learning saw nothing (measured on the small emitter: with
/// 64-record splits, α = 10 % and a 25 % mixture, the floor 0.1 gives 6.6× less variance per
/// guided sample than cosine, 0.02 gives 15–20×).
pub const MIXED_AMBIENT: f32 = 0.02;
/// Salts separating the random streams of one (texel, iteration).
const LIGHT_SALT: u32 = 0x6c69_6768;
const EMITTER_SALT: u32 = 0x656d_6974;
const ORIGIN_SALT: u32 = 0x6f72_6967;
/// Salts the random streams of the pass that keeps guide seeds
/// ([`TileBaker::writes_guide_seeds`]), so the last pass's points are independent of them.
const GUIDE_SEED_SALT: u32 = 0x7365_6564;

/// One worker's tile baker: fixed buffers reused tile after tile.
pub struct TileBaker<'w> {
    world: &'w World,
    settings: BakeSettings,
    /// The presorted Sobol order of each sample count a texel's iteration takes (the
    /// iterations' own, and those the spatial budget scales them to).
    orders: HashMap<u32, Vec<u32>>,
    /// Per valid texel: the spatial budget's factor ([`World::budget_factor`]).
    factors: Vec<f32>,
    rotated: Vec<u32>,
    /// The cluster's learning records of the current iteration.
    learning: GuideRecords,
    nodes: Vec<GuideNode>,
    /// Scratch the guide build's sort scatters through when the records outgrow `nodes`
    /// (`guide::sort_room`); grown to the largest pool the worker has met.
    sort_room: Vec<GuideNode>,
    /// Per valid texel and iteration: the weight of `--combine cluster`.
    weights: Vec<f64>,
    batches: Vec<Welford>,
    /// Per valid texel: its gather-only samples `L π / q` (all iterations), the series
    /// transport's indirect irradiance for the next pass.
    gathered: Vec<Welford>,
    /// Per valid texel and iteration: its samples' spherical-harmonic projections, when the
    /// bake keeps directional coefficients ([`Self::keep_directional`]).
    sh: Vec<ShSums>,
    keep_directional: bool,
    /// Series transport's direct pass ([`Self::direct_only`]).
    direct_only: bool,
    /// Whether each sample includes the texel's next-event estimate ([`Self::texel_direct`]).
    texel_direct: bool,
    /// Whether the tiles keep their clusters' guide seeds ([`Self::writes_guide_seeds`]).
    writes_guide_seeds: bool,
    /// The seed the gather's random numbers derive from ([`Self::stream_seed`]).
    stream_seed: u32,
    /// Per valid texel: its cell of its cluster's guide seed, when kept.
    seeds: Vec<f32>,
    valid: Vec<u32>,
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    permutation: Vec<u32>,
    ranges: Vec<ClusterRange>,
    unguided: Vec<bool>,
    /// This worker's counts.
    pub counters: GatherCounters,
}

/// A texel as the gather needs it.
#[derive(Clone, Copy, Debug)]
struct GatherTexel {
    id: u64,
    position: Vec3,
    normal: Vec3,
    tangent: Vec3,
    bitangent: Vec3,
    dpdu: Vec3,
    dpdv: Vec3,
    jitter: bool,
    triangle: u32,
}

impl<'w> TileBaker<'w> {
    /// A baker for `world` with `settings` (already validated).
    pub fn new(world: &'w World, settings: BakeSettings) -> Self {
        let orders = (0..settings.iterations)
            .map(|k| settings.samples_in_iteration(k))
            .map(|n| (n, if n == 0 { Vec::new() } else { presorted(n) }))
            .collect();
        Self {
            world,
            settings,
            orders,
            factors: Vec::new(),
            rotated: Vec::new(),
            learning: GuideRecords::default(),
            nodes: vec![GuideNode::default(); GUIDE_CAPACITY],
            sort_room: Vec::new(),
            weights: Vec::new(),
            batches: Vec::new(),
            gathered: Vec::new(),
            sh: Vec::new(),
            keep_directional: false,
            direct_only: false,
            texel_direct: true,
            writes_guide_seeds: false,
            stream_seed: settings.seed,
            seeds: Vec::new(),
            valid: Vec::new(),
            positions: Vec::new(),
            normals: Vec::new(),
            permutation: Vec::new(),
            ranges: Vec::new(),
            unguided: Vec::new(),
            counters: GatherCounters::default(),
        }
    }

    /// Keeps each texel's directional coefficients in this baker's tiles (`--directional
    /// sh-l1`, the last pass: earlier series passes feed only the irradiance forward).
    pub fn keep_directional(mut self, keep: bool) -> Self {
        self.keep_directional = keep && self.settings.directional == Directional::ShL1;
        self
    }

    /// Bakes each texel's direct light alone (series transport's
    /// [`DIRECT_PASS`](super::settings::DIRECT_PASS)): next-event estimation with the
    /// iterations' sample counts, no gather rays, no clusters, no guide. Pass 1's gather hits
    /// read it as the previous pass's total, where they would otherwise trace a shadow ray.
    pub fn direct_only(mut self, direct_only: bool) -> Self {
        self.direct_only = direct_only;
        self
    }

    /// Whether the texels' samples include their own next-event estimate (the default). A
    /// series pass that borrows the direct pass's
    /// ([`BakeSettings::borrows_direct`](super::settings::BakeSettings::borrows_direct))
    /// leaves it out: its samples are the gathered light alone, no shadow ray at the texel.
    pub fn texel_direct(mut self, texel_direct: bool) -> Self {
        self.texel_direct = texel_direct;
        self
    }

    /// Keeps each cluster's guide seed in its texels' results ([`TexelResult::seed`]): the
    /// pass before a guided last pass
    /// ([`BakeSettings::writes_guide_seeds`](super::settings::BakeSettings::writes_guide_seeds)).
    /// The last pass reads them through [`World::guide_seed`]. Such a pass draws its random
    /// numbers from another stream ([`GUIDE_SEED_SALT`]): every pass of a bake rotates a
    /// texel's points alike, and a seed learned from the very points the last pass then warps
    /// through it would bias that pass (measured along a room's corner, `tests/surfaces.rs`).
    /// The settings keep the bake's `--seed`; [`Self::stream_seed`] says which stream the
    /// baker draws from.
    pub fn writes_guide_seeds(mut self, writes: bool) -> Self {
        self.writes_guide_seeds = writes;
        self.stream_seed = if writes {
            self.settings.seed ^ GUIDE_SEED_SALT
        } else {
            self.settings.seed
        };
        self
    }

    /// The seed every random number of this baker derives from (with the texel, iteration
    /// and sample): the bake's `--seed`, or, in a pass that keeps guide seeds
    /// ([`Self::writes_guide_seeds`]), `--seed` salted with [`GUIDE_SEED_SALT`].
    pub fn stream_seed(&self) -> u32 {
        self.stream_seed
    }

    /// Bakes tile `tile` whose texels (`texels`, global ids from `first_texel`) are given;
    /// writes one result per texel into `out` (and, for `--combine global`, every texel's K
    /// batches) and returns the tile's journal data.
    pub fn bake_tile(
        &mut self,
        tile: u32,
        first_texel: u64,
        texels: &[TexelRecord],
        out: &mut TileBuffer,
    ) -> TileBaked {
        out.results.clear();
        out.results.resize(texels.len(), TexelResult::default());
        out.batches.clear();
        out.directional.clear();
        let k = self.settings.iterations as usize;
        if self.settings.combine == Combine::Global {
            out.batches.resize(texels.len() * k, Welford::new());
        }
        if self.keep_directional {
            let per_texel = if self.settings.combine == Combine::Global {
                k
            } else {
                1
            };
            out.directional
                .resize(texels.len() * per_texel, ShL1::default());
        }
        self.collect_valid(texels);
        let clusters = if self.direct_only {
            0
        } else if self.settings.guiding == Guiding::Grid {
            self.grid_squares(texels)
        } else {
            self.cluster()
        };
        self.batches.clear();
        self.batches.resize(self.valid.len() * k, Welford::new());
        self.weights.clear();
        self.weights.resize(self.valid.len() * k, 1.0);
        self.gathered.clear();
        self.gathered.resize(self.valid.len(), Welford::new());
        self.sh.clear();
        if self.keep_directional {
            self.sh.resize(self.valid.len() * k, ShSums::default());
        }
        self.unguided.clear();
        self.unguided.resize(self.valid.len(), true);
        self.seeds.clear();
        self.seeds.resize(self.valid.len(), 0.0);
        let rays_before = self.counters.rays();
        for c in 0..clusters {
            let range = self.ranges[c];
            let members: Vec<u32> =
                self.permutation[range.start as usize..range.end as usize].to_vec();
            self.bake_cluster(&members, texels, first_texel);
        }
        if self.direct_only {
            self.bake_direct(texels, first_texel);
        }
        let record = self.finish_tile(tile, out);
        let rays = self.counters.rays() - rays_before;
        TileBaked {
            first_texel,
            record: TileRecord { rays, ..record },
        }
    }

    fn collect_valid(&mut self, texels: &[TexelRecord]) {
        self.valid.clear();
        self.factors.clear();
        self.positions.clear();
        self.normals.clear();
        for (i, t) in texels.iter().enumerate() {
            if t.flags & TEXEL_VALID != 0 {
                self.valid.push(i as u32);
                self.positions.push(t.position);
                self.normals.push(t.normal);
                let factor = self.world.budget_factor(t.page, t.pixel.map(u32::from));
                self.factors.push(factor);
                if factor != 1.0 {
                    for k in 0..self.settings.iterations {
                        let n = budget::scaled(self.settings.samples_in_iteration(k), factor);
                        self.orders.entry(n).or_insert_with(|| presorted(n));
                    }
                }
            } else {
                self.counters.texels_invalid_skipped += 1;
                self.counters.texels_inside_geometry += u64::from(t.flags & TEXEL_INSIDE != 0);
            }
        }
    }

    /// Clusters the valid texels (paper §2.1); returns the number of clusters. The texel file
    /// was validated on open (finite positions, unit normals), so clustering cannot fail on
    /// its input; should it anyway, every texel becomes its own cluster.
    fn cluster(&mut self) -> usize {
        let n = self.valid.len();
        self.permutation.resize(n, 0);
        self.ranges.resize(n.max(1), ClusterRange::default());
        match build_clusters(
            &self.positions,
            &self.normals,
            &ClusterParams::default(),
            &mut self.permutation,
            &mut self.ranges,
        ) {
            Ok(count) => count,
            Err(_) => {
                for i in 0..n {
                    self.permutation[i] = i as u32;
                    self.ranges[i] = ClusterRange {
                        start: i as u32,
                        end: i as u32 + 1,
                    };
                }
                n
            }
        }
    }

    /// The grid comparator's learning groups: the valid texels of each 8×8-texel square of
    /// the atlas ([`grid_guide::SQUARE`]); returns the number of groups.
    fn grid_squares(&mut self, texels: &[TexelRecord]) -> usize {
        let key = |i: u32| {
            let t = &texels[i as usize];
            let s = grid_guide::SQUARE;
            (t.page, t.pixel[1] / s, t.pixel[0] / s)
        };
        let n = self.valid.len();
        self.permutation.clear();
        self.permutation.extend(0..n as u32);
        let valid = &self.valid;
        self.permutation.sort_by_key(|&m| key(valid[m as usize]));
        self.ranges.clear();
        let mut start = 0;
        for end in 1..=n {
            let same = end < n
                && key(valid[self.permutation[end] as usize])
                    == key(valid[self.permutation[start] as usize]);
            if !same {
                self.ranges.push(ClusterRange {
                    start: start as u32,
                    end: end as u32,
                });
                start = end;
            }
        }
        self.ranges.len()
    }
}
