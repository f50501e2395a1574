//! `guidebake demo [-o DIR]`: the bundled default. Builds the generated room lit through a
//! door ajar ([`crate::demo`]), prepares its texels, and bakes it twice at equal sample
//! counts — unguided baseline and coherent guiding — writing both lightmaps (EXR) and their
//! previews (PNG), and each bake's stats JSON.

use std::path::PathBuf;

use crate::bake::run::BakeJob;
use crate::bake::settings::{BakeSettings, Guiding};
use crate::bake::shard::Shard;
use crate::demo::{DEMO_TEXELS_PER_METRE, ajar_room};
use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};

/// Arguments of `guidebake demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Directory for the texel file, lightmaps, previews and stats.
    #[arg(short, long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Final-gather rays per texel for both bakes.
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Worker threads (default: every core).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
}

/// Runs `guidebake demo`.
///
/// # Errors
/// When the output directory cannot be created or a step fails; names the file.
pub fn run(args: &DemoArgs) -> Result<(), super::CmdError> {
    std::fs::create_dir_all(&args.out)
        .map_err(|e| format!("{}: cannot create: {e}", args.out.display()))?;
    let scene = ajar_room();
    let texels = args.out.join("ajar.texels");
    let options = PrepareOptions {
        resolution: Resolution::TexelsPerUnit(DEMO_TEXELS_PER_METRE),
        layout: Layout::Shared,
    };
    let prepared = prepare(&scene, &texels, options)?;
    eprintln!(
        "prepared {} texels in {} tiles: {}",
        prepared.texels,
        prepared.tiles,
        texels.display()
    );
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    for (name, guiding) in [("baseline", Guiding::Off), ("guided", Guiding::Coherent)] {
        let out = args.out.join(format!("{name}.exr"));
        // A demo is always baked afresh: an earlier, interrupted demo's work is not resumed.
        let _ = std::fs::remove_dir_all(crate::bake::workdir::work_dir(&out, Shard::WHOLE));
        let job = BakeJob {
            texels: texels.clone(),
            out: out.clone(),
            settings: BakeSettings {
                spp: args.spp,
                guiding,
                ..Default::default()
            },
            threads,
            shard: Shard::WHOLE,
            resume: false,
            aux: true,
        };
        let report = super::bake::run_with_progress(&job, None, &scene)?;
        if report.interrupted {
            return Err("interrupted".into());
        }
        super::bake::write_stats(&args.out.join(format!("{name}.json")), &report)?;
        eprintln!(
            "{name:>8}: {:.2} s gather, {:.1} Mrays/s, ρ = {:.4}, {} guided cluster-iterations: {} (+ .png)",
            report.seconds.gather,
            report.rays_per_second / 1e6,
            report.rho,
            report.counters.iterations_guided,
            out.display()
        );
    }
    Ok(())
}
