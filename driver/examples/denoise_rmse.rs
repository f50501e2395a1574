//! RMSE of raw and denoised lightmaps against a 16× reference (docs/lightmaps.md,
//! "Denoising"). For each scene: prepare at a `--size`-like page of 192², bake the reference
//! (the unbiased baseline at 16 × 256 = 4096 spp, series transport, `bench`'s reference
//! settings), then bake the default settings at 64 and 256 spp with `--denoise off` and `on`
//! (the same seed, so the denoised run filters exactly the raw run's estimates) and print a
//! Markdown table of the RMSE of each against the reference.
//!
//! ```sh
//! cargo run --release -p guidebake --example denoise_rmse -- ../shared/scenes/converted/*.glb
//! ```

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use guidebake::bake::finish::FinishOptions;
use guidebake::bake::run::{BakeJob, bake};
use guidebake::bake::settings::{BakeSettings, Transport};
use guidebake::bake::shard::Shard;
use guidebake::bench::metrics::compare;
use guidebake::bench::readback::read_lightmap;
use guidebake::bench::reference::reference_settings;
use guidebake::prepare::{Layout, PrepareOptions, Resolution, prepare};
use guidebake::scene::Scene;
use guidebake::texels::TexelFile;

type Error = Box<dyn std::error::Error>;

/// Page edge of the measurement's texel files.
const PAGE: u32 = 192;
/// Samples of the measured runs; the reference has 16 × the largest.
const SPP: [u32; 2] = [64, 256];

fn main() -> Result<(), Error> {
    let scenes: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if scenes.is_empty() {
        return Err("usage: denoise_rmse SCENE... (e.g. ../shared/scenes/converted/*.glb)".into());
    }
    let work = tempfile::tempdir()?;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("| scene | texels | spp | RMSE raw | RMSE denoised | denoised / raw |");
    println!("|---|---|---|---|---|---|");
    for path in &scenes {
        let scene = Scene::load(path)?;
        let name = path
            .file_stem()
            .map_or("scene".into(), |s| s.to_string_lossy());
        let texels = work.path().join(format!("{name}.texels"));
        let options = PrepareOptions {
            resolution: Resolution::Size(PAGE, PAGE),
            layout: Layout::Auto,
        };
        let prepared = prepare(&scene, &texels, options)?;
        let file = TexelFile::open(&texels)?;
        let bake_to = |settings: BakeSettings, out: &Path, denoise: Denoise| -> Result<_, Error> {
            let job = BakeJob {
                texels: texels.clone(),
                out: out.to_owned(),
                settings,
                threads,
                shard: Shard::WHOLE,
                resume: false,
                aux: false,
                finish: FinishOptions {
                    denoise,
                    ..Default::default()
                },
            };
            bake(&job, &scene, &AtomicBool::new(false), &mut |_, _| {})?;
            Ok(read_lightmap(&file, out)?)
        };
        let defaults = BakeSettings::default();
        let reference = reference_settings(
            16 * SPP[1],
            defaults.iterations,
            Transport::Series,
            defaults.bounces,
        );
        let clock = std::time::Instant::now();
        let truth = bake_to(reference, &work.path().join("ref.exr"), Denoise::Off)?;
        eprintln!(
            "{name}: reference of {} texels in {:.0} s",
            prepared.texels,
            clock.elapsed().as_secs_f64()
        );
        for spp in SPP {
            let settings = BakeSettings {
                spp,
                seed: 1,
                ..defaults
            };
            let raw = bake_to(settings, &work.path().join("raw.exr"), Denoise::Off)?;
            let denoised = bake_to(settings, &work.path().join("dn.exr"), Denoise::On)?;
            let (a, b) = (compare(&raw, &truth)?, compare(&denoised, &truth)?);
            println!(
                "| {name} | {} | {spp} | {:.5} | {:.5} | {:.2} |",
                prepared.texels,
                a.rmse,
                b.rmse,
                b.rmse / a.rmse
            );
        }
    }
    Ok(())
}
