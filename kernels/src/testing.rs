//! Test support shared by the kernels' unit tests, the workspace's integration tests, the
//! benches and the fuzz targets: a seeded PCG32 generator and a chi-square goodness-of-fit
//! test in the style of Mitsuba's `ChiSquareTest` and pbrt's `Chi2Test` (pooled
//! low-expectation cells, Šidák-corrected significance). Not part of the stable API: it is
//! compiled only for tests and under the `testing` feature.

/// PCG32 (O'Neill 2014, XSH-RR output): small, seeded, reproducible, `no_std`.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

impl Pcg32 {
    /// A generator for `seed` on stream `stream`.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut rng = Pcg32 {
            state: 0,
            inc: (stream << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// A uniform `f32` in [0, 1): 24 random bits, so never 1.0.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// A uniform `f64` in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        let hi = u64::from(self.next_u32()) << 21;
        let lo = u64::from(self.next_u32() >> 11);
        (hi | lo) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }
}

/// The outcome of [`chi_square`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChiSquare {
    /// The statistic Σ (observed − expected)² / expected over the pooled cells.
    pub statistic: f64,
    /// Degrees of freedom: pooled cells − 1.
    pub dof: u32,
    /// Probability of a statistic at least this large if the sampler matches the pdf.
    pub p_value: f64,
    /// Cells merged into the pool because their expectation was below the minimum.
    pub pooled_cells: u32,
}

impl ChiSquare {
    /// Whether the test passes at significance `alpha`, Šidák-corrected for `tests` tests
    /// run together: rejects when `p < 1 − (1 − alpha)^(1/tests)`.
    pub fn passes(&self, alpha: f64, tests: u32) -> bool {
        let corrected = 1.0 - libm::pow(1.0 - alpha, 1.0 / f64::from(tests.max(1)));
        self.p_value >= corrected
    }
}

/// Pearson's chi-square test of observed counts against expected counts (same total).
///
/// Cells whose expectation is below `min_expected` (5 is customary) are pooled into one
/// cell, as Mitsuba and pbrt do. A cell with zero expectation but observations makes the
/// test fail outright (`p_value = 0`): the sampler produced what the pdf calls impossible.
///
/// # Panics
/// If `observed` and `expected` differ in length.
pub fn chi_square(observed: &[f64], expected: &[f64], min_expected: f64) -> ChiSquare {
    assert_eq!(
        observed.len(),
        expected.len(),
        "histogram and pdf differ in size"
    );
    let (mut statistic, mut cells, mut pooled_cells) = (0.0, 0u32, 0u32);
    let (mut pool_obs, mut pool_exp) = (0.0, 0.0);
    let mut impossible = false;
    for (&o, &e) in observed.iter().zip(expected) {
        if e <= 0.0 {
            impossible |= o > 0.0;
        } else if e < min_expected {
            pool_obs += o;
            pool_exp += e;
            pooled_cells += 1;
        } else {
            statistic += (o - e) * (o - e) / e;
            cells += 1;
        }
    }
    if pool_exp > 0.0 {
        statistic += (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
        cells += 1;
    }
    let dof = cells.saturating_sub(1);
    let p_value = if impossible {
        0.0
    } else if dof == 0 {
        1.0
    } else {
        regularized_gamma_q(f64::from(dof) / 2.0, statistic / 2.0)
    };
    ChiSquare {
        statistic,
        dof,
        p_value,
        pooled_cells,
    }
}

/// Q(a, x) = Γ(a, x) / Γ(a), the upper regularized incomplete gamma function: a series for
/// x < a + 1, a continued fraction (modified Lentz) otherwise (Numerical Recipes §6.2).
pub fn regularized_gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let log_prefix = a * libm::log(x) - x - libm::lgamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * libm::exp(log_prefix)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -f64::from(i) * (f64::from(i) - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        libm::exp(log_prefix) * h
    }
}

/// The "known anisotropic radiance" on the square of the guide tests and the warp bench: a
/// small bright disk (radius 0.05 around (0.7, 0.23), radiance 100) over a dim sky (1).
pub fn disk_and_sky(u: [f32; 2]) -> f32 {
    let (dx, dy) = (u[0] - 0.7, u[1] - 0.23);
    if dx * dx + dy * dy < 0.05 * 0.05 {
        100.0
    } else {
        1.0
    }
}

/// `n` learning records of `radiance`: points drawn uniformly (from PCG32 stream 17 of
/// `seed`), warped through `previous` when given, each with flux `L / p`.
#[cfg(feature = "alloc")]
pub fn learning_records(
    previous: Option<&crate::guide::Guide<'_>>,
    n: usize,
    seed: u64,
    radiance: impl Fn([f32; 2]) -> f32,
) -> alloc::vec::Vec<crate::guide::Record> {
    let mut rng = Pcg32::new(seed, 17);
    (0..n)
        .map(|_| {
            let u = [rng.next_f32(), rng.next_f32()];
            let s = previous.map_or(crate::warp::Warped { u, pdf: 1.0 }, |g| {
                crate::warp::sample(g, u)
            });
            crate::guide::Record {
                u: s.u,
                flux: radiance(s.u) / s.pdf,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_q_matches_known_chi_square_quantiles() {
        // chi-square critical values at p = 0.05 for 1, 10 and 100 degrees of freedom.
        for (dof, x) in [(1.0, 3.841_458_8), (10.0, 18.307_038), (100.0, 124.342_11)] {
            let p = regularized_gamma_q(dof / 2.0, x / 2.0);
            assert!((p - 0.05).abs() < 1e-6, "dof {dof}: p = {p}");
        }
        assert_eq!(regularized_gamma_q(3.0, 0.0), 1.0);
    }

    #[test]
    fn chi_square_accepts_uniform_and_rejects_skewed_samples() {
        let mut rng = Pcg32::new(7, 1);
        let cells = 37;
        let n = 100_000;
        let mut uniform = [0.0f64; 37];
        let mut skewed = [0.0f64; 37];
        for _ in 0..n {
            uniform[(rng.next_f64() * cells as f64) as usize] += 1.0;
            let u = rng.next_f64();
            skewed[((u * u) * cells as f64) as usize] += 1.0;
        }
        let expected = [n as f64 / cells as f64; 37];
        assert!(chi_square(&uniform, &expected, 5.0).passes(0.01, 1));
        assert!(!chi_square(&skewed, &expected, 5.0).passes(0.01, 1));
    }

    #[test]
    fn chi_square_pools_small_cells_and_flags_impossible_samples() {
        let r = chi_square(&[10.0, 1.0, 2.0, 7.0], &[10.0, 1.5, 1.5, 7.0], 5.0);
        assert_eq!(r.pooled_cells, 2);
        assert_eq!(r.dof, 2);
        assert_eq!(chi_square(&[5.0, 1.0], &[6.0, 0.0], 5.0).p_value, 0.0);
    }

    #[test]
    fn pcg32_is_reproducible_and_in_range() {
        let (mut a, mut b) = (Pcg32::new(42, 54), Pcg32::new(42, 54));
        for _ in 0..1000 {
            assert_eq!(a.next_u32(), b.next_u32());
            let f = a.next_f32();
            assert!((0.0..1.0).contains(&f));
            b.next_f32();
        }
    }
}
