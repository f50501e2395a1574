//! The denoiser figures of docs/denoise.md: raw, `atrous` and `oidn` against a 16× reference
//! on real scenes, with the time each denoiser adds, the seams' edge jumps, and the spp at
//! which the raw bake reaches the OIDN-denoised 64-spp error.
//!
//! Ignored (minutes of baking on two cores); it needs the `oidn` feature and `../shared`:
//!
//! ```sh
//! eval "$(scripts/oidn/fetch.sh)"
//! cargo test --release -p guidebake --features oidn --test denoise_figures -- --ignored --nocapture
//! ```
//!
//! `GUIDEBAKE_DENOISE_SCENES` (comma-separated: `cornell`, `ajar`, `bidir`, `zdm2`; default
//! all) picks the scenes, `GUIDEBAKE_DENOISE_CACHE` the reference cache (default
//! `target/denoise-ref`, shared with the `denoise_rmse` example's: same page, same reference),
//! `GUIDEBAKE_DENOISE_PAGE` the page edge of every scene, `GUIDEBAKE_DENOISE_IMAGES` a folder
//! for a crop of chart borders and its error maps per scene and spp ([`crops`]).
//! Per scene: prepare at a page of 192² (zdm2: 512²), bake the reference — `bench`'s unbiased baseline at
//! 16 × 256 = 4096 spp, series transport, so only the estimator's noise and the filter differ
//! — then the default settings at 64, 128, 256, 512 and 1024 spp, each finished raw; 64 and
//! 256 also with each denoiser, and with OIDN on every island (no least size). Prints Markdown
//! tables (each row on stderr as it is measured); asserts that every lightmap is finite.
#![cfg(feature = "oidn")]

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use std::collections::HashMap;

use guidebake::bake::finish::{DILATION_PIXELS, Seams, finish_filtered, merge_pass};
use guidebake::bake::run::{BakeJob, bake, bake_pass_with_progress};
use guidebake::bake::settings::{BakeSettings, Transport};
use guidebake::bake::shard::Shard;
use guidebake::bake::workdir::work_dir;
use guidebake::bench::metrics::{ErrorStats, compare};
use guidebake::bench::reference::reference_settings;
use guidebake::output::denoise::{ATrous, Denoiser, Oidn};
use guidebake::output::readback::read_lightmap;
use guidebake::output::seams::{
    PageFacts, Pixel, Written, edge_system, read_seam_file, seam_file_path,
};
use guidebake::prepare::{Layout, PrepareOptions, Resolution, prepare};
use guidebake::scene::Scene;
use guidebake::texels::TexelFile;

type Error = Box<dyn std::error::Error>;

/// Page edge of the measurement's texel files: `GUIDEBAKE_DENOISE_PAGE` when set; else the
/// À-Trous sweep's for the rooms, and more for a level to keep its thousands of charts (zdm2
/// has 1 114 texels at 192²).
fn page(name: &str) -> u32 {
    if let Some(edge) = std::env::var("GUIDEBAKE_DENOISE_PAGE")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        return edge;
    }
    if name == "zdm2" { 512 } else { 192 }
}
/// Samples finished with each denoiser; the reference has 16 × the largest.
const SPP: [u32; 2] = [64, 256];
/// The raw ladder (for the spp that reaches OIDN's 64-spp error, and equal time).
const LADDER: [u32; 5] = [64, 128, 256, 512, 1024];

/// A scene of the measurement: its short name and how to load it.
fn scene_path(name: &str, shared: &Path, work: &Path) -> Result<PathBuf, Error> {
    let converted = |f: &str| shared.join("converted").join(f);
    Ok(match name {
        "cornell" => converted("bitterli_cornell_box.glb"),
        "ajar" => converted("bitterli_veach_ajar_no_teapots.glb"),
        "bidir" => converted("bitterli_veach_bidir.glb"),
        "zdm2" => {
            // docs/levels.md's light: the sun towards (0.3, 1, 0.45) at 4, a blue-grey sky.
            let toml = work.join("zdm2.toml");
            std::fs::write(
                &toml,
                format!(
                    "geometry = {:?}\n[sun]\ndirection = [0.3, 1.0, 0.45]\nangular_radius_deg = 0.27\nirradiance = [4.0, 4.0, 4.0]\n[sky]\nconstant = [0.45, 0.55, 0.7]\n",
                    shared.join("calinou_zdm2/zdm2.obj")
                ),
            )?;
            toml
        }
        other => return Err(format!("unknown scene {other}").into()),
    })
}

/// One finish of a bake: its errors, seam edge jump, wall time and values.
struct Finished {
    stats: ErrorStats,
    edge_jump: f64,
    seconds: f64,
    values: Vec<Option<[f32; 3]>>,
}

#[test]
#[ignore = "minutes of baking; run by hand for docs/denoise.md"]
fn denoiser_figures() -> Result<(), Error> {
    let Some(shared) = guidebake::test_support::shared_scenes_dir() else {
        return Ok(());
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cache = std::env::var_os("GUIDEBAKE_DENOISE_CACHE")
        .map_or_else(|| root.join("target/denoise-ref"), PathBuf::from);
    std::fs::create_dir_all(&cache)?;
    let names = std::env::var("GUIDEBAKE_DENOISE_SCENES")
        .unwrap_or_else(|_| "cornell,ajar,bidir,zdm2".into());
    let work = tempfile::tempdir()?;
    let oidn = Oidn::new()?;
    // The same network on every island, the smallest too (what leaving them out buys).
    let mut every = Oidn::new()?;
    every.min_island = 0;
    let atrous = ATrous::default();
    let mut main_rows = Vec::new();
    let mut speed_rows = Vec::new();
    let mut every_rows = Vec::new();
    for name in names.split(',') {
        let path = scene_path(name, &shared, work.path())?;
        let scene = Scene::load(&path)?;
        let texels = work.path().join(format!("{name}.texels"));
        let options = PrepareOptions {
            resolution: Resolution::Size(page(name), page(name)),
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
            finish: Default::default(),
        };
        let defaults = BakeSettings::default();
        let reference = reference_settings(
            16 * SPP[1],
            defaults.iterations,
            Transport::Series,
            defaults.bounces,
        );
        let stem = path
            .file_stem()
            .map_or(name.into(), |s| s.to_string_lossy());
        let ref_out = cache.join(format!("ref-{stem}-{}-{}.exr", page(name), reference.spp));
        let truth = match read_lightmap(&file, &ref_out) {
            Ok(values) => values,
            Err(_) => {
                let clock = Instant::now();
                let never = AtomicBool::new(false);
                bake(
                    &job(reference, ref_out.clone()),
                    &scene,
                    &never,
                    &mut |_, _| {},
                )?;
                eprintln!(
                    "{name}: reference of {count} texels in {:.0} s",
                    clock.elapsed().as_secs_f64()
                );
                read_lightmap(&file, &ref_out)?
            }
        };
        let seams = Seam::load(&file, &texels)?;
        let ref_edge = seams.edge_jump(&truth);
        let mut ladder: Vec<(u32, f64, ErrorStats)> = Vec::new();
        let mut oidn_64: Option<(ErrorStats, f64)> = None;
        for spp in LADDER {
            let settings = BakeSettings {
                spp,
                seed: 1,
                ..defaults
            };
            let out = work.path().join(format!("{name}-{spp}.exr"));
            let clock = Instant::now();
            let dir = bake_passes(&job(settings, out.clone()), &scene, &file)?;
            let bake_seconds = clock.elapsed().as_secs_f64();
            let finish = |filter: Option<&dyn Denoiser>| -> Result<Finished, Error> {
                let clock = Instant::now();
                finish_filtered(&file, std::slice::from_ref(&dir), &out, filter, Seams::Off)?;
                let seconds = clock.elapsed().as_secs_f64();
                let values = read_lightmap(&file, &out)?;
                assert!(
                    values.iter().flatten().flatten().all(|v| v.is_finite()),
                    "{name} {spp}: a value that is not finite"
                );
                Ok(Finished {
                    stats: compare(&values, &truth)?,
                    edge_jump: seams.edge_jump(&values),
                    seconds,
                    values,
                })
            };
            let raw = finish(None)?;
            ladder.push((spp, bake_seconds + raw.seconds, raw.stats));
            if SPP.contains(&spp) {
                let a = finish(Some(&atrous))?;
                let o = finish(Some(&oidn))?;
                let u = finish(Some(&every))?;
                every_rows.push(format!(
                    "| {name} | {spp} | {:.2} | {:.2} | {:.4} | {:.4} |",
                    o.stats.rmse / raw.stats.rmse,
                    u.stats.rmse / raw.stats.rmse,
                    o.stats.rel_mse,
                    u.stats.rel_mse,
                ));
                eprintln!("{}", every_rows.last().expect("just pushed"));
                if spp == SPP[0] {
                    oidn_64 = Some((o.stats, bake_seconds + o.seconds));
                }
                if let Some(dir) = std::env::var_os("GUIDEBAKE_DENOISE_IMAGES") {
                    let png = Path::new(&dir).join(format!("{name}-{}-{spp}spp.png", page(name)));
                    let panels = [&truth, &raw.values, &a.values, &o.values];
                    crops::write(&png, &file, panels)?;
                    eprintln!("{name} {spp}: {}", png.display());
                }
                main_rows.push(format!(
                    "| {name} | {count} | {spp} | {:.4} | {:.2} | {:.2} | {:.4} | {:.4} | {:.4} | {:.1} | +{:.2} | +{:.2} | {:.3} / {:.3} / {:.3} ({:.3}) |",
                    raw.stats.rmse,
                    a.stats.rmse / raw.stats.rmse,
                    o.stats.rmse / raw.stats.rmse,
                    raw.stats.rel_mse,
                    a.stats.rel_mse,
                    o.stats.rel_mse,
                    bake_seconds + raw.seconds,
                    a.seconds - raw.seconds,
                    o.seconds - raw.seconds,
                    raw.edge_jump,
                    a.edge_jump,
                    o.edge_jump,
                    ref_edge,
                ));
                eprintln!("{}", main_rows.last().expect("just pushed"));
            }
            std::fs::remove_dir_all(&dir)?;
        }
        let (o, o_seconds) = oidn_64.expect("64 spp is on the ladder");
        let at_equal_time = |error: fn(&ErrorStats) -> f64| {
            interpolate(&ladder, |(_, s, _)| *s, |(_, _, e)| error(e), o_seconds)
        };
        // The spp where the raw ladder reaches `target`: "≤ 64" when its first rung already
        // does, "> 1024" when its last does not.
        let reaching = |error: fn(&ErrorStats) -> f64, target: f64| {
            let spp = |(spp, _, _): &(u32, f64, ErrorStats)| f64::from(*spp);
            match interpolate(&ladder, |(_, _, e)| error(e), spp, target) {
                Some(spp) => format!("{spp:.0}"),
                None if error(&ladder[0].2) <= target => format!("≤ {}", LADDER[0]),
                None => format!("> {}", LADDER[LADDER.len() - 1]),
            }
        };
        let rmse = |e: &ErrorStats| e.rmse;
        let rel = |e: &ErrorStats| e.rel_mse;
        speed_rows.push(format!(
            "| {name} | {:.4} | {:.4} | {:.1} | {} | {} | {} | {} |",
            o.rmse,
            o.rel_mse,
            o_seconds,
            shown(at_equal_time(rmse), 4),
            shown(at_equal_time(rel), 4),
            reaching(rmse, o.rmse),
            reaching(rel, o.rel_mse),
        ));
        eprintln!("{}", speed_rows.last().expect("just pushed"));
    }
    println!(
        "| scene | texels | spp | RMSE raw | atrous ÷ raw | oidn ÷ raw | relMSE raw | relMSE atrous | relMSE oidn | bake + write s | atrous adds s | oidn adds s | edge jump raw / atrous / oidn (reference) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    main_rows.iter().for_each(|r| println!("{r}"));
    println!();
    println!(
        "| scene | OIDN 64 spp RMSE | relMSE | its seconds | raw RMSE at equal time | raw relMSE at equal time | raw spp to its RMSE | raw spp to its relMSE |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    speed_rows.iter().for_each(|r| println!("{r}"));
    println!();
    println!(
        "| scene | spp | oidn ÷ raw | every island ÷ raw | relMSE oidn | relMSE every island |"
    );
    println!("|---|---|---|---|---|---|");
    every_rows.iter().for_each(|r| println!("{r}"));
    Ok(())
}

/// `y` at `x = at` along the ladder, interpolated in log–log between the two rungs around it
/// (`None` when `at` lies outside the ladder).
fn interpolate<T>(
    ladder: &[T],
    x: impl Fn(&T) -> f64,
    y: impl Fn(&T) -> f64,
    at: f64,
) -> Option<f64> {
    let mut points: Vec<(f64, f64)> = ladder.iter().map(|p| (x(p).ln(), y(p).ln())).collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let at = at.ln();
    points.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        ((x0..=x1).contains(&at) && x1 > x0).then(|| (y0 + (y1 - y0) * (at - x0) / (x1 - x0)).exp())
    })
}

/// A figure, or where it lies outside the ladder.
fn shown(value: Option<f64>, decimals: usize) -> String {
    value.map_or("outside the ladder".into(), |v| format!("{v:.decimals$}"))
}

/// The seam edge points of a texel file, to measure the edge jump of any lightmap of it.
struct Seam<'a> {
    file: &'a TexelFile,
    at: HashMap<Pixel, usize>,
    points: Vec<guidebake::output::seams::EdgePoint>,
}

impl<'a> Seam<'a> {
    fn load(file: &'a TexelFile, texels: &Path) -> Result<Self, Error> {
        let samples = read_seam_file(&seam_file_path(texels))?;
        let at = file
            .texels()
            .iter()
            .enumerate()
            .map(|(i, t)| ([t.page, u32::from(t.pixel[0]), u32::from(t.pixel[1])], i))
            .collect();
        Ok(Self {
            file,
            at,
            points: samples.points,
        })
    }

    /// The mean relative jump between the two sides' bilinear values at the edge points.
    fn edge_jump(&self, values: &[Option<[f32; 3]>]) -> f64 {
        let facts = Facts { seam: self, values };
        let system = edge_system(&self.points, &facts, DILATION_PIXELS);
        let value = |p: &Pixel| {
            self.at
                .get(p)
                .and_then(|&i| values[i])
                .unwrap_or([f32::NAN; 3])
        };
        let read: Vec<[f32; 3]> = system.pixels.iter().map(value).collect();
        system.edge_jump(&read)
    }
}

/// A lightmap read back, as the seam measures see the page.
struct Facts<'a> {
    seam: &'a Seam<'a>,
    values: &'a [Option<[f32; 3]>],
}

impl PageFacts for Facts<'_> {
    fn size(&self, page: u32) -> Option<(u32, u32)> {
        let size = self.seam.file.pages().get(page as usize)?;
        Some((size.width, size.height))
    }

    fn written(&self, p: Pixel) -> Written {
        match self.seam.at.get(&p).and_then(|&i| self.values[i]) {
            Some(v) if v.iter().all(|c| c.is_finite()) => Written::Texel,
            Some(_) => Written::NonFinite,
            None => Written::Empty,
        }
    }
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

/// A crop of chart borders: the reference, raw, `atrous` and `oidn` (top row, tone mapped at
/// one exposure), and each one's relative error against the reference (bottom row).
mod crops {
    use std::path::Path;

    use guidebake::preview::{tonemap_reinhard, write_png_rgb8};
    use guidebake::texels::TexelFile;

    use super::Error;

    /// Crop edge in texels, and how many pixels each texel is drawn as.
    const EDGE: u32 = 96;
    const ZOOM: u32 = 3;
    /// Padding and texels outside the crop.
    const EMPTY: [u8; 3] = [40, 48, 64];

    fn luminance(v: [f32; 3]) -> f32 {
        0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2]
    }

    /// A relative error as a colour: black at 0, red at 0.25, yellow at 0.5, white from 1.
    fn ramp(e: f32) -> [u8; 3] {
        let e = if e.is_finite() {
            e.clamp(0.0, 1.0)
        } else {
            1.0
        };
        let f = |a: f32, b: f32| (255.0 * ((e - a) / (b - a)).clamp(0.0, 1.0)) as u8;
        [f(0.0, 0.25), f(0.25, 0.5), f(0.5, 1.0)]
    }

    /// Writes the crop of page 0 where most lit texels border padding: `panels` are the
    /// reference and the three finishes, per texel in file order.
    pub fn write(
        png: &Path,
        file: &TexelFile,
        panels: [&Vec<Option<[f32; 3]>>; 4],
    ) -> Result<(), Error> {
        let size = file.pages()[0];
        let (w, h) = (size.width, size.height);
        let mut at = vec![usize::MAX; (w * h) as usize];
        for (i, t) in file.texels().iter().enumerate() {
            if t.page == 0 {
                at[(u32::from(t.pixel[1]) * w + u32::from(t.pixel[0])) as usize] = i;
            }
        }
        let truth = panels[0];
        let lit = |x: u32, y: u32| -> Option<f32> {
            let i = at[(y * w + x) as usize];
            (i != usize::MAX).then(|| truth[i].map_or(0.0, luminance))
        };
        // The window (stepped by 16) with the most luminance on texels beside padding.
        let edge = EDGE.min(w).min(h);
        let mut best = (0.0f64, 0, 0);
        for y0 in (0..=h - edge).step_by(16) {
            for x0 in (0..=w - edge).step_by(16) {
                let mut score = 0.0;
                for y in y0..y0 + edge {
                    for x in x0..x0 + edge {
                        let Some(l) = lit(x, y) else { continue };
                        let border =
                            [(1i32, 0i32), (-1, 0), (0, 1), (0, -1)]
                                .iter()
                                .any(|&(dx, dy)| {
                                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                                    nx < 0
                                        || ny < 0
                                        || nx >= w as i32
                                        || ny >= h as i32
                                        || lit(nx as u32, ny as u32).is_none()
                                });
                        if border {
                            score += f64::from(l);
                        }
                    }
                }
                if score > best.0 {
                    best = (score, x0, y0);
                }
            }
        }
        let (_, x0, y0) = best;
        // One exposure for every panel: the reference's 95th percentile maps to 0.5.
        let mut l: Vec<f32> = truth.iter().flatten().map(|&v| luminance(v)).collect();
        l.sort_by(f32::total_cmp);
        let p95 = l.get(l.len() * 95 / 100).copied().unwrap_or(1.0).max(1e-6);
        let exposure = 1.0 / p95;
        let side = edge * ZOOM;
        let gap = 4;
        let (iw, ih) = (4 * side + 3 * gap, 2 * side + gap);
        let mut rgb = vec![255u8; (iw * ih * 3) as usize];
        for (k, panel) in panels.iter().enumerate() {
            for y in 0..edge {
                for x in 0..edge {
                    let i = at[((y0 + y) * w + x0 + x) as usize];
                    let (top, bottom) = match (i != usize::MAX).then(|| (panel[i], truth[i])) {
                        Some((Some(v), Some(t))) => {
                            let e = (luminance(v) - luminance(t)).abs() / luminance(t).max(1e-4);
                            (
                                tonemap_reinhard(v, exposure),
                                if k == 0 { [255; 3] } else { ramp(e) },
                            )
                        }
                        _ => (EMPTY, EMPTY),
                    };
                    for (row, colour) in [(0, top), (side + gap, bottom)] {
                        for dy in 0..ZOOM {
                            for dx in 0..ZOOM {
                                let px = k as u32 * (side + gap) + x * ZOOM + dx;
                                let py = row + y * ZOOM + dy;
                                let o = ((py * iw + px) * 3) as usize;
                                rgb[o..o + 3].copy_from_slice(&colour);
                            }
                        }
                    }
                }
            }
        }
        write_png_rgb8(png, iw, ih, &rgb)?;
        Ok(())
    }
}
