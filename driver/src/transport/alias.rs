//! A power alias table: O(1) selection of one emitter in proportion to a weight (its power,
//! area × luminance of its emission), the baseline the [`super::light_tree`] is measured
//! against and the sampler for worlds whose emitters all matter everywhere.
//!
//! Walker's alias method, built with Vose's stable O(n) construction (M. D. Vose, "A linear
//! algorithm for generating random numbers with a given distribution", IEEE TSE 1991), as
//! pbrt-v4's `AliasTable`. The build runs in f64; the table stores per slot an f32
//! threshold and a u32 alias (8 bytes), plus each entry's f32 probability.
//!
//! - One random number per pick: `u · n` gives the slot and its fractional part, rescaled
//!   to [0, 1), is compared with the slot's threshold. The fraction has `24 − log2 n` bits
//!   of an f32 `u` left (pbrt-v4 splits its `u` the same way), so for very large tables
//!   the thresholds are resolved only to steps of `n / 2^24`: at 10^4 entries 1/1677 of a
//!   slot, at 10^6 entries 1/16. Feed the table a `u` with all 24 bits random.
//! - Non-finite and negative weights count as 0. Zero-weight entries are never picked
//!   (their slots alias away entirely; Vose's worklist handles them first, so rounding can
//!   not leave one behind with a threshold of 1).
//! - [`AliasTable::pmf`] is the weight over the f64 sum, rounded once to f32; the pick
//!   frequencies match it to the f32 rounding of the thresholds.

use guidebake_kernels::sobol::ONE_MINUS_EPSILON;

/// One slot of the table: keep the slot's own entry when the rescaled fraction of `u` is
/// below `threshold`, otherwise take `alias`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Slot {
    threshold: f32,
    alias: u32,
}

/// Walker/Vose alias table over non-negative weights; `Send + Sync`, immutable once built.
#[derive(Clone, Debug, PartialEq)]
pub struct AliasTable {
    slots: Vec<Slot>,
    pmf: Vec<f32>,
}

/// A weight as the table counts it: non-finite and negative weights are 0.
fn clean(w: f32) -> f64 {
    if w.is_finite() && w > 0.0 {
        f64::from(w)
    } else {
        0.0
    }
}

impl AliasTable {
    /// The table for `weights` (entry i is picked with probability `w_i / Σ w`).
    ///
    /// Returns `None` when `weights` is empty, has no positive finite weight, or has more
    /// than `u32::MAX` entries.
    #[must_use]
    pub fn new(weights: &[f32]) -> Option<AliasTable> {
        let n = weights.len();
        if n == 0 || u32::try_from(n).is_err() {
            return None;
        }
        let total: f64 = weights.iter().map(|&w| clean(w)).sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let pmf: Vec<f32> = weights.iter().map(|&w| (clean(w) / total) as f32).collect();
        // Scaled probabilities: mean 1. Small ones (< 1) borrow from large ones (≥ 1).
        let mut q: Vec<f64> = weights
            .iter()
            .map(|&w| clean(w) / total * n as f64)
            .collect();
        let mut slots = vec![
            Slot {
                threshold: 1.0,
                alias: 0,
            };
            n
        ];
        let (mut small, mut large): (Vec<u32>, Vec<u32>) = (Vec::new(), Vec::new());
        // Zero weights go last so that `pop` takes them first, while every large entry is
        // still there to absorb their whole slot.
        let mut zeros = Vec::new();
        for (i, &qi) in q.iter().enumerate() {
            if qi == 0.0 {
                zeros.push(i as u32);
            } else if qi < 1.0 {
                small.push(i as u32);
            } else {
                large.push(i as u32);
            }
        }
        small.extend(zeros);
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            large.pop();
            slots[s as usize] = Slot {
                threshold: q[s as usize] as f32,
                alias: l,
            };
            q[l as usize] -= 1.0 - q[s as usize];
            if q[l as usize] < 1.0 {
                small.push(l);
            } else {
                large.push(l);
            }
        }
        // What remains is 1 up to rounding: each keeps its own slot. (A zero weight can not
        // remain: it was paired while large entries still carried the rest of the mass.)
        for i in small.into_iter().chain(large) {
            debug_assert!(q[i as usize] > 0.0, "zero-weight entry {i} left over");
            slots[i as usize] = Slot {
                threshold: 1.0,
                alias: i,
            };
        }
        Some(AliasTable { slots, pmf })
    }

    /// Picks an entry with one uniform `u` in [0, 1) (values outside are clamped, NaN is
    /// 0): the entry's index and its probability, [`AliasTable::pmf`] of it.
    #[must_use]
    pub fn pick(&self, u: f32) -> (u32, f32) {
        let u = if u > 0.0 {
            u.min(ONE_MINUS_EPSILON)
        } else {
            0.0
        };
        let n = self.slots.len();
        let x = f64::from(u) * n as f64;
        let slot = (x as usize).min(n - 1);
        let rest = (x - slot as f64) as f32;
        let s = self.slots[slot];
        let index = if rest < s.threshold {
            slot as u32
        } else {
            s.alias
        };
        (index, self.pmf[index as usize])
    }

    /// The probability that [`AliasTable::pick`] returns `index` (0 for indices out of
    /// range and zero weights).
    #[must_use]
    pub fn pmf(&self, index: u32) -> f32 {
        self.pmf.get(index as usize).copied().unwrap_or(0.0)
    }

    /// Number of entries (including zero-weight ones).
    #[must_use]
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether the table has no entries; never true for a built table.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::{Pcg32, chi_square};

    /// Picks `count` times with a fixed seed; returns the histogram of indices.
    fn histogram(table: &AliasTable, count: u32, seed: u64) -> Vec<f64> {
        let mut rng = Pcg32::new(seed, 3);
        let mut h = vec![0.0; table.len()];
        for _ in 0..count {
            let (i, p) = table.pick(rng.next_f32());
            assert_eq!(p, table.pmf(i));
            h[i as usize] += 1.0;
        }
        h
    }

    fn assert_frequencies_match(weights: &[f32], seed: u64, tests: u32) {
        let table = AliasTable::new(weights).unwrap();
        let count = 1_000_000;
        let observed = histogram(&table, count, seed);
        let expected: Vec<f64> = (0..table.len() as u32)
            .map(|i| f64::from(table.pmf(i)) * f64::from(count))
            .collect();
        let c = chi_square(&observed, &expected, 5.0);
        assert!(
            c.passes(0.01, tests),
            "{} weights: chi² {} dof {} p {}",
            weights.len(),
            c.statistic,
            c.dof,
            c.p_value
        );
        for (i, &w) in weights.iter().enumerate() {
            if clean(w) == 0.0 {
                assert_eq!(observed[i], 0.0, "zero-weight entry {i} picked");
                assert_eq!(table.pmf(i as u32), 0.0);
            }
        }
    }

    #[test]
    fn pick_frequencies_follow_the_weights() {
        let mut rng = Pcg32::new(11, 2);
        // Powers spanning 1e-4..1e5, with zeros, negatives and non-finite weights mixed in.
        let spread: Vec<f32> = (0..997)
            .map(|i| match i % 13 {
                0 => 0.0,
                5 => -3.0,
                7 => f32::NAN,
                9 => f32::INFINITY,
                _ => 10f32.powf(rng.next_f32() * 9.0 - 4.0),
            })
            .collect();
        let cases: [&[f32]; 5] = [
            &[1.0, 2.0, 3.0, 4.0],
            &[0.0, 5.0, 0.0, 0.0, 1.0, 0.0],
            &[1.0; 101],
            &[1e-4, 1e5, 1.0, 0.0, 7.0],
            &spread,
        ];
        for (k, w) in cases.iter().enumerate() {
            assert_frequencies_match(w, 40 + k as u64, cases.len() as u32);
        }
    }

    #[test]
    fn the_test_rejects_a_wrong_table() {
        // A table for other weights must fail the same chi-square test, so the test above
        // can fail.
        let table = AliasTable::new(&[1.0, 2.0, 3.0, 4.1]).unwrap();
        let observed = histogram(&table, 1_000_000, 7);
        let expected: Vec<f64> = [1.0, 2.0, 3.0, 4.0].map(|w| w / 10.0 * 1e6).to_vec();
        assert!(!chi_square(&observed, &expected, 5.0).passes(0.01, 1));
    }

    #[test]
    fn pmf_sums_to_one_and_matches_the_weights() {
        let mut rng = Pcg32::new(5, 9);
        for n in [1usize, 2, 3, 17, 1000, 65_537] {
            let w: Vec<f32> = (0..n)
                .map(|i| {
                    if i % 4 == 3 {
                        0.0
                    } else {
                        rng.next_f32() * 100.0
                    }
                })
                .collect();
            let Some(t) = AliasTable::new(&w) else {
                assert!(w.iter().all(|&x| x == 0.0));
                continue;
            };
            let total: f64 = w.iter().map(|&x| f64::from(x)).sum();
            let sum: f64 = (0..n as u32).map(|i| f64::from(t.pmf(i))).sum();
            assert!((sum - 1.0).abs() < 1e-5, "n {n}: Σ pmf = {sum}");
            for (i, &x) in w.iter().enumerate() {
                let want = (f64::from(x) / total) as f32;
                assert_eq!(t.pmf(i as u32), want, "n {n} entry {i}");
            }
            // The mass each entry gets from the slots equals its pmf (the table is exact up
            // to the f32 thresholds).
            let mut mass = vec![0.0f64; n];
            for (i, s) in t.slots.iter().enumerate() {
                mass[i] += f64::from(s.threshold.min(1.0)) / n as f64;
                mass[s.alias as usize] += (1.0 - f64::from(s.threshold.min(1.0))) / n as f64;
            }
            for (i, m) in mass.iter().enumerate() {
                let p = f64::from(t.pmf(i as u32));
                assert!(
                    (m - p).abs() <= 1e-6 * p + 1e-12,
                    "n {n} entry {i}: {m} vs {p}"
                );
            }
        }
    }

    #[test]
    fn degenerate_inputs() {
        assert!(AliasTable::new(&[]).is_none());
        assert!(AliasTable::new(&[0.0, 0.0]).is_none());
        assert!(AliasTable::new(&[-1.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY]).is_none());
        let one = AliasTable::new(&[0.0, 0.0, 2.5, 0.0]).unwrap();
        assert_eq!(one.len(), 4);
        for u in [
            0.0,
            0.1,
            0.25,
            0.5,
            0.74,
            0.75,
            0.9999,
            ONE_MINUS_EPSILON,
            1.0,
            7.0,
            -1.0,
        ] {
            assert_eq!(one.pick(u), (2, 1.0), "u = {u}");
        }
        assert_eq!(one.pick(f32::NAN), (2, 1.0));
        assert_eq!(one.pmf(0), 0.0);
        assert_eq!(one.pmf(99), 0.0);
        // Two f32 weights whose sum overflows f32 but not the f64 build.
        let big = AliasTable::new(&[f32::MAX, f32::MAX]).unwrap();
        assert_eq!(big.pmf(0), 0.5);
        // A single entry.
        let single = AliasTable::new(&[1e-30]).unwrap();
        assert_eq!(single.pick(0.3), (0, 1.0));
    }

    #[test]
    fn zero_weights_are_never_picked_at_any_u() {
        // Sweep u over a fine grid: slots of zero-weight entries always alias away.
        let w = [0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1e-7, 0.0];
        let t = AliasTable::new(&w).unwrap();
        for k in 0..(1u32 << 16) {
            let (i, p) = t.pick(k as f32 / 65536.0);
            assert!(w[i as usize] > 0.0, "u = {k}/65536 picked {i}");
            assert!(p > 0.0);
        }
    }
}
