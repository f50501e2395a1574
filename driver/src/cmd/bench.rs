//! `guidebake bench [SCENE]`: run time against error for every method of the bake, and the
//! Figure-5 overhead (see [`crate::bench`]).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::bake::settings::{BakeSettings, EmitterSampling, Transport};
use crate::bench::method::Method;
use crate::bench::{BenchConfig, LightSampling, run};
use crate::demo::{DEMO_TEXELS_PER_METRE, ajar_room};
use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};
use crate::scene::Scene;
use crate::transport::emitters::EmitterSelection;

/// Arguments of `guidebake bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Scene (.gltf, .glb, .obj or .toml). Without one: the demo's room with a door ajar.
    pub scene: Option<PathBuf>,
    /// A texel file prepared from the scene; without one, the scene is prepared into the
    /// output directory at --size / --texels-per-unit.
    #[arg(long)]
    pub texels: Option<PathBuf>,
    /// Page size when preparing, e.g. 64x64 (default for a scene file: 64x64, a reduced atlas
    /// so a full run takes minutes on two cores).
    #[arg(long, value_parser = super::prepare::parse_size, conflicts_with = "texels_per_unit")]
    pub size: Option<(u32, u32)>,
    /// Texels per world unit when preparing (default for the demo room: 8, --quick 4).
    #[arg(long)]
    pub texels_per_unit: Option<f32>,
    /// Output directory: runs.csv, overhead.csv, summary.json, table.md and the charts.
    #[arg(short, long = "output", alias = "out", default_value = "out/bench")]
    pub out: PathBuf,
    /// Directory of cached reference lightmaps (reused while scene, texels and settings match).
    #[arg(long, default_value = "out/bench-cache")]
    pub cache: PathBuf,
    /// A small run for CI (under a minute on two cores): the demo room at 4 texels/m, one
    /// bounce, the ladder 32,64, one seed, a 512-spp reference, 3 overhead repeats at 32 spp.
    #[arg(long)]
    pub quick: bool,
    /// Rays per texel of the ladder, comma-separated (default 32,64,128,256).
    #[arg(long, value_delimiter = ',')]
    pub spp: Option<Vec<u32>>,
    /// Seeds per (method, spp) (default 2).
    #[arg(long)]
    pub seeds: Option<u32>,
    /// Learning iterations of every bake (the bake's default; an unguided pass bakes in one).
    #[arg(long, default_value_t = BakeSettings::default().iterations)]
    pub iterations: u32,
    /// Light transport of the ladder's bakes. Against a reference of the same transport the
    /// errors fall to zero as samples grow; `series` (the bake's default) against a `path`
    /// reference adds series' own bias (docs/bake.md).
    #[arg(long, value_enum, default_value_t = Transport::Series)]
    pub transport: Transport,
    /// Light transport of the reference: `path` (the truth of the bounce-limited transport)
    /// or `series` (to measure the estimators of series bakes without series' bias).
    #[arg(long, value_enum, default_value_t = Transport::Path)]
    pub reference_transport: Transport,
    /// Light transport of the Figure-5 overhead runs. `series` (the bake's default) makes
    /// the final gather most of the bake's cost, as in the paper's figure; under `path` each
    /// gather ray carries a whole path and guiding's cost is diluted.
    #[arg(long, value_enum, default_value_t = Transport::Series)]
    pub overhead_transport: Transport,
    /// Bounces of every bake and of the reference (default: the bake's; --quick 1).
    #[arg(long)]
    pub bounces: Option<u32>,
    /// Rays per texel of the reference (default 4096; --quick 1024): at least 16× the largest
    /// --spp.
    #[arg(long)]
    pub ref_spp: Option<u32>,
    /// Also bake an independent twin of the reference (another seed, the same samples; cached
    /// beside it), measure every run against the mean of the two, and report that mean's own
    /// noise, which every error includes (`reference_noise` in summary.json, a line in
    /// table.md): subtracted, it leaves a run's error against the truth.
    #[arg(long)]
    pub reference_noise: bool,
    /// Rays per texel of the overhead runs (default 256).
    #[arg(long)]
    pub overhead_spp: Option<u32>,
    /// Methods of the ladder, comma-separated labels as the tables print them
    /// (`guiding/combine/rho|-`, optional `+mix=N+schedule=even|doubling+split=N+smooth=N`,
    /// `+passes=last|every+gain=N+transport=series|path+select=…+budget=uniform|bounded|balanced|mse|relative`,
    /// `+direct=P` and `+lookup=P` for `--direct-spp` and `--lookup-spp` at P % of the rung's
    /// spp, `+target=radiance` for `--guide-target`, `+stop=N` for `--target-error` N/1000
    /// (the rung its cap), `+iters=N` for the method's own `--iterations`, or `+before` for
    /// every lever as before the guiding levers);
    /// default every guiding × combine × ρ with the bake's levers. The baseline
    /// (`off/average/-`) is always run, first.
    #[arg(long, value_delimiter = ',')]
    pub methods: Option<Vec<String>>,
    /// Interleaved repeats of the overhead runs (default 5; 0 skips them).
    #[arg(long)]
    pub repeats: Option<u32>,
    /// Worker threads of every measured bake (default: every core).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Worker threads of the reference bakes (default: every core). They are not timed, and
    /// a bake is the same bits on any thread count, so `--threads 1` runs still bake their
    /// reference on every core; give 1 here too when benches run side by side, one a core.
    #[arg(long, value_parser = super::parse_threads)]
    pub reference_threads: Option<usize>,
    /// How the measured bakes light emissive triangles (`guidebake bake --emitters`); the
    /// reference always uses the bake's default.
    #[arg(long, value_enum, default_value_t = EmitterSampling::default())]
    pub emitters: EmitterSampling,
    /// How the measured bakes pick an emitter (`guidebake bake --emitter-selection`).
    #[arg(long, value_enum, default_value_t = EmitterSelection::default())]
    pub emitter_selection: EmitterSelection,
    /// Name of the scene in the outputs (default: the file's stem, or `demo-ajar`).
    #[arg(long)]
    pub name: Option<String>,
}

/// Runs `guidebake bench`.
///
/// # Errors
/// Bad options, a scene or texel file that cannot be used, a failed bake or write: each
/// names the option or file.
pub fn run_bench(args: &BenchArgs) -> Result<(), super::CmdError> {
    let quick = args.quick;
    let pick = |given: Option<u32>, full: u32, small: u32| {
        given.unwrap_or(if quick { small } else { full })
    };
    let seeds = pick(args.seeds, 2, 1);
    let mut config = BenchConfig {
        name: String::new(),
        texels: PathBuf::new(),
        out: args.out.clone(),
        cache: args.cache.clone(),
        threads: args.threads.unwrap_or_else(super::every_core).max(1),
        reference_threads: args
            .reference_threads
            .unwrap_or_else(super::every_core)
            .max(1),
        methods: match &args.methods {
            None => Method::all(),
            Some(labels) => {
                let mut methods = vec![Method::baseline()];
                for l in labels {
                    let m = Method::parse(l)?;
                    if !methods.contains(&m) {
                        methods.push(m);
                    }
                }
                methods
            }
        },
        spp: args.spp.clone().unwrap_or_else(|| {
            if quick {
                vec![32, 64]
            } else {
                vec![32, 64, 128, 256]
            }
        }),
        seeds: (1..=seeds).collect(),
        iterations: args.iterations,
        transport: args.transport,
        overhead_transport: args.overhead_transport,
        reference_transport: args.reference_transport,
        bounces: pick(args.bounces, BakeSettings::default().bounces, 1),
        reference_spp: pick(args.ref_spp, 4096, 1024),
        reference_noise: args.reference_noise,
        overhead_spp: pick(args.overhead_spp, 256, 32),
        repeats: pick(args.repeats, 5, 3),
        light: LightSampling {
            emitters: args.emitters,
            selection: args.emitter_selection,
        },
    };
    if let Some(d) = args.texels_per_unit
        && !(d.is_finite() && d > 0.0)
    {
        return Err(format!("--texels-per-unit {d} must be positive and finite").into());
    }
    config.validate()?;
    let (scene, default_name, resolution, layout) = match &args.scene {
        Some(path) => {
            let scene = Scene::load(path)?;
            let stem = path
                .file_stem()
                .map_or_else(|| "scene".into(), |s| s.to_string_lossy().into_owned());
            let resolution = match (args.size, args.texels_per_unit) {
                (_, Some(d)) => Resolution::TexelsPerUnit(d),
                (Some((w, h)), None) => Resolution::Size(w, h),
                (None, None) => Resolution::Size(64, 64),
            };
            (scene, stem, resolution, Layout::Auto)
        }
        None => {
            let density = args.texels_per_unit.unwrap_or(if quick {
                DEMO_TEXELS_PER_METRE / 6.0
            } else {
                DEMO_TEXELS_PER_METRE / 3.0
            });
            let resolution = match args.size {
                Some((w, h)) => Resolution::Size(w, h),
                None => Resolution::TexelsPerUnit(density),
            };
            (
                ajar_room(),
                "demo-ajar".to_owned(),
                resolution,
                Layout::Shared,
            )
        }
    };
    config.name = args.name.clone().unwrap_or(default_name);
    std::fs::create_dir_all(&config.out)
        .map_err(|e| format!("{}: cannot create: {e}", config.out.display()))?;
    config.texels = match &args.texels {
        Some(t) => t.clone(),
        None => {
            let path = config.out.join(format!("{}.texels", config.name));
            let report = prepare(&scene, &path, PrepareOptions { resolution, layout })?;
            eprintln!(
                "prepared {} texels in {} tiles on {:?}: {}",
                report.texels,
                report.tiles,
                report.pages,
                path.display()
            );
            path
        }
    };
    let cancel = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&cancel);
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed));
    let written = run(&config, &scene, &cancel)?;
    println!("{}", crate::bench::report::markdown(&written.summary));
    for f in &written.files {
        eprintln!("wrote {}", f.display());
    }
    Ok(())
}
