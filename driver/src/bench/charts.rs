//! The harness's charts, drawn with `plotters` as PNG (bitmap backend, encoded by
//! [`crate::preview`]) and SVG: error against wall time per method (log–log), and the
//! Figure-5 overhead bars (paper Figure 5: time of each guiding mode over the baseline's at
//! equal samples).
//!
//! Text is set in DejaVu Sans, bundled in `font/` with its licence and registered with
//! plotters' `ab_glyph` backend, so the charts need no system fonts.
//!
//! Colour says the guiding mode, the marker the combination (circle: average, triangle:
//! Graybill–Deal per texel, cross: any other), and a thick line that ρ is applied.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::analysis::{Curve, Overhead};
use crate::atomic;

const FONT: &[u8] = include_bytes!("font/DejaVuSans.ttf");
const SIZE: (u32, u32) = (1000, 680);

/// Why a chart could not be drawn or written; names the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {what}")]
pub struct ChartError {
    /// The chart file.
    pub path: PathBuf,
    /// What failed.
    pub what: String,
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bundled file is a valid TrueType font; should it fail to parse, text is simply
        // not drawn (plotters reports a missing font per string), which the SVG still carries.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// A chart that can be drawn on any plotters backend.
pub trait Chart {
    /// Draws the chart on `root`.
    ///
    /// # Errors
    /// plotters' error, as text.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// Writes `chart` as `STEM.png` and `STEM.svg`, each through a temporary name; returns both.
///
/// # Errors
/// [`ChartError`] naming the file that could not be drawn or written.
pub fn write_chart(chart: &impl Chart, stem: &Path) -> Result<Vec<PathBuf>, ChartError> {
    register_font();
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    let fail = |path: &Path, what: String| ChartError {
        path: path.to_owned(),
        what,
    };
    let mut pixels = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, SIZE).into_drawing_area();
        chart.draw(&root).map_err(|e| fail(&png, e))?;
        root.present().map_err(|e| fail(&png, e.to_string()))?;
    }
    crate::preview::write_png_rgb8(&png, SIZE.0, SIZE.1, &pixels)
        .map_err(|e| fail(&png, e.to_string()))?;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, SIZE).into_drawing_area();
        chart.draw(&root).map_err(|e| fail(&svg, e))?;
        root.present().map_err(|e| fail(&svg, e.to_string()))?;
    }
    atomic::write(&svg, text).map_err(|e| fail(&svg, format!("cannot write: {e}")))?;
    Ok(vec![png, svg])
}

/// Which of a curve's values an [`ErrorChart`] plots.
#[derive(Clone, Copy, Debug)]
pub enum Metric {
    /// RMSE.
    Rmse,
    /// Relative MSE.
    RelMse,
}

/// Error against wall time, one line per method, log–log.
pub struct ErrorChart<'a> {
    /// Title.
    pub title: String,
    /// The curves.
    pub curves: &'a [Curve],
    /// What to plot.
    pub metric: Metric,
}

fn guiding_colour(label: &str) -> RGBColor {
    match label.split('/').next().unwrap_or("") {
        "off" => RGBColor(40, 40, 40),
        "naive" => RGBColor(214, 39, 40),
        "coherent" => RGBColor(31, 119, 180),
        "grid" => RGBColor(44, 160, 44),
        _ => RGBColor(148, 103, 189),
    }
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The range of log10 of the positive `values`, with a margin. The error charts plot log10 of
/// their values on linear axes labelled with 10^v: plotters' own log axes label only whole
/// decades, and a ladder of run times often spans less than one.
fn log10_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .map(f64::log10)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return -1.0..0.0;
    }
    let margin = ((hi - lo) * 0.06).max(0.05);
    (lo - margin)..(hi + margin)
}

/// A label for the value 10^`v` with three significant digits.
fn power_label(v: f64) -> String {
    let x = 10f64.powf(v);
    if (0.01..1000.0).contains(&x) {
        let digits = (2 - x.log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.2e}")
    }
}

impl Chart for ErrorChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let value = |p: &super::analysis::CurvePoint| match self.metric {
            Metric::Rmse => p.rmse,
            Metric::RelMse => p.rel_mse,
        };
        let points = || self.curves.iter().flat_map(|c| c.points.iter());
        let x = log10_range(points().map(|p| p.wall_s));
        let y = log10_range(points().map(value));
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(76)
            .build_cartesian_2d(x, y)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("wall time of the bake (s, log scale)")
            .y_desc(match self.metric {
                Metric::Rmse => "RMSE against the reference (log scale)",
                Metric::RelMse => "relative MSE against the reference (log scale)",
            })
            .x_labels(12)
            .y_labels(12)
            .y_label_formatter(&|v| power_label(*v))
            .x_label_formatter(&|v| power_label(*v))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(err)?;
        for curve in self.curves {
            let colour = guiding_colour(&curve.method);
            let rho = curve.method.ends_with("/rho");
            let style = colour.stroke_width(if rho { 3 } else { 1 });
            let pts: Vec<(f64, f64)> = curve
                .points
                .iter()
                .map(|p| (p.wall_s, value(p)))
                .filter(|(a, b)| *a > 0.0 && *b > 0.0 && a.is_finite() && b.is_finite())
                .map(|(a, b)| (a.log10(), b.log10()))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), style))
                .map_err(err)?
                .label(curve.method.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], style));
            let combine = curve.method.split('/').nth(1).unwrap_or("");
            let marker = colour.filled();
            match combine {
                "average" => {
                    chart
                        .draw_series(pts.iter().map(|&p| Circle::new(p, 4, marker)))
                        .map_err(err)?;
                }
                "texel" => {
                    chart
                        .draw_series(pts.iter().map(|&p| TriangleMarker::new(p, 5, marker)))
                        .map_err(err)?;
                }
                _ => {
                    chart
                        .draw_series(
                            pts.iter()
                                .map(|&p| Cross::new(p, 5, colour.stroke_width(2))),
                        )
                        .map_err(err)?;
                }
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .draw()
            .map_err(err)?;
        Ok(())
    }
}

/// The Figure-5 bars: median gather time of each guiding mode over the baseline's.
pub struct OverheadChart<'a> {
    /// Title.
    pub title: String,
    /// One entry per mode, `off` first.
    pub overhead: &'a [Overhead],
    /// The target ratio drawn as a line (the paper's 1.05).
    pub target: f64,
}

impl Chart for OverheadChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let n = self.overhead.len();
        let top = self
            .overhead
            .iter()
            .map(|o| o.gather_ratio.max(o.wall_ratio))
            .filter(|r| r.is_finite())
            .fold(self.target, f64::max)
            * 1.2;
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..n as f64, 0f64..top)
            .map_err(err)?;
        let names: Vec<String> = self.overhead.iter().map(|o| o.guiding.clone()).collect();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .light_line_style(WHITE)
            .x_labels(2 * n + 1)
            .x_label_formatter(&|v| {
                let i = v.floor() as usize;
                if (v - v.floor() - 0.5).abs() < 1e-6 && i < names.len() {
                    names[i].clone()
                } else {
                    String::new()
                }
            })
            .y_desc("median time / median time of guiding off")
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(err)?;
        for (i, o) in self.overhead.iter().enumerate() {
            let x = i as f64;
            let colour = guiding_colour(&o.guiding);
            let bars = [
                (x + 0.12, x + 0.48, o.gather_ratio, colour.filled()),
                (x + 0.52, x + 0.88, o.wall_ratio, colour.mix(0.4).filled()),
            ];
            for (x0, x1, r, style) in bars {
                if !r.is_finite() {
                    continue;
                }
                chart
                    .draw_series([Rectangle::new([(x0, 0.0), (x1, r)], style)])
                    .map_err(err)?;
                chart
                    .draw_series([Text::new(
                        format!("{r:.3}×"),
                        (x0 + 0.02, r + top * 0.015),
                        ("sans-serif", 14),
                    )])
                    .map_err(err)?;
            }
        }
        let target = self.target;
        chart
            .draw_series(LineSeries::new(
                [(0.0, target), (n as f64, target)],
                RED.stroke_width(1),
            ))
            .map_err(err)?
            .label(format!("target {target:.2}×"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], RED));
        chart
            .draw_series([Rectangle::new([(0.0, 0.0), (0.0, 0.0)], BLACK.filled())])
            .map_err(err)?
            .label("left bar: gather time")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 22, y + 5)], BLACK.filled()));
        chart
            .draw_series([Rectangle::new(
                [(0.0, 0.0), (0.0, 0.0)],
                BLACK.mix(0.4).filled(),
            )])
            .map_err(err)?
            .label("right bar: whole bake (wall)")
            .legend(|(x, y)| {
                Rectangle::new([(x, y - 5), (x + 22, y + 5)], BLACK.mix(0.4).filled())
            });
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .draw()
            .map_err(err)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axes_cover_the_values_and_label_them_readably() {
        let r = log10_range([0.5, 2.0, 8.0].into_iter());
        assert!(r.start < 0.5f64.log10() && r.end > 8.0f64.log10());
        assert_eq!(log10_range([0.0, f64::NAN].into_iter()), -1.0..0.0);
        assert_eq!(power_label(0.0), "1.00");
        assert_eq!(power_label(2.0), "100");
        assert_eq!(power_label(-1.0), "0.100");
        assert_eq!(power_label(-4.0), "1.00e-4");
    }
}
