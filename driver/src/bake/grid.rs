//! The grid guide, a comparator (docs/ARCHITECTURE.md, "Comparators"): the first-bounce guiding of the
//! HWRTL baker and of Unreal's GPU Lightmass. Each square of 8×8 lightmap texels learns one
//! 16×16-bin piecewise-constant density over the primary sample square from the previous
//! iteration's gather samples of all its texels, and samples it by inverting the marginal
//! (rows) and conditional (columns) distributions, one sample at a time.
//!
//! Differences from the paper's guide, which the benchmarks measure: a fixed resolution
//! instead of an adaptive quadtree, groups by texel-space square instead of by position and
//! normal (paper §2.1), and no hierarchical smoothing. Like the quadtree, each bin keeps at
//! least an ambient floor ([`FLOOR`] of the mean bin) so no direction has zero probability.
//!
//! Every warp is a triple here too: [`GridGuide::sample`], [`GridGuide::pdf`],
//! [`GridGuide::invert`].

use guidebake_kernels::guide::Record;

/// Bins along each axis of the primary sample square.
pub const BINS: usize = 16;
/// Texels along each side of the square of texels that shares one grid.
pub const SQUARE: u16 = 8;
/// Each bin's flux is at least this fraction of the mean bin's.
pub const FLOOR: f32 = 0.1;

/// A learned 16×16 density on [0,1)², sampled by marginal–conditional inversion.
#[derive(Clone, Debug, PartialEq)]
pub struct GridGuide {
    /// Cumulative row probabilities, `rows[0] = 0`, `rows[BINS] = 1`.
    rows: [f32; BINS + 1],
    /// Per row, cumulative column probabilities within the row.
    cols: [[f32; BINS + 1]; BINS],
    /// Density on the square of each bin (row-major), `BINS²` × its probability.
    density: [f32; BINS * BINS],
}

impl GridGuide {
    /// Learns a grid from `records` (points on the square and their flux), mixed with the
    /// uniform density by the share `uniform` ∈ [0, 1] (the defensive mixture: every bin's
    /// density at least `uniform`). `None` when the records carry no usable energy (no
    /// finite positive flux), so the caller stays unguided. Records with non-finite or
    /// negative flux, or points off the square, are ignored.
    pub fn learn(records: &[Record], uniform: f32) -> Option<Self> {
        let mut flux = [0.0f64; BINS * BINS];
        for r in records {
            let [x, y] = r.u;
            let usable = r.flux.is_finite()
                && r.flux >= 0.0
                && (0.0..1.0).contains(&x)
                && (0.0..1.0).contains(&y);
            if !usable {
                continue;
            }
            flux[bin(y) * BINS + bin(x)] += f64::from(r.flux);
        }
        let total: f64 = flux.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let floor = total / (BINS * BINS) as f64 * f64::from(FLOOR);
        flux.iter_mut().for_each(|f| *f = f.max(floor));
        // The defensive mixture with the uniform density, in the bins' masses.
        let total: f64 = flux.iter().sum();
        let c = f64::from(uniform.clamp(0.0, 1.0));
        flux.iter_mut()
            .for_each(|f| *f = (1.0 - c) * *f / total + c / (BINS * BINS) as f64);
        let total: f64 = flux.iter().sum();
        let mut g = GridGuide {
            rows: [0.0; BINS + 1],
            cols: [[0.0; BINS + 1]; BINS],
            density: [0.0; BINS * BINS],
        };
        let mut row_sum = 0.0f64;
        for r in 0..BINS {
            let row = &flux[r * BINS..(r + 1) * BINS];
            let in_row: f64 = row.iter().sum();
            let mut acc = 0.0f64;
            for (c, &f) in row.iter().enumerate() {
                acc += f;
                g.cols[r][c + 1] = (acc / in_row) as f32;
                g.density[r * BINS + c] = (f / total * (BINS * BINS) as f64) as f32;
            }
            g.cols[r][BINS] = 1.0;
            row_sum += in_row;
            g.rows[r + 1] = (row_sum / total) as f32;
        }
        g.rows[BINS] = 1.0;
        Some(g)
    }

    /// Warps `u` ∈ [0,1)² to a point distributed by the grid; returns it and its density.
    pub fn sample(&self, u: [f32; 2]) -> ([f32; 2], f32) {
        debug_assert!(u.iter().all(|v| (0.0..1.0).contains(v)), "u = {u:?}");
        let (r, y) = invert_cdf(&self.rows, u[1]);
        let (c, x) = invert_cdf(&self.cols[r], u[0]);
        ([x, y], self.density[r * BINS + c])
    }

    /// The density of the grid at `u` on the square.
    pub fn pdf(&self, u: [f32; 2]) -> f32 {
        self.density[bin(u[1]) * BINS + bin(u[0])]
    }

    /// The `u` that [`Self::sample`] maps to `w` (up to rounding).
    pub fn invert(&self, w: [f32; 2]) -> [f32; 2] {
        let (r, c) = (bin(w[1]), bin(w[0]));
        let along = |cdf: &[f32; BINS + 1], i: usize, v: f32| {
            let t = v * BINS as f32 - i as f32;
            (cdf[i] + t * (cdf[i + 1] - cdf[i])).min(ONE_BELOW)
        };
        [along(&self.cols[r], c, w[0]), along(&self.rows, r, w[1])]
    }
}

/// The largest f32 below 1.
const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

fn bin(v: f32) -> usize {
    ((v * BINS as f32) as usize).min(BINS - 1)
}

/// The bin `i` whose cumulative interval holds `u`, and the point of that bin's span on
/// [0,1) that `u` maps to linearly; strictly below 1.
fn invert_cdf(cdf: &[f32; BINS + 1], u: f32) -> (usize, f32) {
    // The last i with cdf[i] <= u, among bins of non-zero width.
    let mut i = cdf[1..BINS].partition_point(|&c| c <= u);
    while i > 0 && cdf[i + 1] <= cdf[i] {
        i -= 1;
    }
    let width = cdf[i + 1] - cdf[i];
    let t = if width > 0.0 {
        ((u - cdf[i]) / width).clamp(0.0, 1.0)
    } else {
        0.5
    };
    (i, ((i as f32 + t) / BINS as f32).min(ONE_BELOW))
}

#[cfg(test)]
mod tests {
    use guidebake_kernels::testing::{Pcg32, chi_square, disk_and_sky, learning_records};

    use super::*;

    fn learned() -> GridGuide {
        learned_mixed(0.0)
    }

    fn learned_mixed(uniform: f32) -> GridGuide {
        let records = learning_records(None, 4096, 3, disk_and_sky);
        GridGuide::learn(&records, uniform).expect("the disk and sky carry energy")
    }

    #[test]
    fn samples_follow_the_pdf_chi_square() {
        samples_follow_the_pdf(&learned());
    }

    /// The defensive mixture: no bin's density below the uniform share, the rest learned,
    /// and the samples still follow the density.
    #[test]
    fn a_mixed_grid_keeps_the_uniform_share_and_follows_its_pdf() {
        let (plain, mixed) = (learned(), learned_mixed(0.25));
        for b in 0..BINS * BINS {
            let want = 0.25 + 0.75 * plain.density[b];
            assert!(
                (mixed.density[b] - want).abs() <= 1e-5 * want,
                "bin {b}: {} vs {want}",
                mixed.density[b]
            );
            assert!(mixed.density[b] >= 0.25 * (1.0 - 1e-6));
        }
        samples_follow_the_pdf(&mixed);
    }

    fn samples_follow_the_pdf(g: &GridGuide) {
        // A resolution that does not align with the bins (odd), pooled low cells.
        let res = 37;
        let mut observed = vec![0.0; res * res];
        let mut rng = Pcg32::new(7, 1);
        let n = 400_000;
        for _ in 0..n {
            let (w, pdf) = g.sample([rng.next_f32(), rng.next_f32()]);
            assert!(w.iter().all(|v| (0.0..1.0).contains(v)), "{w:?}");
            assert_eq!(pdf, g.pdf(w), "sample's pdf is pdf(w)");
            let (x, y) = ((w[0] * res as f32) as usize, (w[1] * res as f32) as usize);
            observed[y * res + x] += 1.0;
        }
        // Expected counts: the pdf integrated exactly over each cell (bin overlaps).
        let overlap = |a0: f64, a1: f64, b: usize| {
            let (b0, b1) = (b as f64 / BINS as f64, (b + 1) as f64 / BINS as f64);
            (a1.min(b1) - a0.max(b0)).max(0.0)
        };
        let expected: Vec<f64> = (0..res * res)
            .map(|i| {
                let (cx, cy) = ((i % res) as f64, (i / res) as f64);
                let (x0, x1, y0, y1) = (
                    cx / res as f64,
                    (cx + 1.0) / res as f64,
                    cy / res as f64,
                    (cy + 1.0) / res as f64,
                );
                let mut sum = 0.0;
                for b in 0..BINS * BINS {
                    let area = overlap(x0, x1, b % BINS) * overlap(y0, y1, b / BINS);
                    sum += area * f64::from(g.density[b]);
                }
                sum * n as f64
            })
            .collect();
        let total: f64 = expected.iter().sum();
        assert!(
            (total - n as f64).abs() < 1e-3 * n as f64,
            "pdf integrates to {total}"
        );
        let r = chi_square(&observed, &expected, 5.0);
        assert!(r.passes(0.01, 1), "{r:?}");
    }

    #[test]
    fn the_grid_learns_the_bright_disk_and_inverts() {
        let g = learned();
        // The disk of `disk_and_sky` is far brighter than the sky: its bins have more density.
        let (mut bright, mut dim) = (0.0f32, f32::INFINITY);
        for i in 0..BINS * BINS {
            let u = [
                ((i % BINS) as f32 + 0.5) / BINS as f32,
                ((i / BINS) as f32 + 0.5) / BINS as f32,
            ];
            if disk_and_sky(u) > 1.0 {
                bright = bright.max(g.pdf(u));
            } else {
                dim = dim.min(g.pdf(u));
            }
        }
        assert!(bright > 4.0 * dim, "bright {bright}, dim {dim}");
        assert!(dim > 0.0, "the floor keeps every bin reachable");
        let mut rng = Pcg32::new(3, 9);
        for _ in 0..10_000 {
            let u = [rng.next_f32(), rng.next_f32()];
            let (w, _) = g.sample(u);
            let back = g.invert(w);
            assert!(
                (back[0] - u[0]).abs() < 1e-4 && (back[1] - u[1]).abs() < 1e-4,
                "{u:?} -> {w:?} -> {back:?}"
            );
        }
    }

    #[test]
    fn edges_and_bad_records() {
        assert!(GridGuide::learn(&[], 0.0).is_none());
        let zero = [Record {
            u: [0.5, 0.5],
            flux: 0.0,
        }];
        assert!(
            GridGuide::learn(&zero, 0.25).is_none(),
            "no energy, no guide"
        );
        let bad = [
            Record {
                u: [0.5, 0.5],
                flux: f32::NAN,
            },
            Record {
                u: [1.5, 0.5],
                flux: 1.0,
            },
            Record {
                u: [0.1, 0.1],
                flux: 2.0,
            },
        ];
        let g = GridGuide::learn(&bad, 0.0).expect("one good record");
        // One hot bin of flux 2; the 255 others keep the floor, 0.1 × 2/256 each.
        let floor = FLOOR * 2.0 / 256.0;
        let want = 2.0 / (2.0 + 255.0 * floor) * 256.0;
        let hot = g.pdf([0.1, 0.1]);
        assert!((hot - want).abs() < 1e-3 * want, "{hot} vs {want}");
        let cold = floor / (2.0 + 255.0 * floor) * 256.0;
        assert!((g.pdf([0.9, 0.9]) - cold).abs() < 1e-3 * cold);
        for u in [[0.0, 0.0], [ONE_BELOW, ONE_BELOW], [0.0, ONE_BELOW]] {
            let (w, pdf) = g.sample(u);
            assert!(w.iter().all(|v| (0.0..1.0).contains(v)), "{u:?} -> {w:?}");
            assert!(pdf > 0.0 && pdf.is_finite());
        }
    }
}
