//! The stopping rule (`--target-error`; issue 44): spend a texel's samples only until its
//! estimate is as good as asked, `--spp` the cap. Production bakers stop where a texel has
//! converged (Cycles' noise threshold); the paper's learning iterations (§2.2) are where this
//! bake can stop, so `--iterations 8` with the doubling schedule stops at every doubling of
//! the samples.
//!
//! **The error a texel has.** After iterations `0..=k`, a texel's samples pooled over them
//! give the variance of its mean, `σ²/n`, of the luminance. Its *relative* error is that over
//! `μ² + ε`, with `μ` the texel's value — its mean, plus the direct light a series pass
//! borrows from the direct pass (its samples are the gathered light alone, its value the
//! sum) — and `ε` a hundredth of the squared value over its neighbours (the cluster's texels,
//! or the direct pass's tile): the bench's relative MSE regularises dark texels the same way
//! (docs/BENCHMARKS.md), so a texel in shadow, whose relative error has no bound, does not
//! keep its cluster sampling to the cap.
//!
//! **Who stops.** A gather cluster, once the root mean square of its texels' relative errors
//! is within the target: its texels share the guide and stop together, and the mean over them
//! (not the worst) makes the bake's error per texel, measured over every texel, the target. A
//! texel of the direct pass (no clusters, no guide), once its own is within it. Where the
//! lightmap sums the two (series transport borrowing the direct pass's light), each stops at
//! `target/√2` ([`share_of`]): their errors add in squares.
//!
//! Only the cluster's (or the tile's) own samples decide, so a bake is the same bits on any
//! thread count, shard split or resume. What a texel's estimate cannot see, it cannot stop
//! for: a series pass's lookups read the previous pass's noise at every hit, which no texel's
//! own variance holds (docs/estimator.md, "The stopping rule").

use guidebake_kernels::estimator::Welford;

/// `ε` over the squared mean of a texel's neighbours (the bench's regulariser).
const DARK_FLOOR: f64 = 1e-2;

/// The target one estimate of a texel's value stops at, of the bake's `target`: all of it
/// where the estimate is the whole value, `target/√2` where the value is the sum of two
/// estimates that stop apart (`split`: a series pass's gathered light and the direct pass's
/// direct light, each within `target/√2` relative to the value, sum to within `target`).
pub fn share_of(target: f32, split: bool) -> f32 {
    if split {
        target * core::f32::consts::FRAC_1_SQRT_2
    } else {
        target
    }
}

/// The squared relative standard error of the luminance mean of `batches` pooled, over
/// `(μ + besides)² + floor`; `None` without two samples or a finite value. Samples that are
/// all the same (all zero, in an unlit tile too) have none.
fn relative_variance(batches: &[Welford], besides: f64, floor: f64) -> Option<f64> {
    let mut pooled = Welford::new();
    batches.iter().for_each(|b| pooled.merge(b));
    let (var, mean) = (pooled.luminance_variance()?, pooled.mean_luminance()?);
    if var == 0.0 {
        return Some(0.0);
    }
    let level = mean + besides;
    let r = var / pooled.count() as f64 / (level * level + floor);
    r.is_finite().then_some(r)
}

/// The mean luminance of `batches` pooled (0 without samples).
fn mean_luminance(batches: &[Welford]) -> f64 {
    let mut pooled = Welford::new();
    batches.iter().for_each(|b| pooled.merge(b));
    pooled
        .mean_luminance()
        .filter(|m| m.is_finite())
        .unwrap_or(0.0)
}

/// Whether a cluster may skip its iterations after `k`: `texels` are its texels' batch rows
/// (each the texel's iterations, `0..=k` filled) and the light each texel's value holds
/// besides them (the direct light a series pass borrows from the direct pass, which its
/// samples do not hold; 0 where they hold it all), and the root mean square of their
/// relative standard errors is within `target`. A texel without two finite samples counts
/// as unknown: the cluster goes on.
pub fn cluster_converged<'b>(
    texels: impl Iterator<Item = (&'b [Welford], f64)> + Clone,
    k: usize,
    target: f32,
) -> bool {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (row, besides) in texels.clone() {
        let m = mean_luminance(&row[..=k]) + besides;
        sum += m * m;
        n += 1;
    }
    if n == 0 {
        return true;
    }
    let floor = DARK_FLOOR * sum / n as f64;
    let mut squared = 0.0f64;
    for (row, besides) in texels {
        match relative_variance(&row[..=k], besides, floor) {
            Some(r) => squared += r,
            None => return false,
        }
    }
    squared / n as f64 <= f64::from(target) * f64::from(target)
}

/// The direct pass's stopping floor for a tile: `ε` from its texels' mean luminance over
/// iterations `0..=k` (`rows`: each texel's iterations).
pub fn tile_floor<'b>(rows: impl Iterator<Item = &'b [Welford]>, k: usize) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for row in rows {
        let m = mean_luminance(&row[..=k]);
        sum += m * m;
        n += 1;
    }
    if n == 0 {
        0.0
    } else {
        DARK_FLOOR * sum / n as f64
    }
}

/// Whether a texel of the direct pass may skip its iterations after `k`: its relative
/// standard error over `0..=k`, with the tile's `floor`, is within `target`. A texel whose
/// every sample so far was zero (in shadow, or facing no light) stops: it has no variance.
pub fn texel_converged(row: &[Welford], k: usize, floor: f64, target: f32) -> bool {
    match relative_variance(&row[..=k], 0.0, floor) {
        Some(r) => r <= f64::from(target) * f64::from(target),
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::Pcg32;

    /// A batch of `n` samples of mean `mean` and standard deviation `sd` (uniform noise).
    fn batch(rng: &mut Pcg32, n: usize, mean: f32, sd: f32) -> Welford {
        let mut w = Welford::new();
        for _ in 0..n {
            let x = mean + sd * 3f32.sqrt() * (2.0 * rng.next_f32() - 1.0);
            w.push([x; 3]);
        }
        w
    }

    #[test]
    fn a_cluster_stops_once_its_root_mean_square_relative_error_is_within_the_target() {
        // Per-sample relative sd 1: after n samples the relative error is 1/√n (the floor,
        // a hundredth of μ², shrinks it by √1.01). 64 + 64 samples: 0.088; 0.09 stops,
        // 0.08 does not; a third batch of 128 (0.062) then does.
        let mut rng = Pcg32::new(3, 7);
        let rows: Vec<Vec<Welford>> = (0..16)
            .map(|_| {
                vec![
                    batch(&mut rng, 64, 2.0, 2.0),
                    batch(&mut rng, 64, 2.0, 2.0),
                    batch(&mut rng, 128, 2.0, 2.0),
                    Welford::new(),
                ]
            })
            .collect();
        let texels = || rows.iter().map(|r| (r.as_slice(), 0.0));
        assert!(cluster_converged(texels(), 1, 0.095));
        assert!(!cluster_converged(texels(), 1, 0.08));
        assert!(cluster_converged(texels(), 2, 0.08));
        assert!(!cluster_converged(texels(), 2, 0.05));
        // The same samples beside as much light again (the borrowed direct light): half the
        // relative error.
        let beside = || rows.iter().map(|r| (r.as_slice(), 2.0));
        assert!(cluster_converged(beside(), 1, 0.05));
        assert!(!cluster_converged(beside(), 1, 0.04));
    }

    #[test]
    fn a_dark_texel_is_judged_against_its_neighbours_not_its_own_mean() {
        // One texel of mean 10⁻⁴ beside bright ones: alone its relative error is ~0.09/10⁻⁴,
        // against a hundredth of its neighbours' squared mean it is small; one texel without
        // two samples keeps the cluster going.
        let mut rng = Pcg32::new(5, 9);
        let mut rows: Vec<Vec<Welford>> = (0..8)
            .map(|_| vec![batch(&mut rng, 256, 1.0, 0.5), Welford::new()])
            .collect();
        rows.push(vec![batch(&mut rng, 256, 1e-4, 1e-4), Welford::new()]);
        assert!(cluster_converged(
            rows.iter().map(|r| (r.as_slice(), 0.0)),
            0,
            0.05
        ));
        let floor = tile_floor(rows.iter().map(Vec::as_slice), 0);
        assert!(texel_converged(&rows[8], 0, floor, 0.01));
        assert!(!texel_converged(&rows[8], 0, 0.0, 0.01));
        rows.push(vec![Welford::new(), Welford::new()]);
        assert!(!cluster_converged(
            rows.iter().map(|r| (r.as_slice(), 0.0)),
            0,
            0.5
        ));
    }

    #[test]
    fn a_texel_of_zeros_stops_on_a_lit_tile_and_an_unlit_tile_stops() {
        let mut rng = Pcg32::new(1, 1);
        let lit = [batch(&mut rng, 64, 3.0, 1.0)];
        let dark = [batch(&mut rng, 64, 0.0, 0.0)];
        let floor = tile_floor([&lit[..], &dark[..]].into_iter(), 0);
        assert!(floor > 0.0);
        assert!(texel_converged(&dark, 0, floor, 0.01));
        // A tile with no light at all: zeros have no error to wait for.
        let floor = tile_floor([&dark[..]].into_iter(), 0);
        assert_eq!(floor, 0.0);
        assert!(texel_converged(&dark, 0, floor, 0.01));
        // One sample is no estimate of the error.
        let one = [batch(&mut rng, 1, 3.0, 1.0)];
        assert!(!texel_converged(&one, 0, floor, 0.5));
    }
}
