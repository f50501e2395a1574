//! `estimator`: per-texel, per-iteration estimators and their combination (paper §2.5).
//!
//! Silvennoinen & Sloan, *Ray Guiding for Production Lightmap Baking*, §2.5: every learning
//! iteration k of a texel yields an independent estimate (its batch mean μ̂_k of n_k gather
//! samples). Rather than throwing the early, poorly guided iterations away, they are combined
//! with the Graybill–Deal estimator (eq. 3), weights inversely proportional to the estimated
//! variance of each batch mean, w_k ∝ n_k / σ̂²_k. Because σ̂²_k is estimated from the same
//! samples as μ̂_k, a batch that caught a firefly has both a large mean and a large variance and
//! is down-weighted: the combination is biased low. The paper corrects this globally with
//! ρ = L̂ / L̂_GD, the ratio of the sums over all texels of the unweighted and of the weighted
//! mean luminance, applied to every texel in a final pass.
//!
//! What this module provides:
//! - [`Welford`]: one batch (one texel, one iteration), Welford's running mean and M2 for R, G,
//!   B and luminance, accumulated in `f64` from `f32` samples. Non-finite samples are rejected
//!   and counted. Batches merge exactly as Chan et al. (1979) describe.
//! - [`GraybillDeal`]: the per-texel inverse-variance combination, with the variance floor
//!   described below, returning a [`TexelEstimate`] — an explicit
//!   [`TexelEstimate::NoSamples`] when a texel has no finite sample (never a NaN).
//! - [`plain_average`]: the sample-count weighted average of all batches (the unbiased
//!   baseline).
//! - [`IterationVariance`] + [`combine_weighted`]: Müller et al.'s production scheme
//!   (*Practical Path Guiding*, 2017, §5.2): one global weight per iteration, the inverse of the
//!   mean over all texels of the variance of that iteration's estimate. Built for a streaming
//!   baker: pass 1 calls [`IterationVariance::add_texel`] per texel (and merges per-thread
//!   or per-shard accumulators), pass 2 calls [`IterationVariance::weights`] once and
//!   [`combine_weighted`] per texel. The weights do not depend on a texel's own samples, so
//!   this combination is unbiased and needs no ρ.
//! - [`cluster_weights`]: per-iteration weights pooled over one cluster's texels instead of the
//!   world's (the bake's default combination), applied per texel by [`combine_weighted`].
//! - [`CombinationWeights`] ([`PlainAverage`], [`GraybillDeal`], [`Weighted`]): the normalised
//!   per-batch weights each combination applies, for other per-batch means of the same samples.
//! - [`relative_std_error`]: a texel's relative standard error over all its batches, what a
//!   baker keeps to spend samples where the error is.
//! - [`RhoAccumulator`]: the global sums for ρ.
//! - [`ExactSum`]: the exact fixed-point accumulator behind every global reduction here.
//!
//! # Determinism of global sums
//! Floating-point addition is not associative, so a sum over texels computed by a different
//! number of threads, or over a different shard split, would differ in its last bits and so
//! would the whole lightmap after ρ is applied. [`ExactSum`] therefore adds every `f64` exactly
//! into a 256-bit two's-complement fixed-point integer with 96 fractional bits (quantum
//! 2⁻⁹⁶ ≈ 1.3·10⁻²⁹; every finite `f64` of magnitude up to 2¹⁰⁰ ≈ 1.3·10³⁰ is representable up
//! to that quantum, larger ones are clamped). Integer addition is associative and commutative,
//! so merging partial sums in *any* order gives bit-identical results; the only rounding
//! happens once, in [`ExactSum::value`]. Capacity: 2⁵⁹ additions of the largest value.
//!
//! # The variance floor (deviation: the paper does not say how it guards σ̂² = 0)
//! A batch whose samples are all equal has σ̂²_k = 0 and, unguarded, infinite weight. Each
//! batch's sample variance is floored at `(c · μ̄)²`, where μ̄ is the texel's pooled
//! (sample-count weighted) mean luminance over *all* its batches and `c` is
//! [`GraybillDeal::rel_std_floor`] (default [`DEFAULT_REL_STD_FLOOR`] = 0.25): no batch may
//! claim a per-sample relative standard deviation below 25 % of the texel's mean. Using the
//! pooled mean rather than the batch's own means an all-zero batch (a dark iteration) is
//! floored too. Consequences, all tested:
//! - a texel whose batches are all noise-free (constant radiance) gets weights ∝ n_k, i.e. the
//!   plain average;
//! - a zero-variance batch gets at most `(s/c)²` times the per-sample weight of a batch with
//!   per-sample relative standard deviation `s` (16× for s = 1): finite, but still most of the
//!   weight. No floor relative to the mean stops a dark batch beside a lit one from
//!   dominating (its share is 0.93 even at c = 0.5, `tests/estimator.rs`); the floor prevents
//!   infinite weights, the global ρ removes the resulting bias on average, and Müller's
//!   global weights avoid it altogether;
//! - the price of the floor: batches with a true relative standard deviation below `c` are
//!   weighted as if it were `c`. On the synthetic normal test (relative σ down to 0.07) GD's
//!   RMSE is 0.473× the average's with c = 0.25, 0.380× with c = 0.1 (optimal 0.375×);
//! - the benefit beyond zero variances: the floor pulls low-noise batches toward
//!   sample-count weights and so limits Graybill–Deal's per-texel bias. With c = 0.1 the
//!   driver's guided constant-sky plane test (`bake::gather`, no ρ) comes out 1 % low, outside
//!   its 3σ; with c = 0.25 it passes. Hence the default 0.25;
//! - a texel whose pooled mean is 0 has all variances floored at [`ABSOLUTE_VARIANCE_FLOOR`]
//!   and combines to the plain average, 0.
//!
//! A batch with one sample has no sample variance; it uses the texel's pooled variance (over
//! all its batches), floored as above.
//!
//! Luminance is Rec. 709 / sRGB: Y = 0.2126 R + 0.7152 G + 0.0722 B. Graybill–Deal weights
//! come from the luminance variance and are applied to all three channels, so the combination
//! never shifts hue by weighting channels differently.
//!
//! Nothing here allocates; nothing in the per-sample or per-texel paths returns `Result`.
//!
//! # Example: a streaming baker
//! Pass 1 bakes each texel's iterations into [`Welford`] batches (kept, e.g., in a
//! memory-mapped file: they are `Pod`), and reduces the global statistics per thread; pass 2
//! merges the reductions (in any order) and writes the final values.
//!
//! ```
//! use guidebake_kernels::estimator::{
//!     GraybillDeal, IterationVariance, RhoAccumulator, Welford, combine_weighted, plain_average,
//! };
//! // Radiance the baker's own gather would return for texel t, iteration k, sample i.
//! let gather = |t: usize, k: usize, i: usize| {
//!     let noise = ((t * 31 + k * 7 + i * 13) % 17) as f32 / 17.0;
//!     [1.0 + noise / (k + 1) as f32, 0.8, 0.5]
//! };
//! const K: usize = 3;
//! let texels = 100;
//! let gd = GraybillDeal::default();
//! // pass 1, per worker: batches per texel and iteration, global sums
//! let mut batches = vec![[Welford::new(); K]; texels];
//! let (mut rho, mut muller) = (RhoAccumulator::new(), IterationVariance::<K>::new());
//! for (t, texel) in batches.iter_mut().enumerate() {
//!     for (k, batch) in texel.iter_mut().enumerate() {
//!         for i in 0..(16 << k) {
//!             batch.push(gather(t, k, i));
//!         }
//!     }
//!     rho.add_texel(&plain_average(texel), &gd.combine(texel));
//!     muller.add_texel(texel);
//! }
//! // (workers' and shards' accumulators would be merged here: `rho.merge(&other)`)
//! // pass 2: the global factors, then every texel
//! let (r, weights) = (rho.rho(), muller.weights());
//! for texel in &batches {
//!     let guided = gd.combine(texel).corrected_rgb(r).expect("texel has samples");
//!     let production = combine_weighted(texel, &weights).value().unwrap().rgb;
//!     assert!(guided.iter().chain(&production).all(|c| c.is_finite()));
//! }
//! ```

use bytemuck::{Pod, Zeroable};

/// Rec. 709 luminance weights for R, G and B.
pub const LUMINANCE_WEIGHTS: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Default [`GraybillDeal::rel_std_floor`]: the smallest per-sample relative standard
/// deviation a batch may claim, relative to the texel's pooled mean luminance.
pub const DEFAULT_REL_STD_FLOOR: f64 = 0.25;

/// The variance floor used when a texel's pooled mean luminance is zero.
pub const ABSOLUTE_VARIANCE_FLOOR: f64 = 1e-300;

/// Rec. 709 luminance of a linear RGB triple.
#[inline]
pub fn luminance(rgb: [f64; 3]) -> f64 {
    LUMINANCE_WEIGHTS[0] * rgb[0] + LUMINANCE_WEIGHTS[1] * rgb[1] + LUMINANCE_WEIGHTS[2] * rgb[2]
}

/// [`LUMINANCE_WEIGHTS`] in `f32` (each the nearest `f32` to the decimal weight).
pub const LUMINANCE_WEIGHTS_F32: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// [`luminance`] in `f32`, for radiance and emission (the one luminance of the workspace).
#[inline]
pub fn luminance_f32(rgb: [f32; 3]) -> f32 {
    let w = LUMINANCE_WEIGHTS_F32;
    w[0] * rgb[0] + w[1] * rgb[1] + w[2] * rgb[2]
}

/// One batch of samples (one texel, one iteration): Welford's running mean and sum of
/// squared deviations (M2) for R, G, B and luminance, in `f64`.
///
/// `f64` accumulation keeps the mean and variance accurate to ~1e-12 relative over 10⁶
/// samples spread over 1e-4…1e5 (tested against an exact reference); the error grows at most
/// like n·2⁻⁵³. `#[repr(C)]` and `Pod`, so a baker can keep batches in a memory-mapped file.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Welford {
    count: u64,
    rejected: u64,
    mean: [f64; 4],
    m2: [f64; 4],
}

impl Welford {
    /// An empty batch.
    pub const fn new() -> Self {
        Welford {
            count: 0,
            rejected: 0,
            mean: [0.0; 4],
            m2: [0.0; 4],
        }
    }

    /// Adds one radiance sample. A sample with a NaN or infinite channel is rejected: it only
    /// increments [`Welford::rejected`].
    #[inline]
    pub fn push(&mut self, rgb: [f32; 3]) {
        if !(rgb[0].is_finite() && rgb[1].is_finite() && rgb[2].is_finite()) {
            self.rejected += 1;
            return;
        }
        let c = [f64::from(rgb[0]), f64::from(rgb[1]), f64::from(rgb[2])];
        let x = [c[0], c[1], c[2], luminance(c)];
        self.count += 1;
        let inv_n = 1.0 / self.count as f64;
        for ((&x, mean), m2) in x.iter().zip(&mut self.mean).zip(&mut self.m2) {
            let delta = x - *mean;
            *mean += delta * inv_n;
            *m2 += delta * (x - *mean);
        }
    }

    /// Adds another batch's samples (Chan, Golub & LeVeque's pairwise update). The result does
    /// not depend on how the samples were split, up to rounding.
    pub fn merge(&mut self, other: &Welford) {
        self.rejected += other.rejected;
        if other.count == 0 {
            return;
        }
        if self.count == 0 {
            let rejected = self.rejected;
            *self = *other;
            self.rejected = rejected;
            return;
        }
        let (na, nb) = (self.count as f64, other.count as f64);
        let n = na + nb;
        for ch in 0..4 {
            let delta = other.mean[ch] - self.mean[ch];
            self.mean[ch] += delta * (nb / n);
            self.m2[ch] += other.m2[ch] + delta * delta * (na * nb / n);
        }
        self.count += other.count;
    }

    /// Finite samples accepted.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Non-finite samples rejected.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// Mean RGB, or `None` without samples.
    pub fn mean_rgb(&self) -> Option<[f64; 3]> {
        (self.count > 0).then_some([self.mean[0], self.mean[1], self.mean[2]])
    }

    /// Mean luminance, or `None` without samples.
    pub fn mean_luminance(&self) -> Option<f64> {
        (self.count > 0).then_some(self.mean[3])
    }

    /// Unbiased sample variance of R, G, B and luminance (M2 / (n − 1)), or `None` with fewer
    /// than two samples.
    pub fn variance(&self) -> Option<[f64; 4]> {
        if self.count < 2 {
            return None;
        }
        let d = 1.0 / (self.count - 1) as f64;
        Some(self.m2.map(|m2| m2 * d))
    }

    /// Unbiased sample variance of the luminance, or `None` with fewer than two samples.
    pub fn luminance_variance(&self) -> Option<f64> {
        self.variance().map(|v| v[3])
    }
}

/// The combined estimate of one texel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TexelEstimate {
    /// No finite sample in any batch: the texel has no estimate (a baker marks it invalid or
    /// fills it from its neighbours). `rejected` counts the non-finite samples seen.
    NoSamples {
        /// Non-finite samples rejected across all batches.
        rejected: u64,
    },
    /// A finite estimate.
    Value(Estimate),
}

/// A finite combined estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Combined RGB radiance.
    pub rgb: [f64; 3],
    /// Combined luminance (the same weights applied to the luminance means).
    pub luminance: f64,
    /// Finite samples over all batches.
    pub samples: u64,
    /// Non-finite samples rejected over all batches.
    pub rejected: u64,
}

impl TexelEstimate {
    /// The estimate, if the texel has one.
    pub fn value(&self) -> Option<&Estimate> {
        match self {
            TexelEstimate::NoSamples { .. } => None,
            TexelEstimate::Value(e) => Some(e),
        }
    }

    /// The luminance, if the texel has an estimate.
    pub fn luminance(&self) -> Option<f64> {
        self.value().map(|e| e.luminance)
    }

    /// RGB scaled by `rho` (the bias correction), if the texel has an estimate.
    pub fn corrected_rgb(&self, rho: f64) -> Option<[f64; 3]> {
        self.value().map(|e| e.rgb.map(|c| c * rho))
    }
}

/// All batches of a texel merged: the texel's pooled statistics.
pub fn pooled(batches: &[Welford]) -> Welford {
    let mut all = Welford::new();
    for b in batches {
        all.merge(b);
    }
    all
}

/// The normalised weights `weighted_mean` gives each batch, written to `out` (at least as long
/// as `batches`): `w_k / Σ w` for batches with samples and 0 for the others, or the pooled
/// count weights `n_k / N` when every weight is zero. Returns `false` (and leaves `out`
/// untouched) when no batch has a sample.
fn normalised_weights(
    batches: &[Welford],
    pooled: &Welford,
    mut weight: impl FnMut(usize, &Welford) -> f64,
    out: &mut [f64],
) -> bool {
    debug_assert!(out.len() >= batches.len(), "output shorter than batches");
    if pooled.count == 0 {
        return false;
    }
    let mut total = 0.0f64;
    for ((k, b), o) in batches.iter().enumerate().zip(out.iter_mut()) {
        *o = if b.count == 0 { 0.0 } else { weight(k, b) };
        total += *o;
    }
    if total > 0.0 && total.is_finite() {
        let inv = 1.0 / total;
        out.iter_mut().take(batches.len()).for_each(|w| *w *= inv);
    } else {
        let inv = 1.0 / pooled.count as f64;
        for (b, o) in batches.iter().zip(out.iter_mut()) {
            *o = b.count as f64 * inv;
        }
    }
    true
}

/// The weights a combination gives a texel's batches, so that another per-batch mean (a
/// directional lightmap's coefficients, accumulated from the same samples) combines exactly
/// as the irradiance does: `Σ_k out[k] · m_k` is the combined value. `out` must be at least as
/// long as `batches`; `false` when no batch has a sample.
pub trait CombinationWeights {
    /// Writes the normalised weights of `batches` to `out`.
    fn weights(&self, batches: &[Welford], out: &mut [f64]) -> bool;
}

/// [`plain_average`]'s weights: `n_k / N`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlainAverage;

impl CombinationWeights for PlainAverage {
    fn weights(&self, batches: &[Welford], out: &mut [f64]) -> bool {
        normalised_weights(batches, &pooled(batches), |_, _| 0.0, out)
    }
}

/// [`combine_weighted`]'s weights for the given per-iteration weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weighted<'a>(pub &'a [f64]);

impl CombinationWeights for Weighted<'_> {
    fn weights(&self, batches: &[Welford], out: &mut [f64]) -> bool {
        normalised_weights(batches, &pooled(batches), iteration_weight(self.0), out)
    }
}

/// Σ w_k μ_k / Σ w_k over batches with samples, `weight(k, batch)` giving w_k ≥ 0; falls back
/// to the pooled mean when every weight is zero.
fn weighted_mean(
    batches: &[Welford],
    pooled: &Welford,
    mut weight: impl FnMut(usize, &Welford) -> f64,
) -> TexelEstimate {
    if pooled.count == 0 {
        return TexelEstimate::NoSamples {
            rejected: pooled.rejected,
        };
    }
    let (mut sum, mut total) = ([0.0f64; 4], 0.0f64);
    for (k, b) in batches.iter().enumerate() {
        if b.count == 0 {
            continue;
        }
        let w = weight(k, b);
        total += w;
        for (s, &m) in sum.iter_mut().zip(&b.mean) {
            *s += w * m;
        }
    }
    let mean = if total > 0.0 && total.is_finite() {
        let inv = 1.0 / total;
        sum.map(|s| s * inv)
    } else {
        pooled.mean
    };
    TexelEstimate::Value(Estimate {
        rgb: [mean[0], mean[1], mean[2]],
        luminance: mean[3],
        samples: pooled.count,
        rejected: pooled.rejected,
    })
}

/// The plain, sample-count weighted average of all batches: Σ n_k μ_k / Σ n_k. Unbiased;
/// the baseline the other combinations are compared against.
pub fn plain_average(batches: &[Welford]) -> TexelEstimate {
    let all = pooled(batches);
    weighted_mean(&[], &all, |_, _| 0.0)
}

/// Graybill–Deal inverse-variance combination (paper §2.5, eq. 3) with the variance floor
/// described in the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraybillDeal {
    /// `c`: each batch's per-sample variance is floored at `(c · μ̄)²`, μ̄ the texel's pooled
    /// mean luminance. Must be finite and > 0 (release builds clamp to ≥ 1e-6).
    pub rel_std_floor: f64,
}

impl Default for GraybillDeal {
    fn default() -> Self {
        GraybillDeal {
            rel_std_floor: DEFAULT_REL_STD_FLOOR,
        }
    }
}

impl GraybillDeal {
    /// The floored per-sample luminance variance each batch is weighted by, in batch order,
    /// written to `out` (which must be at least as long as `batches`; extra entries untouched).
    /// Batches without samples get `f64::INFINITY` (weight 0). Exposed for tests and for
    /// bakers that want to store the weights.
    pub fn floored_variances(&self, batches: &[Welford], out: &mut [f64]) {
        debug_assert!(out.len() >= batches.len(), "output shorter than batches");
        let all = pooled(batches);
        let floor = self.floor(&all);
        let pooled_var = all.luminance_variance().unwrap_or(0.0).max(floor);
        for (b, o) in batches.iter().zip(out.iter_mut()) {
            *o = match b.count {
                0 => f64::INFINITY,
                1 => pooled_var,
                _ => b.luminance_variance().unwrap_or(0.0).max(floor),
            };
        }
    }

    fn floor(&self, all: &Welford) -> f64 {
        debug_assert!(
            self.rel_std_floor.is_finite() && self.rel_std_floor > 0.0,
            "rel_std_floor must be finite and > 0"
        );
        let c = if self.rel_std_floor.is_finite() {
            self.rel_std_floor.max(1e-6)
        } else {
            1.0
        };
        let mu = all.mean[3];
        (c * c * mu * mu).max(ABSOLUTE_VARIANCE_FLOOR)
    }

    /// Combines a texel's batches: weights w_k = n_k / max(σ̂²_k, floor), normalised by the
    /// smallest floored variance so no weight overflows. Batches with no samples get weight 0.
    pub fn combine(&self, batches: &[Welford]) -> TexelEstimate {
        let all = pooled(batches);
        if all.count == 0 {
            return TexelEstimate::NoSamples {
                rejected: all.rejected,
            };
        }
        weighted_mean(batches, &all, self.batch_weight(batches, &all))
    }

    /// The weight of a batch: `n_k / max(σ̂²_k, floor)`, normalised by the smallest floored
    /// variance of `batches` (whose pooled statistics are `all`).
    fn batch_weight(&self, batches: &[Welford], all: &Welford) -> impl Fn(usize, &Welford) -> f64 {
        let floor = self.floor(all);
        let pooled_var = all.luminance_variance().unwrap_or(0.0).max(floor);
        let var = move |b: &Welford| match b.count {
            1 => pooled_var,
            _ => b.luminance_variance().unwrap_or(0.0).max(floor),
        };
        let min_var = batches
            .iter()
            .filter(|b| b.count > 0)
            .map(var)
            .fold(f64::INFINITY, f64::min);
        move |_, b| b.count as f64 * (min_var / var(b))
    }
}

impl CombinationWeights for GraybillDeal {
    fn weights(&self, batches: &[Welford], out: &mut [f64]) -> bool {
        let all = pooled(batches);
        if all.count == 0 {
            return false;
        }
        normalised_weights(batches, &all, self.batch_weight(batches, &all), out)
    }
}

/// Müller et al.'s production weights, applied to one texel: Σ w_k μ_k / Σ w_k with the global
/// per-iteration weights from [`IterationVariance::weights`] (`weights[k]` for batch k;
/// missing entries count as 0). If every batch with samples has weight 0, the plain average
/// is returned.
pub fn combine_weighted(batches: &[Welford], weights: &[f64]) -> TexelEstimate {
    let all = pooled(batches);
    weighted_mean(batches, &all, iteration_weight(weights))
}

/// Batch k's weight under per-iteration `weights`: `weights[k]` if finite and positive, else 0.
fn iteration_weight(weights: &[f64]) -> impl Fn(usize, &Welford) -> f64 + '_ {
    |k, _| {
        let w = weights.get(k).copied().unwrap_or(0.0);
        if w.is_finite() && w > 0.0 { w } else { 0.0 }
    }
}

/// The relative standard error of a texel's pooled luminance mean, `√(σ̂² / N) / μ̂` over all
/// its batches: what a bake keeps per texel and the spatial budget and the stopping rule read.
/// 0 when unknown (fewer than two samples, a mean that is not positive, or a result that is
/// not finite).
pub fn relative_std_error(batches: &[Welford]) -> f32 {
    let all = pooled(batches);
    match (all.luminance_variance(), all.mean_luminance()) {
        (Some(var), Some(mean)) if mean > 0.0 && all.count() > 1 => {
            let e = libm::sqrt(var / all.count() as f64) / mean;
            if e.is_finite() { e as f32 } else { 0.0 }
        }
        _ => 0.0,
    }
}

/// Cluster-pooled iteration weights (`--combine cluster`, the bake's default) for a cluster's
/// `members` (indices of texels, `k` batches each in `batches`: texel `m`'s iteration `j` is
/// `batches[m·k + j]`), written to `weights` at the same places: iteration j's weight is
/// `n_j / max(v_j, floor)` with `v_j = Σ_texels σ̂²_j / Σ_texels μ̂²` the cluster's pooled
/// relative per-sample variance of iteration j (σ̂²_j a texel's luminance variance in
/// iteration j, μ̂ its mean over all iterations) and the floor a hundredth of the largest
/// `v_j` (and of a relative standard deviation of 0.1): a batch of zeros beside noisy ones
/// cannot take all the weight. Without any variance every iteration weighs its sample count.
/// The weights are then applied per texel by [`combine_weighted`]. `K` bounds `k` (scratch
/// on the stack, nothing allocated).
///
/// The texel's own samples are part of the pool, so its weights are not independent of
/// its values: a firefly raises its iteration's pooled variance and lowers that iteration's
/// weight in its own texel (−2.9 % on the ajar room, path; ρ, on by default with this
/// combination, restores the world's mean). Leaving the texel out of its pool removes that
/// bias but gives a firefly in an otherwise quiet iteration that iteration's large weight:
/// measured and dropped (docs/estimator.md).
///
/// # Panics
/// When `k > K`, or `batches` or `weights` hold fewer than `(m + 1)·k` entries for a member `m`.
pub fn cluster_weights<const K: usize>(
    members: &[u32],
    batches: &[Welford],
    k: usize,
    weights: &mut [f64],
) {
    assert!(
        k <= K,
        "{k} iterations, more than the {K} cluster_weights holds"
    );
    let mut var = [0.0f64; K];
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
    let mut rel = [0.0f64; K];
    for j in 0..k {
        rel[j] = var[j] / mean2;
    }
    let rel = &rel[..k];
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

/// The global statistics of Müller's scheme for up to `K` iterations: per iteration, the sum
/// over texels of the variance of that iteration's luminance estimate (σ̂²_k / n_k) and the
/// number of texels contributing. Mergeable in any order with bit-identical results.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationVariance<const K: usize> {
    sums: [ExactSum; K],
    texels: [u64; K],
}

impl<const K: usize> Default for IterationVariance<K> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const K: usize> IterationVariance<K> {
    /// Empty statistics.
    pub const fn new() -> Self {
        IterationVariance {
            sums: [ExactSum::new(); K],
            texels: [0; K],
        }
    }

    /// Adds one texel's batches (batch k = iteration k; batches beyond `K` are ignored, as are
    /// batches with fewer than two samples, which have no variance).
    pub fn add_texel(&mut self, batches: &[Welford]) {
        for (k, b) in batches.iter().take(K).enumerate() {
            if let Some(v) = b.luminance_variance() {
                self.sums[k].add(v / b.count as f64);
                self.texels[k] += 1;
            }
        }
    }

    /// Adds another accumulator (another thread's or shard's texels).
    pub fn merge(&mut self, other: &Self) {
        for k in 0..K {
            self.sums[k].merge(&other.sums[k]);
            self.texels[k] += other.texels[k];
        }
    }

    /// Mean over texels of the variance of iteration k's estimate, or `None` if no texel
    /// contributed to iteration k (or k ≥ K).
    pub fn mean_variance(&self, k: usize) -> Option<f64> {
        let texels = *self.texels.get(k)?;
        (texels > 0).then(|| self.sums[k].value() / texels as f64)
    }

    /// One weight per iteration, ∝ 1 / mean variance, scaled so the largest is 1. Iterations
    /// without data get 0. Mean variances are floored at 1e-12 × the largest one (and at
    /// [`ABSOLUTE_VARIANCE_FLOOR`]), so a noise-free iteration cannot take all the weight;
    /// if all are zero every iteration with data gets weight 1.
    pub fn weights(&self) -> [f64; K] {
        let mut mv = [f64::NAN; K];
        let mut max = 0.0f64;
        for (k, m) in mv.iter_mut().enumerate() {
            if let Some(v) = self.mean_variance(k) {
                *m = v;
                max = max.max(v);
            }
        }
        let floor = (max * 1e-12).max(ABSOLUTE_VARIANCE_FLOOR);
        let min = mv
            .iter()
            .filter(|v| !v.is_nan())
            .fold(f64::INFINITY, |a, &v| a.min(v.max(floor)));
        mv.map(|v| if v.is_nan() { 0.0 } else { min / v.max(floor) })
    }
}

/// The global bias correction of paper §2.5: ρ = L̂ / L̂_GD, with L̂ the sum over texels of the
/// unweighted (plain average) mean luminance and L̂_GD the sum of the Graybill–Deal luminance.
///
/// Both sums are [`ExactSum`]s, so per-thread and per-shard accumulators merge in any order
/// to bit-identical results. [`RhoAccumulator::to_le_bytes`] / [`RhoAccumulator::from_le_bytes`]
/// carry a shard's sums between machines.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RhoAccumulator {
    unweighted: ExactSum,
    weighted: ExactSum,
    texels: u64,
    skipped: u64,
}

/// Size of [`RhoAccumulator::to_le_bytes`].
pub const RHO_BYTES: usize = core::mem::size_of::<RhoAccumulator>();

impl RhoAccumulator {
    /// Empty sums.
    pub const fn new() -> Self {
        RhoAccumulator {
            unweighted: ExactSum::new(),
            weighted: ExactSum::new(),
            texels: 0,
            skipped: 0,
        }
    }

    /// Adds one texel: its plain average and its Graybill–Deal estimate. A texel without an
    /// estimate in either is skipped (counted in [`RhoAccumulator::skipped`]).
    pub fn add_texel(&mut self, unweighted: &TexelEstimate, weighted: &TexelEstimate) {
        match (unweighted.luminance(), weighted.luminance()) {
            (Some(u), Some(w)) => self.add(u, w),
            _ => self.skipped += 1,
        }
    }

    /// Adds one texel's unweighted and weighted mean luminance; a pair with a non-finite
    /// value is skipped (counted in [`RhoAccumulator::skipped`]), in both sums alike.
    #[inline]
    pub fn add(&mut self, unweighted: f64, weighted: f64) {
        self.add_sums(unweighted, weighted, 1);
    }

    /// Adds the sums of `texels` texels at once (e.g. one tile's, as a bake's journal keeps
    /// them); order does not matter, results are bit-identical. A pair with a non-finite
    /// value is skipped in both sums (counted in [`RhoAccumulator::skipped`]), so one broken
    /// tile neither enters ρ nor unbalances it.
    #[inline]
    pub fn add_sums(&mut self, unweighted: f64, weighted: f64, texels: u64) {
        if !(unweighted.is_finite() && weighted.is_finite()) {
            self.skipped += texels;
            return;
        }
        self.unweighted.add(unweighted);
        self.weighted.add(weighted);
        self.texels += texels;
    }

    /// Adds another accumulator; order does not matter, results are bit-identical.
    pub fn merge(&mut self, other: &Self) {
        self.unweighted.merge(&other.unweighted);
        self.weighted.merge(&other.weighted);
        self.texels += other.texels;
        self.skipped += other.skipped;
    }

    /// ρ = L̂ / L̂_GD; 1 when the weighted sum is not positive (nothing to correct).
    pub fn rho(&self) -> f64 {
        let (u, w) = (self.unweighted.value(), self.weighted.value());
        if w > 0.0 && u.is_finite() { u / w } else { 1.0 }
    }

    /// Texels added.
    pub fn texels(&self) -> u64 {
        self.texels
    }

    /// Texels skipped because they had no estimate.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The sums as little-endian bytes, for merging shards computed on other machines.
    pub fn to_le_bytes(&self) -> [u8; RHO_BYTES] {
        let mut out = [0u8; RHO_BYTES];
        let (u, w) = (&self.unweighted, &self.weighted);
        let words = [
            u.limbs[0],
            u.limbs[1],
            u.limbs[2],
            u.limbs[3],
            u.rejected,
            w.limbs[0],
            w.limbs[1],
            w.limbs[2],
            w.limbs[3],
            w.rejected,
            self.texels,
            self.skipped,
        ];
        for (chunk, w) in out.chunks_exact_mut(8).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        out
    }

    /// The inverse of [`RhoAccumulator::to_le_bytes`].
    pub fn from_le_bytes(bytes: &[u8; RHO_BYTES]) -> Self {
        let mut w = [0u64; RHO_BYTES / 8];
        for (word, chunk) in w.iter_mut().zip(bytes.chunks_exact(8)) {
            let mut b = [0u8; 8];
            b.copy_from_slice(chunk);
            *word = u64::from_le_bytes(b);
        }
        RhoAccumulator {
            unweighted: ExactSum {
                limbs: [w[0], w[1], w[2], w[3]],
                rejected: w[4],
            },
            weighted: ExactSum {
                limbs: [w[5], w[6], w[7], w[8]],
                rejected: w[9],
            },
            texels: w[10],
            skipped: w[11],
        }
    }
}

/// Fractional bits of [`ExactSum`]'s fixed-point representation.
pub const EXACT_FRAC_BITS: i32 = 96;
/// Largest magnitude [`ExactSum::add`] represents; larger finite values are clamped to it.
pub const EXACT_MAX: f64 = 1_267_650_600_228_229_401_496_703_205_376.0; // 2^100

/// An exact, order-independent sum of `f64`s: a 256-bit two's-complement fixed-point integer
/// with [`EXACT_FRAC_BITS`] fractional bits (see the module docs). Each addend is truncated
/// toward zero to a multiple of 2⁻⁹⁶ and clamped to ±[`EXACT_MAX`]; after that every
/// operation is exact integer arithmetic.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct ExactSum {
    limbs: [u64; 4],
    rejected: u64,
}

impl ExactSum {
    /// Zero.
    pub const fn new() -> Self {
        ExactSum {
            limbs: [0; 4],
            rejected: 0,
        }
    }

    /// Adds `x` exactly (to 2⁻⁹⁶). NaN and ±∞ are not added; they are counted in
    /// [`ExactSum::rejected`].
    #[inline]
    pub fn add(&mut self, x: f64) {
        if !x.is_finite() {
            self.rejected += 1;
            return;
        }
        let negative = x.is_sign_negative();
        let a = x.abs().min(EXACT_MAX);
        let bits = a.to_bits();
        let exp = ((bits >> 52) & 0x7ff) as i32;
        let frac = bits & ((1u64 << 52) - 1);
        let (m, e) = if exp == 0 {
            (frac, -1074)
        } else {
            (frac | (1u64 << 52), exp - 1075)
        };
        let shift = e + EXACT_FRAC_BITS;
        let mag = if shift < 0 {
            if shift <= -64 {
                return;
            }
            [m >> (-shift) as u32, 0, 0, 0]
        } else {
            shift_left(m, shift as u32)
        };
        self.limbs = if negative {
            sub256(self.limbs, mag)
        } else {
            add256(self.limbs, mag)
        };
    }

    /// Adds another sum exactly.
    pub fn merge(&mut self, other: &ExactSum) {
        self.limbs = add256(self.limbs, other.limbs);
        self.rejected += other.rejected;
    }

    /// Non-finite addends ignored.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// The sum rounded to `f64` (within one ulp: the 64 leading bits are rounded to nearest,
    /// lower bits are truncated). Deterministic: a function of the exact integer only.
    pub fn value(&self) -> f64 {
        let negative = self.limbs[3] >> 63 == 1;
        let mag = if negative {
            sub256([0; 4], self.limbs)
        } else {
            self.limbs
        };
        let Some(top) = (0..4).rev().find(|&i| mag[i] != 0) else {
            return 0.0;
        };
        let p = top as i32 * 64 + 63 - mag[top].leading_zeros() as i32; // highest set bit
        let (lead, low_bit) = if p < 64 {
            (mag[0], 0)
        } else {
            (extract64(mag, p - 63), p - 63)
        };
        let v = libm::scalbn(lead as f64, low_bit - EXACT_FRAC_BITS);
        if negative { -v } else { v }
    }
}

/// `m << shift` as a 256-bit integer (shift < 200 here, so nothing is lost).
fn shift_left(m: u64, shift: u32) -> [u64; 4] {
    let mut out = [0u64; 4];
    let (limb, off) = ((shift / 64) as usize, shift % 64);
    out[limb] = m << off;
    if off != 0 && limb + 1 < 4 {
        out[limb + 1] = m >> (64 - off);
    }
    out
}

/// The 64 bits of `x` starting at bit `lo` (lo ≥ 0, lo + 63 < 256).
fn extract64(x: [u64; 4], lo: i32) -> u64 {
    let (limb, off) = ((lo / 64) as usize, (lo % 64) as u32);
    let low = x[limb] >> off;
    if off == 0 || limb + 1 >= 4 {
        low
    } else {
        low | (x[limb + 1] << (64 - off))
    }
}

fn add256(a: [u64; 4], b: [u64; 4]) -> [u64; 4] {
    let mut out = [0u64; 4];
    let mut carry = false;
    for i in 0..4 {
        let (s1, c1) = a[i].overflowing_add(b[i]);
        let (s2, c2) = s1.overflowing_add(u64::from(carry));
        out[i] = s2;
        carry = c1 || c2;
    }
    out
}

fn sub256(a: [u64; 4], b: [u64; 4]) -> [u64; 4] {
    let mut out = [0u64; 4];
    let mut borrow = false;
    for i in 0..4 {
        let (d1, b1) = a[i].overflowing_sub(b[i]);
        let (d2, b2) = d1.overflowing_sub(u64::from(borrow));
        out[i] = d2;
        borrow = b1 || b2;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;

    /// A batch of grey samples (luminance = the value, up to the weights' rounding).
    fn grey(values: &[f32]) -> Welford {
        let mut w = Welford::new();
        for &v in values {
            w.push([v; 3]);
        }
        w
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1.0)
    }

    #[test]
    fn relative_std_error_pools_every_batch() {
        // Samples 1 and 3: mean 2, unbiased variance 2, standard error √(2/2) = 1.
        let e = relative_std_error(&[grey(&[1.0, 3.0])]);
        assert!(close(f64::from(e), 0.5), "{e}");
        // The same samples split over two batches: pooled first.
        let split = relative_std_error(&[grey(&[1.0]), grey(&[3.0])]);
        assert!(close(f64::from(split), 0.5), "{split}");
        // Unknown: no batch, one sample, a mean of zero.
        assert_eq!(relative_std_error(&[]), 0.0);
        assert_eq!(relative_std_error(&[Welford::new(), grey(&[2.0])]), 0.0);
        assert_eq!(relative_std_error(&[grey(&[0.0, 0.0, 0.0])]), 0.0);
        // Constant light: no error.
        assert_eq!(relative_std_error(&[grey(&[2.0; 5])]), 0.0);
    }

    #[test]
    fn cluster_weights_divide_counts_by_pooled_relative_variance() {
        // One texel, two iterations: samples 1, 3 (n 2, σ̂² 2) then 2, 2, 2, 2 (n 4, σ̂² 0).
        // μ̂ = 12 / 6 = 2, so v = [2/4, 0]; the floor is max(0.5/100, 0.01) = 0.01.
        let batches = [grey(&[1.0, 3.0]), grey(&[2.0; 4])];
        let mut weights = [0.0; 2];
        cluster_weights::<4>(&[0], &batches, 2, &mut weights);
        assert!(close(weights[0], 2.0 / 0.5), "{weights:?}");
        assert!(close(weights[1], 4.0 / 0.01), "{weights:?}");
    }

    #[test]
    fn cluster_weights_without_variance_are_the_sample_counts() {
        // Texels 0 and 2 of three are the cluster; texel 1's weights are left as they were.
        let batches = [
            grey(&[1.0; 3]),
            grey(&[5.0; 8]),
            grey(&[1.0, 9.0]),
            grey(&[1.0]),
            grey(&[0.5; 2]),
            grey(&[0.5; 16]),
        ];
        let mut weights = [-1.0; 6];
        cluster_weights::<2>(&[0, 2], &batches, 2, &mut weights);
        assert_eq!(weights, [3.0, 8.0, -1.0, -1.0, 2.0, 16.0]);
    }

    #[test]
    fn cluster_weights_leave_dark_texels_out_of_the_pool_but_weigh_them() {
        // A dark texel adds nothing to Σ μ̂² nor to the variances; it still gets the weights.
        let lit = [grey(&[1.0, 3.0]), grey(&[2.0; 4])];
        let dark = [grey(&[0.0; 2]), grey(&[0.0; 4])];
        let mut alone = [0.0; 2];
        cluster_weights::<2>(&[0], &lit, 2, &mut alone);
        let both = [lit[0], lit[1], dark[0], dark[1]];
        let mut weights = [0.0; 4];
        cluster_weights::<2>(&[0, 1], &both, 2, &mut weights);
        assert_eq!(weights[..2], alone);
        assert_eq!(weights[2..], alone);
    }

    #[test]
    #[should_panic(expected = "more than the 2")]
    fn cluster_weights_refuse_more_iterations_than_they_hold() {
        let batches = [Welford::new(); 3];
        cluster_weights::<2>(&[0], &batches, 3, &mut [0.0; 3]);
    }

    #[test]
    fn the_f32_luminance_has_the_f64_weights_rounded() {
        for (w32, w64) in LUMINANCE_WEIGHTS_F32.iter().zip(LUMINANCE_WEIGHTS) {
            assert_eq!(*w32, w64 as f32);
        }
        let rgb = [0.25f32, 3.0, 1e5];
        let want = luminance(rgb.map(f64::from));
        assert!((f64::from(luminance_f32(rgb)) - want).abs() <= 1e-6 * want);
    }

    #[test]
    fn exact_sum_recovers_small_terms_that_f64_loses() {
        let mut s = ExactSum::new();
        let mut naive = 0.0f64;
        for x in [1e30, 1e-20, -1e30, 3.0, -3.0] {
            s.add(x);
            naive += x;
        }
        assert_eq!(naive, 0.0, "f64 summation loses the small term");
        let v = s.value();
        assert!((v - 1e-20).abs() <= 1e-20 * 1e-9, "exact sum gave {v}");
        s.add(f64::NAN);
        s.add(f64::INFINITY);
        assert_eq!(s.rejected(), 2);
        assert!((s.value() - 1e-20).abs() <= 1e-29);
    }

    #[test]
    fn exact_sum_matches_integer_reference_and_is_order_independent() {
        let mut rng = Pcg32::new(11, 3);
        let values: [f64; 500] = core::array::from_fn(|_| {
            (i64::from(rng.next_u32() as i32) * 1024 + i64::from(rng.next_u32() % 1024)) as f64
        });
        let exact: i128 = values.iter().map(|&v| v as i128).sum();
        let mut fwd = ExactSum::new();
        values.iter().for_each(|&v| fwd.add(v));
        let mut rev = ExactSum::new();
        values.iter().rev().for_each(|&v| rev.add(v));
        // three shards, merged in a different order
        let mut shards = [ExactSum::new(); 3];
        for (i, &v) in values.iter().enumerate() {
            shards[(i * 7) % 3].add(v);
        }
        let mut merged = shards[2];
        merged.merge(&shards[0]);
        merged.merge(&shards[1]);
        assert_eq!(fwd, rev);
        assert_eq!(fwd, merged);
        assert_eq!(fwd.value(), exact as f64);
    }

    #[test]
    fn exact_sum_handles_sign_subnormals_and_clamp() {
        let mut s = ExactSum::new();
        s.add(-2.5);
        assert_eq!(s.value(), -2.5);
        s.add(f64::from_bits(1)); // subnormal: below the quantum, truncated away
        assert_eq!(s.value(), -2.5);
        let mut big = ExactSum::new();
        big.add(f64::MAX);
        assert_eq!(big.value(), EXACT_MAX);
        let mut tiny = ExactSum::new();
        tiny.add(3.0 * libm::scalbn(1.0, -96));
        assert_eq!(tiny.value(), 3.0 * libm::scalbn(1.0, -96));
    }

    #[test]
    fn welford_matches_two_pass_and_merges() {
        let mut rng = Pcg32::new(5, 9);
        let xs: [[f32; 3]; 257] = core::array::from_fn(|_| {
            [
                rng.next_f32() * 10.0,
                rng.next_f32(),
                rng.next_f32() * 0.1 + 3.0,
            ]
        });
        let mut w = Welford::new();
        xs.iter().for_each(|&x| w.push(x));
        let (mut a, mut b) = (Welford::new(), Welford::new());
        xs[..100].iter().for_each(|&x| a.push(x));
        xs[100..].iter().for_each(|&x| b.push(x));
        a.merge(&b);
        let n = xs.len() as f64;
        for ch in 0..3 {
            let mean = xs.iter().map(|x| f64::from(x[ch])).sum::<f64>() / n;
            let var = xs
                .iter()
                .map(|x| (f64::from(x[ch]) - mean).powi(2))
                .sum::<f64>()
                / (n - 1.0);
            let (wm, wv) = (w.mean_rgb().unwrap()[ch], w.variance().unwrap()[ch]);
            assert!((wm - mean).abs() <= 1e-13 * mean.abs().max(1.0));
            assert!((wv - var).abs() <= 1e-12 * var);
            assert!((a.mean_rgb().unwrap()[ch] - mean).abs() <= 1e-13 * mean.abs().max(1.0));
            assert!((a.variance().unwrap()[ch] - var).abs() <= 1e-12 * var);
        }
        assert_eq!(a.count(), 257);
    }

    #[test]
    fn welford_rejects_non_finite_samples() {
        let mut w = Welford::new();
        w.push([f32::NAN, 1.0, 1.0]);
        w.push([1.0, f32::INFINITY, 1.0]);
        w.push([1.0, 1.0, f32::NEG_INFINITY]);
        assert_eq!((w.count(), w.rejected()), (0, 3));
        assert_eq!(w.mean_rgb(), None);
        assert_eq!(w.variance(), None);
        w.push([2.0, 2.0, 2.0]);
        assert_eq!(w.mean_luminance(), Some(luminance([2.0; 3])));
        assert_eq!(w.variance(), None);
    }
}
