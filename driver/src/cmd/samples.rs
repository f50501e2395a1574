//! `guidebake samples`: the presorted Sobol packets of Silvennoinen & Sloan 2019, Figure 3,
//! drawn with plotters to a PNG, and the packet-coherence table behind README's figure.
//!
//! The figure has three columns — presorted packets as built; the same order after one
//! texel's Cranley–Patterson rotation; and after [`reorder_after_rotation_into`] — and two
//! rows: the primary sample space [0,1)² (grey lines: where the rotation's torus wrap cuts
//! the square) and the cosine-weighted hemisphere seen from above (the projected disk).
//! Points are coloured by packet, each joined to its packet's centroid.
//!
//! `--coherence` prints the mean angular spread of 8-ray packets (mean angle between each ray
//! and its packet's mean direction) on the hemisphere for N = 64, 256, 1024, averaged over
//! many random rotations: Sobol order ("unsorted"), presorted in Morton and in Hilbert
//! order, Hilbert plus the wrap-quadrant reorder, and a full quadtree re-sort of the rotated
//! points (the per-texel O(N log N) ideal the reorder approximates).

use std::path::PathBuf;

use guidebake_kernels::packet::LANES;
use guidebake_kernels::presort::coherence::{CoherenceRow, coherence_table, direction};
use guidebake_kernels::presort::{presorted, reorder_after_rotation_into};
use guidebake_kernels::sobol::{rotate, rotation, sobol_2d, to_unit};

use image::RgbImage;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf32;
use plotters::prelude::*;

use crate::preview::{PreviewError, categorical_color, write_png_rgb8};

/// Largest N the figure draws (beyond it the dots merge into a blur).
pub const MAX_FIGURE_N: u32 = 16_384;

/// Arguments of `guidebake samples`.
#[derive(Debug, clap::Args)]
pub struct SamplesArgs {
    /// Output PNG (its directory is created). Default: out/samples.png, unless --coherence
    /// is given alone.
    #[arg(short, long, alias = "out")]
    pub output: Option<PathBuf>,
    /// Sample count N per texel (any N from 1 to 16384; packets are consecutive groups of 8).
    #[arg(long, default_value_t = 256)]
    pub n: u32,
    /// Seed of the Cranley–Patterson rotations.
    #[arg(long, default_value_t = 1)]
    pub seed: u32,
    /// Texel id whose rotation the figure shows.
    #[arg(long, default_value_t = 0)]
    pub texel: u64,
    /// Print the packet-spread table for N = 64, 256, 1024 (README's coherence figure).
    #[arg(long)]
    pub coherence: bool,
    /// Random rotations averaged per row of the coherence table.
    #[arg(long, default_value_t = 1000)]
    pub rotations: u32,
}

/// What `guidebake samples` failed with.
#[derive(Debug, thiserror::Error)]
pub enum SamplesError {
    /// N outside what the figure can draw.
    #[error("--n {n} is out of range: the figure draws 1 to {MAX_FIGURE_N} samples")]
    BadCount {
        /// The requested N.
        n: u32,
    },
    /// The coherence table needs at least one rotation.
    #[error("--rotations must be at least 1")]
    NoRotations,
    /// plotters failed to draw the figure.
    #[error("cannot draw the figure: {what}")]
    Draw {
        /// plotters' message.
        what: String,
    },
    /// Writing the PNG failed.
    #[error(transparent)]
    Preview(#[from] PreviewError),
}

/// Runs `guidebake samples`.
///
/// # Errors
/// [`SamplesError`] for an N outside 1..=16384, zero rotations, or a PNG that cannot be
/// written (the message names the file).
pub fn run(args: &SamplesArgs) -> Result<(), super::CmdError> {
    run_typed(args).map_err(Into::into)
}

fn run_typed(args: &SamplesArgs) -> Result<(), SamplesError> {
    if args.n == 0 || args.n > MAX_FIGURE_N {
        return Err(SamplesError::BadCount { n: args.n });
    }
    if args.coherence {
        if args.rotations == 0 {
            return Err(SamplesError::NoRotations);
        }
        let rows = coherence_table(&[64, 256, 1024], args.rotations, args.seed);
        print!("{}", format_coherence_table(&rows, args.rotations));
    }
    let output = match (&args.output, args.coherence) {
        (Some(path), _) => path.clone(),
        (None, false) => PathBuf::from("out/samples.png"),
        (None, true) => return Ok(()),
    };
    let r = rotation(args.seed, args.texel, 0);
    let image = figure(args.n, r)?;
    write_png_rgb8(&output, image.width(), image.height(), image.as_raw())?;
    println!(
        "wrote {} (N = {}, {} packets, rotation of texel {} seed {}: {:.3}, {:.3})",
        output.display(),
        args.n,
        args.n.div_ceil(LANES as u32),
        args.texel,
        args.seed,
        to_unit(r[0]),
        to_unit(r[1])
    );
    Ok(())
}

/// The table as Markdown, with its ratios.
pub fn format_coherence_table(rows: &[CoherenceRow], rotations: u32) -> String {
    let mut s = format!(
        "Mean angular spread of 8-ray packets on the cosine hemisphere, degrees, mean over {rotations} random rotations\n\n\
         | N | unsorted | presorted (Morton) | Morton + wrap reorder | presorted (Hilbert) | Hilbert + wrap reorder | re-sorted after rotation | no rotation | packets split by the wrap | unsorted / Hilbert + reorder |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    for r in rows {
        s += &format!(
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.0}% | {:.1}x |\n",
            r.n,
            r.unsorted,
            r.morton,
            r.morton_reordered,
            r.hilbert,
            r.reordered,
            r.resorted,
            r.unrotated,
            100.0 * r.split_fraction,
            r.unsorted / r.reordered
        );
    }
    s
}

const PANEL: u32 = 300;
const MARGIN: u32 = 20;
const BACKGROUND: RGBColor = RGBColor(250, 250, 248);
const FRAME: RGBColor = RGBColor(60, 60, 60);
const CUT: RGBColor = RGBColor(170, 170, 170);

/// A panel of the figure: a `PANEL`-pixel square whose coordinates are the data's, y up.
type Panel<'a> = DrawingArea<BitMapBackend<'a>, Cartesian2d<RangedCoordf32, RangedCoordf32>>;

/// Draws the figure for `n` samples and rotation `r` (layout in the module docs) with
/// plotters on an RGB buffer. It sets no text, so it needs no font (the charts register
/// theirs: `bench/charts.rs`).
///
/// # Errors
/// [`SamplesError::Draw`] with plotters' message.
pub fn figure(n: u32, r: [u32; 2]) -> Result<RgbImage, SamplesError> {
    let presorted = presorted(n);
    let mut reordered = vec![0; n as usize];
    reorder_after_rotation_into(&presorted, r, &mut reordered);
    let columns: [(&[u32], [u32; 2]); 3] = [(&presorted, [0, 0]), (&presorted, r), (&reordered, r)];
    let cell = PANEL + 2 * MARGIN;
    let size = (3 * cell, 2 * cell);
    let radius = (PANEL as f32 / (n as f32).sqrt() / 5.0).clamp(1.0, 4.0);
    let mut pixels = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        root.fill(&BACKGROUND).map_err(draw_error)?;
        for (col, &(order, rot)) in columns.iter().enumerate() {
            let x0 = (col as u32 * cell + MARGIN) as i32;
            let square = panel(&root, x0, MARGIN as i32, 0.0..1.0);
            draw_square_panel(&square, order, rot, radius)?;
            let disk = panel(&root, x0, (cell + MARGIN) as i32, -1.0..1.0);
            draw_disk_panel(&disk, order, rot, radius)?;
        }
        root.present().map_err(draw_error)?;
    }
    RgbImage::from_raw(size.0, size.1, pixels).ok_or_else(|| SamplesError::Draw {
        what: "the figure's buffer has the wrong size".into(),
    })
}

fn draw_error(e: impl std::fmt::Display) -> SamplesError {
    SamplesError::Draw {
        what: e.to_string(),
    }
}

/// The `PANEL`-pixel square at (`x0`, `y0`) with `range` on both axes, y up.
fn panel<'a>(
    root: &DrawingArea<BitMapBackend<'a>, Shift>,
    x0: i32,
    y0: i32,
    range: std::ops::Range<f32>,
) -> Panel<'a> {
    let side = PANEL as i32;
    root.apply_coord_spec(Cartesian2d::new(
        range.clone(),
        range,
        (x0..x0 + side, y0 + side..y0),
    ))
}

/// Draws `order`'s packets in `[0,1)²` (v up), the rotation's cuts and the frame.
fn draw_square_panel(
    area: &Panel<'_>,
    order: &[u32],
    r: [u32; 2],
    radius: f32,
) -> Result<(), SamplesError> {
    if r != [0, 0] {
        let [u, v] = r.map(to_unit);
        area.draw(&PathElement::new([(u, 0.0), (u, 1.0)], CUT))
            .map_err(draw_error)?;
        area.draw(&PathElement::new([(0.0, v), (1.0, v)], CUT))
            .map_err(draw_error)?;
    }
    let at = |i| {
        let [u, v] = rotate(sobol_2d(i), r).map(to_unit);
        (u, v)
    };
    draw_packets(area, order, at, radius)?;
    area.draw(&Rectangle::new([(0.0, 0.0), (1.0, 1.0)], FRAME))
        .map_err(draw_error)
}

/// Draws `order`'s packets on the hemisphere seen from above (x right, y up) in the unit
/// disk's outline.
fn draw_disk_panel(
    area: &Panel<'_>,
    order: &[u32],
    r: [u32; 2],
    radius: f32,
) -> Result<(), SamplesError> {
    area.draw(&Circle::new((0.0, 0.0), PANEL / 2, FRAME))
        .map_err(draw_error)?;
    let at = |i| {
        let w = direction(rotate(sobol_2d(i), r));
        (w.x, w.y)
    };
    draw_packets(area, order, at, radius)
}

/// Each packet: spokes from its centroid to its points in a light tint of its colour, then
/// the points in its colour, as disks `2 * radius` pixels across (2×2 squares below 1.5).
fn draw_packets(
    area: &Panel<'_>,
    order: &[u32],
    at: impl Fn(u32) -> (f32, f32),
    radius: f32,
) -> Result<(), SamplesError> {
    for (k, packet) in order.chunks(LANES).enumerate() {
        let [r, g, b] = categorical_color(k);
        let color = RGBColor(r, g, b);
        let light = RGBColor(tint(r), tint(g), tint(b));
        let pts: Vec<(f32, f32)> = packet.iter().map(|&i| at(i)).collect();
        let m = pts.len() as f32;
        let centroid = pts
            .iter()
            .fold((0.0, 0.0), |(a, b), p| (a + p.0 / m, b + p.1 / m));
        for &p in &pts {
            area.draw(&PathElement::new([centroid, p], light))
                .map_err(draw_error)?;
        }
        for &p in &pts {
            if radius < 1.5 {
                // The bitmap backend fills [x0, x1) × [y0, y1): 2×2 pixels.
                let square = Rectangle::new([(0, 0), (2, 2)], color.filled());
                area.draw(&(EmptyElement::at(p) + square))
            } else {
                // A plotters disk of radius k is 2k + 1 pixels across.
                area.draw(&Circle::new(
                    p,
                    (radius - 0.5).round() as u32,
                    color.filled(),
                ))
            }
            .map_err(draw_error)?;
        }
    }
    Ok(())
}

/// A channel a third of the way from `c` to white.
fn tint(c: u8) -> u8 {
    ((u16::from(c) + 2 * 255) / 3) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(output: Option<PathBuf>, n: u32) -> SamplesArgs {
        SamplesArgs {
            output,
            n,
            seed: 1,
            texel: 0,
            coherence: false,
            rotations: 10,
        }
    }

    #[test]
    fn writes_the_figure_and_rejects_bad_counts() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out/figure.png");
        run_typed(&args(Some(path.clone()), 100)).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(
            img.dimensions(),
            (3 * (PANEL + 2 * MARGIN), 2 * (PANEL + 2 * MARGIN))
        );
        // Every packet's colour is on the canvas (not just a blank frame).
        let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
        for k in 0..100usize.div_ceil(LANES) {
            assert!(
                colours.contains(&categorical_color(k)),
                "packet {k} not drawn"
            );
        }
        assert!(matches!(
            run_typed(&args(None, 0)),
            Err(SamplesError::BadCount { n: 0 })
        ));
        assert!(matches!(
            run_typed(&args(None, MAX_FIGURE_N + 1)),
            Err(SamplesError::BadCount { .. })
        ));
    }

    fn rgb(c: RGBColor) -> [u8; 3] {
        [c.0, c.1, c.2]
    }

    /// One packet (N = 8), so no other covers it: each point is a disk of the packet's colour
    /// where the point is, in every panel; the frames, the cuts and the background are there.
    #[test]
    fn points_are_drawn_in_their_colour_where_they_are() {
        let r = [1 << 30, 3 << 30]; // the cuts at u = 1/4 and v = 3/4
        let img = figure(8, r).unwrap();
        let cell = PANEL + 2 * MARGIN;
        assert_eq!(img.dimensions(), (3 * cell, 2 * cell));
        let px = |x: f32, y: f32| img.get_pixel(x.floor() as u32, y.floor() as u32).0;
        let side = PANEL as f32;
        let colour = categorical_color(0);
        assert_eq!(px(0.0, 0.0), rgb(BACKGROUND));
        for (col, rot) in [[0, 0], r, r].into_iter().enumerate() {
            let x0 = (col as u32 * cell + MARGIN) as f32;
            let (y_square, y_disk) = (MARGIN as f32, (cell + MARGIN) as f32);
            for i in 0..8 {
                let [u, v] = rotate(sobol_2d(i), rot).map(to_unit);
                // Points on the frame are covered by it (it is drawn last).
                if [u, v].iter().all(|t| (0.01..0.99).contains(t)) {
                    let at = px(x0 + u * side, y_square + (1.0 - v) * side);
                    assert_eq!(
                        at, colour,
                        "column {col}, point {i} ({u}, {v}) in the square"
                    );
                }
                let w = direction(rotate(sobol_2d(i), rot));
                let half = side / 2.0;
                let at = px(x0 + half * (1.0 + w.x), y_disk + half * (1.0 - w.y));
                assert_eq!(at, colour, "column {col}, point {i} on the disk");
            }
            // The square's frame (its top edge) and the disk's centre row left of the rim.
            assert_eq!(px(x0 + side / 2.0, y_square), rgb(FRAME));
            assert_eq!(px(x0 - 2.0, y_disk + side / 2.0), rgb(BACKGROUND));
            // The cuts: the rotated columns' squares have a grey column at u = 1/4.
            let cut = (0..PANEL)
                .filter(|&y| px(x0 + side / 4.0, y_square + y as f32) == rgb(CUT))
                .count();
            if col == 0 {
                assert_eq!(cut, 0, "an unrotated square has no cut");
            } else {
                assert!(cut > PANEL as usize / 2, "column {col}: {cut} cut pixels");
            }
        }
    }
}
