//! Combining each texel's iterations (paper §2.5) with the kernels' estimators
//! (`guidebake_kernels::estimator`): Graybill–Deal, the global or cluster weights, ρ's sums,
//! the relative error the spatial budget reads, and the directional coefficients combined with
//! the same weights.

use guidebake_kernels::estimator::{
    CombinationWeights, GraybillDeal, PlainAverage, TexelEstimate, Weighted, combine_weighted,
    plain_average, relative_std_error,
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
