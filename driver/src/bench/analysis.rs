//! From runs to answers: error-against-time curves per method, the error each method reaches
//! within a time budget, the equivalent-sample factor of a method against the baseline, and
//! the Figure-5 overhead ratios (paper §3, Figure 5).
//!
//! Curves are interpolated piecewise linearly in log–log space (Monte Carlo error falls as a
//! power of time, a straight line there). Outside the measured range a least-squares line
//! through all of a curve's points extends it, and the value is marked `extrapolated`.

use serde::Serialize;

use super::harness::{OverheadRecord, RunRecord};
use super::method::Method;

/// One point of a method's curve: a sample count, over its seeds.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct CurvePoint {
    /// Rays per texel.
    pub spp: u32,
    /// Median wall-clock seconds over the seeds.
    pub wall_s: f64,
    /// Median gather seconds over the seeds.
    pub gather_s: f64,
    /// Median CPU seconds of the whole bake over the seeds.
    pub cpu_s: f64,
    /// RMSE over the seeds: the square root of the mean MSE.
    pub rmse: f64,
    /// Smallest and largest RMSE of one seed.
    pub rmse_range: [f64; 2],
    /// Mean relative MSE over the seeds.
    pub rel_mse: f64,
    /// Mean bias over the seeds.
    pub bias: f64,
    /// Mean relative bias over the seeds.
    pub rel_bias: f64,
    /// Mean fraction of guided cluster-iterations.
    pub guided_fraction: f64,
}

/// A method's error against time.
#[derive(Clone, Debug, Serialize)]
pub struct Curve {
    /// Method label.
    pub method: String,
    /// Its points, by ascending spp.
    pub points: Vec<CurvePoint>,
}

/// The median of `values` (the mean of the middle two for an even count); NaN for none.
pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Groups `runs` into one curve per method of `methods` (in that order).
pub fn curves(methods: &[Method], runs: &[RunRecord]) -> Vec<Curve> {
    methods
        .iter()
        .map(|m| {
            let label = m.label();
            let mine: Vec<&RunRecord> = runs.iter().filter(|r| r.method == label).collect();
            let mut spps: Vec<u32> = mine.iter().map(|r| r.spp).collect();
            spps.sort_unstable();
            spps.dedup();
            let points = spps
                .into_iter()
                .map(|spp| {
                    let at: Vec<&&RunRecord> = mine.iter().filter(|r| r.spp == spp).collect();
                    let n = at.len() as f64;
                    let col =
                        |f: fn(&RunRecord) -> f64| at.iter().map(|r| f(r)).collect::<Vec<_>>();
                    let rmses = col(|r| r.error.rmse);
                    CurvePoint {
                        spp,
                        wall_s: median(&col(|r| r.wall_s)),
                        gather_s: median(&col(|r| r.gather_s)),
                        cpu_s: median(&col(|r| r.cpu_s)),
                        rmse: (rmses.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
                        rmse_range: [
                            rmses.iter().copied().fold(f64::INFINITY, f64::min),
                            rmses.iter().copied().fold(0.0, f64::max),
                        ],
                        rel_mse: col(|r| r.error.rel_mse).iter().sum::<f64>() / n,
                        bias: col(|r| r.error.bias).iter().sum::<f64>() / n,
                        rel_bias: col(|r| r.error.rel_bias).iter().sum::<f64>() / n,
                        guided_fraction: col(|r| r.guided_fraction).iter().sum::<f64>() / n,
                    }
                })
                .collect();
            Curve {
                method: label,
                points,
            }
        })
        .collect()
}

/// A value read off a curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Interpolated {
    /// The value.
    pub value: f64,
    /// Whether it lies outside the measured range (read off the fitted line).
    pub extrapolated: bool,
}

/// `y` at `x` on the curve through `points` (x, y), all positive, in log–log space: piecewise
/// linear inside the range of x, the least-squares line outside it. `None` with fewer than two
/// distinct positive x, or a non-positive query.
pub fn log_log_at(points: &[(f64, f64)], x: f64) -> Option<Interpolated> {
    let mut logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|(a, b)| *a > 0.0 && *b > 0.0 && a.is_finite() && b.is_finite())
        .map(|(a, b)| (a.ln(), b.ln()))
        .collect();
    logs.sort_by(|a, b| a.0.total_cmp(&b.0));
    logs.dedup_by(|a, b| a.0 == b.0);
    if logs.len() < 2 || !(x > 0.0 && x.is_finite()) {
        return None;
    }
    let lx = x.ln();
    let (first, last) = (logs[0], logs[logs.len() - 1]);
    if (first.0..=last.0).contains(&lx) {
        let i = logs.partition_point(|p| p.0 <= lx).clamp(1, logs.len() - 1);
        let (a, b) = (logs[i - 1], logs[i]);
        let t = (lx - a.0) / (b.0 - a.0);
        return Some(Interpolated {
            value: (a.1 + t * (b.1 - a.1)).exp(),
            extrapolated: false,
        });
    }
    let (slope, intercept) = fit_line(&logs);
    Some(Interpolated {
        value: (intercept + slope * lx).exp(),
        extrapolated: true,
    })
}

/// Least-squares line `y = slope·x + intercept` through at least two distinct x.
fn fit_line(points: &[(f64, f64)]) -> (f64, f64) {
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = points.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let slope = sxy / sxx;
    (slope, my - slope * mx)
}

/// The slope of a curve's RMSE against wall time in log–log space (−½ for plain Monte Carlo
/// at a time proportional to the samples).
pub fn convergence_slope(curve: &Curve) -> Option<f64> {
    let logs: Vec<(f64, f64)> = curve
        .points
        .iter()
        .filter(|p| p.wall_s > 0.0 && p.rmse > 0.0)
        .map(|p| (p.wall_s.ln(), p.rmse.ln()))
        .collect();
    (logs.len() >= 2).then(|| fit_line(&logs).0)
}

/// Each method's errors within one time budget.
#[derive(Clone, Debug, Serialize)]
pub struct EqualTime {
    /// Method label.
    pub method: String,
    /// RMSE reached in the budget.
    pub rmse: Option<Interpolated>,
    /// Relative MSE reached in the budget.
    pub rel_mse: Option<Interpolated>,
}

/// The errors every curve reaches at `budget_s` seconds of wall time.
pub fn equal_time(curves: &[Curve], budget_s: f64) -> Vec<EqualTime> {
    curves
        .iter()
        .map(|c| {
            let at = |f: fn(&CurvePoint) -> f64| {
                let pts: Vec<(f64, f64)> = c.points.iter().map(|p| (p.wall_s, f(p))).collect();
                log_log_at(&pts, budget_s)
            };
            EqualTime {
                method: c.method.clone(),
                rmse: at(|p| p.rmse),
                rel_mse: at(|p| p.rel_mse),
            }
        })
        .collect()
}

/// The error an equivalent-sample factor is read by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorMetric {
    /// Root-mean-square error: the bright texels weigh the most.
    Rmse,
    /// Relative MSE: every texel's error relative to its own value (the path-guiding
    /// literature's measure, and closer to what a viewer sees in a lightmap).
    RelMse,
}

impl ErrorMetric {
    fn of(self, p: &CurvePoint) -> f64 {
        match self {
            Self::Rmse => p.rmse,
            Self::RelMse => p.rel_mse,
        }
    }
}

/// How many baseline samples reach a method's error, per sample of the method.
#[derive(Clone, Debug, Serialize)]
pub struct EquivalentSamples {
    /// Method label.
    pub method: String,
    /// The error compared.
    pub metric: ErrorMetric,
    /// Rays per texel of the method.
    pub spp: u32,
    /// Baseline rays per texel with the same error.
    pub baseline_spp: Interpolated,
    /// `baseline_spp / spp`: above 1, the method is worth that many more baseline samples.
    pub factor: f64,
}

/// The equivalent-sample factor of every point of `curve` against `baseline`, by `metric`.
pub fn equivalent_samples(
    curve: &Curve,
    baseline: &Curve,
    metric: ErrorMetric,
) -> Vec<EquivalentSamples> {
    let inverse: Vec<(f64, f64)> = baseline
        .points
        .iter()
        .map(|p| (metric.of(p), f64::from(p.spp)))
        .collect();
    curve
        .points
        .iter()
        .filter_map(|p| {
            let b = log_log_at(&inverse, metric.of(p))?;
            Some(EquivalentSamples {
                method: curve.method.clone(),
                metric,
                spp: p.spp,
                baseline_spp: b,
                factor: b.value / f64::from(p.spp),
            })
        })
        .collect()
}

/// One `--guiding` mode of the Figure-5 measurement.
#[derive(Clone, Debug, Serialize)]
pub struct Overhead {
    /// `--guiding`.
    pub guiding: String,
    /// Repeats measured.
    pub repeats: usize,
    /// Median gather seconds.
    pub gather_s: f64,
    /// Median wall seconds.
    pub wall_s: f64,
    /// Median gather seconds over the baseline's (`off`).
    pub gather_ratio: f64,
    /// Median wall seconds over the baseline's.
    pub wall_ratio: f64,
    /// Median over repeats of this repeat's gather time over the baseline's in the same repeat.
    pub paired_gather_ratio: f64,
    /// The same for the whole bake's CPU time (every phase and thread, user + system): the
    /// paper's Figure 5 times whole bakes.
    pub paired_cpu_ratio: f64,
    /// Mean fraction of guided cluster-iterations.
    pub guided_fraction: f64,
}

/// Medians and ratios to `off` of the overhead runs, one entry per mode in first-seen order.
pub fn overhead(records: &[OverheadRecord]) -> Vec<Overhead> {
    let mut modes: Vec<&str> = Vec::new();
    for r in records {
        if !modes.contains(&r.guiding.as_str()) {
            modes.push(&r.guiding);
        }
    }
    modes.sort_by_key(|m| *m != "off");
    let of = |mode: &str| -> Vec<&OverheadRecord> {
        records.iter().filter(|r| r.guiding == mode).collect()
    };
    let base = of("off");
    let base_gather = median(&base.iter().map(|r| r.gather_s).collect::<Vec<_>>());
    let base_wall = median(&base.iter().map(|r| r.wall_s).collect::<Vec<_>>());
    modes
        .iter()
        .map(|&mode| {
            let mine = of(mode);
            let gather_s = median(&mine.iter().map(|r| r.gather_s).collect::<Vec<_>>());
            let wall_s = median(&mine.iter().map(|r| r.wall_s).collect::<Vec<_>>());
            // This mode's time over the baseline's in the same repeat, per repeat.
            let paired = |time: fn(&OverheadRecord) -> f64| -> Vec<f64> {
                mine.iter()
                    .filter_map(|r| {
                        let b = base.iter().find(|b| b.repeat == r.repeat)?;
                        Some(time(r) / time(b))
                    })
                    .collect()
            };
            Overhead {
                guiding: mode.to_owned(),
                repeats: mine.len(),
                gather_s,
                wall_s,
                gather_ratio: gather_s / base_gather,
                wall_ratio: wall_s / base_wall,
                paired_gather_ratio: median(&paired(|r| r.gather_s)),
                paired_cpu_ratio: median(&paired(|r| r.cpu_s)),
                guided_fraction: mine.iter().map(|r| r.guided_fraction).sum::<f64>()
                    / mine.len().max(1) as f64,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&[]).is_nan());
        assert_eq!(median(&[f64::NAN, 5.0]), 5.0);
    }

    #[test]
    fn a_power_law_is_read_off_exactly_inside_and_outside() {
        // y = 3 x^-0.5 at x = 1, 4, 16.
        let pts: Vec<(f64, f64)> = [1.0f64, 4.0, 16.0]
            .iter()
            .map(|&x| (x, 3.0 * x.powf(-0.5)))
            .collect();
        let inside = log_log_at(&pts, 9.0).unwrap();
        assert!(!inside.extrapolated);
        assert!((inside.value - 1.0).abs() < 1e-12);
        let outside = log_log_at(&pts, 64.0).unwrap();
        assert!(outside.extrapolated);
        assert!((outside.value - 3.0 / 8.0).abs() < 1e-12);
        assert!(log_log_at(&pts[..1], 2.0).is_none());
        assert!(log_log_at(&pts, 0.0).is_none());
    }

    #[test]
    fn interpolation_is_piecewise_between_neighbours() {
        let pts = [(1.0, 1.0), (2.0, 4.0), (4.0, 4.0)];
        // Between 2 and 4 the curve is flat at 4.
        assert!((log_log_at(&pts, 3.0).unwrap().value - 4.0).abs() < 1e-12);
        // Between 1 and 2 it is y = x².
        assert!((log_log_at(&pts, 1.5).unwrap().value - 2.25).abs() < 1e-12);
        assert!((log_log_at(&pts, 4.0).unwrap().value - 4.0).abs() < 1e-12);
    }

    fn curve(label: &str, pts: &[(u32, f64, f64)]) -> Curve {
        Curve {
            method: label.into(),
            points: pts
                .iter()
                .map(|&(spp, wall_s, rmse)| CurvePoint {
                    spp,
                    wall_s,
                    gather_s: wall_s,
                    cpu_s: wall_s,
                    rmse,
                    rmse_range: [rmse; 2],
                    rel_mse: rmse * rmse,
                    bias: 0.0,
                    rel_bias: 0.0,
                    guided_fraction: 0.0,
                })
                .collect(),
        }
    }

    #[test]
    fn a_method_with_half_the_error_is_worth_four_times_the_samples() {
        let base = curve("b", &[(64, 1.0, 0.4), (256, 4.0, 0.2), (1024, 16.0, 0.1)]);
        let better = curve("g", &[(64, 1.0, 0.2), (256, 4.0, 0.1)]);
        let eq = equivalent_samples(&better, &base, ErrorMetric::Rmse);
        assert_eq!(eq.len(), 2);
        assert!((eq[0].factor - 4.0).abs() < 1e-9);
        assert!(!eq[0].baseline_spp.extrapolated);
        assert!((eq[1].factor - 4.0).abs() < 1e-9);
        let t = equal_time(&[base.clone(), better.clone()], 4.0);
        assert!((t[0].rmse.unwrap().value - 0.2).abs() < 1e-12);
        assert!((t[1].rmse.unwrap().value - 0.1).abs() < 1e-12);
        let slope = convergence_slope(&base).unwrap();
        assert!((slope + 0.5).abs() < 1e-12);
        // Relative MSE goes as 1/spp like MSE: half the RMSE is a quarter of the relMSE,
        // and again four times the samples.
        let rel = equivalent_samples(&better, &base, ErrorMetric::RelMse);
        assert!(rel.iter().all(|e| (e.factor - 4.0).abs() < 1e-9), "{rel:?}");
    }

    #[test]
    fn overhead_ratios_are_of_medians_against_off() {
        let rec = |g: &str, repeat, gather_s: f64| OverheadRecord {
            guiding: g.into(),
            repeat,
            spp: 64,
            wall_s: gather_s + 1.0,
            gather_s,
            rays: 0,
            guided_fraction: 0.5,
            cpu_s: 2.0 * gather_s,
            guide_build_s: 0.0,
            warp_s: 0.0,
        };
        let records = vec![
            rec("coherent", 0, 1.1),
            rec("off", 0, 1.0),
            rec("off", 1, 2.0),
            rec("coherent", 1, 2.2),
            rec("off", 2, 1.5),
            rec("coherent", 2, 9.0),
        ];
        let o = overhead(&records);
        assert_eq!(o[0].guiding, "off");
        assert!((o[0].gather_ratio - 1.0).abs() < 1e-12);
        assert!((o[1].gather_ratio - 2.2 / 1.5).abs() < 1e-12);
        assert!((o[1].paired_gather_ratio - 1.1).abs() < 1e-9);
        // CPU time is twice the gather in every record: the same paired ratios.
        assert!((o[1].paired_cpu_ratio - 1.1).abs() < 1e-9);
        assert!((o[0].paired_cpu_ratio - 1.0).abs() < 1e-12);
        assert!((o[1].wall_ratio - 3.2 / 2.5).abs() < 1e-12);
        assert_eq!(o[1].repeats, 3);
    }
}
