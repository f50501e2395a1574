//! Combining each texel's iterations (paper §2.5): Graybill–Deal, the global or cluster
//! weights, ρ's sums, the relative error the spatial budget reads, and the directional
//! coefficients combined with the same weights.

use guidebake_kernels::estimator::{
    CombinationWeights, GraybillDeal, PlainAverage, TexelEstimate, Weighted, Welford,
    combine_weighted, plain_average,
};

use crate::bake::directional::{self, ShL1};
use crate::bake::pipeline::TileBuffer;
use crate::bake::settings::{Combine, Guiding};
use crate::output::journal::TileRecord;
use crate::output::result_file::{
    FLAG_BAKED, FLAG_NO_FINITE_SAMPLES, FLAG_UNGUIDED, FLAG_VALID, TexelResult,
};

use super::*;

impl TileBaker<'_> {
    /// Combines every valid texel's iterations and fills the tile's results and ρ sums.
    pub(super) fn finish_tile(&mut self, tile: u32, out: &mut TileBuffer) -> TileRecord {
        let k = self.settings.iterations as usize;
        let gd = GraybillDeal::default();
        let mut record = TileRecord {
            tile,
            ..Default::default()
        };
        for (m, &i) in self.valid.iter().enumerate() {
            let batches = &self.batches[m * k..(m + 1) * k];
            let average = plain_average(batches);
            let combined = match self.settings.combine {
                Combine::Average => average,
                Combine::Texel => gd.combine(batches),
                Combine::Cluster => combine_weighted(batches, &self.weights[m * k..(m + 1) * k]),
                // Combined in the final pass, once every texel's variances give the weights;
                // until then the plain average stands in.
                Combine::Global => {
                    out.batches[i as usize * k..(i as usize + 1) * k].copy_from_slice(batches);
                    average
                }
            };
            let mut flags = FLAG_BAKED | FLAG_VALID;
            if self.unguided[m] && self.settings.guiding != Guiding::Off && !self.direct_only {
                flags |= FLAG_UNGUIDED;
            }
            let (rgb, samples, rejected) = match combined {
                TexelEstimate::Value(e) => (e.rgb.map(|c| c as f32), e.samples, e.rejected),
                TexelEstimate::NoSamples { rejected } => {
                    flags |= FLAG_NO_FINITE_SAMPLES;
                    self.counters.texels_without_finite_samples += 1;
                    ([0.0; 3], 0, rejected)
                }
            };
            if self.keep_directional {
                self.finish_directional(m, i as usize, out);
            }
            self.counters.samples_rejected += rejected;
            self.counters.texels_baked += 1;
            if let (Some(u), Some(w)) = (average.luminance(), combined.luminance()) {
                record.unweighted_luminance += u;
                record.weighted_luminance += w;
                record.texels += 1;
            }
            out.results[i as usize] = TexelResult {
                irradiance: rgb,
                gathered: self.gathered[m]
                    .mean_rgb()
                    .map_or([0.0; 3], |c| c.map(|x| x as f32)),
                rel_std_error: relative_std_error(batches),
                samples: samples.min(u64::from(u32::MAX)) as u32,
                flags,
                total: match average {
                    TexelEstimate::Value(e) => e.rgb.map(|c| c as f32),
                    TexelEstimate::NoSamples { .. } => [0.0; 3],
                },
                seed: self.seeds[m],
            };
        }
        record
    }

    /// Valid texel `m` (index `i` in the tile)'s directional coefficients into `out`: its
    /// iterations' means for `--combine global` (combined in the final pass), else combined
    /// with the weights its irradiance was combined with.
    fn finish_directional(&self, m: usize, i: usize, out: &mut TileBuffer) {
        let k = self.settings.iterations as usize;
        let batches = &self.batches[m * k..(m + 1) * k];
        let means: Vec<ShL1> = self.sh[m * k..(m + 1) * k]
            .iter()
            .zip(batches)
            .map(|(s, b)| s.mean(b.count()))
            .collect();
        let gd = GraybillDeal::default();
        let cluster = Weighted(&self.weights[m * k..(m + 1) * k]);
        let weights: &dyn CombinationWeights = match self.settings.combine {
            Combine::Global => {
                out.directional[i * k..(i + 1) * k].copy_from_slice(&means);
                return;
            }
            Combine::Average => &PlainAverage,
            Combine::Texel => &gd,
            Combine::Cluster => &cluster,
        };
        out.directional[i] = directional::combine(&means, batches, weights);
    }
}

/// The relative standard error of a texel's pooled luminance mean (0 when unknown).
pub(super) fn relative_std_error(batches: &[Welford]) -> f32 {
    let mut pooled = Welford::new();
    batches.iter().for_each(|b| pooled.merge(b));
    match (pooled.luminance_variance(), pooled.mean_luminance()) {
        (Some(var), Some(mean)) if mean > 0.0 && pooled.count() > 1 => {
            let e = (var / pooled.count() as f64).sqrt() / mean;
            if e.is_finite() { e as f32 } else { 0.0 }
        }
        _ => 0.0,
    }
}

/// The weights of `--combine cluster` for the cluster's `members` (indices of valid texels,
/// `k` batches each in `batches`), written to `weights`: iteration j's weight is
/// `n_j / max(v_j, floor)` with `v_j = Σ_texels σ̂²_j / Σ_texels μ̂²` the cluster's pooled
/// relative per-sample variance of iteration j (σ̂²_j a texel's luminance variance in
/// iteration j, μ̂ its mean over all iterations) and the floor a hundredth of the largest
/// `v_j` (and of a relative standard deviation of 0.1): a batch of zeros beside noisy ones
/// cannot take all the weight. Without any variance every iteration weighs its sample count.
///
/// The texel's own samples are part of the pool, so its weights are not independent of
/// its values: a firefly raises its iteration's pooled variance and lowers that iteration's
/// weight in its own texel (−2.9 % on the ajar room, path; ρ, on by default with this
/// combination, restores the world's mean). Leaving the texel out of its pool removes that
/// bias but gives a firefly in an otherwise quiet iteration that iteration's large weight:
/// measured and dropped (docs/estimator.md).
pub(super) fn cluster_weights(members: &[u32], batches: &[Welford], k: usize, weights: &mut [f64]) {
    let mut var = [0.0f64; crate::bake::settings::MAX_ITERATIONS];
    let mut mean2 = 0.0f64;
    for &m in members {
        let b = &batches[m as usize * k..(m as usize + 1) * k];
        let Some(mu) = plain_average(b).luminance() else {
            continue;
        };
        if !(mu.is_finite() && mu > 0.0) {
            continue;
        }
        mean2 += mu * mu;
        for (j, batch) in b.iter().enumerate() {
            if let Some(v) = batch.luminance_variance().filter(|v| v.is_finite()) {
                var[j] += v;
            }
        }
    }
    let rel: Vec<f64> = (0..k).map(|j| var[j] / mean2).collect();
    let largest = rel
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let floor = (largest * 0.01).max(0.01);
    for &m in members {
        for j in 0..k {
            let b = &batches[m as usize * k + j];
            let w = if mean2 > 0.0 && largest > 0.0 {
                b.count() as f64 / rel[j].max(floor)
            } else {
                b.count() as f64
            };
            weights[m as usize * k + j] = w;
        }
    }
}
