//! The spatial budget (`--budget`): how many gather samples each texel of the last pass of a
//! series bake gets, from the error the previous passes measured there — and how many
//! next-event samples the direct pass's later iterations take, from the error its tile's
//! earlier iterations measured ([`tile_factors`]). Paper §2.5 weighs a texel's iterations
//! by their variance; this spends the samples themselves by it, as production bakers spend
//! them where the error is (docs/budget.md, "The spatial budget").
//!
//! The last pass b ≥ 2 of a series bake reads, per texel, the previous gather pass's result (and the
//! direct pass's, when that pass borrowed its direct light): the per-sample luminance
//! variance σ² = (relative standard error × mean)² × samples, summed over the two, and the
//! mean μ. Each 8×8-texel block of a page gets the root mean square over its baked texels of
//! the allocation's `a` — σ ([`Budget::Mse`]), σ/√(μ·μ̄) ([`Budget::Balanced`]) or
//! σ/√(μ² + 10⁻²·μ̄²) ([`Budget::Relative`]), or σ·√(1/(μ² + 10⁻²·μ̄²) + λ/μ̄²)
//! ([`Budget::Bounded`]: the least relative error whose predicted squared error stays within
//! the uniform budget's, λ the smallest that keeps it there), μ̄ the world's mean — and its
//! texels take
//! `a_block / ā` times the iteration's samples, ā the texel-weighted mean over the world's
//! blocks, clamped to [¼, 4] and normalised again, so the pass spends about `--spp` samples
//! a texel in all (each count rounded to a step of 2^¼ and to whole packets, [`scaled`]). The blocks are computed once, before the pass, from the merged previous
//! pass: every tile's factors are fixed whatever thread, shard or resume bakes it.

use crate::output::OutputFileError;
use crate::output::result_file::{FLAG_BAKED, ResultFile, TexelResult};
use crate::texels::TexelFile;

use super::settings::Budget;
use crate::transport::world::Blocks;
pub use crate::transport::world::{BLOCK, SpatialBudget};

/// Fewest samples a texel gets, as a fraction of the uniform count.
pub const MIN_FACTOR: f32 = 0.25;
/// Most samples a texel gets, as a multiple of the uniform count.
pub const MAX_FACTOR: f32 = 4.0;
/// The relative allocation's floor on μ², as a fraction of μ̄² (the bench's relative MSE's ε).
const RELATIVE_EPSILON: f64 = 1e-2;
/// [`Budget::Bounded`] tries λ from 2^-20 to 2^20 of 1/μ̄² (in half-powers): past either end
/// the factors are the relative or the MSE allocation's.
const BOUNDED_DOUBLINGS: i32 = 20;

/// One texel of the previous passes, as the budget reads it.
#[derive(Clone, Copy, Debug)]
pub struct Measured {
    /// Page of the texel.
    pub page: u32,
    /// Pixel (x, y) on the page.
    pub pixel: [u32; 2],
    /// Per-sample luminance variance.
    pub variance: f64,
    /// Mean luminance.
    pub mean: f64,
}

impl SpatialBudget {
    /// The budget of `budget` for pages of `sizes` (width, height) from the texels
    /// `for_each` hands its callback — called twice, first for the world's mean, then for the
    /// blocks, so nothing per texel is held; `None` for [`Budget::Uniform`] or when nothing
    /// lit was measured.
    ///
    /// # Errors
    /// `for_each`'s.
    pub fn from_measured<E>(
        budget: Budget,
        sizes: &[(u32, u32)],
        for_each: impl Fn(&mut dyn FnMut(Measured)) -> Result<(), E>,
    ) -> Result<Option<Self>, E> {
        if budget == Budget::Uniform {
            return Ok(None);
        }
        let usable = |m: &Measured| m.mean.is_finite() && m.variance.is_finite();
        let (mut sum, mut count) = (0.0, 0u64);
        for_each(&mut |m| {
            if usable(&m) {
                sum += m.mean.max(0.0);
                count += 1;
            }
        })?;
        let world_mean = sum / count.max(1) as f64;
        if count == 0 || world_mean.is_nan() || world_mean <= 0.0 {
            return Ok(None);
        }
        let columns = |w: u32| w.div_ceil(BLOCK);
        let mut sums: Vec<Vec<BlockSums>> = sizes
            .iter()
            .map(|&(w, h)| vec![BlockSums::default(); (columns(w) * h.div_ceil(BLOCK)) as usize])
            .collect();
        for_each(&mut |m| {
            let Some(page) = sums.get_mut(m.page as usize).filter(|_| usable(&m)) else {
                return;
            };
            let i = (m.pixel[1] / BLOCK * columns(sizes[m.page as usize].0) + m.pixel[0] / BLOCK)
                as usize;
            if let Some(block) = page.get_mut(i) {
                let (variance, mean) = (m.variance.max(0.0), m.mean.max(0.0));
                block.a2 += allocation(budget, variance, mean, world_mean);
                block.variance += variance;
                block.texels += 1;
            }
        })?;
        let factors = if budget == Budget::Bounded {
            bounded(&sums, world_mean)
        } else {
            block_factors(&sums, |b| b.a2)
        };
        let Some(factors) = factors else {
            return Ok(None);
        };
        let pages = factors
            .into_iter()
            .zip(sizes)
            .map(|(factors, &(w, _))| Blocks {
                columns: columns(w),
                factors,
            })
            .collect();
        Ok(Some(Self { pages }))
    }

    /// The budget from the previous gather pass's results (and the direct pass's, when that
    /// pass borrowed its direct light), reading the result files tile by tile, twice.
    ///
    /// # Errors
    /// A result file that cannot be read, with its path.
    pub fn from_results(
        budget: Budget,
        texels: &TexelFile,
        results: &ResultFile,
        direct: Option<&ResultFile>,
    ) -> Result<Option<Self>, OutputFileError> {
        let sizes: Vec<(u32, u32)> = texels.pages().iter().map(|p| (p.width, p.height)).collect();
        Self::from_measured(budget, &sizes, |visit| {
            let (mut buffer, mut direct_buffer) = (Vec::new(), Vec::new());
            for (t, tile) in texels.tiles().iter().enumerate() {
                let n = tile.texel_count as usize;
                buffer.resize(n, TexelResult::default());
                results.read(tile.first_texel, &mut buffer)?;
                direct_buffer.resize(n, TexelResult::default());
                if let Some(direct) = direct {
                    direct.read(tile.first_texel, &mut direct_buffer)?;
                }
                let each = texels
                    .tile_texels(t)
                    .iter()
                    .zip(&buffer)
                    .zip(&direct_buffer);
                for ((texel, r), d) in each {
                    if r.flags & FLAG_BAKED == 0 {
                        continue;
                    }
                    let (variance, mean) = per_sample(r);
                    let (dv, dm) = if direct.is_some() {
                        per_sample(d)
                    } else {
                        (0.0, 0.0)
                    };
                    visit(Measured {
                        page: texel.page,
                        pixel: texel.pixel.map(u32::from),
                        variance: variance + dv,
                        mean: mean + dm,
                    });
                }
                texels.release_tile(t);
            }
            Ok(())
        })
    }
}

/// The direct pass's budget within one tile ([`super::gather`]'s `TileBaker::direct_budget`:
/// the later iterations by the earlier ones): per texel of `measured`, in its order, the
/// factor of its 8×8-texel block by `budget`, normalised over the tile's texels alone, so a
/// tile spends about its uniform samples and decides from nothing but its own; `None` for
/// [`Budget::Uniform`] or where nothing lit was measured. The blocks span only the tile's
/// bounding box on each page (its corner on the block grid, so the blocks are the page's).
pub fn tile_factors(budget: Budget, measured: &[Measured]) -> Option<Vec<f32>> {
    // Per page: the block-aligned corner and the far edge of the tile's texels on it.
    let mut boxes: Vec<([u32; 2], [u32; 2])> = Vec::new();
    for m in measured {
        let page = m.page as usize;
        if boxes.len() <= page {
            boxes.resize(page + 1, ([u32::MAX; 2], [0; 2]));
        }
        let (corner, end) = &mut boxes[page];
        for axis in 0..2 {
            corner[axis] = corner[axis].min(m.pixel[axis] / BLOCK * BLOCK);
            end[axis] = end[axis].max(m.pixel[axis] + 1);
        }
    }
    let sizes: Vec<(u32, u32)> = boxes
        .iter()
        .map(|&(corner, end)| {
            (
                end[0].saturating_sub(corner[0]).max(1),
                end[1].saturating_sub(corner[1]).max(1),
            )
        })
        .collect();
    let local: Vec<Measured> = measured
        .iter()
        .map(|m| {
            let corner = boxes[m.page as usize].0;
            Measured {
                pixel: [m.pixel[0] - corner[0], m.pixel[1] - corner[1]],
                ..*m
            }
        })
        .collect();
    let each = |visit: &mut dyn FnMut(Measured)| {
        local.iter().copied().for_each(visit);
        Ok::<(), std::convert::Infallible>(())
    };
    let Ok(factors) = SpatialBudget::from_measured(budget, &sizes, each);
    let factors = factors?;
    Some(
        local
            .iter()
            .map(|m| factors.factor(m.page, m.pixel))
            .collect(),
    )
}

/// One block's sums over its measured texels.
#[derive(Clone, Copy, Debug, Default)]
struct BlockSums {
    /// Σ of the allocation's `a²` (the relative one's for [`Budget::Bounded`], [`allocation`]).
    a2: f64,
    /// Σ of the per-sample variances σ².
    variance: f64,
    texels: u32,
}

/// Each page's block factors for the per-texel `a²` sums `a2` hands: a block's root mean
/// square `a` over the texel-weighted mean ā, clamped to [¼, 4] and normalised again; `None`
/// where no block has any `a`.
fn block_factors(sums: &[Vec<BlockSums>], a2: impl Fn(&BlockSums) -> f64) -> Option<Vec<Vec<f32>>> {
    let a = |b: &BlockSums| {
        if b.texels > 0 {
            (a2(b) / f64::from(b.texels)).sqrt()
        } else {
            0.0
        }
    };
    let weighted = |f: &dyn Fn(&BlockSums) -> f64| -> f64 {
        let (mut total, mut texels) = (0.0, 0u64);
        for block in sums.iter().flatten() {
            total += f(block) * f64::from(block.texels);
            texels += u64::from(block.texels);
        }
        total / texels.max(1) as f64
    };
    let mean_a = weighted(&a);
    if !(mean_a.is_finite() && mean_a > 0.0) {
        return None;
    }
    let clamp = |f: f64| f.clamp(f64::from(MIN_FACTOR), f64::from(MAX_FACTOR));
    let first = |b: &BlockSums| clamp(a(b) / mean_a);
    let renormalise = weighted(&first);
    Some(
        sums.iter()
            .map(|blocks| {
                blocks
                    .iter()
                    .map(|b| clamp(first(b) / renormalise) as f32)
                    .collect()
            })
            .collect(),
    )
}

/// The [`Budget::Bounded`] factors: n ∝ σ·√(1/(μ² + ε) + λ/μ̄²) — the least relative MSE
/// for the samples once the squared error Σσ²/n is bounded by the uniform budget's (the
/// Lagrangian of both sums) — with the smallest λ of a grid of half-powers of 2 whose
/// predicted squared error is within the uniform budget's; `None` (uniform) if none is.
fn bounded(sums: &[Vec<BlockSums>], world_mean: f64) -> Option<Vec<Vec<f32>>> {
    let uniform: f64 = sums.iter().flatten().map(|b| b.variance).sum();
    let predicted = |factors: &[Vec<f32>]| -> f64 {
        sums.iter()
            .flatten()
            .zip(factors.iter().flatten())
            .map(|(b, &f)| b.variance / f64::from(f))
            .sum()
    };
    let scale = 1.0 / (world_mean * world_mean);
    std::iter::once(0.0)
        .chain(
            (-2 * BOUNDED_DOUBLINGS..=2 * BOUNDED_DOUBLINGS).map(|k| (f64::from(k) * 0.5).exp2()),
        )
        .find_map(|lambda| {
            let factors = block_factors(sums, |b| lambda.mul_add(b.variance * scale, b.a2))?;
            (predicted(&factors) <= uniform).then_some(factors)
        })
}

/// A texel result's per-sample luminance variance and mean luminance (of its plain average,
/// which its relative standard error is of).
pub(super) fn per_sample(r: &TexelResult) -> (f64, f64) {
    let mean = f64::from(guidebake_kernels::estimator::luminance_f32(r.total));
    let se = f64::from(r.rel_std_error) * mean;
    (se * se * f64::from(r.samples), mean)
}

/// The allocation's `a²` for a texel of per-sample variance `variance` and mean `mean`, in a
/// world of mean `world_mean` (> 0); [`Budget::Bounded`]'s is the relative one, to which
/// [`bounded`] adds its λ term.
fn allocation(budget: Budget, variance: f64, mean: f64, world_mean: f64) -> f64 {
    match budget {
        Budget::Uniform => 1.0,
        Budget::Mse => variance,
        Budget::Balanced => {
            variance / (mean.max(RELATIVE_EPSILON.sqrt() * world_mean) * world_mean)
        }
        Budget::Relative | Budget::Bounded => {
            variance / (mean * mean + RELATIVE_EPSILON * world_mean * world_mean)
        }
    }
}

/// Steps per doubling the factors are rounded to before they scale a sample count: at most
/// 17 counts per iteration between ¼ and 4, so a worker keeps at most 17 presorted orders
/// per iteration whatever `--spp` (a 19 % step).
pub const STEPS_PER_DOUBLING: f32 = 4.0;

/// Samples a texel of factor `factor` takes where the uniform budget takes `n`: the factor
/// rounded to a power of 2^(1/[`STEPS_PER_DOUBLING`]), then whole packets of 8, at least one.
pub fn scaled(n: u32, factor: f32) -> u32 {
    if n == 0 || factor == 1.0 {
        return n;
    }
    let steps = (factor.log2() * STEPS_PER_DOUBLING).round() / STEPS_PER_DOUBLING;
    let packets = (f64::from(n) / 8.0 * f64::from(steps).exp2())
        .round()
        .max(1.0);
    packets as u32 * 8
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texel(x: u32, y: u32, variance: f64, mean: f64) -> Measured {
        Measured {
            page: 0,
            pixel: [x, y],
            variance,
            mean,
        }
    }

    fn of(budget: Budget, sizes: &[(u32, u32)], texels: &[Measured]) -> Option<SpatialBudget> {
        let each = |visit: &mut dyn FnMut(Measured)| {
            texels.iter().copied().for_each(&mut *visit);
            Ok::<(), ()>(())
        };
        SpatialBudget::from_measured(budget, sizes, each).unwrap()
    }

    /// A 16×8 page: the left block's texels four times as noisy (σ) as the right block's.
    fn two_blocks(budget: Budget) -> SpatialBudget {
        let texels: Vec<Measured> = (0..16)
            .flat_map(|x| (0..8).map(move |y| (x, y)))
            .map(|(x, y)| texel(x, y, if x < 8 { 16.0 } else { 1.0 }, 1.0))
            .collect();
        of(budget, &[(16, 8)], &texels).unwrap()
    }

    #[test]
    fn noisier_blocks_get_more_samples_and_the_total_stays() {
        for budget in [
            Budget::Mse,
            Budget::Balanced,
            Budget::Relative,
            Budget::Bounded,
        ] {
            let b = two_blocks(budget);
            let (left, right) = (b.factor(0, [3, 3]), b.factor(0, [12, 7]));
            // a = 4 and 1, ā = 2.5: 1.6 and 0.4, which average 1.
            assert!((left - 1.6).abs() < 1e-6, "{budget:?}: {left}");
            assert!((right - 0.4).abs() < 1e-6, "{budget:?}: {right}");
            assert_eq!(b.factor(1, [0, 0]), 1.0, "outside the pages");
        }
    }

    #[test]
    fn the_allocations_weigh_bright_and_dark_texels_as_their_errors_do() {
        // Two texels of the same relative noise (σ = μ), one 4× brighter; μ̄ = 2.5.
        let texels = [texel(0, 0, 16.0, 4.0), texel(8, 0, 1.0, 1.0)];
        let ratio = |budget| {
            let b = of(budget, &[(16, 8)], &texels).unwrap();
            let (bright, dark) = (b.factor(0, [0, 0]), b.factor(0, [8, 0]));
            assert!(
                ((bright + dark) / 2.0 - 1.0).abs() < 1e-6,
                "{budget:?}: about --spp"
            );
            bright / dark
        };
        // n ∝ σ: 4 to 1; σ/√(μ·μ̄): 2 to 1; σ/√(μ² + ε), ε = 0.0625: √(16.0625 / 17) to 1.
        assert!((ratio(Budget::Mse) - 4.0).abs() < 1e-5);
        assert!((ratio(Budget::Balanced) - 2.0).abs() < 1e-5);
        assert!((ratio(Budget::Relative) - (17.0f32 / 16.0625).sqrt()).abs() < 1e-5);
    }

    #[test]
    fn the_bounded_allocation_keeps_the_squared_error_within_the_uniform_budgets() {
        // Three blocks (μ̄ = 3): bright of relative noise 1, bright and quiet, dim of relative
        // noise 2. The relative allocation takes samples from both bright blocks to the dim
        // one and raises Σσ²/f above the uniform 21; taking them from the quiet one alone
        // keeps it within.
        let texels = [
            texel(0, 0, 16.0, 4.0),
            texel(8, 0, 1.0, 4.0),
            texel(16, 0, 4.0, 1.0),
        ];
        let epsilon = RELATIVE_EPSILON * 3.0 * 3.0;
        let a = texels.map(|t| t.variance / (t.mean * t.mean + epsilon));
        let predicted = |budget| {
            let b = of(budget, &[(24, 8)], &texels).unwrap();
            let f = [0, 8, 16].map(|x| f64::from(b.factor(0, [x, 0])));
            let mse: f64 = (0..3).map(|i| texels[i].variance / f[i]).sum();
            let relative: f64 = (0..3).map(|i| a[i] / f[i]).sum();
            (mse, relative)
        };
        let (relative_mse, least_relative) = predicted(Budget::Relative);
        let (mse, relative) = predicted(Budget::Bounded);
        assert!(
            relative_mse > 21.0,
            "the relative allocation alone: {relative_mse}"
        );
        assert!(
            mse <= 21.0 && mse > 20.0,
            "within the uniform MSE, and close: {mse}"
        );
        let uniform: f64 = a.iter().sum();
        assert!(
            relative < 0.9 * uniform,
            "{relative} against uniform {uniform}"
        );
        assert!(
            relative > least_relative,
            "{relative} against {least_relative}"
        );
        // Where the relative allocation keeps within the uniform MSE it is the bounded one.
        let same_mean = [texel(0, 0, 16.0, 1.0), texel(8, 0, 1.0, 1.0)];
        assert_eq!(
            of(Budget::Bounded, &[(16, 8)], &same_mean),
            of(Budget::Relative, &[(16, 8)], &same_mean)
        );
    }

    #[test]
    fn a_tiles_factors_are_its_own_blocks_normalised_over_its_texels() {
        // A tile of 8 texels on page 1, four in a block 16× as noisy as the other four's,
        // listed out of order: the noisy block's texels get 1.6, the quiet one's 0.4, in the
        // order given, whatever else lies on the page.
        let tile: Vec<Measured> = [
            (9, 1),
            (17, 0),
            (8, 0),
            (16, 1),
            (9, 0),
            (17, 1),
            (8, 1),
            (16, 0),
        ]
        .into_iter()
        .map(|(x, y)| Measured {
            page: 1,
            ..texel(x, y, if x < 16 { 16.0 } else { 1.0 }, 1.0)
        })
        .collect();
        let factors = tile_factors(Budget::Mse, &tile).unwrap();
        for (m, f) in tile.iter().zip(&factors) {
            let want = if m.pixel[0] < 16 { 1.6 } else { 0.4 };
            assert!((f - want).abs() < 1e-6, "{m:?}: {f}");
        }
        // The same tile far down the page, on the same block grid: the same factors.
        let far: Vec<Measured> = tile
            .iter()
            .map(|m| Measured {
                pixel: [m.pixel[0] + 800, m.pixel[1] + 1600],
                ..*m
            })
            .collect();
        assert_eq!(tile_factors(Budget::Mse, &far).unwrap(), factors);
        assert!(tile_factors(Budget::Uniform, &tile).is_none());
        let dark: Vec<Measured> = tile.iter().map(|m| Measured { mean: 0.0, ..*m }).collect();
        assert!(tile_factors(Budget::Bounded, &dark).is_none());
        assert!(tile_factors(Budget::Bounded, &[]).is_none());
    }

    #[test]
    fn nothing_measured_or_no_light_is_no_budget() {
        assert!(of(Budget::Mse, &[(8, 8)], &[]).is_none());
        let dark = [texel(0, 0, 0.0, 0.0)];
        assert!(of(Budget::Mse, &[(8, 8)], &dark).is_none());
        let nan = [texel(0, 0, f64::NAN, 1.0), texel(1, 0, 1.0, f64::INFINITY)];
        assert!(of(Budget::Mse, &[(8, 8)], &nan).is_none());
        let lit = [texel(0, 0, 1.0, 1.0)];
        assert!(of(Budget::Uniform, &[(8, 8)], &lit).is_none());
        assert_eq!(
            of(Budget::Mse, &[(8, 8)], &lit).unwrap().factor(0, [7, 7]),
            1.0
        );
    }

    #[test]
    fn scaled_counts_are_whole_packets() {
        assert_eq!(scaled(32, 1.0), 32);
        assert_eq!(scaled(32, 0.25), 8);
        assert_eq!(scaled(8, 0.25), 8);
        assert_eq!(scaled(32, 4.0), 128);
        // 1.3 → 2^0.5 (the nearest step, 1.41); 0.95 → 1; 0.9 → 2^-0.25 (0.84).
        assert_eq!(scaled(64, 1.3), 88);
        assert_eq!(scaled(64, 0.95), 64);
        assert_eq!(scaled(64, 0.9), 56);
        assert_eq!(scaled(24, 1.0), 24);
        assert_eq!(scaled(0, 4.0), 0);
    }
}
