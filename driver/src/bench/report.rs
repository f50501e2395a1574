//! The harness's written results: the per-run CSVs, the JSON summary and the Markdown table.
//! Every file is written through a temporary name and renamed, so a file that exists is whole.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::BenchError;
use super::analysis::{Curve, EqualTime, EquivalentSamples, ErrorMetric, Interpolated, Overhead};
use super::harness::{Ladder, OverheadRecord, RunRecord};
use super::method::{Method, serialize_value_name, value_name};
use super::reference::{ReferenceInfo, ReferenceNoise};
use crate::atomic;
use crate::bake::settings::Transport;

/// The machine the numbers were measured on.
#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    /// CPU model (from /proc/cpuinfo where available).
    pub cpu: String,
    /// Hardware threads available to the process.
    pub cores: usize,
    /// SIMD the CPU offers (of AVX2, FMA, AVX-512F).
    pub simd: Vec<String>,
}

impl Machine {
    /// What this process runs on.
    pub fn detect() -> Machine {
        let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let field = |name: &str| {
            info.lines()
                .find(|l| l.starts_with(name))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_owned())
        };
        let flags = field("flags").unwrap_or_default();
        let simd = ["avx2", "fma", "avx512f"]
            .iter()
            .filter(|f| flags.split_whitespace().any(|x| x == **f))
            .map(|f| (*f).to_owned())
            .collect();
        Machine {
            cpu: field("model name").unwrap_or_else(|| std::env::consts::ARCH.to_owned()),
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            simd,
        }
    }
}

/// Today's date in UTC as `YYYY-MM-DD` (from the system clock; civil-from-days).
pub fn today_utc() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    date_of_unix_day((secs / 86_400) as i64)
}

/// The civil date `YYYY-MM-DD` of day `days` after 1970-01-01 (Howard Hinnant's
/// `civil_from_days`).
fn date_of_unix_day(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

/// One of the targets, as measured.
#[derive(Clone, Debug, Serialize)]
pub struct Target {
    /// What is aimed for.
    pub goal: String,
    /// The measured value the goal is judged on.
    pub value: Option<f64>,
    /// Whether it is met (`None`: not measurable in this run).
    pub met: Option<bool>,
}

/// The equal-time comparison.
#[derive(Clone, Debug, Serialize)]
pub struct EqualTimeSummary {
    /// The budget in seconds of wall time.
    pub budget_s: f64,
    /// How the budget was chosen.
    pub rule: String,
    /// Each method's errors within the budget.
    pub methods: Vec<EqualTime>,
    /// The baseline's RMSE with four times the budget.
    pub baseline_rmse_at_4x: Option<Interpolated>,
}

/// The Figure-5 overhead measurement.
#[derive(Clone, Debug, Serialize)]
pub struct OverheadSummary {
    /// Rays per texel of every run.
    pub spp: u32,
    /// Repeats of each mode.
    pub repeats: u32,
    /// Light transport of every run.
    #[serde(serialize_with = "serialize_value_name")]
    pub transport: Transport,
    /// Per mode, `off` first.
    pub modes: Vec<Overhead>,
}

/// Everything `summary.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Scene name.
    pub scene: String,
    /// Scene file (or the demo's description).
    pub scene_path: String,
    /// Texel file.
    pub texels_path: String,
    /// Valid texels compared.
    pub texels: u64,
    /// Page sizes of the texel file.
    pub pages: Vec<(u32, u32)>,
    /// Machine.
    pub machine: Machine,
    /// Date of the run (UTC).
    pub date_utc: String,
    /// Worker threads of every bake.
    pub threads: usize,
    /// Methods, sample counts, seeds.
    pub ladder: Ladder,
    /// The reference.
    pub reference: ReferenceInfo,
    /// The reference's own noise, a part of every error (`--reference-noise`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_noise: Option<ReferenceNoise>,
    /// Error against time per method.
    pub curves: Vec<Curve>,
    /// Log–log slope of RMSE against wall time per method.
    pub slopes: Vec<(String, Option<f64>)>,
    /// Errors at equal time.
    pub equal_time: EqualTimeSummary,
    /// Equivalent-sample factors against the baseline, by RMSE and by relative MSE.
    pub equivalent_samples: Vec<EquivalentSamples>,
    /// The Figure-5 overhead.
    pub overhead: OverheadSummary,
    /// The targets.
    pub targets: Vec<Target>,
    /// Seconds the whole harness took.
    pub total_seconds: f64,
}

fn write_atomic(path: &Path, text: &str) -> Result<(), BenchError> {
    atomic::write(path, text).map_err(|e| BenchError::file(path, e))
}

/// The columns of `runs.csv`.
pub const RUN_COLUMNS: [&str; 24] = [
    "scene",
    "method",
    "guiding",
    "combine",
    "rho",
    "spp",
    "iterations",
    "seed",
    "wall_s",
    "cpu_s",
    "open_s",
    "bvh_s",
    "gather_s",
    "write_s",
    "gather_rays",
    "shadow_rays",
    "rays_per_s",
    "guided_fraction",
    "rho_value",
    "rmse",
    "rel_mse",
    "bias",
    "rel_bias",
    "texels",
];

/// The columns of `overhead.csv`.
pub const OVERHEAD_COLUMNS: [&str; 11] = [
    "scene",
    "guiding",
    "repeat",
    "spp",
    "wall_s",
    "gather_s",
    "rays",
    "guided_fraction",
    "cpu_s",
    "guide_build_s",
    "warp_s",
];

/// Writes `runs.csv`: one row per bake of the ladder.
///
/// # Errors
/// [`BenchError::File`] naming the file.
pub fn write_runs_csv(path: &Path, scene: &str, runs: &[RunRecord]) -> Result<(), BenchError> {
    let mut text = RUN_COLUMNS.join(",") + "\n";
    for r in runs {
        let e = &r.error;
        let _ = writeln!(
            text,
            "{scene},{},{},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{:.1},{:.6},{:.6},{:.6e},{:.6e},{:.6e},{:.6e},{}",
            r.method,
            r.guiding,
            r.combine,
            r.rho,
            r.spp,
            r.iterations,
            r.seed,
            r.wall_s,
            r.cpu_s,
            r.open_s,
            r.bvh_s,
            r.gather_s,
            r.write_s,
            r.gather_rays,
            r.shadow_rays,
            r.rays_per_s,
            r.guided_fraction,
            r.rho_value,
            e.rmse,
            e.rel_mse,
            e.bias,
            e.rel_bias,
            e.texels
        );
    }
    write_atomic(path, &text)
}

/// Writes `overhead.csv`: one row per bake of the Figure-5 measurement.
///
/// # Errors
/// [`BenchError::File`] naming the file.
pub fn write_overhead_csv(
    path: &Path,
    scene: &str,
    records: &[OverheadRecord],
) -> Result<(), BenchError> {
    let mut text = OVERHEAD_COLUMNS.join(",") + "\n";
    for r in records {
        let _ = writeln!(
            text,
            "{scene},{},{},{},{:.6},{:.6},{},{:.6},{:.6},{:.6},{:.6}",
            r.guiding,
            r.repeat,
            r.spp,
            r.wall_s,
            r.gather_s,
            r.rays,
            r.guided_fraction,
            r.cpu_s,
            r.guide_build_s,
            r.warp_s
        );
    }
    write_atomic(path, &text)
}

/// Writes `summary.json`.
///
/// # Errors
/// [`BenchError::File`] naming the file.
pub fn write_summary(path: &Path, summary: &Summary) -> Result<(), BenchError> {
    let text = serde_json::to_string_pretty(summary).map_err(|e| BenchError::file(path, e))?;
    write_atomic(path, &text)
}

fn opt(v: Option<Interpolated>, digits: usize) -> String {
    match v {
        Some(i) if i.value.is_finite() => {
            format!(
                "{:.digits$e}{}",
                i.value,
                if i.extrapolated { "*" } else { "" }
            )
        }
        _ => "—".into(),
    }
}

/// The Markdown tables of a summary (`table.md`, and what `docs/BENCHMARKS.md` quotes).
pub fn markdown(s: &Summary) -> String {
    let mut md = String::new();
    let pages: Vec<String> = s.pages.iter().map(|(w, h)| format!("{w}×{h}")).collect();
    let _ = writeln!(
        md,
        "### {}\n\n{} valid texels on {} page(s) {}; {} threads; {} ({} cores), {}.\n\
         Ladder: spp {:?}, seeds {:?}, {} learning iterations, `{}` transport with {} bounces. Reference: {} spp, {} ({:.1} s to bake{}).\n",
        s.scene,
        s.texels,
        s.pages.len(),
        pages.join(", "),
        s.threads,
        s.machine.cpu,
        s.machine.cores,
        s.date_utc,
        s.ladder.spp,
        s.ladder.seeds,
        s.ladder.iterations,
        value_name(&s.ladder.transport),
        s.ladder.bounces,
        s.reference.spp,
        s.reference.settings,
        s.reference.bake_seconds,
        if s.reference.cached { ", cached" } else { "" }
    );
    if let Some(n) = &s.reference_noise {
        let _ = writeln!(
            md,
            "The reference is the mean of the bake above and its twin ({}{}). Its own noise is a part of every error below: relative MSE {:.3e}, MSE {:.3e}. Subtract it for a run's error against the truth.\n",
            n.twin.path.display(),
            if n.twin.cached { ", cached" } else { "" },
            n.rel_mse,
            n.mse
        );
    }
    let max_spp = s.ladder.spp.iter().copied().max().unwrap_or(0);
    let _ = writeln!(
        md,
        "| method | time at {max_spp} spp (s) | RMSE at {max_spp} | relMSE at {max_spp} | rel. bias at {max_spp} | RMSE in {:.3} s | relMSE in {:.3} s | × baseline spp at {max_spp} | × baseline spp at equal time | at equal CPU time | at equal CPU time, by relMSE | guided |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        s.equal_time.budget_s, s.equal_time.budget_s
    );
    let baseline_label = crate::bench::method::Method::baseline().label();
    let baseline_top = s
        .curves
        .iter()
        .find(|c| c.method == baseline_label)
        .and_then(|c| c.points.iter().find(|p| p.spp == max_spp));
    for (c, t) in s.curves.iter().zip(&s.equal_time.methods) {
        let Some(p) = c.points.iter().find(|p| p.spp == max_spp) else {
            continue;
        };
        let equivalent = |metric| {
            s.equivalent_samples
                .iter()
                .find(|e| e.method == c.method && e.spp == max_spp && e.metric == metric)
        };
        // Baseline samples with the method's error over the baseline samples that fit in the
        // method's time: the equivalent-sample factor times the baseline's time over the
        // method's, both at the top of the ladder.
        let at_by = |metric, b: f64, m: f64| match equivalent(metric) {
            Some(e) if m > 0.0 && b > 0.0 => format!(
                "{:.2}{}",
                e.factor * b / m,
                if e.baseline_spp.extrapolated { "*" } else { "" }
            ),
            _ => "—".into(),
        };
        let at = |b, m| at_by(ErrorMetric::Rmse, b, m);
        let equivalent = equivalent(ErrorMetric::Rmse);
        let at_equal_time = baseline_top.map_or_else(|| "—".into(), |b| at(b.wall_s, p.wall_s));
        let at_equal_cpu = baseline_top.map_or_else(|| "—".into(), |b| at(b.cpu_s, p.cpu_s));
        let rel_at_equal_cpu = baseline_top.map_or_else(
            || "—".into(),
            |b| at_by(ErrorMetric::RelMse, b.cpu_s, p.cpu_s),
        );
        let factor = equivalent.map_or_else(
            || "—".into(),
            |e| {
                format!(
                    "{:.2}{}",
                    e.factor,
                    if e.baseline_spp.extrapolated { "*" } else { "" }
                )
            },
        );
        let _ = writeln!(
            md,
            "| {} | {:.3} | {:.3e} | {:.3e} | {:+.2}% | {} | {} | {} | {} | {} | {} | {:.0}% |",
            c.method,
            p.wall_s,
            p.rmse,
            p.rel_mse,
            100.0 * p.rel_bias,
            opt(t.rmse, 3),
            opt(t.rel_mse, 3),
            factor,
            at_equal_time,
            at_equal_cpu,
            rel_at_equal_cpu,
            100.0 * p.guided_fraction
        );
    }
    let _ = writeln!(
        md,
        "\n\\* read off the fitted log–log line outside the measured range. Budget: {}.\n",
        s.equal_time.rule
    );
    let _ = writeln!(
        md,
        "Figure-5 overhead, {} spp, `{}` transport, {} interleaved repeats (medians; every \
         `--guiding` mode with the bake's defaults otherwise, `{}`):\n\n\
         | guiding | gather (s) | wall (s) | gather / off | wall / off | paired gather / off | paired CPU / off | guided |\n|---|---:|---:|---:|---:|---:|---:|---:|",
        s.overhead.spp,
        value_name(&s.overhead.transport),
        s.overhead.repeats,
        Method::default_bake().label()
    );
    for o in &s.overhead.modes {
        let _ = writeln!(
            md,
            "| {} | {:.3} | {:.3} | {:.3}× | {:.3}× | {:.3}× | {:.3}× | {:.0}% |",
            o.guiding,
            o.gather_s,
            o.wall_s,
            o.gather_ratio,
            o.wall_ratio,
            o.paired_gather_ratio,
            o.paired_cpu_ratio,
            100.0 * o.guided_fraction
        );
    }
    let _ = writeln!(md, "\n| target | measured | met |\n|---|---:|---|");
    for t in &s.targets {
        let _ = writeln!(
            md,
            "| {} | {} | {} |",
            t.goal,
            t.value.map_or_else(|| "—".into(), |v| format!("{v:.3}")),
            match t.met {
                Some(true) => "yes",
                Some(false) => "**no**",
                None => "not measured",
            }
        );
    }
    md
}

/// Writes `table.md`.
///
/// # Errors
/// [`BenchError::File`] naming the file.
pub fn write_markdown(path: &Path, summary: &Summary) -> Result<(), BenchError> {
    write_atomic(path, &markdown(summary))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unix_days_become_civil_dates() {
        assert_eq!(date_of_unix_day(0), "1970-01-01");
        assert_eq!(date_of_unix_day(59), "1970-03-01");
        assert_eq!(date_of_unix_day(11_016), "2000-02-29");
        assert_eq!(date_of_unix_day(20_415), "2025-11-23");
        assert_eq!(date_of_unix_day(-1), "1969-12-31");
        assert_eq!(today_utc().len(), 10);
    }
}
