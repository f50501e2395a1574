//! A whole bake, from texel file to EXR pages: `guidebake bake`, `guidebake merge` and
//! `guidebake demo` call [`bake`] and [`finish`].
//!
//! A run works in a *work directory* beside its output (`OUT.exr.bake/`, or
//! `OUT.exr.shard-I-of-N/` for `--shard I/N`) holding the [result
//! file](crate::output::result_file), the [journal](crate::output::journal) and a
//! `manifest.json` naming the texel file, the settings and the shard. An unsharded run that
//! finishes applies ρ and writes the pages ([`finish`]), then removes its work directory; a
//! shard leaves its work directory for `guidebake merge`. An interrupted run leaves it for
//! `--resume`. A work directory is never overwritten without `--resume`: nothing baked is
//! lost by a repeated command.
//!
//! Series bakes shard pass by pass, in commands a batch scheduler chains: `bake --pass B
//! --shard I/N` bakes pass B of one shard into its work directory, `merge --pass B` gathers
//! pass B of every shard into one result file in `OUT.exr.merged/` ([`merge_pass`]), which
//! the shards of pass B + 1 read as their previous pass; the last pass is merged into pages by
//! [`finish`] as before. Every tile's bytes depend on its index, the settings and the previous
//! pass only, so N shards × B passes give the bytes of one unsharded bake.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::gather::{GatherCounters, TileBaker};
use super::pipeline::{self, PipelineConfig, PipelineError, TileBuffer, TileFiles};
use super::settings::{BakeSettings, Combine, MAX_ITERATIONS, SettingsError};
use super::shard::{Shard, tiles_to_bake};
use super::world::World;
use crate::bvh::{BvhError, Preset};
use crate::output::OutputFileError;
use crate::output::atomic::temporary_name;
use crate::output::exr_pages::{PageStream, PageWriteError, page_path};
use crate::output::fnv1a64;
use crate::output::journal::{Journal, RhoSums, TileRecord, dedup_tiles};
use crate::output::result_file::{BatchFile, FLAG_BAKED, ResultFile, TexelResult};
use crate::scene::Scene;
use crate::texels::{TexelFile, TexelFileError};
use crate::transport::series::{PreviousPass, PreviousPassWriter};
use guidebake_kernels::estimator::{
    IterationVariance, RhoAccumulator, TexelEstimate, Welford, combine_weighted, plain_average,
};

/// Pixels of padding around every chart in the written pages.
pub const DILATION_PIXELS: u32 = 2;

/// What a bake run is asked to do.
#[derive(Clone, Debug)]
pub struct BakeJob {
    /// The texel file.
    pub texels: PathBuf,
    /// The lightmap to write (`.exr`; more pages become `OUT.pageN.exr`).
    pub out: PathBuf,
    /// The bake's settings.
    pub settings: BakeSettings,
    /// Worker threads.
    pub threads: usize,
    /// Which tiles this run bakes.
    pub shard: Shard,
    /// Continue an interrupted run from its journal.
    pub resume: bool,
    /// Write auxiliary channels (sample count, relative standard error, validity).
    pub aux: bool,
}

/// The work directory's manifest: what `--resume` and `merge` check before trusting it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// The texel file baked.
    pub texels: PathBuf,
    /// Identity of the bake (settings and texel file).
    pub bake_id: u64,
    /// Which shard this directory holds.
    pub shard_index: u32,
    /// How many shards.
    pub shard_count: u32,
    /// Whether ρ is applied when the pages are written.
    pub bias_correction: bool,
    /// Whether auxiliary channels are written.
    pub aux: bool,
    /// Passes over the world (series transport's bounces); the last one is the lightmap.
    pub passes: u32,
    /// Whether the final pass combines the kept batches with global weights
    /// (`--combine global`).
    pub combine_global: bool,
    /// Learning iterations (batches per texel in the batch file).
    pub iterations: u32,
    /// The settings, for people.
    pub settings: String,
}

/// What a bake did: the stats JSON.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BakeReport {
    /// Tiles this run baked (not counting those a resume skipped).
    pub tiles_baked: usize,
    /// Tiles skipped because the journal had them (`--resume`).
    pub tiles_resumed: usize,
    /// Whether Ctrl-C cut the run short (the work directory is kept for `--resume`).
    pub interrupted: bool,
    /// Passes over the world (series transport: one per bounce).
    pub passes: u32,
    /// What the gather counted over every pass: rays by kind, texels, clusters, skips.
    pub counters: GatherCounters,
    /// Seconds per phase.
    pub seconds: PhaseSeconds,
    /// ρ = L̂ / L̂_GD over the world (1 when not applied or not yet known).
    pub rho: f64,
    /// Gather and shadow rays per second of the gather phase.
    pub rays_per_second: f64,
    /// Analytic lights in the scene.
    pub lights: usize,
    /// Emissive triangles sampled by next-event estimation (0: no emitter table, no shadow
    /// rays to emitters; with `lights` also 0, no shadow rays at all).
    pub emitters: usize,
    /// The pages written (empty for a shard).
    pub pages: Vec<PathBuf>,
    /// Pixels with non-finite results replaced by zero when writing (should be 0).
    pub non_finite_pixels: u64,
}

/// Wall-clock seconds of each phase.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseSeconds {
    /// Opening and validating the texel file.
    pub open_texels: f64,
    /// Building the BVH.
    pub build_bvh: f64,
    /// The gather (all tiles and passes of this run).
    pub gather: f64,
    /// Writing and dilating the previous passes' images for series transport.
    pub previous_pass_images: f64,
    /// Applying ρ and writing the pages.
    pub write_pages: f64,
}

/// Why a bake stopped; every variant names what it was working on.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// Bad settings.
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// The texel file could not be opened or is invalid.
    #[error(transparent)]
    Texels(#[from] TexelFileError),
    /// The BVH could not be built from the scene.
    #[error("cannot build the BVH: {0}")]
    Bvh(#[from] BvhError),
    /// Writing, reading or syncing the result file or the journal failed.
    #[error(transparent)]
    Output(#[from] OutputFileError),
    /// The pipeline failed.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// A page could not be written.
    #[error(transparent)]
    Page(#[from] PageWriteError),
    /// A file or directory operation failed.
    #[error("{path}: {what}")]
    File {
        /// The file or directory.
        path: PathBuf,
        /// What failed.
        what: String,
    },
    /// A previous run's work exists and `--resume` was not given.
    #[error(
        "{dir}: a previous bake's work is here; pass --resume to continue it, or delete the directory to start over"
    )]
    WorkExists {
        /// The work directory.
        dir: PathBuf,
    },
    /// The scene and the texel file disagree.
    #[error("{0}")]
    Mismatch(String),
}

/// The work directory of `out` for `shard`.
pub fn work_dir(out: &Path, shard: Shard) -> PathBuf {
    let name = out
        .file_name()
        .map_or_else(|| "lightmap".into(), |s| s.to_string_lossy());
    let suffix = if shard.count == 1 {
        "bake".to_owned()
    } else {
        format!("shard-{}-of-{}", shard.index, shard.count)
    };
    out.with_file_name(format!("{name}.{suffix}"))
}

fn file_error(path: &Path, what: impl std::fmt::Display) -> BakeError {
    BakeError::File {
        path: path.to_owned(),
        what: what.to_string(),
    }
}

/// Identity of a texel file: a hash of its header (sizes, counts, bounds, offsets).
fn texel_file_id(texels: &TexelFile) -> u64 {
    fnv1a64(bytemuck::bytes_of(texels.header()))
}

/// How far a bake is, as [`bake_with_progress`] reports it after every tile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Progress {
    /// Texels done, over every pass (a resumed run counts what its journals hold).
    pub texels_done: u64,
    /// Texels to do, over every pass.
    pub texels_total: u64,
    /// Rays this run has traced so far (all kinds).
    pub rays: u64,
}

/// Bakes `job` over `scene`. `cancel` (a Ctrl-C flag) stops it early with its work kept;
/// `progress(done, total)` counts texels over every pass.
///
/// # Errors
/// A [`BakeError`] naming the file or option at fault; work committed before the error stays
/// in the work directory for `--resume`.
pub fn bake(
    job: &BakeJob,
    scene: &Scene,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<BakeReport, BakeError> {
    bake_with_progress(job, scene, cancel, &mut |p: Progress| {
        progress(p.texels_done, p.texels_total);
    })
}

/// [`bake`] with the rays traced in each report too (the progress bar's rays/s).
///
/// # Errors
/// As [`bake`].
pub fn bake_with_progress(
    job: &BakeJob,
    scene: &Scene,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(Progress),
) -> Result<BakeReport, BakeError> {
    bake_pass_with_progress(job, None, scene, cancel, progress)
}

/// [`bake_with_progress`] of one series pass only (`bake --pass B`), or of every pass
/// (`only_pass` `None`). A run of one pass never writes pages: it leaves its work directory
/// for `guidebake merge --pass B` ([`merge_pass`] before the last pass, [`finish`] after it).
/// Pass B > 1 reads pass B − 1 from the merged result file that [`merge_pass`] wrote
/// ([`merged_results`]), so the shards of a pass may run anywhere once the previous pass is
/// merged.
///
/// # Errors
/// As [`bake`]; also a pass out of range, or pass B − 1 not merged yet.
pub fn bake_pass_with_progress(
    job: &BakeJob,
    only_pass: Option<u32>,
    scene: &Scene,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(Progress),
) -> Result<BakeReport, BakeError> {
    job.settings.validate()?;
    let run_passes = passes_to_run(job, only_pass)?;
    let mut report = BakeReport {
        rho: 1.0,
        ..Default::default()
    };
    let clock = Instant::now();
    let texels = TexelFile::open(&job.texels)?;
    report.seconds.open_texels = clock.elapsed().as_secs_f64();
    check_scene_matches(&texels, scene)?;

    let clock = Instant::now();
    let mut world = World::new(scene, Preset::DEFAULT)?;
    world.set_transport(job.settings.transport, job.settings.bounces);
    world.set_emitters(job.settings.emitters, job.settings.emitter_selection);
    report.seconds.build_bvh = clock.elapsed().as_secs_f64();
    report.lights = world.lights().len();
    report.emitters = world.emitters().map_or(0, |e| e.len());

    let passes = job.settings.passes();
    let bake_id = job.settings.bake_id(texel_file_id(&texels));
    let dir = work_dir(&job.out, job.shard);
    let manifest = Manifest {
        texels: std::path::absolute(&job.texels).unwrap_or_else(|_| job.texels.clone()),
        bake_id,
        shard_index: job.shard.index,
        shard_count: job.shard.count,
        bias_correction: job.settings.bias_correction,
        aux: job.aux,
        passes,
        combine_global: job.settings.combine == Combine::Global,
        iterations: job.settings.iterations,
        settings: format!("{:?}", job.settings),
    };
    open_work(&dir, &manifest, job.resume, only_pass)?;
    let pass_texels = shard_texels(&texels, job.shard);
    let mut now = Progress {
        texels_total: pass_texels * u64::from(run_passes.end() + 1 - run_passes.start()),
        ..Default::default()
    };
    let clock = Instant::now();
    for pass in run_passes.clone() {
        if pass > 1 {
            // A one-pass run reads the merged previous pass; a run of every pass its own.
            let source = match only_pass {
                Some(_) => merged_results(&job.out, pass - 1),
                None => pass_files(&dir, pass - 1).0,
            };
            let image = dir.join(format!("indirect.{}.bin", pass - 1));
            let previous = previous_pass(&texels, scene, &source, &image, bake_id, &mut report)
                .map_err(|e| not_merged_hint(e, &source, pass - 1))?;
            world.set_previous_pass(Some(previous));
        }
        let run = bake_pass(
            job,
            &texels,
            &world,
            &dir,
            pass,
            bake_id,
            cancel,
            &mut |texels, rays| {
                now.texels_done += texels;
                now.rays += rays;
                progress(now);
            },
        )?;
        report.tiles_baked += run.tiles_baked;
        report.tiles_resumed += run.tiles_resumed;
        report.counters.merge(&run.counters);
        if run.interrupted {
            report.interrupted = true;
            break;
        }
        now.texels_done = pass_texels * u64::from(pass + 1 - run_passes.start());
    }
    report.passes = run_passes.end() + 1 - run_passes.start();
    report.seconds.gather = clock.elapsed().as_secs_f64() - report.seconds.previous_pass_images;
    report.rays_per_second = report.counters.rays() as f64 / report.seconds.gather.max(1e-9);
    drop(world);
    if !report.interrupted && job.shard.count == 1 && only_pass.is_none() {
        let clock = Instant::now();
        let written = finish(&texels, std::slice::from_ref(&dir), &job.out)?;
        report.seconds.write_pages = clock.elapsed().as_secs_f64();
        report.rho = written.rho;
        report.pages = written.pages;
        report.non_finite_pixels = written.non_finite_pixels;
        retire_work(&dir)?;
    }
    Ok(report)
}

/// The passes a run bakes: `only_pass`, or every pass of the bake. A shard of a multi-pass
/// series bake must name its pass: each pass needs the whole previous one, merged.
fn passes_to_run(
    job: &BakeJob,
    only_pass: Option<u32>,
) -> Result<std::ops::RangeInclusive<u32>, BakeError> {
    let passes = job.settings.passes();
    match only_pass {
        Some(b) if b == 0 || b > passes => Err(BakeError::Settings(SettingsError::new(format!(
            "--pass {b}: this bake has passes 1..={passes} (--transport series makes one pass \
             per bounce, other transports one pass)"
        )))),
        Some(b) => Ok(b..=b),
        None if job.shard.count > 1 && passes > 1 => {
            Err(BakeError::Settings(SettingsError::new(format!(
                "--shard {}/{} with --transport series --bounces {passes}: each series pass needs \
                 the whole previous pass, so shard the passes one by one: `bake --pass B --shard \
                 {}/{}` for B = 1..={passes}, each pass followed by `merge --pass B` over its \
                 shards (docs/farm.md)",
                job.shard.index, job.shard.count, job.shard.index, job.shard.count
            ))))
        }
        None => Ok(1..=passes),
    }
}

/// The directory `merge --pass B` writes the merged result files of the passes before the
/// last into: `OUT.exr.merged/`.
pub fn merged_dir(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map_or_else(|| "lightmap".into(), |s| s.to_string_lossy());
    out.with_file_name(format!("{name}.merged"))
}

/// The merged result file of pass `pass`, which the shards of pass `pass + 1` read.
pub fn merged_results(out: &Path, pass: u32) -> PathBuf {
    merged_dir(out).join(format!("results.{pass}.bin"))
}

/// Says how to make the previous pass's merged result file when it is missing.
fn not_merged_hint(e: BakeError, source: &Path, pass: u32) -> BakeError {
    if source.exists() {
        return e;
    }
    file_error(
        source,
        format!(
            "pass {pass} is not merged: run `guidebake merge --pass {pass}` over every shard of \
             pass {pass} first"
        ),
    )
}

/// Texels in the tiles of `shard`.
fn shard_texels(texels: &TexelFile, shard: Shard) -> u64 {
    tiles_to_bake(texels.tiles().len() as u32, shard, &HashSet::new())
        .iter()
        .map(|&t| u64::from(texels.tiles()[t as usize].texel_count))
        .sum()
}

/// What one pass over the world did.
#[derive(Default)]
struct PassRun {
    tiles_baked: usize,
    tiles_resumed: usize,
    interrupted: bool,
    counters: GatherCounters,
}

/// Bakes pass `pass` of the job's tiles (those its journal lacks) into the pass's result file.
#[allow(clippy::too_many_arguments)]
fn bake_pass(
    job: &BakeJob,
    texels: &TexelFile,
    world: &World,
    dir: &Path,
    pass: u32,
    bake_id: u64,
    cancel: &AtomicBool,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PassRun, BakeError> {
    let tile_count = texels.tiles().len() as u32;
    let (results, mut journal, done) =
        open_pass(dir, pass, bake_id, texels.header().texel_count, tile_count)?;
    // Global weights combine the last pass's batches once the whole world is baked.
    let batches = (job.settings.combine == Combine::Global && pass == job.settings.passes())
        .then(|| {
            open_batches(
                dir,
                bake_id,
                texels.header().texel_count,
                job.settings.iterations,
                !done.is_empty(),
            )
        })
        .transpose()?;
    let todo = tiles_to_bake(
        tile_count,
        job.shard,
        &done.iter().map(|r| r.tile).collect::<HashSet<u32>>(),
    );
    progress(
        done.iter()
            .map(|r| u64::from(texels.tiles()[r.tile as usize].texel_count))
            .sum(),
        0,
    );
    let counters = Mutex::new(GatherCounters::default());
    let config = PipelineConfig {
        threads: job.threads.max(1),
        window: 4 * job.threads.max(1),
        commit_every: 64,
    };
    let make_worker = || CountedBaker {
        baker: TileBaker::new(world, job.settings),
        sink: &counters,
    };
    let bake_tile = |w: &mut CountedBaker<'_, '_>, tile: u32, out: &mut TileBuffer| {
        let record = &texels.tiles()[tile as usize];
        let baked = w.baker.bake_tile(
            tile,
            record.first_texel,
            texels.tile_texels(tile as usize),
            out,
        );
        texels.release_tile(tile as usize);
        baked
    };
    let pipeline = pipeline::run(
        config,
        &todo,
        TileFiles {
            results: &results,
            batches: batches.as_ref(),
        },
        &mut journal,
        cancel,
        make_worker,
        bake_tile,
        &mut |b| {
            let texel_count = texels.tiles()[b.record.tile as usize].texel_count;
            progress(u64::from(texel_count), b.record.rays);
        },
    )?;
    let counters = *counters.lock().expect("no worker panicked");
    Ok(PassRun {
        tiles_baked: pipeline.tiles_committed,
        tiles_resumed: done.len(),
        interrupted: pipeline.interrupted,
        counters,
    })
}

/// Writes the image (at `image_path`) of the gather-only irradiance in a pass's result file
/// `results_path` and maps it for the next pass (series transport).
fn previous_pass(
    texels: &TexelFile,
    scene: &Scene,
    results_path: &Path,
    image_path: &Path,
    bake_id: u64,
    report: &mut BakeReport,
) -> Result<PreviousPass, BakeError> {
    let clock = Instant::now();
    let (results, _) = ResultFile::open(
        results_path,
        false,
        Some((texels.header().texel_count, bake_id)),
    )?;
    let mut image = PreviousPassWriter::create(image_path, texels.pages())
        .map_err(|e| file_error(&e.path, e.what))?;
    let mut buffer = Vec::new();
    for (t, tile) in texels.tiles().iter().enumerate() {
        buffer.resize(tile.texel_count as usize, TexelResult::default());
        results.read(tile.first_texel, &mut buffer)?;
        for (texel, r) in texels.tile_texels(t).iter().zip(&buffer) {
            if r.flags & FLAG_BAKED != 0 {
                image.set(
                    texel.page,
                    u32::from(texel.pixel[0]),
                    u32::from(texel.pixel[1]),
                    r.gathered,
                );
            }
        }
        texels.release_tile(t);
    }
    let previous = image
        .finish(scene, texels.meshes())
        .map_err(|e| file_error(&e.path, e.what))?;
    report.seconds.previous_pass_images += clock.elapsed().as_secs_f64();
    Ok(previous)
}

/// A worker's baker whose counters join the bake's when the worker ends.
struct CountedBaker<'w, 's> {
    baker: TileBaker<'w>,
    sink: &'s Mutex<GatherCounters>,
}

impl Drop for CountedBaker<'_, '_> {
    fn drop(&mut self) {
        if let Ok(mut total) = self.sink.lock() {
            total.merge(&self.baker.counters);
        }
    }
}

fn check_scene_matches(texels: &TexelFile, scene: &Scene) -> Result<(), BakeError> {
    let expected = texels.header().triangle_count as usize;
    if expected != scene.triangles.len() {
        return Err(BakeError::Mismatch(format!(
            "{}: the texel file was prepared from a scene of {expected} triangles, but {} has {}",
            texels.path().display(),
            scene.path.display(),
            scene.triangles.len()
        )));
    }
    Ok(())
}

/// Creates the work directory and its manifest, or, with `resume`, checks that the one there
/// belongs to this bake. A run of one pass (`only_pass`) continues the work directory its
/// earlier passes left without `--resume`, unless its own pass has begun there.
fn open_work(
    dir: &Path,
    manifest: &Manifest,
    resume: bool,
    only_pass: Option<u32>,
) -> Result<(), BakeError> {
    let manifest_path = dir.join("manifest.json");
    if dir.exists() {
        let begun = only_pass.is_none_or(|b| {
            let (results, journal) = pass_files(dir, b);
            results.exists() || journal.exists()
        });
        if !resume && begun {
            return Err(BakeError::WorkExists {
                dir: dir.to_owned(),
            });
        }
        let found = read_manifest(&manifest_path)?;
        if found.bake_id != manifest.bake_id {
            return Err(BakeError::Mismatch(format!(
                "{}: --resume of a different bake (other settings or texel file); delete it to start over",
                dir.display()
            )));
        }
        return Ok(());
    }
    // The directory appears with its manifest or not at all: it is made under a temporary
    // name and renamed, so a crash in between leaves nothing that --resume would refuse.
    let staging = temporary_name(dir);
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging)
        .map_err(|e| file_error(dir, format!("cannot create the work directory: {e}")))?;
    let json = serde_json::to_string_pretty(manifest).expect("a manifest serializes");
    std::fs::write(staging.join("manifest.json"), json)
        .map_err(|e| file_error(&manifest_path, format!("cannot write: {e}")))?;
    std::fs::rename(&staging, dir)
        .map_err(|e| file_error(dir, format!("cannot create the work directory: {e}")))
}

/// Removes a finished bake's work directory. It is renamed out of the way first, so a crash
/// during the removal leaves no half-deleted work directory (one without its manifest) for
/// `--resume` to refuse; at worst a hidden temporary directory beside it.
fn retire_work(dir: &Path) -> Result<(), BakeError> {
    let retired = temporary_name(dir);
    let _ = std::fs::remove_dir_all(&retired);
    std::fs::rename(dir, &retired)
        .and_then(|()| std::fs::remove_dir_all(&retired))
        .map_err(|e| {
            file_error(
                dir,
                format!("cannot remove the finished work directory: {e}"),
            )
        })
}

/// Opens pass `pass`'s result file and journal in `dir` (with the tiles its journal holds),
/// creating them when this pass has not started.
fn open_pass(
    dir: &Path,
    pass: u32,
    bake_id: u64,
    texel_count: u64,
    tile_count: u32,
) -> Result<(ResultFile, Journal, Vec<TileRecord>), BakeError> {
    let (results_path, journal_path) = pass_files(dir, pass);
    if results_path.exists() && journal_path.exists() {
        let (results, _) = ResultFile::open(&results_path, true, Some((texel_count, bake_id)))?;
        let (journal, _, mut done) =
            Journal::open(&journal_path, true, Some((tile_count, bake_id)))?;
        dedup_tiles(&mut done);
        return Ok((results, journal, done));
    }
    let results = ResultFile::create(&results_path, texel_count, bake_id)?;
    let journal = Journal::create(&journal_path, tile_count, bake_id)?;
    Ok((results, journal, Vec::new()))
}

/// Opens the batch file of `--combine global` (`resume`: the one a resumed pass wrote
/// into), or creates it.
fn open_batches(
    dir: &Path,
    bake_id: u64,
    texel_count: u64,
    iterations: u32,
    resume: bool,
) -> Result<BatchFile, BakeError> {
    let path = dir.join("batches.bin");
    if resume && path.exists() {
        let (file, _) =
            BatchFile::open_with(&path, true, iterations, Some((texel_count, bake_id)))?;
        return Ok(file);
    }
    Ok(BatchFile::create_with(
        &path,
        texel_count,
        iterations,
        bake_id,
    )?)
}

/// The result file and journal of pass `pass` (1-based) in a work directory.
fn pass_files(dir: &Path, pass: u32) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("results.{pass}.bin")),
        dir.join(format!("journal.{pass}.bin")),
    )
}

/// Reads a work directory's manifest.
///
/// # Errors
/// [`BakeError::File`] when it is missing or not a manifest.
pub fn read_manifest(path: &Path) -> Result<Manifest, BakeError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| file_error(path, format!("cannot read the manifest: {e}")))?;
    serde_json::from_str(&text)
        .map_err(|e| file_error(path, format!("not a guidebake manifest: {e}")))
}

/// What [`finish`] wrote.
#[derive(Clone, Debug, Default)]
pub struct Written {
    /// ρ applied (1 without bias correction).
    pub rho: f64,
    /// The page files.
    pub pages: Vec<PathBuf>,
    /// Their tone-mapped PNG previews.
    pub previews: Vec<PathBuf>,
    /// Non-finite pixels replaced by zero.
    pub non_finite_pixels: u64,
}

/// The final streaming pass: reduces ρ over every tile of the work directories (one per
/// shard; together they must cover every tile exactly once), then writes each page — results
/// times ρ, dilated — as EXR. Used by an unsharded bake and by `guidebake merge`.
///
/// # Errors
/// A [`BakeError`] naming the work directory or page: a shard missing, shards of different
/// bakes, a tile not baked, a page that cannot be written.
pub fn finish(texels: &TexelFile, dirs: &[PathBuf], out: &Path) -> Result<Written, BakeError> {
    let shards = open_shards(texels, dirs, None)?;
    let first = &shards[0].manifest;
    let all = every_tile(texels, &shards)?;
    let batches = open_batch_files(texels, &shards)?;
    let global = batches
        .as_deref()
        .map(|files| global_weights(texels, &shards, files))
        .transpose()?;
    let rho = match (first.bias_correction, &global) {
        (false, _) => 1.0,
        (true, None) => RhoSums::reduce(&all).rho(),
        (true, Some(g)) => g.rho,
    };
    let mut written = Written {
        rho,
        ..Default::default()
    };
    let k = first.iterations as usize;
    let mut texel_batches = Vec::new();
    let page_count = texels.pages().len() as u32;
    for (page, size) in texels.pages().iter().enumerate() {
        let path = page_path(out, page as u32, page_count);
        let aux: &[&str] = if first.aux { &AUX_CHANNELS } else { &[] };
        let mut image = PageStream::create(
            &temporary_name(&path.with_extension("pixels")),
            size.width,
            size.height,
            aux,
        )?;
        let mut buffer = Vec::new();
        for (t, tile) in texels
            .tiles()
            .iter()
            .enumerate()
            .filter(|(_, t)| t.page as usize == page)
        {
            let results = &shards[t % shards.len()].results;
            buffer.resize(tile.texel_count as usize, TexelResult::default());
            results.read(tile.first_texel, &mut buffer)?;
            if let (Some(files), Some(_)) = (&batches, &global) {
                texel_batches.resize(buffer.len() * k, Welford::new());
                files[t % files.len()].read(tile.first_texel, &mut texel_batches)?;
            }
            let mut rect = image.rect(tile.x, tile.y, tile.width, tile.height)?;
            for (i, (texel, r)) in texels.tile_texels(t).iter().zip(&buffer).enumerate() {
                if r.flags & FLAG_BAKED == 0 {
                    continue;
                }
                let [x, y] = texel.pixel.map(u32::from);
                let irradiance = match &global {
                    Some(g) => g.combine(&texel_batches[i * k..(i + 1) * k]),
                    None => r.irradiance.map(f64::from),
                };
                let rgb = irradiance.map(|c| (c * rho) as f32);
                let [px, py, pz] = texel.position;
                let [nx, ny, nz] = texel.normal;
                // In AUX_CHANNELS' order; unused without --aux.
                let aux = [
                    r.samples as f32,
                    r.rel_std_error,
                    1.0,
                    px,
                    py,
                    pz,
                    nx,
                    ny,
                    nz,
                ];
                image.set(&mut rect, x, y, rgb, &aux);
            }
            image.put_rect(&rect)?;
            texels.release_tile(t);
        }
        written.non_finite_pixels += image.non_finite_pixels();
        let preview = path.with_extension("png");
        image.finish(DILATION_PIXELS, &path, &preview)?;
        written.pages.push(path);
        written.previews.push(preview);
    }
    Ok(written)
}

/// The journal records of every tile from the shards' work (each tile once), or an error
/// naming a tile no shard has baked.
fn every_tile(texels: &TexelFile, shards: &[ShardWork]) -> Result<Vec<TileRecord>, BakeError> {
    let mut all: Vec<TileRecord> = shards
        .iter()
        .flat_map(|s| s.records.iter().copied())
        .collect();
    dedup_tiles(&mut all);
    let tile_count = texels.tiles().len();
    if all.len() != tile_count {
        let done: HashSet<u32> = all.iter().map(|r| r.tile).collect();
        let missing = (0..tile_count as u32)
            .find(|t| !done.contains(t))
            .unwrap_or(0);
        return Err(BakeError::Mismatch(format!(
            "{} of {tile_count} tiles are baked (tile {missing} is not): finish every shard, or --resume the interrupted one",
            all.len()
        )));
    }
    Ok(all)
}

/// `guidebake merge --pass B` before the last pass: gathers pass `pass` of every shard
/// (together they must cover every tile once) into one result file, [`merged_results`] of
/// `out`, which the shards of pass `pass + 1` read. Each tile's records are copied from the
/// shard that baked it, so the merged file holds the same bytes as an unsharded bake's result
/// file of that pass. The file appears under its name only when complete. Returns its path.
///
/// # Errors
/// A [`BakeError`] naming the work directory or file: a shard missing or of another bake, a
/// tile not baked, `pass` not before the last pass, a write that fails.
pub fn merge_pass(
    texels: &TexelFile,
    dirs: &[PathBuf],
    out: &Path,
    pass: u32,
) -> Result<PathBuf, BakeError> {
    let shards = open_shards(texels, dirs, Some(pass.max(1)))?;
    let first = &shards[0].manifest;
    if pass == 0 || pass >= first.passes {
        return Err(BakeError::Settings(SettingsError::new(format!(
            "merge --pass {pass}: the bake has passes 1..={}; passes before the last are merged \
             into a result file, the last into pages by `merge` with --pass {} or without --pass",
            first.passes, first.passes
        ))));
    }
    every_tile(texels, &shards)?;
    let path = merged_results(out, pass);
    let dir = merged_dir(out);
    std::fs::create_dir_all(&dir)
        .map_err(|e| file_error(&dir, format!("cannot create the directory: {e}")))?;
    let staging = temporary_name(&path);
    let copy = || -> Result<(), BakeError> {
        let merged = ResultFile::create(&staging, texels.header().texel_count, first.bake_id)?;
        let mut buffer = Vec::new();
        for (t, tile) in texels.tiles().iter().enumerate() {
            buffer.resize(tile.texel_count as usize, TexelResult::default());
            shards[t % shards.len()]
                .results
                .read(tile.first_texel, &mut buffer)?;
            merged.write(tile.first_texel, &buffer)?;
        }
        merged.sync()?;
        std::fs::rename(&staging, &path)
            .map_err(|e| file_error(&path, format!("cannot rename into place: {e}")))
    };
    copy().inspect_err(|_| {
        let _ = std::fs::remove_file(&staging);
    })?;
    Ok(path)
}

/// The auxiliary EXR channels of `--aux`: gather samples, relative standard error of the
/// luminance, validity (1 where a texel was baked), world position and normal.
pub const AUX_CHANNELS: [&str; 9] = [
    "samples",
    "rel_std_error",
    "validity",
    "P.X",
    "P.Y",
    "P.Z",
    "N.X",
    "N.Y",
    "N.Z",
];

/// The shards' batch files when the bake combines with global weights (in shard order).
fn open_batch_files(
    texels: &TexelFile,
    shards: &[ShardWork],
) -> Result<Option<Vec<BatchFile>>, BakeError> {
    if !shards[0].manifest.combine_global {
        return Ok(None);
    }
    let mut files = Vec::new();
    for shard in shards {
        let (file, _) = BatchFile::open_with(
            &shard.dir.join("batches.bin"),
            false,
            shard.manifest.iterations,
            Some((texels.header().texel_count, shard.manifest.bake_id)),
        )?;
        files.push(file);
    }
    Ok(Some(files))
}

/// Müller's global per-iteration weights, from every baked texel's batches, and the ρ they
/// give (which is ~1: the weights do not depend on a texel's own samples).
struct GlobalWeights {
    weights: [f64; MAX_ITERATIONS],
    rho: f64,
}

impl GlobalWeights {
    /// A texel's irradiance combined with the global weights (zero when it has no samples).
    fn combine(&self, batches: &[Welford]) -> [f64; 3] {
        match combine_weighted(batches, &self.weights) {
            TexelEstimate::Value(e) => e.rgb,
            TexelEstimate::NoSamples { .. } => [0.0; 3],
        }
    }
}

/// Streams every shard's batches twice: the per-iteration variances give the weights, then the
/// weighted and unweighted luminance sums give ρ. Exact sums: any shard split, same bits.
fn global_weights(
    texels: &TexelFile,
    shards: &[ShardWork],
    files: &[BatchFile],
) -> Result<GlobalWeights, BakeError> {
    let k = shards[0].manifest.iterations as usize;
    let mut variance = IterationVariance::<MAX_ITERATIONS>::new();
    let mut g = GlobalWeights {
        weights: [0.0; MAX_ITERATIONS],
        rho: 1.0,
    };
    let mut rho = RhoAccumulator::default();
    for second in [false, true] {
        let (mut results, mut batches) = (Vec::new(), Vec::new());
        for (t, tile) in texels.tiles().iter().enumerate() {
            results.resize(tile.texel_count as usize, TexelResult::default());
            batches.resize(tile.texel_count as usize * k, Welford::new());
            shards[t % shards.len()]
                .results
                .read(tile.first_texel, &mut results)?;
            files[t % files.len()].read(tile.first_texel, &mut batches)?;
            for (i, r) in results.iter().enumerate() {
                let texel = &batches[i * k..(i + 1) * k];
                if r.flags & FLAG_BAKED == 0 {
                    continue;
                }
                if second {
                    rho.add_texel(&plain_average(texel), &combine_weighted(texel, &g.weights));
                } else {
                    variance.add_texel(texel);
                }
            }
        }
        if !second {
            g.weights = variance.weights();
        }
    }
    g.rho = rho.rho();
    Ok(g)
}

/// One shard's finished work, opened for the final pass.
struct ShardWork {
    manifest: Manifest,
    dir: PathBuf,
    /// The opened pass's results (the last pass's for the pages).
    results: ResultFile,
    /// The opened pass's journal records.
    records: Vec<TileRecord>,
}

/// Opens pass `pass` (default: the last) of the work directories in shard order and checks
/// they belong to one bake.
fn open_shards(
    texels: &TexelFile,
    dirs: &[PathBuf],
    pass: Option<u32>,
) -> Result<Vec<ShardWork>, BakeError> {
    let mut shards = Vec::new();
    for dir in dirs {
        let manifest = read_manifest(&dir.join("manifest.json"))?;
        let (results_path, journal_path) = pass_files(dir, pass.unwrap_or(manifest.passes));
        let (results, _) = ResultFile::open(
            &results_path,
            false,
            Some((texels.header().texel_count, manifest.bake_id)),
        )?;
        let (_, _, records) = Journal::open(
            &journal_path,
            false,
            Some((texels.tiles().len() as u32, manifest.bake_id)),
        )?;
        shards.push(ShardWork {
            manifest,
            dir: dir.clone(),
            results,
            records,
        });
    }
    let Some(first) = shards.first().map(|s| s.manifest.clone()) else {
        return Err(BakeError::Mismatch("no work directories to finish".into()));
    };
    shards.sort_by_key(|s| s.manifest.shard_index);
    let count = first.shard_count as usize;
    let indices: Vec<u32> = shards.iter().map(|s| s.manifest.shard_index).collect();
    if shards.len() != count || indices != (0..count as u32).collect::<Vec<_>>() {
        return Err(BakeError::Mismatch(format!(
            "shards {indices:?} given; a bake of {count} shards needs each of 0..{count} once"
        )));
    }
    if let Some(other) = shards.iter().find(|s| s.manifest.bake_id != first.bake_id) {
        return Err(BakeError::Mismatch(format!(
            "shard {} belongs to another bake (other settings or texel file) than shard {}",
            other.manifest.shard_index, first.shard_index
        )));
    }
    Ok(shards)
}
