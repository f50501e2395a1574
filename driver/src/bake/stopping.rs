//! The stopping rule (`--target-error`): spend a texel's samples only until its
//! estimate is as good as asked, `--spp` the cap. Production bakers stop where a texel has
//! converged (Cycles' noise threshold); the paper's learning iterations (§2.2) are where this
//! bake can stop, so `--iterations 8` with the doubling schedule stops at every doubling of
//! the samples.
//!
//! **The error a texel has.** Each iteration draws its samples from its own Cranley–Patterson
//! rotation of the Sobol points (§2.4): the iterations are independent randomised
//! quasi-Monte Carlo replicates of the texel's value. The spread of the samples within an
//! iteration (`σ²/n`) is no measure of such an estimate's error — stratified points err less,
//! 1.7–2× less on the Cornell box at 1024 spp, so a rule on it sampled about 4× too long —
//! but the difference between two replicates is: `d = m_k − m_{k−1}` of the last two
//! iterations' means (`n_{k−1}`, `n_k` samples) has the variance of both, and the mean over
//! iterations `0..=k` (`N` samples) has about `d² · n_{k−1} n_k / ((n_{k−1} + n_k) N)`
//! (exact for independent samples, and falling as fast as the points converge). Its
//! *relative* error is that over `μ² + ε`, with `μ` the texel's value — its mean, plus the
//! direct light a series pass borrows from the direct pass (its samples are the gathered
//! light alone, its value the sum) — and `ε` a hundredth of the squared value over its group:
//! the bench's relative MSE regularises dark texels the same way (docs/BENCHMARKS.md), so a
//! texel in shadow, whose relative error has no bound, does not keep its group sampling to
//! the cap.
//!
//! **Who stops.** A group of texels, once the mean of their squared relative errors is
//! within the target's square: a gather cluster (its texels share the guide), or a tile of
//! the direct pass. One `d` per texel is a noisy estimate; the mean over a group is not, and
//! the mean (not the worst) makes the bake's error per texel, measured over every texel, the
//! target. Where the lightmap sums the two (series transport borrowing the direct pass's
//! light), their errors add in squares: the direct pass stops at `target/√2` relative to its
//! own light ([`share_of`]), and a gather cluster at what is left of `target²` once each
//! texel's borrowed light has erred that much ([`plan`]).
//!
//! **Where it stops.** At the end of an iteration, or within the next one: where the next
//! iteration's samples would overshoot, the group takes only the samples its error says it
//! still needs (the squared error falling as `1/samples`) in it and stops after it.
//!
//! Only the group's own samples decide, so a bake is the same bits on any thread count,
//! shard split or resume. What a texel's estimate cannot see, it cannot stop for: a series
//! pass's lookups read the previous pass's noise at every hit, which no texel's own
//! iterations hold (docs/budget.md, "The stopping rule").

use guidebake_kernels::estimator::{Welford, pooled};

/// `ε` over the squared mean of a texel's group (the bench's regulariser).
const DARK_FLOOR: f64 = 1e-2;

/// The target the direct pass stops at, of the bake's `target`: `target/√2` where the
/// lightmap borrows its light (`split`: a series texel's value is the direct pass's estimate
/// plus its gathered light, which [`plan`] lets err what is left of `target`²), else all of
/// it.
pub fn share_of(target: f32, split: bool) -> f32 {
    if split {
        target * core::f32::consts::FRAC_1_SQRT_2
    } else {
        target
    }
}

/// The mean luminance of `batches` pooled, from the batches' own luminance channel as
/// [`squared_error`] reads it (0 without samples).
fn mean_luminance(batches: &[Welford]) -> f64 {
    pooled(batches)
        .mean_luminance()
        .filter(|m| m.is_finite())
        .unwrap_or(0.0)
}

/// The squared error of the luminance mean over iterations `0..=k` of a texel's `row`, from
/// the difference of its last two iterations (module docs); `None` where either has no
/// sample or the value is not finite.
fn squared_error(row: &[Welford], k: usize) -> Option<f64> {
    let (a, b) = (&row[k - 1], &row[k]);
    let (ma, mb) = (a.mean_luminance()?, b.mean_luminance()?);
    let (na, nb) = (a.count() as f64, b.count() as f64);
    let total: f64 = row[..=k].iter().map(|w| w.count() as f64).sum();
    let d = mb - ma;
    let e = d * d * na * nb / ((na + nb) * total);
    e.is_finite().then_some(e)
}

/// What a group of texels does after an iteration ([`plan`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan {
    /// Its estimate is within the target: skip the remaining iterations.
    Stop,
    /// The next iteration's samples are more than it needs: take this many (whole packets of
    /// 8) in it, and stop after it.
    Last(u32),
    /// Go on with the next iteration as scheduled.
    Go,
}

/// The stopping rule after iteration `k` (≥ 1) of a group that has taken `taken` samples a
/// texel and is to take `next` in iteration `k + 1`: [`Plan::Stop`] once the mean of its
/// texels' squared relative errors (module docs) is within `target`², less what the direct
/// light they borrow may err (each texel's borrowed light `D` at most `target/√2` relative
/// to itself, the direct pass's share: `target²·D²/2` over the texel's `T² + ε`); else, the
/// squared error falling as `1/samples`, [`Plan::Last`] with the samples that bring it to
/// the target where `next` would take more, so a bake does not overshoot the target by up
/// to a whole doubling; else [`Plan::Go`].
pub fn plan<'b>(
    texels: impl Iterator<Item = (&'b [Welford], f64)>,
    k: usize,
    target: f32,
    taken: u32,
    next: u32,
) -> Plan {
    let t2 = f64::from(target) * f64::from(target);
    let Some((own, borrowed)) = group_errors(texels, k) else {
        return Plan::Go;
    };
    let allowed = t2 * (1.0 - 0.5 * borrowed);
    if own <= allowed {
        return Plan::Stop;
    }
    let needed = f64::from(taken) * (own / allowed - 1.0);
    if needed < f64::from(next) {
        let packets = (needed / 8.0).ceil().max(1.0) as u32;
        Plan::Last((packets * 8).min(next))
    } else {
        Plan::Go
    }
}

/// The root mean square relative error of a group of texels after iteration `k` (≥ 1):
/// `texels` are each texel's iterations (`0..=k` filled) and the light its value holds
/// besides them (the direct light a series pass borrows, which its samples do not hold; else
/// 0). `None` while a texel's last two iterations are not both sampled; 0 for no texel.
#[cfg(test)]
fn relative_error<'b>(texels: impl Iterator<Item = (&'b [Welford], f64)>, k: usize) -> Option<f64> {
    group_errors(texels, k).map(|(own, _)| own.sqrt())
}

/// Over a group: the mean of the texels' squared errors and the mean of their borrowed
/// light's squares, each over the texel's `T² + ε` (`T` its value, `ε` the group's floor).
fn group_errors<'b>(
    texels: impl Iterator<Item = (&'b [Welford], f64)>,
    k: usize,
) -> Option<(f64, f64)> {
    debug_assert!(k >= 1, "a replicate difference needs two iterations");
    // Each texel's value, borrowed light and squared error, in one pass over its batches.
    let texels: Vec<(f64, f64, f64)> = texels
        .map(|(row, besides)| {
            let level = mean_luminance(&row[..=k]) + besides;
            Some((level, besides, squared_error(row, k)?))
        })
        .collect::<Option<_>>()?;
    if texels.is_empty() {
        return Some((0.0, 0.0));
    }
    let n = texels.len() as f64;
    let floor = DARK_FLOOR * texels.iter().map(|(l, _, _)| l * l).sum::<f64>() / n;
    let (mut own, mut borrowed) = (0.0f64, 0.0f64);
    for (level, besides, e) in texels {
        let scale = level * level + floor;
        if scale > 0.0 {
            own += e / scale;
            borrowed += besides * besides / scale;
        }
    }
    Some((own / n, borrowed / n))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the group stops after iteration `k`.
    fn converged<'b>(
        texels: impl Iterator<Item = (&'b [Welford], f64)>,
        k: usize,
        target: f32,
    ) -> bool {
        plan(texels, k, target, 1, 0) == Plan::Stop
    }
    use guidebake_kernels::testing::Pcg32;

    /// A batch of `n` independent samples of mean `mean` and standard deviation `sd`.
    fn batch(rng: &mut Pcg32, n: usize, mean: f32, sd: f32) -> Welford {
        let mut w = Welford::new();
        for _ in 0..n {
            let x = mean + sd * 3f32.sqrt() * (2.0 * rng.next_f32() - 1.0);
            w.push([x; 3]);
        }
        w
    }

    /// Texels of independent samples (relative sd 1 per sample) in doubling iterations of
    /// 32, 32, 64, 128 samples, and the last empty.
    fn texels(rng: &mut Pcg32, count: usize, mean: f32) -> Vec<Vec<Welford>> {
        (0..count)
            .map(|_| {
                [32, 32, 64, 128]
                    .map(|n| batch(rng, n, mean, mean))
                    .into_iter()
                    .chain([Welford::new()])
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_replicates_difference_measures_the_error_of_independent_samples() {
        // Independent samples: the relative error of the mean of N samples is 1/√N (the
        // floor, a hundredth of μ², shrinks it by √1.01): after 64 samples 0.125, after 128
        // 0.088, after 256 0.0625. Over 400 texels the estimate is within 8 %.
        let mut rng = Pcg32::new(3, 7);
        let rows = texels(&mut rng, 400, 2.0);
        let group = || rows.iter().map(|r| (r.as_slice(), 0.0));
        for (k, want) in [(1, 0.125), (2, 0.0884), (3, 0.0625)] {
            let e = relative_error(group(), k).unwrap();
            let got = e * 1.01f64.sqrt();
            assert!((got / want - 1.0).abs() < 0.08, "k {k}: {got} for {want}");
            assert!(converged(group(), k, (e * 1.001) as f32));
            assert!(!converged(group(), k, (e * 0.999) as f32));
        }
        // The same samples beside as much light again (the borrowed direct light): half the
        // relative error.
        let alone = relative_error(group(), 3).unwrap();
        let beside = relative_error(rows.iter().map(|r| (r.as_slice(), 2.0)), 3).unwrap();
        assert!(
            (beside / alone - 0.5).abs() < 0.01,
            "{beside} against {alone}"
        );
        // ... and that light may err target/√2 of its half of the value: the samples get
        // target²·(1 − ¼·½) of the square, so a group stops at beside/√(7/8).
        let stops = beside / (7.0f64 / 8.0).sqrt();
        let group = || rows.iter().map(|r| (r.as_slice(), 2.0));
        assert!(converged(group(), 3, (stops * 1.002) as f32));
        assert!(!converged(group(), 3, (stops * 0.998) as f32));
    }

    #[test]
    fn a_group_takes_only_the_samples_it_still_needs() {
        // After 256 samples a relative error e: the target e/√1.5 needs 384 in all, so 128
        // more, where the next iteration would take 512 (rounded up to whole packets).
        let mut rng = Pcg32::new(11, 3);
        let rows = texels(&mut rng, 100, 1.0);
        let group = || rows.iter().map(|r| (r.as_slice(), 0.0));
        let e = relative_error(group(), 3).unwrap();
        let plan_for = |target: f64, next| plan(group(), 3, target as f32, 256, next);
        assert_eq!(plan_for(e / 1.5f64.sqrt(), 512), Plan::Last(128));
        // Where the next iteration does not overshoot, it is taken as scheduled.
        assert_eq!(plan_for(e / 1.5f64.sqrt(), 120), Plan::Go);
        assert_eq!(plan_for(e / 3.0, 512), Plan::Go);
        assert_eq!(plan_for(e * 1.001, 512), Plan::Stop);
        // At least a packet.
        assert_eq!(plan_for(e * 0.9999, 512), Plan::Last(8));
    }

    #[test]
    fn replicates_that_agree_better_than_their_spread_say_so() {
        // Stratified samples: each iteration's mean is exact up to 10⁻³ relative, whatever
        // its samples' spread (a relative sd of 1 per sample: 0.088 after 128 if they were
        // independent); the rule measures at most 10⁻³.
        let rows: Vec<Vec<Welford>> = (0..16)
            .map(|i| {
                let mut rng = Pcg32::new(i, 1);
                (0..3)
                    .map(|j| {
                        let mut w = Welford::new();
                        let shift = 1e-3 * (2.0 * rng.next_f32() - 1.0);
                        for s in 0..64 {
                            let x = if (s + j) % 2 == 0 { 0.0 } else { 2.0 };
                            w.push([x + shift; 3]);
                        }
                        w
                    })
                    .collect()
            })
            .collect();
        let e = relative_error(rows.iter().map(|r| (r.as_slice(), 0.0)), 1).unwrap();
        assert!(e <= 1e-3, "{e}");
    }

    #[test]
    fn a_dark_texel_is_judged_against_its_group_and_an_unsampled_one_waits() {
        // Texels of mean 10⁻⁴ beside as many of mean 1: alone their relative error is
        // ~0.0625, against a hundredth of the group's squared value next to none.
        let mut rng = Pcg32::new(5, 9);
        let bright = texels(&mut rng, 200, 1.0);
        let dark = texels(&mut rng, 200, 1e-4);
        let error = |rows: &[&Vec<Welford>]| {
            relative_error(rows.iter().map(|r| (r.as_slice(), 0.0)), 3).unwrap()
        };
        let (b, d) = (
            error(&bright.iter().collect::<Vec<_>>()),
            error(&dark.iter().collect::<Vec<_>>()),
        );
        let both = error(&bright.iter().chain(&dark).collect::<Vec<_>>());
        assert!((d / 0.0625 - 1.0).abs() < 0.1, "{d}");
        // Half the texels bright, the other half next to no error: b/√2 (the floor is
        // then half of a bright texel's hundredth).
        assert!(
            (both / (b / 2f64.sqrt()) - 1.0).abs() < 0.01,
            "{both} against {b}"
        );
        // A texel whose last iteration took no sample waits; so does its group.
        let mut rows: Vec<&Vec<Welford>> = bright.iter().collect();
        let unsampled = vec![Welford::new(); 5];
        rows.push(&unsampled);
        assert!(relative_error(rows.iter().map(|r| (r.as_slice(), 0.0)), 3).is_none());
        assert!(!converged(rows.iter().map(|r| (r.as_slice(), 0.0)), 3, 0.5));
        // A group of zeros (an unlit tile) has no error to wait for.
        let mut zeros = Welford::new();
        zeros.push([0.0; 3]);
        let unlit = [zeros, zeros];
        assert!(converged([(&unlit[..], 0.0)].into_iter(), 1, 0.01));
    }
}
