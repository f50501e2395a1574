//! `guidebake probes TEXELS --scene SCENE --lightmap OUT.exr -o LEVEL.probes`: light probes
//! placed over the level and baked with the guided gather ([`crate::probes`];
//! docs/probes.md); `--resume` continues a stopped bake, `--shard K/N` bakes a share and
//! `--merge` joins the shards ([`crate::probes::work`]).

use std::path::PathBuf;

use crate::bake::shard::Shard;
use crate::bake::workdir::BakeRecord;
use crate::probes::file::volume_path;
use crate::probes::gather::{GatherSettings, ProbeTransport};
use crate::probes::placement::{PlacementSettings, read_points};
use crate::probes::work::{self, work_dir};
use crate::probes::{
    BATCH_CLUSTERS, ProbeError, ProbeReport, ProbeSettings, WorkOptions, bake_probes,
};
use crate::render::Lightmap;
use crate::scene::{Scene, TextureOptions};
use crate::texels::TexelFile;

use super::OnOff;

/// Arguments of `guidebake probes`.
#[derive(Debug, clap::Args)]
pub struct ProbesArgs {
    /// The texel file the lightmap was baked from (its roles and seen sides decide what rays
    /// meet and where a probe is inside geometry).
    pub texels: PathBuf,
    /// The scene the texel file was prepared from.
    #[arg(long)]
    pub scene: PathBuf,
    /// The baked lightmap (`bake -o`): what the probes' rays read where they hit a surface.
    /// Without it they trace paths (as `--transport path`).
    #[arg(long)]
    pub lightmap: Option<PathBuf>,
    /// The probe file to write; the volume textures go beside it (OUT.volume-l0.exr, -l1,
    /// -l2) and the stats to OUT.json.
    #[arg(short, long = "output", alias = "out", value_name = "OUT.probes")]
    pub out: PathBuf,
    /// The finest probe spacing, in scene units, near geometry (coarse cells are 4×).
    /// Default: the level's longest side / 24.
    #[arg(long)]
    pub spacing: Option<f32>,
    /// More probes: a text file of points, `x y z` a line (`#` comments).
    #[arg(long, value_name = "FILE")]
    pub points: Option<PathBuf>,
    /// `lattice`: the adaptive lattice (and --points, if given); `points`: --points alone.
    #[arg(long, value_enum, default_value_t = Placement::Lattice)]
    pub placement: Placement,
    /// Where the lattice is finer: `light` (the default) where cells hold geometry and where
    /// the direct light of the sun and the scene's lights changes across them (a shaft of sun
    /// through a window); `geometry`: where cells hold geometry only.
    #[arg(long, value_enum, default_value_t = Refine::Light)]
    pub refine: Refine,
    /// Gather samples per probe.
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(8..=1 << 20))]
    pub spp: u32,
    /// Learning iterations under --guiding on (their samples ⅛, ⅛, ¼, ½ of --spp for four).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=8))]
    pub iterations: u32,
    /// `on`: learning iterations, each after the first guided by what the cluster's probes
    /// found; `off` (the default: it wins at equal time on every scene measured,
    /// docs/probes.md): one stratified set, uniform over the sphere.
    #[arg(long, value_enum, default_value_t = OnOff::Off)]
    pub guiding: OnOff,
    /// What a ray that hits a surface reads: the lightmap (default with --lightmap), or a
    /// path (unbiased: the reference).
    #[arg(long, value_enum)]
    pub transport: Option<TransportChoice>,
    /// Path vertices under --transport path.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub bounces: u32,
    /// Seed of every random number.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// De-ring the SH (Lanczos window: no negative irradiance opposite a bright source, a
    /// blurrier probe).
    #[arg(long)]
    pub dering: bool,
    /// Write the coarse grid as volume textures (one EXR per SH band).
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub volume: OnOff,
    /// Worker threads (default: every core).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Sun and sky, as given to `prepare` and `bake`.
    #[command(flatten)]
    pub lights: super::scene::LightFlags,
    /// Largest width or height a base-colour texture is kept at (as `bake`'s).
    #[arg(long, default_value_t = TextureOptions::DEFAULT_MAX_SIZE, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub max_texture_size: u32,
    /// Continue a stopped probe bake from its work directory (OUT.bake/), baking only the
    /// batches it lacks; refused if that work is of other settings, lights, texel file,
    /// scene or lightmap.
    #[arg(long)]
    pub resume: bool,
    /// Clusters a batch (tests: many small batches).
    #[arg(long, hide = true, default_value_t = BATCH_CLUSTERS as u32, value_parser = clap::value_parser!(u32).range(1..=1 << 20))]
    pub batch_clusters: u32,
    /// Stop as Ctrl-C does after baking this many batches (tests).
    #[arg(long, hide = true)]
    pub stop_after_batches: Option<usize>,
    /// Bake only shard K of N (K/N, 0-based): its contiguous run of the batches, kept in
    /// OUT.shard-K-of-N/; no probe file. Join every shard's with --merge.
    #[arg(long, value_name = "K/N", conflicts_with = "merge")]
    pub shard: Option<Shard>,
    /// Bake nothing: write the probe file (and volume, stats) from these shards' work
    /// directories (OUT.shard-K-of-N, every K of N), the same bytes as one process's bake.
    #[arg(long, value_name = "SHARD_DIR", num_args = 1.., conflicts_with = "resume")]
    pub merge: Vec<PathBuf>,
    /// No summary.
    #[arg(long, short)]
    pub quiet: bool,
}

/// `--placement`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Placement {
    /// The adaptive lattice, plus any --points.
    Lattice,
    /// The --points alone.
    Points,
}

/// `--refine`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Refine {
    /// Near geometry and where the direct light changes.
    Light,
    /// Near geometry only.
    Geometry,
}

/// `--transport`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TransportChoice {
    /// Hits read the baked lightmap.
    Lightmap,
    /// Hits trace paths.
    Path,
}

/// The stats JSON beside the probe file.
fn stats_path(out: &std::path::Path) -> PathBuf {
    let mut name = out.as_os_str().to_owned();
    name.push(".json");
    PathBuf::from(name)
}

/// The checks of `probes`' options among themselves, the probe file named as `out_flag`
/// (`bake --probes` makes them too, before its lightmap is baked).
///
/// # Errors
/// A usage error naming the option.
pub fn check_args(args: &ProbesArgs, out_flag: &str) -> Result<(), super::CmdError> {
    if let Some(d) = args.spacing.filter(|d| !(d.is_finite() && *d > 0.0)) {
        return Err(super::usage(format!(
            "--spacing {d}: a positive, finite distance in scene units"
        )));
    }
    if args.placement == Placement::Points && args.points.is_none() {
        return Err(super::usage("--placement points needs --points FILE"));
    }
    if args.transport == Some(TransportChoice::Lightmap) && args.lightmap.is_none() {
        return Err(super::usage(
            "--transport lightmap needs --lightmap OUT.exr (the lightmap the probes read)",
        ));
    }
    if args
        .out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        return Err(super::usage(format!(
            "{out_flag} {}: the probe file is not an EXR (name it LEVEL.probes; its volume textures are written beside it)",
            args.out.display()
        )));
    }
    Ok(())
}

/// What `probes` reads and writes, `-o` named as `out_flag` (`bake --probes` checks them
/// before baking the lightmap they read: `lightmap_later` leaves the lightmap out).
pub fn probe_files(
    args: &ProbesArgs,
    out_flag: &str,
    lightmap_later: bool,
) -> Result<super::files::Files, super::CmdError> {
    let mut files = super::files::Files::new()
        .reads("the scene (--scene)", &args.scene)
        .reads("the texel file", &args.texels);
    if let Some(points) = &args.points {
        files = files.reads("the probe points (--points)", points);
    }
    if let Some(map) = args.lights.sky_map() {
        files = files.reads("the sky map (--sky)", map);
    }
    if let Some(lightmap) = args.lightmap.as_ref().filter(|_| !lightmap_later) {
        super::files::check_exr("--lightmap", lightmap)?;
        for (path, preview) in super::files::lightmap_files(lightmap, &args.texels) {
            files = files
                .reads("the lightmap (--lightmap)", &path)
                .reads("the lightmap's atlas preview", &preview);
        }
    }
    files = files
        .writes(format!("the probe file ({out_flag})"), &args.out)
        .writes_dir(
            "the probe bake's work directory",
            &work_dir(&args.out, args.shard),
        );
    for dir in &args.merge {
        files = files.reads("a shard's work directory (--merge)", dir);
    }
    if args.volume == OnOff::On {
        for band in 0..3 {
            files = files.writes(
                format!("the volume's band {band}"),
                &volume_path(&args.out, band),
            );
        }
    }
    Ok(files.writes("the stats", &stats_path(&args.out)))
}

/// Runs `guidebake probes`.
///
/// # Errors
/// A wrong command line (exit 2); an unreadable scene, texel file, lightmap or points file,
/// a level no probe can be placed in, an unwritable output, a work directory there without
/// `--resume` or of another bake, shards to merge that are not all this bake's (exit 1):
/// each named; Ctrl-C (exit 130), the finished batches kept for `--resume`. Nothing is ever
/// left at the final paths on failure.
pub fn run(args: &ProbesArgs) -> Result<(), super::CmdError> {
    check_args(args, "-o")?;
    let files = probe_files(args, "-o", false)?;
    files.check()?;
    super::interrupt::register_outputs(files.outputs());
    let (scene, _) = super::scene::load_checked(
        files,
        &args.scene,
        args.max_texture_size,
        &args.lights,
        true,
    )?;
    run_on(args, &scene)
}

/// [`run`] on `scene`, loaded under `args`' lights with its files and `args`' checked
/// (`bake --probes` passes the scene it baked, whose files it checked against the probes').
///
/// # Errors
/// As [`run`].
pub fn run_on(args: &ProbesArgs, scene: &Scene) -> Result<(), super::CmdError> {
    let points = match &args.points {
        Some(p) => read_points(p)?,
        None => Vec::new(),
    };
    let texels = TexelFile::open(&args.texels)?;
    let lightmap = match &args.lightmap {
        Some(path) => Some(Lightmap::load(&texels, scene, path)?),
        None => None,
    };
    let transport = match (args.transport, &lightmap) {
        (Some(TransportChoice::Path), _) | (None, None) => ProbeTransport::Path,
        _ => ProbeTransport::Lightmap,
    };
    let settings = ProbeSettings {
        placement: PlacementSettings {
            spacing: args.spacing,
            points,
            lattice: args.placement == Placement::Lattice,
            refine_light: args.refine == Refine::Light,
        },
        gather: GatherSettings {
            spp: args.spp,
            iterations: args.iterations,
            guiding: args.guiding == OnOff::On,
            transport,
            seed: args.seed,
        },
        bounces: args.bounces,
        dering: args.dering,
        volume: args.volume == OnOff::On,
    };
    let batch_clusters = args.batch_clusters as usize;
    let options = WorkOptions {
        resume: args.resume,
        texels: args.texels.clone(),
        record: BakeRecord::new(
            work::options(&settings, &lightmap_identity(args)?, batch_clusters),
            &texels,
            scene,
        ),
        batch_clusters,
        stop_after: args.stop_after_batches,
        shard: args.shard,
        merge: args.merge.clone(),
    };
    let threads = args.threads.unwrap_or_else(super::every_core);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("cannot start {threads} worker threads: {e}"))?;
    let cancel = super::interrupt::cancel_flag();
    let cooperate = super::interrupt::Cooperate::begin();
    let report = pool
        .install(|| {
            bake_probes(
                scene,
                &texels,
                lightmap.as_ref(),
                &args.out,
                &settings,
                &options,
                cancel,
            )
        })
        .map_err(|e| -> super::CmdError {
            match e {
                ProbeError::Invalid(m) => format!("{}: {m}", args.texels.display()).into(),
                ProbeError::Interrupted { .. } => Box::new(super::Interrupted(e.to_string())),
                other => Box::new(other),
            }
        })?;
    drop(cooperate);
    if let Some(shard) = args.shard {
        if !args.quiet {
            eprintln!(
                "{}: shard {shard} baked ({} of its batches resumed); once every shard is, join them with the same command, --merge and every shard's directory instead of --shard",
                work_dir(&args.out, Some(shard)).display(),
                report.batches_resumed
            );
        }
        return Ok(());
    }
    publish(args, &report)?;
    if !args.quiet {
        summary(args, &report, transport, threads);
    }
    Ok(())
}

/// Writes the stats beside the probe file, then removes the work directory (not the
/// shards' of a merge: they are the user's to delete).
fn publish(args: &ProbesArgs, report: &ProbeReport) -> Result<(), super::CmdError> {
    let stats = stats_path(&args.out);
    let json = serde_json::to_string_pretty(report).map_err(|e| e.to_string())?;
    if let Err(e) = crate::atomic::write(&stats, json) {
        for f in &report.files {
            let _ = std::fs::remove_file(f);
        }
        return Err(format!("{}: cannot write the stats: {e}", stats.display()).into());
    }
    if args.merge.is_empty() {
        work::retire(&work_dir(&args.out, None))?;
    }
    Ok(())
}

/// What the probes read where their rays hit: the lightmap's pages, by the FNV-1a 64 of
/// their bytes (`none` without `--lightmap`), so that `--resume` over another lightmap is
/// refused.
fn lightmap_identity(args: &ProbesArgs) -> Result<String, super::CmdError> {
    let Some(lightmap) = &args.lightmap else {
        return Ok("none".into());
    };
    let mut hash = crate::hash::fnv1a64(&[]);
    for (page, _) in super::files::lightmap_files(lightmap, &args.texels) {
        let bytes = std::fs::read(&page)
            .map_err(|e| format!("{}: cannot read the lightmap: {e}", page.display()))?;
        hash = crate::hash::fnv1a64_more(hash, &bytes);
    }
    Ok(format!("{hash:016x}"))
}

fn summary(args: &ProbesArgs, r: &ProbeReport, transport: ProbeTransport, threads: usize) {
    eprintln!(
        "{}: {} probes in {} clusters{} ({} lattice and {} listed candidates, {} inside geometry skipped, {} cells refined for light), {} spp {}, hits read {}; {:.2} s on {threads} threads (placement {:.2} s, gather {:.2} s, volume {:.2} s); median relative error {:.3}",
        args.out.display(),
        r.probes,
        r.clusters,
        if !args.merge.is_empty() {
            format!(", merged from {} shards", args.merge.len())
        } else if r.batches_resumed > 0 {
            format!(", {} batches resumed", r.batches_resumed)
        } else {
            String::new()
        },
        r.lattice_candidates,
        r.listed_candidates,
        r.skipped_inside_geometry,
        r.cells_cut_for_light,
        args.spp,
        if args.guiding == OnOff::On && args.iterations > 1 {
            "guided"
        } else {
            "unguided"
        },
        transport.name(),
        r.seconds.total,
        r.seconds.placement,
        r.seconds.gather,
        r.seconds.volume,
        r.median_relative_error,
    );
}
