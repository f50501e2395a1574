//! `guidebake samples`: the presorted Sobol packets of Silvennoinen & Sloan 2019, Figure 3,
//! drawn to a PNG, and the packet-coherence table behind README's figure.
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

use crate::preview::{Canvas, PreviewError, categorical_color, write_png};

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
    write_png(&output, &figure(args.n, r))?;
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
const BACKGROUND: [u8; 3] = [250, 250, 248];
const FRAME: [u8; 3] = [60, 60, 60];
const CUT: [u8; 3] = [170, 170, 170];

/// Draws the figure for `n` samples and rotation `r` (layout in the module docs).
pub fn figure(n: u32, r: [u32; 2]) -> Canvas {
    let presorted = presorted(n);
    let mut reordered = vec![0; n as usize];
    reorder_after_rotation_into(&presorted, r, &mut reordered);
    let columns: [(&[u32], [u32; 2]); 3] = [(&presorted, [0, 0]), (&presorted, r), (&reordered, r)];
    let cell = PANEL + 2 * MARGIN;
    let mut canvas = Canvas::new(3 * cell, 2 * cell, BACKGROUND);
    let radius = (PANEL as f32 / (n as f32).sqrt() / 5.0).clamp(1.0, 4.0);
    for (col, &(order, rot)) in columns.iter().enumerate() {
        let x0 = (col as u32 * cell + MARGIN) as f32;
        draw_square_panel(&mut canvas, x0, MARGIN as f32, order, rot, radius);
        draw_disk_panel(&mut canvas, x0, (cell + MARGIN) as f32, order, rot, radius);
    }
    canvas
}

/// Draws `order`'s packets in `[0,1)²` (v up) into the panel at (x0, y0).
fn draw_square_panel(
    canvas: &mut Canvas,
    x0: f32,
    y0: f32,
    order: &[u32],
    r: [u32; 2],
    radius: f32,
) {
    let size = PANEL as f32;
    let to_px = |p: [u32; 2]| {
        let [u, v] = p.map(to_unit);
        (x0 + u * size, y0 + (1.0 - v) * size)
    };
    if r != [0, 0] {
        let (cx, cy) = to_px(r);
        canvas.line(cx, y0, cx, y0 + size, CUT);
        canvas.line(x0, cy, x0 + size, cy, CUT);
    }
    draw_packets(canvas, order, |i| to_px(rotate(sobol_2d(i), r)), radius);
    frame(canvas, x0, y0, size);
}

/// Draws `order`'s packets on the hemisphere seen from above (x right, y up).
fn draw_disk_panel(canvas: &mut Canvas, x0: f32, y0: f32, order: &[u32], r: [u32; 2], radius: f32) {
    let half = PANEL as f32 / 2.0;
    let (cx, cy) = (x0 + half, y0 + half);
    canvas.circle(cx, cy, half, FRAME);
    draw_packets(
        canvas,
        order,
        |i| {
            let w = direction(rotate(sobol_2d(i), r));
            (cx + w.x * half, cy - w.y * half)
        },
        radius,
    );
}

/// Each packet: spokes from its centroid to its points, then the points, in its colour.
fn draw_packets(canvas: &mut Canvas, order: &[u32], at: impl Fn(u32) -> (f32, f32), radius: f32) {
    for (k, packet) in order.chunks(LANES).enumerate() {
        let color = categorical_color(k);
        let pts: Vec<(f32, f32)> = packet.iter().map(|&i| at(i)).collect();
        let m = pts.len() as f32;
        let (mx, my) = pts
            .iter()
            .fold((0.0, 0.0), |(a, b), p| (a + p.0 / m, b + p.1 / m));
        let light = color.map(|c| ((u16::from(c) + 2 * 255) / 3) as u8);
        for &(x, y) in &pts {
            canvas.line(mx, my, x, y, light);
        }
        for &(x, y) in &pts {
            canvas.dot(x, y, radius, color);
        }
    }
}

fn frame(canvas: &mut Canvas, x0: f32, y0: f32, size: f32) {
    let (x1, y1) = (x0 + size, y0 + size);
    canvas.line(x0, y0, x1, y0, FRAME);
    canvas.line(x0, y1, x1, y1, FRAME);
    canvas.line(x0, y0, x0, y1, FRAME);
    canvas.line(x1, y0, x1, y1, FRAME);
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
}
