//! Lightmap quality on real scenes (docs/denoise.md): RMSE of raw and denoised lightmaps
//! against a 16× reference, and the mean relative jumps across seams before and after
//! stitching: between the seam's texel pairs, and between the two sides' bilinear values at
//! the seam's edge points (what a shader shows).
//!
//! For each scene: prepare at a page of 192², bake (or reuse from `--cache DIR`) the
//! reference — `bench`'s unbiased baseline at 16 × 256 = 4096 spp with the series transport,
//! so the bake's own transport is compared and only the estimator's noise and the filter
//! differ — then bake the default settings at 64 and 256 spp once each (pass by pass, keeping
//! the work) and finish that one bake several ways: raw, denoised with the default
//! [`ATrous`] and with the variants of the sweep, and seam-stitched. Prints Markdown tables.
//!
//! ```sh
//! cargo run --release -p guidebake --example denoise_rmse -- --cache target/denoise-ref \
//!     ../shared/scenes/converted/*.glb
//! ```
//!
//! `--seams-only` skips the denoising and its sweep: raw and stitched only.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use std::collections::HashMap;

use guidebake::bake::finish::{DILATION_PIXELS, FinishOptions, Seams, finish_filtered, merge_pass};
use guidebake::bake::run::{BakeJob, bake, bake_pass_with_progress};
use guidebake::bake::settings::{BakeSettings, Transport};
use guidebake::bake::shard::Shard;
use guidebake::bake::workdir::work_dir;
use guidebake::bench::metrics::compare;
use guidebake::bench::reference::reference_settings;
use guidebake::output::denoise::{ATrous, Denoiser};
use guidebake::output::readback::read_lightmap;
use guidebake::output::seams::{
    PageFacts, Pixel, Written, edge_system, mean_relative_jump, read_seam_file, seam_file_path,
};
use guidebake::prepare::{Layout, PrepareOptions, Resolution, prepare};
use guidebake::scene::Scene;
use guidebake::texels::TexelFile;

type Error = Box<dyn std::error::Error>;

/// Page edge of the measurement's texel files.
const PAGE: u32 = 192;
/// Samples of the measured runs; the reference has 16 × the largest.
const SPP: [u32; 2] = [64, 256];
/// The filter variants of the sweep: (levels, luminance σ).
const SWEEP: [(u32, f32); 5] = [(2, 2.0), (3, 4.0), (3, 2.0), (2, 1.0), (1, 2.0)];

fn main() -> Result<(), Error> {
    let mut args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let work = tempfile::tempdir()?;
    let cache = match args.iter().position(|a| a.as_os_str() == "--cache") {
        Some(i) if i + 1 < args.len() => {
            let dir = args.remove(i + 1);
            args.remove(i);
            dir
        }
        _ => work.path().to_owned(),
    };
    if args.is_empty() {
        return Err(
            "usage: denoise_rmse [--cache DIR] SCENE... (e.g. ../shared/scenes/converted/*.glb)"
                .into(),
        );
    }
    let seams_only = args.iter().any(|a| a.as_os_str() == "--seams-only");
    args.retain(|a| a.as_os_str() != "--seams-only");
    std::fs::create_dir_all(&cache)?;
    let mut rmse = Vec::new();
    let mut sweep = Vec::new();
    let mut seams = Vec::new();
    for path in &args {
        let scene = Scene::load(path)?;
        let name = path
            .file_stem()
            .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        let texels = work.path().join(format!("{name}.texels"));
        let options = PrepareOptions {
            resolution: Resolution::Size(PAGE, PAGE),
            layout: Layout::Auto,
        };
        let count = prepare(&scene, &texels, options)?.texels;
        guidebake::output::seams::prepare_seams(&scene, &texels)?;
        let file = TexelFile::open(&texels)?;
        let job = |settings: BakeSettings, out: PathBuf| BakeJob {
            texels: texels.clone(),
            out,
            settings,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            shard: Shard::WHOLE,
            resume: false,
            aux: false,
            finish: FinishOptions::default(),
        };
        let defaults = BakeSettings::default();
        let reference = reference_settings(
            16 * SPP[1],
            defaults.iterations,
            Transport::Series,
            defaults.bounces,
        );
        let ref_out = cache.join(format!("ref-{name}-{PAGE}-{}.exr", reference.spp));
        let truth = match read_lightmap(&file, &ref_out) {
            Ok(values) => values,
            Err(_) => {
                let clock = std::time::Instant::now();
                bake(
                    &job(reference, ref_out.clone()),
                    &scene,
                    &AtomicBool::new(false),
                    &mut |_, _| {},
                )?;
                eprintln!(
                    "{name}: reference of {count} texels in {:.0} s",
                    clock.elapsed().as_secs_f64()
                );
                read_lightmap(&file, &ref_out)?
            }
        };
        let [ref_pairs, ref_edge] = seam_jumps(&file, &texels, &truth)?;
        for spp in SPP {
            let settings = BakeSettings {
                spp,
                seed: 1,
                ..defaults
            };
            let out = work.path().join(format!("{name}-{spp}.exr"));
            let dir = bake_passes(&job(settings, out.clone()), &scene, &file)?;
            let finish = |filter: Option<&dyn Denoiser>, stitch: Seams| -> Result<_, Error> {
                let written =
                    finish_filtered(&file, std::slice::from_ref(&dir), &out, filter, stitch)?;
                Ok((read_lightmap(&file, &out)?, written))
            };
            let (raw, _) = finish(None, Seams::Off)?;
            let raw_rmse = compare(&raw, &truth)?.rmse;
            let (stitched, written) = finish(None, Seams::Stitch)?;
            let [before, after] = written.seam_jump.unwrap_or([0.0; 2]);
            let [edge_before, edge_after] = written.edge_jump.unwrap_or([0.0; 2]);
            let [points, skipped, held] = written.edge_points;
            let stitched_rmse = compare(&stitched, &truth)?.rmse;
            let negative = stitched
                .iter()
                .flatten()
                .filter(|v| v.iter().any(|c| *c < 0.0))
                .count();
            seams.push(format!(
                "| {name} | {spp} | {} | {before:.4} | {after:.4} | {ref_pairs:.4} \
                 | {points} ({skipped} left out, {held} held ≥ 0) | {edge_before:.4} | {edge_after:.4} \
                 | {ref_edge:.4} | {negative} | {raw_rmse:.5} | {stitched_rmse:.5} | {:.4} |",
                written.seam_pairs,
                stitched_rmse / raw_rmse
            ));
            if seams_only {
                std::fs::remove_dir_all(&dir)?;
                continue;
            }
            let (denoised, _) = finish(Some(&ATrous::default()), Seams::Off)?;
            let dn_rmse = compare(&denoised, &truth)?.rmse;
            rmse.push(format!(
                "| {name} | {count} | {spp} | {raw_rmse:.5} | {dn_rmse:.5} | {:.2} |",
                dn_rmse / raw_rmse
            ));
            let mut row = format!("| {name} | {spp} |");
            for (levels, luminance_sigma) in SWEEP {
                let filter = ATrous {
                    levels,
                    luminance_sigma,
                };
                let (values, _) = finish(Some(&filter), Seams::Off)?;
                row += &format!(" {:.2} |", compare(&values, &truth)?.rmse / raw_rmse);
            }
            sweep.push(row);
            std::fs::remove_dir_all(&dir)?;
        }
    }
    if !seams_only {
        println!("| scene | texels | spp | RMSE raw | RMSE denoised | denoised / raw |");
        println!("|---|---|---|---|---|---|");
        rmse.iter().for_each(|r| println!("{r}"));
        println!();
        let head: Vec<String> = SWEEP
            .iter()
            .map(|(l, s)| format!("{l} levels, σ {s}"))
            .collect();
        println!("| scene | spp | {} |", head.join(" | "));
        println!("|---|---|{}", "---|".repeat(SWEEP.len()));
        sweep.iter().for_each(|r| println!("{r}"));
        println!();
    }
    println!(
        "| scene | spp | seam pairs | pair jump raw | pair jump stitched | pair jump reference \
         | edge points | edge jump raw | edge jump stitched | edge jump reference \
         | stitched texels < 0 | RMSE raw | RMSE stitched | stitched / raw |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    seams.iter().for_each(|r| println!("{r}"));
    Ok(())
}

/// The texels of a lightmap read back, as the seam measures see the page.
struct Texels<'a> {
    file: &'a TexelFile,
    at: HashMap<Pixel, usize>,
    values: &'a [Option<[f32; 3]>],
}

impl PageFacts for Texels<'_> {
    fn size(&self, page: u32) -> Option<(u32, u32)> {
        let size = self.file.pages().get(page as usize)?;
        Some((size.width, size.height))
    }

    fn written(&self, p: Pixel) -> Written {
        match self.at.get(&p).and_then(|&i| self.values[i]) {
            Some(v) if v.iter().all(|c| c.is_finite()) => Written::Texel,
            Some(_) => Written::NonFinite,
            None => Written::Empty,
        }
    }
}

/// The seam jumps of `values` (a lightmap read back, e.g. the reference): between texel
/// pairs and between the two sides' bilinear values at the edge points.
fn seam_jumps(
    file: &TexelFile,
    texels: &std::path::Path,
    values: &[Option<[f32; 3]>],
) -> Result<[f64; 2], Error> {
    let samples = read_seam_file(&seam_file_path(texels))?;
    let at: HashMap<Pixel, usize> = file
        .texels()
        .iter()
        .enumerate()
        .map(|(i, t)| ([t.page, u32::from(t.pixel[0]), u32::from(t.pixel[1])], i))
        .collect();
    let value = |p: &Pixel| at.get(p).and_then(|&i| values[i]).unwrap_or([f32::NAN; 3]);
    let mut all: Vec<[f32; 3]> = Vec::new();
    let pairs: Vec<(u32, u32)> = samples
        .pairs
        .iter()
        .map(|p| {
            all.extend([value(&p.a), value(&p.b)]);
            (all.len() as u32 - 2, all.len() as u32 - 1)
        })
        .collect();
    let pair_jump = mean_relative_jump(&all, &pairs);
    let facts = Texels { file, at, values };
    let system = edge_system(&samples.points, &facts, DILATION_PIXELS);
    let value = |p: &Pixel| {
        facts
            .at
            .get(p)
            .and_then(|&i| values[i])
            .unwrap_or([f32::NAN; 3])
    };
    let read: Vec<[f32; 3]> = system.pixels.iter().map(value).collect();
    Ok([pair_jump, system.edge_jump(&read)])
}

/// Bakes every series pass of `job`, merging between passes, and returns the work directory
/// of the last pass, kept for any number of finishes.
fn bake_passes(job: &BakeJob, scene: &Scene, file: &TexelFile) -> Result<PathBuf, Error> {
    let passes = job.settings.last_pass();
    for pass in job.settings.first_pass()..=passes {
        bake_pass_with_progress(job, Some(pass), scene, &AtomicBool::new(false), &mut |_| {})?;
        if pass < passes {
            merge_pass(file, &[work_dir(&job.out, job.shard)], &job.out, pass)?;
        }
    }
    Ok(work_dir(&job.out, job.shard))
}
