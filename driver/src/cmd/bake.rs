//! `guidebake bake TEXELS --scene SCENE -o OUT.exr`: the streaming guided bake.

use std::io::IsTerminal;
use std::path::PathBuf;

use crate::bake::directional::Directional;
use crate::bake::finish::{Denoise, FinishOptions, Seams};
use crate::bake::run::{BakeJob, BakeReport, Progress, bake_pass_with_progress, lights_differ};
use crate::bake::settings::{
    BakeSettings, Budget, Combine, EmitterSampling, GuideSeed, GuideTarget, GuidedPasses, Guiding,
    Schedule, Transport,
};
use crate::bake::shard::Shard;
use crate::bake::workdir::work_dir;
use crate::scene::{Scene, TextureOptions};
use crate::texels::TexelFile;
use crate::transport::emitters::EmitterSelection;

/// `--help`'s heading of the options that shard a bake over a farm.
const FARM: &str = "Sharding over a farm";
/// `--help`'s heading of the estimator's and the guide's options, after a user's own.
const RESEARCH: &str = "Research levers (the defaults are what the benchmarks chose)";

/// Arguments of `guidebake bake`: the options a user reaches for first, then the sharding
/// options, then the research levers (`--help` lists them under those headings).
#[derive(Debug, clap::Args)]
pub struct BakeArgs {
    /// The texel file (from `guidebake prepare` or `guidebake synth`).
    pub texels: PathBuf,
    /// The scene the texel file was prepared from (.gltf, .glb, .obj or a .toml scene file).
    #[arg(long)]
    pub scene: PathBuf,
    /// The lightmap to write, OUT.exr (several pages become OUT.pageN.exr), with its atlas
    /// preview OUT.atlas.png beside it.
    #[arg(short, long = "output", alias = "out", value_name = "OUT.exr")]
    pub out: PathBuf,
    /// Final-gather rays per texel, all learning iterations together.
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Bounces of light after the gather hit (series: passes over the world; path: most
    /// vertices of a path, Russian roulette from the third).
    #[arg(long, default_value_t = BakeSettings::default().bounces)]
    pub bounces: u32,
    /// Sun and sky, replacing the scene file's: give the same as to `prepare`.
    #[command(flatten)]
    pub lights: super::scene::LightFlags,
    /// Denoise the lightmap as its pages are written: `atrous` (or `on`), an edge-aware
    /// À-Trous filter guided by each texel's position, normal and variance; `oidn`, Intel Open
    /// Image Denoise's lightmap network per chart (a build with `--features oidn`;
    /// scripts/oidn/fetch.sh). Off by default: the lightmap is then the estimator's output,
    /// unbiased and unblurred, as the bench measures (docs/denoise.md).
    #[arg(long, value_enum, default_value_t = Denoise::Off)]
    pub denoise: Denoise,
    /// Directional lightmaps: `sh-l1` adds per texel the L1 spherical harmonics of the
    /// incident radiance, world space, as the EXR layers SH0, SH1x, SH1y, SH1z (RGB each;
    /// docs/lightmaps.md has the convention and the conversions to Unity and Unreal).
    #[arg(long, value_enum, default_value_t = Directional::None)]
    pub directional: Directional,
    /// Make the texels on the two sides of a UV seam agree (least-squares stitching after
    /// denoising; docs/lightmaps.md). Off by default, as --denoise.
    #[arg(long, value_enum, default_value_t = Seams::Off)]
    pub seams: Seams,
    /// Stop where the estimate is good enough: a cluster (a tile of the direct pass) stops
    /// once its texels' relative error, measured between its iterations, is at most this
    /// (0.02: 2 %); `--spp` is then the cap. Use `--iterations 8` to stop at every doubling
    /// (docs/budget.md, "The stopping rule").
    #[arg(long, value_name = "ERROR")]
    pub target_error: Option<f32>,
    /// Extra EXR channels: sample count, relative standard error, validity.
    #[arg(long)]
    pub aux: bool,
    /// Write the bake's statistics as JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Light probes too: once the lightmap is written, place probes over the level and bake
    /// them from it, into this probe file with its volume textures and stats beside it (what
    /// `guidebake probes --lightmap OUT.exr` does with its defaults; docs/probes.md).
    #[arg(long, value_name = "OUT.probes")]
    pub probes: Option<PathBuf>,
    /// Worker threads (default: every core).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Seed of every random number.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Largest width or height a base-colour texture is kept at; larger images are
    /// box-filtered down (3 bytes a texel: 3 MiB an image at the default).
    #[arg(long, default_value_t = TextureOptions::DEFAULT_MAX_SIZE, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub max_texture_size: u32,
    /// Continue an interrupted bake from its journal.
    #[arg(long)]
    pub resume: bool,
    /// No progress and no summary: errors and warnings only.
    #[arg(long, short)]
    pub quiet: bool,
    /// Bake only shard I of N (I/N, 0-based); combine with `guidebake merge`.
    #[arg(help_heading = FARM, long, default_value = "0/1")]
    pub shard: Shard,
    /// Bake series pass B only (1-based), reading pass B−1 from `merge --pass B−1`; finish
    /// with `merge --pass B` (docs/farm.md).
    #[arg(help_heading = FARM, long)]
    pub pass: Option<u32>,
    /// Learning iterations (iteration 0 is unguided unless the pass before kept a guide seed).
    #[arg(help_heading = RESEARCH, long, default_value_t = BakeSettings::default().iterations)]
    pub iterations: u32,
    /// How gather directions are chosen.
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = BakeSettings::default().guiding)]
    pub guiding: Guiding,
    /// How a texel's iterations are combined.
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = BakeSettings::default().combine)]
    pub combine: Combine,
    /// Percent of the cosine baseline in the defensive mixture each guided iteration samples
    /// (`c + (1 − c)·guide`, folded into the guide; every sample is weighted with the
    /// mixture's density).
    #[arg(help_heading = RESEARCH, long, default_value_t = BakeSettings::default().mix)]
    pub mix: u32,
    /// Which series passes sample a learned guide: the `last` (the lightmap; the passes
    /// before it gather with cosine sampling) or `every` gather pass.
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = BakeSettings::default().guided_passes)]
    pub guided_passes: GuidedPasses,
    /// How the last pass of a series bake of 2 or more bounces spreads its samples over the
    /// texels: `uniform` (`--spp` everywhere), or by the error the previous passes measured,
    /// per 8×8-texel block (¼ to 4 times `--spp`, about `--spp` in all): `bounded` (the least
    /// relative error whose predicted squared error stays the uniform budget's), `mse`
    /// (n ∝ σ), `relative` (n ∝ σ/√(μ² + ε)), `balanced` (n ∝ σ/√(μ·μ̄)). The direct pass
    /// spends the later half of its iterations the same way, by each tile's earlier half.
    /// Default: `bounded`; `uniform` with `--guiding off` or `--target-error`.
    #[arg(
        help_heading = RESEARCH,
        long,
        value_enum
    )]
    pub budget: Option<Budget>,
    /// Next-event samples per texel of a series bake's direct pass (default: `--spp`), whose
    /// estimate the lightmap takes as its direct light: its last pass gathers the indirect
    /// light alone. With `--directional sh-l1` or `--combine global` the last pass estimates
    /// the direct light itself (weighted against its gather), and this is refused.
    #[arg(
        help_heading = RESEARCH,
        long,
        value_name = "N"
    )]
    pub direct_spp: Option<u32>,
    /// Gather rays per texel of the series passes between the direct pass and the last, whose
    /// results only feed the next pass's lookups (default: a quarter of `--spp`, at least a
    /// packet of 8, one per iteration where they are guided: their lookups are filtered,
    /// `--lookup-filter`).
    #[arg(
        help_heading = RESEARCH,
        long,
        value_name = "N"
    )]
    pub lookup_spp: Option<u32>,
    /// Radius in texels over which the gathered light of those passes is filtered before the
    /// next pass looks it up (texels of the same surface that agree within their noise;
    /// 0: none). Series transport only.
    #[arg(help_heading = RESEARCH, long, value_name = "TEXELS", default_value_t = BakeSettings::default().lookup_filter)]
    pub lookup_filter: u32,
    /// What each cluster's guide learns: `second-moment` (the density ∝ √E[L²] over the
    /// cluster's texels: the least summed variance, Rath et al. 2020) or `radiance` (∝ E[L],
    /// the paper's).
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = BakeSettings::default().guide_target)]
    pub guide_target: GuideTarget,
    /// Whether the last series pass's first iteration samples a guide seeded by the pass
    /// before it (`previous`: that pass keeps, per cluster, a coarse histogram of what its
    /// gather brought back) or gathers with cosine points (`off`, the paper's).
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = BakeSettings::default().guide_seed)]
    pub guide_seed: GuideSeed,
    /// How the samples are split over the learning iterations.
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = BakeSettings::default().schedule)]
    pub schedule: Schedule,
    /// A guide node splits only if it holds at least this many records.
    #[arg(help_heading = RESEARCH, long, default_value_t = BakeSettings::default().min_split)]
    pub min_split: u32,
    /// The guide's smoothing α in percent (paper §2.3): how far each child's share of its
    /// parent is pulled toward a quarter.
    #[arg(help_heading = RESEARCH, long, default_value_t = BakeSettings::default().smooth)]
    pub smooth: u32,
    /// A cluster keeps sampling its guide only while the guide shows at least this gain, in
    /// percent (150: 1.5× less variance per sample than stratified cosine points, measured
    /// on the samples of the iteration that used it); below, it gathers with cosine points
    /// for its remaining iterations. 0: guide always.
    #[arg(help_heading = RESEARCH, long, default_value_t = BakeSettings::default().min_gain)]
    pub min_gain: u32,
    /// A cluster whose light the pass before measured as flat — a relative variance per
    /// sample below this many thousandths, pooled over its texels — gathers the last pass
    /// with cosine points alone, as one set of all its samples, no guide (one stratified set
    /// integrates flat and broad light better than a guide learned from it). 0: guide every
    /// cluster.
    #[arg(help_heading = RESEARCH, long, value_name = "PERMILLE", default_value_t = BakeSettings::default().flat_below)]
    pub flat_below: u32,
    /// Light transport at gather hits: `series` (passes through the previous pass's
    /// lightmap, the paper's production setting) or `path` (unbiased path tracing).
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = Transport::Series)]
    pub transport: Transport,
    /// How emissive triangles are found: next-event estimation and hits weighted by MIS,
    /// next-event estimation alone, or hits alone (the bake before emitters were lights).
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = EmitterSampling::default())]
    pub emitters: EmitterSampling,
    /// How next-event estimation picks an emitter: `local` (the default) weighs each of a
    /// world's emitters at the shading point (power, distance, both cosines; worlds of up to
    /// 8 emitters, beyond by power), `power` in proportion to power alone, `tree` by the light
    /// tree (which prefers emitters that matter at the shading point).
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = EmitterSelection::default())]
    pub emitter_selection: EmitterSelection,
    /// The world-wide bias correction ρ (paper §2.5): `auto` applies it to the combinations
    /// whose mean needs it (`texel`, `cluster`), not to `average` and `global`.
    #[arg(help_heading = RESEARCH, long, value_enum, default_value_t = Rho::Auto)]
    pub bias_correction: Rho,
}

/// `--bias-correction`: by the combination, or forced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Rho {
    /// On for `texel` and `cluster`, off for `average` and `global`.
    Auto,
    /// Always.
    On,
    /// Never.
    Off,
}

/// Runs `guidebake bake`.
///
/// # Errors
/// Bad options, an invalid texel file or scene, I/O failures: each names the file or option.
/// An interrupted bake is an error too (exit code 1) that says how to resume.
pub fn run(args: &BakeArgs) -> Result<(), super::CmdError> {
    check_denoiser(args.denoise)?;
    let probes = args
        .probes
        .as_ref()
        .map(|p| probe_args(args, p))
        .transpose()?;
    let settings = BakeSettings {
        spp: args.spp,
        iterations: args.iterations,
        guiding: args.guiding,
        combine: args.combine,
        bias_correction: match args.bias_correction {
            Rho::Auto => args.combine.wants_rho(),
            Rho::On => true,
            Rho::Off => false,
        },
        seed: args.seed,
        transport: args.transport,
        bounces: args.bounces,
        mix: args.mix,
        schedule: args.schedule,
        guided_passes: args.guided_passes,
        budget: args
            .budget
            .unwrap_or(Budget::default_for(args.guiding, args.target_error)),
        direct_spp: args.direct_spp,
        lookup_spp: args.lookup_spp,
        lookup_filter: args.lookup_filter,
        guide_target: args.guide_target,
        guide_seed: args.guide_seed,
        target_error: args.target_error,
        min_split: args.min_split,
        smooth: args.smooth,
        min_gain: args.min_gain,
        flat_below: args.flat_below,
        emitters: args.emitters,
        emitter_selection: args.emitter_selection,
        directional: args.directional,
    };
    settings.validate()?;
    let files = bake_files(args)?;
    files.check()?;
    super::interrupt::register_outputs(files.outputs());
    let (scene, notes) = super::scene::load_checked(
        files,
        &args.scene,
        args.max_texture_size,
        &args.lights,
        true,
    )?;
    if let Some(p) = &probes {
        // The probes' files against the inputs and the scene's own files, before any baking;
        // the lightmap they read is this bake's output.
        let files = super::probes::probe_files(p, "--probes", true)?
            .reads_each("a file of the scene", &notes.files_read);
        files.check()?;
        super::interrupt::register_outputs(files.outputs());
    }
    if TexelFile::peek_header(&args.texels).is_some_and(|h| lights_differ(&h, &scene)) {
        eprintln!(
            "guidebake: warning: {}: prepared under other lights than this bake's (--sun, --sky, the scene's lights or emission differ); prepare decided under those which sides of each surface are baked and which texels lie inside geometry: run prepare again with the same --sun and --sky",
            args.texels.display()
        );
    }
    let job = BakeJob {
        texels: args.texels.clone(),
        out: args.out.clone(),
        settings,
        threads: args.threads.unwrap_or_else(super::every_core),
        shard: args.shard,
        resume: args.resume,
        aux: args.aux,
        finish: FinishOptions {
            denoise: args.denoise,
            seams: args.seams,
        },
    };
    let feedback = if args.quiet {
        Feedback::Quiet
    } else {
        Feedback::for_stderr()
    };
    let report = run_with_progress(&job, args.pass, &scene, feedback)?;
    if let Some(path) = &args.stats {
        write_stats_noting(path, &report, &notes)?;
    }
    if report.interrupted {
        return Err(Box::new(super::Interrupted(format!(
            "interrupted after {} tiles; the work is kept in {}: run the same command with --resume to finish",
            report.tiles_baked,
            work_dir(&job.out, job.shard).display()
        ))));
    }
    if !args.quiet {
        eprintln!("{}", summary(&job, &report));
    }
    match probes {
        Some(p) => bake_probes(&p, &scene, &args.out),
        None => Ok(()),
    }
}

/// `guidebake probes`' command line for `bake --probes OUT.probes`: its defaults, the bake's
/// texel file, scene, lights, seed, threads and `--resume`, reading the lightmap this bake
/// writes; checked before the lightmap is baked.
fn probe_args(
    args: &BakeArgs,
    out: &std::path::Path,
) -> Result<super::probes::ProbesArgs, super::CmdError> {
    #[derive(clap::Parser)]
    struct Probes {
        #[command(flatten)]
        args: super::probes::ProbesArgs,
    }
    if args.shard.count > 1 || args.pass.is_some() {
        return Err(super::usage(
            "--probes bakes from the whole lightmap: with --shard or --pass, run `guidebake probes --lightmap OUT.exr` after `guidebake merge`",
        ));
    }
    if super::files::lightmap_files(&args.out, &args.texels)
        .iter()
        .any(|(page, preview)| page == out || preview == out)
        || args.stats.as_deref() == Some(out)
    {
        return Err(super::usage(format!(
            "--probes {}: would overwrite the lightmap or its stats",
            out.display()
        )));
    }
    let path = |p: &std::path::Path| p.to_string_lossy().into_owned();
    let mut probes = <Probes as clap::Parser>::try_parse_from([
        "probes".to_owned(),
        path(&args.texels),
        "--scene".to_owned(),
        path(&args.scene),
        "--lightmap".to_owned(),
        path(&args.out),
        "-o".to_owned(),
        path(out),
        "--seed".to_owned(),
        args.seed.to_string(),
        "--max-texture-size".to_owned(),
        args.max_texture_size.to_string(),
    ])
    .map_err(|e| super::usage(format!("--probes: {e}")))?
    .args;
    probes.lights = args.lights.clone();
    probes.threads = args.threads;
    probes.resume = args.resume;
    probes.quiet = args.quiet;
    super::probes::check_args(&probes, "--probes")?;
    Ok(probes)
}

/// Bakes the probes of `bake --probes` in `scene` from the lightmap just written; if they are stopped,
/// says so, and that `guidebake probes … --resume` finishes them without baking the lightmap
/// again.
fn bake_probes(
    probes: &super::probes::ProbesArgs,
    scene: &Scene,
    lightmap: &std::path::Path,
) -> Result<(), super::CmdError> {
    super::probes::run_on(probes, scene).map_err(|e| -> super::CmdError {
        if e.downcast_ref::<super::Interrupted>().is_none() {
            return e;
        }
        let lights = if probes.lights.sun.is_some() || probes.lights.sky.is_some() {
            " and this bake's --sun and --sky"
        } else {
            ""
        };
        Box::new(super::Interrupted(format!(
            "the lightmap {} is written; its probes were stopped, their finished batches kept in {}: finish them alone with guidebake probes {} --scene {} --lightmap {} -o {} --resume{lights}",
            lightmap.display(),
            crate::probes::work::work_dir(&probes.out, None).display(),
            probes.texels.display(),
            probes.scene.display(),
            lightmap.display(),
            probes.out.display(),
        )))
    })
}

/// What `bake` reads and writes: the texel file, the scene, a sky map and the seam sidecar;
/// the lightmap's pages, their atlas previews, the work directory and the stats.
fn bake_files(args: &BakeArgs) -> Result<super::files::Files, super::CmdError> {
    super::files::check_exr("-o", &args.out)?;
    let mut files = super::files::Files::new()
        .reads("the texel file", &args.texels)
        .reads("the scene (--scene)", &args.scene)
        .reads(
            "the texel file's seams",
            &crate::output::seams::seam_file_path(&args.texels),
        );
    if let Some(map) = args.lights.sky_map() {
        files = files.reads("the sky map (--sky)", map);
    }
    for (path, preview) in super::files::lightmap_files(&args.out, &args.texels) {
        files = files
            .writes("the lightmap (-o)", &path)
            .writes("the lightmap's atlas preview", &preview);
    }
    files = files.writes_dir(
        "the bake's work directory",
        &work_dir(&args.out, args.shard),
    );
    if let Some(stats) = &args.stats {
        files = files.writes("the stats (--stats)", stats);
    }
    Ok(files)
}

/// The line a finished bake ends with: what it baked, in how long, where.
fn summary(job: &BakeJob, report: &BakeReport) -> String {
    let t = &report.seconds;
    let seconds = t.open_texels + t.build_bvh + t.gather + t.previous_pass_images + t.write_pages;
    // Every pass skips the same texels; the counter sums the passes.
    let inside = report.counters.texels_inside_geometry / u64::from(report.passes.max(1));
    let written = match report.pages.as_slice() {
        [] => format!(
            "shard {} of {} kept in {} (finish with guidebake merge)",
            job.shard.index,
            job.shard.count,
            work_dir(&job.out, job.shard).display()
        ),
        [one] => one.display().to_string(),
        pages => format!("{} pages, {} …", pages.len(), pages[0].display()),
    };
    format!(
        "guidebake: baked {} tiles ({} resumed) in {} pass(es), {seconds:.1} s, {:.1} Mrays/s: {written}",
        report.tiles_baked,
        report.tiles_resumed,
        report.passes,
        report.rays_per_second / 1e6,
    ) + &if inside > 0 {
        format!("; {inside} texels inside geometry skipped")
    } else {
        String::new()
    }
}

/// How a bake tells a person how far it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feedback {
    /// Nothing but errors and warnings (`--quiet`).
    Quiet,
    /// A progress bar (stderr is a terminal).
    Bar,
    /// A line when a pass ends and every few seconds within it (a log, a Slurm job).
    Lines,
}

impl Feedback {
    /// A bar on a terminal, lines elsewhere.
    #[must_use]
    pub fn for_stderr() -> Self {
        if std::io::stderr().is_terminal() {
            Self::Bar
        } else {
            Self::Lines
        }
    }
}

/// Seconds between two progress lines within a pass ([`Feedback::Lines`]).
const LINE_EVERY: f64 = 10.0;

/// A `--denoise` this build can run, checked before any baking: `oidn` needs the `oidn`
/// feature (a usage error saying how to get it) and a library that makes its CPU device.
fn check_denoiser(denoise: Denoise) -> Result<(), super::CmdError> {
    if denoise != Denoise::Oidn {
        return Ok(());
    }
    #[cfg(feature = "oidn")]
    {
        crate::output::denoise::Oidn::new()
            .map(drop)
            .map_err(|e| super::usage(format!("--denoise oidn: {e}")))
    }
    #[cfg(not(feature = "oidn"))]
    {
        Err(super::usage(crate::output::denoise::OIDN_MISSING))
    }
}

/// Runs a bake (of pass `only_pass`, or every pass); Ctrl-C stops it with its work kept
/// ([`super::interrupt`]); `feedback` says how far it is.
///
/// # Errors
/// What [`bake_pass_with_progress`] returns.
pub fn run_with_progress(
    job: &BakeJob,
    only_pass: Option<u32>,
    scene: &Scene,
    feedback: Feedback,
) -> Result<BakeReport, super::CmdError> {
    let cancel = super::interrupt::cancel_flag();
    let _cooperate = super::interrupt::Cooperate::begin();
    let bar = (feedback == Feedback::Bar).then(|| {
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40} {pos}/{len} texels  {msg}  ETA {eta}",
            )
            .expect("a valid template"),
        );
        bar
    });
    let passes = only_pass.map_or_else(
        || job.settings.last_pass() + 1 - job.settings.first_pass(),
        |_| 1,
    );
    let mut lines = PassLines::new(passes, feedback == Feedback::Lines);
    let start = std::time::Instant::now();
    let mut progress = |p: Progress| {
        if let Some(bar) = &bar {
            bar.set_length(p.texels_total);
            bar.set_position(p.texels_done);
            let seconds = start.elapsed().as_secs_f64().max(1e-3);
            bar.set_message(format!("{:.1} Mrays/s", p.rays as f64 / seconds / 1e6));
        }
        lines.update(p);
    };
    let report = bake_pass_with_progress(job, only_pass, scene, cancel, &mut progress)?;
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    Ok(report)
}

/// The progress lines of [`Feedback::Lines`]: one when a pass ends, and one every
/// [`LINE_EVERY`] seconds within a long pass, with texels done, rays per second and the ETA.
struct PassLines {
    passes: u32,
    on: bool,
    start: std::time::Instant,
    last_line: f64,
    pass_done: u32,
    /// Texels done and rays when this run's first report came (a resumed run starts ahead).
    first: Option<(u64, u64)>,
}

impl PassLines {
    fn new(passes: u32, on: bool) -> Self {
        Self {
            passes: passes.max(1),
            on,
            start: std::time::Instant::now(),
            last_line: 0.0,
            pass_done: 0,
            first: None,
        }
    }

    fn update(&mut self, p: Progress) {
        if !self.on || p.texels_total == 0 {
            return;
        }
        let (done0, rays0) = *self.first.get_or_insert((p.texels_done, p.rays));
        let per_pass = p.texels_total.div_ceil(u64::from(self.passes)).max(1);
        let now = self.start.elapsed().as_secs_f64();
        let finished = (p.texels_done / per_pass) as u32;
        let rate = (p.rays - rays0) as f64 / now.max(1e-3) / 1e6;
        let eta =
            (now / (p.texels_done - done0).max(1) as f64) * (p.texels_total - p.texels_done) as f64;
        if finished > self.pass_done {
            self.pass_done = finished;
            self.last_line = now;
            eprintln!(
                "bake: pass {finished}/{} done: {}/{} texels, {now:.1} s, {rate:.1} Mrays/s, ETA {}",
                self.passes,
                p.texels_done,
                p.texels_total,
                clock(eta)
            );
        } else if now - self.last_line >= LINE_EVERY {
            self.last_line = now;
            eprintln!(
                "bake: pass {}/{}: {}/{} texels ({:.0} %), {rate:.1} Mrays/s, ETA {}",
                self.pass_done + 1,
                self.passes,
                p.texels_done,
                p.texels_total,
                100.0 * p.texels_done as f64 / p.texels_total as f64,
                clock(eta)
            );
        }
    }
}

/// `s` seconds as `H:MM:SS` or `M:SS`.
fn clock(s: f64) -> String {
    let s = if s.is_finite() { s.round() as u64 } else { 0 };
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

/// [`write_stats`] with the textures the scene's loader could not read, counted
/// (`missing_textures`) and listed (`missing_texture_files`: file and material).
///
/// # Errors
/// When the file cannot be written; names it.
pub fn write_stats_noting(
    path: &std::path::Path,
    report: &BakeReport,
    notes: &crate::scene::LoadNotes,
) -> Result<(), super::CmdError> {
    let mut json = serde_json::to_value(report)?;
    if let Some(object) = json.as_object_mut() {
        object.insert(
            "missing_textures".into(),
            notes.missing_textures.len().into(),
        );
        object.insert(
            "missing_texture_files".into(),
            serde_json::to_value(&notes.missing_textures)?,
        );
    }
    let json = serde_json::to_string_pretty(&json)?;
    crate::atomic::write(path, json)
        .map_err(|e| format!("{}: cannot write the stats: {e}", path.display()))?;
    Ok(())
}

/// Writes the stats JSON through a temporary name.
///
/// # Errors
/// When the file cannot be written; names it.
pub fn write_stats(path: &std::path::Path, report: &BakeReport) -> Result<(), super::CmdError> {
    let json = serde_json::to_string_pretty(report)?;
    crate::atomic::write(path, json)
        .map_err(|e| format!("{}: cannot write the stats: {e}", path.display()))?;
    Ok(())
}
