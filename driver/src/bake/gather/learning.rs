//! What a cluster learns between iterations (paper §2.2–2.3): the guide built from the
//! records ([`learn`]; the grid comparator's, [`learn_grid`]) and the one the next iteration
//! samples ([`IterationGuide`]), the records pooled since the last cosine iteration and the
//! gain `--min-gain` judges ([`GuideRecords`]), the guide seed the pass before the last keeps
//! ([`SeedHistogram`], [`seeded_guide`]), and whether the pass before measured a cluster's
//! light as flat ([`is_flat`]).

use guidebake_kernels::guide::{self, Guide, GuideNode, GuideParams, Record};
use guidebake_kernels::packet::LANES;
use wide::f32x8;

use crate::bake::budget;
use crate::bake::grid::GridGuide;
use crate::output::result_file::{FLAG_BAKED, TexelResult};

use super::*;

/// Builds the next iteration's guide from this iteration's records; `None` when the cluster
/// should stay unguided (no energy seen, or a uniform guide), which is counted. Where the
/// records outgrow `nodes` as the sort's scratch, `room` grows to hold it: sorted in place,
/// the builds took 1.2–1.5× as long at 1 024 spp (docs/guide.md, "The build").
pub(super) fn learn<'n>(
    records: &mut [Record],
    params: &GuideParams,
    nodes: &'n mut [GuideNode],
    room: &mut Vec<GuideNode>,
    counters: &mut GatherCounters,
) -> Option<Guide<'n>> {
    let needed = guide::sort_room(records.len());
    if needed > nodes.len() && needed > room.len() {
        room.resize(needed, GuideNode::default());
    }
    let (learned, stats) = guide::build_in(records, params, nodes, room);
    if stats.total_flux.is_nan() || stats.total_flux <= 0.0 {
        counters.iterations_unguided_no_energy += 1;
        None
    } else if learned.is_uniform() {
        counters.iterations_unguided_uniform_guide += 1;
        None
    } else {
        counters.iterations_guided += 1;
        Some(learned)
    }
}

/// The first guide of a cluster whose texels hold a guide seed (`cells`: each texel's cell, in
/// the cluster's texel order, [`SeedHistogram::cells`]): one record at the centre of each lit
/// cell, split down to the cells (one record a node suffices: each stands for all the records
/// of its cell). `None` for a cluster too small to hold a seed, or where the seed saw no light
/// or gives a uniform guide: the first iteration gathers with cosine points.
pub(super) fn seeded_guide<'n>(
    cells: impl ExactSizeIterator<Item = f32>,
    learning: &mut GuideRecords,
    params: &GuideParams,
    nodes: &'n mut [GuideNode],
) -> Option<Guide<'n>> {
    let side = seed_side(cells.len());
    if side == 0 {
        return None;
    }
    learning.clear();
    let centre = |i: usize| (i as f32 + 0.5) / side as f32;
    for (j, flux) in cells.take(side * side).enumerate() {
        if flux > 0.0 && flux.is_finite() {
            let u = [centre(j % side), centre(j / side)];
            learning.push(Record { u, flux }, 1.0);
        }
    }
    let params = GuideParams {
        min_records: 1,
        max_depth: side.trailing_zeros(),
        ..*params
    };
    let (seeded, stats) = guide::build(&mut learning.records, &params, nodes);
    (stats.total_flux > 0.0 && !seeded.is_uniform()).then_some(seeded)
}

/// The grid comparator's next guide, mixed with the uniform density by `uniform` (`None`,
/// counted, when learning saw no energy).
pub(super) fn learn_grid(
    records: &[Record],
    uniform: f32,
    counters: &mut GatherCounters,
) -> Option<GridGuide> {
    let grid = GridGuide::learn(records, uniform);
    if grid.is_some() {
        counters.iterations_guided += 1;
    } else {
        counters.iterations_unguided_no_energy += 1;
    }
    grid
}

/// The grid warp of eight points, one lane at a time (the comparator has no 8-wide warp).
pub(super) fn grid_sample8(g: &GridGuide, x: f32x8, y: f32x8) -> (f32x8, f32x8, f32x8) {
    let (x, y) = (x.to_array(), y.to_array());
    let (mut wx, mut wy, mut q) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
    for lane in 0..LANES {
        ([wx[lane], wy[lane]], q[lane]) = g.sample([x[lane], y[lane]]);
    }
    (f32x8::from(wx), f32x8::from(wy), f32x8::from(q))
}

/// Whether the light of a cluster whose texels' results in the pass before are `measured` is
/// flat: their pooled relative per-sample variance, `Σ σ² / Σ μ²` (σ² a texel's per-sample
/// luminance variance, μ its mean; dark texels left out), below `permille` thousandths. Never
/// with `permille` 0, nor where the pass before measured no light.
pub(super) fn is_flat(measured: impl Iterator<Item = TexelResult>, permille: u32) -> bool {
    if permille == 0 {
        return false;
    }
    let (mut variance, mut mean2) = (0.0f64, 0.0f64);
    for r in measured.filter(|r| r.flags & FLAG_BAKED != 0) {
        let (v, mu) = budget::per_sample(&r);
        if v.is_finite() && mu.is_finite() && mu > 0.0 {
            variance += v;
            mean2 += mu * mu;
        }
    }
    mean2 > 0.0 && variance < mean2 * f64::from(permille) / 1000.0
}

/// The guide an iteration samples: the paper's quadtree, or the grid comparator's bins.
#[derive(Clone, Copy)]
pub(super) enum IterationGuide<'a> {
    Tree(&'a Guide<'a>),
    Grid(&'a GridGuide),
}

/// The records one iteration of a cluster learns from, and what `--min-gain` needs of them.
#[derive(Default)]
pub(super) struct GuideRecords {
    /// Point and flux `lum(L) / q` of every finite sample.
    pub(super) records: Vec<Record>,
    /// `densities[i]`: the density `q` on the primary sample square that drew `records[i]`
    /// (until a guide's build reorders the records).
    densities: Vec<f32>,
    /// What the next guide learns from: the records of the cluster's iterations since the
    /// last one that sampled cosine points, that one included (docs/guiding-levers.md, "The records a
    /// guide learns from, and three iterations").
    pub(super) pool: Vec<Record>,
}

impl GuideRecords {
    pub(super) fn clear(&mut self) {
        self.records.clear();
        self.densities.clear();
    }

    pub(super) fn push(&mut self, record: Record, density: f32) {
        self.records.push(record);
        self.densities.push(density);
    }

    /// The records the next guide learns from: this iteration's added to those of the
    /// iterations before it, or this iteration's alone when it sampled cosine points
    /// (`guided` false: a guide that saw no energy, or a cluster's first iteration without a
    /// seed, starts the pool again). Each record is `g/q` (or `g²/q`) for the density `q`
    /// that drew it, so the mean over records drawn by different densities still estimates
    /// each cell's integral.
    pub(super) fn pooled(&mut self, guided: bool) -> &mut [Record] {
        if !guided {
            self.pool.clear();
        }
        self.pool.extend_from_slice(&self.records);
        &mut self.pool
    }

    /// Turns each record's flux `g/q` into `g²/q`, what a guide of the second moment learns
    /// from ([`GuideParams::second_moment`]): `∫ g²` over a region is the mean of `g²/q` over
    /// the records there, whatever density drew them. After [`Self::gain`], which reads the
    /// fluxes as `g/q`. A square past `f32::MAX` is kept at it: the brightest record must not
    /// become ∞, which the build would drop.
    pub(super) fn square_fluxes(&mut self) {
        for (r, &q) in self.records.iter_mut().zip(&self.densities) {
            let flux = f64::from(r.flux);
            r.flux = (flux * flux * f64::from(q)).min(f64::from(f32::MAX)) as f32;
        }
    }

    /// How many times less variance per sample the density that drew the records had than
    /// stratified cosine points would have had, both estimated from the records: the
    /// iteration's own samples measure the guide it sampled, out of sample (a guide judged
    /// on the records it was fitted to looks better than it is).
    ///
    /// A record drawn with density `q` has flux `g/q`, so the iteration's variance per
    /// sample is the flux's, `∫ g²/q − (∫ g)²`. The cosine points are stratified: an
    /// iteration's presorted Sobol points cover the square's [`GAIN_STRATA`]² cells evenly,
    /// so their variance is what is left inside the cells, `∫ g² − Σ_c (∫_c g)² / a_c`, with
    /// `∫ g²` estimated as the mean of `flux² · q` and each `(∫_c g)²` without bias from the
    /// cell's records. (Against independent cosine points a guide would look better than it
    /// is on smooth light: docs/BENCHMARKS.md, "Why guiding does not pay by RMSE".)
    /// Infinite when the records show no variance; 1 with fewer than two.
    pub(super) fn gain(&self) -> f64 {
        let n = self.records.len() as f64;
        if n < 2.0 {
            return 1.0;
        }
        const CELLS: usize = GAIN_STRATA * GAIN_STRATA;
        let cell = |x: f32| ((x * GAIN_STRATA as f32) as usize).min(GAIN_STRATA - 1);
        let (mut sums, mut squares) = ([0.0f64; CELLS], [0.0f64; CELLS]);
        let (mut mean, mut second, mut cosine) = (0.0f64, 0.0f64, 0.0f64);
        for (r, &q) in self.records.iter().zip(&self.densities) {
            let (flux, q) = (f64::from(r.flux), f64::from(q));
            let c = cell(r.u[0]) + GAIN_STRATA * cell(r.u[1]);
            sums[c] += flux;
            squares[c] += flux * flux;
            mean += flux;
            second += flux * flux;
            cosine += flux * flux * q;
        }
        // ((Σ X)² − Σ X²) / (n (n − 1)) estimates (∫_c g)² without bias, X a record's flux
        // in cell c and 0 elsewhere.
        let between = sums
            .iter()
            .zip(&squares)
            .map(|(s, q)| (s * s - q) / (n * (n - 1.0)))
            .sum::<f64>()
            * CELLS as f64;
        let mean = mean / n;
        let stratified = cosine / n - between;
        let sampled = second / n - mean * mean;
        if sampled > 0.0 {
            stratified.max(0.0) / sampled
        } else {
            f64::INFINITY
        }
    }
}

/// Cells per side of the largest guide seed: 8 × 8, one cell per texel of a full cluster.
pub(super) const SEED_SIDE: usize = 8;

/// Cells per side of the guide seed of a cluster of `members` texels: the largest power of two
/// whose square they hold, at most [`SEED_SIDE`]; 0 below four texels (no seed).
pub(super) fn seed_side(members: usize) -> usize {
    match members {
        64.. => SEED_SIDE,
        16.. => 4,
        4.. => 2,
        _ => 0,
    }
}

/// A cluster's guide seed (docs/guiding-levers.md, "The seed guide"): what the gather of the pass before
/// a guided last pass brought back, summed over a grid of [`seed_side`]² cells on the primary
/// sample square. The cluster's j-th texel keeps cell j in its result; the last pass, whose
/// clusters are the same, builds the cluster's first guide from the cells
/// ([`seeded_guide`]), so its first iteration is guided too.
pub(super) struct SeedHistogram {
    side: usize,
    sums: [f64; SEED_SIDE * SEED_SIDE],
    records: u64,
}

impl SeedHistogram {
    pub(super) fn new(members: usize) -> Self {
        Self {
            side: seed_side(members),
            sums: [0.0; SEED_SIDE * SEED_SIDE],
            records: 0,
        }
    }

    /// Adds an iteration's records, each as its guide would learn it: `g/q`, or `g²/q` for a
    /// second-moment guide (as [`GuideRecords::square_fluxes`]).
    pub(super) fn add(&mut self, learning: &GuideRecords, second_moment: bool) {
        if self.side == 0 {
            return;
        }
        let side = self.side;
        let cell = |x: f32| ((x * side as f32) as usize).min(side - 1);
        for (r, &q) in learning.records.iter().zip(&learning.densities) {
            let flux = f64::from(r.flux).max(0.0);
            let value = if second_moment {
                flux * flux * f64::from(q)
            } else {
                flux
            };
            self.sums[cell(r.u[0]) + side * cell(r.u[1])] += value;
        }
        self.records += learning.records.len() as u64;
    }

    /// Each texel's cell, in the cluster's texel order: the cell's sum over the records divided
    /// by their number (an estimate of the integral over the cell), at most `f32::MAX`; 0 past
    /// the seed's cells.
    pub(super) fn cells(&self) -> impl Iterator<Item = f32> + '_ {
        let records = self.records.max(1) as f64;
        (0..).map(move |j| match self.sums.get(j) {
            Some(sum) if j < self.side * self.side => {
                (sum / records).min(f64::from(f32::MAX)) as f32
            }
            _ => 0.0,
        })
    }
}

/// Cells per side of the square over which [`GuideRecords::gain`] takes the cosine
/// points as stratified: 64 cells, about one per sample of a texel's middle iterations at
/// 256 spp.
pub(super) const GAIN_STRATA: usize = 8;
