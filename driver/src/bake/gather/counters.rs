//! What the gather counts, per worker and merged over the bake: rays by kind, iterations
//! guided or not and why, clusters, timed warps ([`GatherCounters`], the stats JSON's
//! `gather` object).

use std::time::Instant;

/// What the workers counted, merged over the bake.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct GatherCounters {
    /// Gather rays traced.
    pub gather_rays: u64,
    /// Shadow rays traced (at texels and at gather hits).
    pub shadow_rays: u64,
    /// Path continuation rays traced beyond the gather hits (`path` transport).
    pub path_rays: u64,
    /// Gather hits that read the previous series pass's total irradiance, where next-event
    /// estimation (a shadow ray where a light faces the hit) is skipped.
    pub series_totals_read: u64,
    /// Valid texels baked.
    pub texels_baked: u64,
    /// Invalid texels skipped without tracing.
    pub texels_invalid_skipped: u64,
    /// Of those, texels inside geometry (`prepare` found their rays meeting sides of
    /// surfaces that face no open space; the lightmap's dilation fills them).
    pub texels_inside_geometry: u64,
    /// Texels whose every sample was non-finite (baked black, flagged).
    pub texels_without_finite_samples: u64,
    /// Non-finite samples rejected by the estimators.
    pub samples_rejected: u64,
    /// Clusters baked.
    pub clusters: u64,
    /// Guided iterations that fell back to the baseline because learning saw no energy.
    pub iterations_unguided_no_energy: u64,
    /// Guided iterations that fell back to the baseline because the guide was uniform.
    pub iterations_unguided_uniform_guide: u64,
    /// Guided iterations that fell back to the baseline because the guide the cluster sampled
    /// in an earlier iteration beat stratified cosine points by less than `--min-gain`.
    pub iterations_unguided_no_gain: u64,
    /// Guided iterations folded into one set of cosine points because the pass before
    /// measured the cluster's light as flat (`--flat-below`: [`GatherCounters::clusters_flat`];
    /// each such cluster bakes its iterations' samples as one set: `iterations − 1` here).
    pub iterations_unguided_flat: u64,
    /// Guided iterations that sampled a learned guide.
    pub iterations_guided: u64,
    /// Clusters of a guided last pass that gathered with cosine points alone, no seed and no
    /// guide learned, because the pass before measured their light as flat: a pooled relative
    /// per-sample variance below `--flat-below` thousandths.
    pub clusters_flat: u64,
    /// Clusters whose first iteration sampled a guide seeded by the pass before
    /// ([`BakeSettings::reads_guide_seeds`](crate::bake::settings::BakeSettings::reads_guide_seeds));
    /// not among the learnable iterations, which follow the first.
    pub clusters_seeded: u64,
    /// Texel-iterations the stopping rule skipped (`--target-error`): each iteration a texel
    /// of a stopped cluster, or of a stopped tile of the direct pass, did not take.
    pub texel_iterations_stopped: u64,
    /// Nanoseconds spent building guides (summed over workers: CPU time, not wall time).
    pub guide_build_ns: u64,
    /// Nanoseconds spent warping samples through guides (summed over workers): every
    /// [`WARP_TIMED_EVERY`]-th packet of eight is timed and counts that many times (a clock
    /// read per packet cost 4% of a guided bake, perf, 2026-11-24).
    pub warp_ns: u64,
}

impl GatherCounters {
    /// Rays of every kind.
    pub fn rays(&self) -> u64 {
        self.gather_rays + self.shadow_rays + self.path_rays
    }

    /// Cluster-iterations that could sample a learned guide (every iteration after the first
    /// of a guided pass), guided or fallen back to the baseline for one of the counted reasons.
    pub fn iterations_learnable(&self) -> u64 {
        self.iterations_guided
            + self.iterations_unguided_no_energy
            + self.iterations_unguided_uniform_guide
            + self.iterations_unguided_no_gain
            + self.iterations_unguided_flat
    }

    /// Adds another worker's counts.
    pub fn merge(&mut self, o: &Self) {
        self.gather_rays += o.gather_rays;
        self.shadow_rays += o.shadow_rays;
        self.path_rays += o.path_rays;
        self.series_totals_read += o.series_totals_read;
        self.texels_baked += o.texels_baked;
        self.texels_invalid_skipped += o.texels_invalid_skipped;
        self.texels_inside_geometry += o.texels_inside_geometry;
        self.texels_without_finite_samples += o.texels_without_finite_samples;
        self.samples_rejected += o.samples_rejected;
        self.clusters += o.clusters;
        self.iterations_unguided_no_energy += o.iterations_unguided_no_energy;
        self.iterations_unguided_uniform_guide += o.iterations_unguided_uniform_guide;
        self.iterations_unguided_no_gain += o.iterations_unguided_no_gain;
        self.iterations_unguided_flat += o.iterations_unguided_flat;
        self.iterations_guided += o.iterations_guided;
        self.clusters_flat += o.clusters_flat;
        self.clusters_seeded += o.clusters_seeded;
        self.texel_iterations_stopped += o.texel_iterations_stopped;
        self.guide_build_ns += o.guide_build_ns;
        self.warp_ns += o.warp_ns;
    }
}

/// One packet in this many has its warp timed ([`GatherCounters::warp_ns`]).
pub(super) const WARP_TIMED_EVERY: u32 = 8;

/// Adds a timed warp to the counters, standing for the [`WARP_TIMED_EVERY`] packets it samples.
pub(super) fn count_warp(clock: Option<Instant>, counters: &mut GatherCounters) {
    if let Some(clock) = clock {
        counters.warp_ns += clock.elapsed().as_nanos() as u64 * u64::from(WARP_TIMED_EVERY);
    }
}
