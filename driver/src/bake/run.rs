//! A whole bake, from texel file to EXR pages: `guidebake bake`, `guidebake merge` and
//! `guidebake demo` call [`bake`] and [`finish`].
//!
//! A run works in a *work directory* beside its output (`OUT.exr.bake/`, or
//! `OUT.exr.shard-I-of-N/` for `--shard I/N`) holding the [result
//! file](crate::output::result_file), the [journal](crate::output::journal) and a
//! `manifest.json` naming the texel file, the settings and the shard, and recording what the
//! bake is made of ([`BakeRecord`]: `--resume` of a bake that differs names each difference).
//! An unsharded run that finishes applies ρ and writes the pages ([`finish`]), then removes
//! its work directory; a shard leaves its work directory for `guidebake merge`. An interrupted run leaves it for
//! `--resume`. A work directory is never overwritten without `--resume`: nothing baked is
//! lost by a repeated command.
//!
//! Series bakes shard pass by pass, in commands a batch scheduler chains: `bake --pass B
//! --shard I/N` bakes pass B of one shard into its work directory, `merge --pass B` gathers
//! pass B of every shard into one result file in `OUT.exr.merged/` ([`merge_pass`](super::finish::merge_pass)), which
//! the shards of pass B + 1 read as their previous pass; the last pass is merged into pages by
//! [`finish`] as before. Every tile's bytes depend on its index, the settings and the previous
//! pass only, so N shards × B passes give the bytes of one unsharded bake.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use serde::Serialize;

use super::budget::SpatialBudget;
pub use super::error::BakeError;
use super::error::file_error;
use super::finish::{FinishOptions, finish_with};
use super::gather::{GatherCounters, TileBaker};
use super::pipeline::{self, PipelineConfig, TileBuffer, TileFiles};
use super::settings::{BakeSettings, Budget, Combine, DIRECT_PASS, Directional, SettingsError};
use super::shard::{Shard, tiles_to_bake};
use super::workdir::{
    BakeRecord, Manifest, merged_results, open_batches, open_directional, open_pass, open_work,
    pass_files, pass_image, retire_work, work_dir,
};
use crate::bvh::Preset;
use crate::hash::fnv1a64;
use crate::output::result_file::{FLAG_BAKED, FinishedResults, ResultFile, TexelResult};
use crate::scene::Scene;
use crate::texels::{FLAG_INSIDE, TexelFile, TileRect};
use crate::transport::lookup_filter::Surfel;
use crate::transport::pass_image::{CELL, Source, SourceTexel};
use crate::transport::series::{BuildError, PreviousPass, TriangleUvs};
use crate::transport::world::World;

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
    /// Denoising and seam stitching as the pages are written.
    pub finish: FinishOptions,
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
    /// Passes over the world this run made (series transport: the direct pass and one per
    /// bounce).
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
    /// Bytes of base-colour texture texels held in memory (each image once, after the
    /// `--max-texture-size` cap; `scene::texture`).
    pub texture_bytes: usize,
    /// The pages written (empty for a shard).
    pub pages: Vec<PathBuf>,
    /// Whether the texel file was prepared under other lights than this bake's (its seen
    /// sides were decided under those; [`lights_differ`]).
    pub prepared_under_other_lights: bool,
    /// Bytes of the largest pass image the series transport built (its file in the work
    /// directory; 0 for other transports).
    pub pass_image_bytes: u64,
    /// Bytes the lookups' filter held at most while it built a pass image (what it knows of
    /// the texels within its reach; 0 unfiltered).
    pub filter_window_bytes: u64,
    /// Pixels with non-finite results replaced by zero when writing (should be 0).
    pub non_finite_pixels: u64,
    /// Mean relative jump between the two texels of each seam pair, before and after
    /// stitching (`--seams stitch`).
    pub seam_jump: Option<[f64; 2]>,
    /// Mean relative jump of the two sides' bilinear values at the seams' edge points —
    /// what a shader shows, and what the stitch closes — before and after stitching.
    pub edge_jump: Option<[f64; 2]>,
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
    /// Building the previous passes' images for series transport.
    pub previous_pass_images: f64,
    /// Applying ρ and writing the pages.
    pub write_pages: f64,
}

/// What the bake is made of besides its settings ([`BakeRecord`]): the texel file, the
/// scene's geometry, materials and lights, and `--aux`.
fn bake_record(job: &BakeJob, texels: &TexelFile, scene: &Scene) -> BakeRecord {
    let mut options = job.settings.options();
    options.insert("--aux".into(), if job.aux { "on" } else { "off" }.into());
    BakeRecord::new(options, texels, scene)
}

/// The identity the bake's settings are combined with ([`BakeSettings::bake_id`]): the
/// record's every field but the version, so a bake of any other texel file, geometry,
/// materials, lights or `--aux` is another bake.
fn record_id(record: &BakeRecord) -> u64 {
    let BakeRecord {
        options,
        texels,
        geometry,
        materials,
        lighting,
        lights: _,
        version: _,
    } = record;
    fnv1a64(
        format!(
            "{texels} {geometry} {materials} {lighting} aux {}",
            options["--aux"]
        )
        .as_bytes(),
    )
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
/// for `guidebake merge --pass B` ([`merge_pass`](super::finish::merge_pass) before the last pass, [`finish`] after it).
/// Pass B > 1 reads pass B − 1 from the merged result file that [`merge_pass`](super::finish::merge_pass) wrote
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
    report.prepared_under_other_lights = lights_differ(texels.header(), scene);

    let clock = Instant::now();
    // The roles `prepare` recorded decide what rays meet (`scene::roles`).
    let traced = crate::scene::ids_where(texels.triangles().len(), |t| {
        texels.triangles()[t].role().traced()
    });
    let preset = run_preset(job, &texels, scene, &run_passes);
    let mut world = World::tracing(scene, traced.as_deref(), preset)?;
    world.set_transport(job.settings.transport, job.settings.bounces);
    world.set_emitters(job.settings.emitters, job.settings.emitter_selection);
    report.seconds.build_bvh = clock.elapsed().as_secs_f64();
    report.lights = world.lights().len();
    report.emitters = world.emitters().map_or(0, |e| e.len());
    report.texture_bytes = scene.texture_bytes();

    let passes = job.settings.last_pass();
    let record = bake_record(job, &texels, scene);
    let bake_id = job.settings.bake_id(record_id(&record));
    let dir = work_dir(&job.out, job.shard);
    let manifest = Manifest {
        texels: std::path::absolute(&job.texels).unwrap_or_else(|_| job.texels.clone()),
        bake_id,
        shard_index: job.shard.index,
        shard_count: job.shard.count,
        bias_correction: job.settings.bias_correction,
        aux: job.aux,
        passes,
        first_pass: job.settings.first_pass(),
        combine_global: job.settings.combine == Combine::Global,
        iterations: job.settings.iterations,
        directional: job.settings.directional == Directional::ShL1,
        direct_apart: job.settings.lightmap_borrows_direct(),
        settings: format!("{:?}", job.settings),
        record: Some(record),
    };
    open_work(&dir, &manifest, job.resume, only_pass)?;
    let pass_texels = shard_texels(&texels, job.shard);
    let mut now = Progress {
        texels_total: pass_texels * u64::from(run_passes.end() + 1 - run_passes.start()),
        ..Default::default()
    };
    let clock = Instant::now();
    // The pass images' table of triangles, made by the first image the run builds.
    let triangle_uvs = std::cell::OnceCell::new();
    for pass in run_passes.clone() {
        if pass > job.settings.first_pass() {
            // A one-pass run reads the merged previous pass; a run of every pass its own.
            let results_of = |b: u32| match only_pass {
                Some(_) => merged_results(&job.out, b),
                None => pass_files(&dir, b).0,
            };
            // A pass that borrowed the direct pass's light gets it back in its image.
            let paths = |b: u32| {
                let direct = job
                    .settings
                    .borrows_direct(b)
                    .then(|| results_of(DIRECT_PASS));
                (results_of(b), direct)
            };
            let image_of = |b: u32, report: &mut BakeReport| {
                let (source, direct) = paths(b);
                let sources = PassSources {
                    results: &source,
                    direct: direct.as_deref(),
                };
                let image = pass_image(&dir, b);
                let target = PassImage {
                    path: &image,
                    filter: lookup_filter(&job.settings, b),
                    triangles: triangle_uvs
                        .get_or_init(|| TriangleUvs::new(scene, texels.triangles())),
                };
                previous_pass(&texels, sources, target, bake_id, job.threads, report)
                    .map(|p| p.of_pass(b))
                    .map_err(|e| not_merged_hint(e, &source, b))
            };
            // Memory holds two pass images: the previous pass's, and the one before it, read
            // one bounce beyond the gather's hits near their origin (`NEAR_PATH_TEXELS`). The
            // previous pass's image becomes the earlier one; each is rebuilt from its result
            // file where the run has none (a resumed run, a run of one pass).
            let (kept, _) = world.take_pass_images();
            if let Some(oldest) = pass.checked_sub(3) {
                let _ = std::fs::remove_file(pass_image(&dir, oldest));
            }
            let previous = image_of(pass - 1, &mut report)?;
            let earlier = match pass.checked_sub(2) {
                Some(b) if kept.as_ref().is_some_and(|k| k.pass() == b) => kept,
                Some(b) => Some(image_of(b, &mut report)?),
                None => None,
            };
            world.set_previous_pass(Some(previous));
            world.set_earlier_pass(earlier);
            let (source, direct) = paths(pass - 1);
            let sources = PassSources {
                results: &source,
                direct: direct.as_deref(),
            };
            // The last pass's clusters start from the guide seeds the pass before kept in its
            // results (docs/guiding-levers.md, "The seed guide").
            world.set_guide_seeds(None);
            if job.settings.reads_guide_seeds(pass) {
                let (results, _) = sources.open(&texels, bake_id)?;
                world.set_guide_seeds(Some(FinishedResults::new(&results)?));
            }
            // The last pass, after a gather pass, spends its samples by the passes' error (a
            // budgeted middle pass makes the last one's lookups noisier: docs/estimator.md).
            // Its noise holds the direct light's only when it estimates that light itself.
            world.set_budget(None);
            if pass - 1 > DIRECT_PASS && pass == job.settings.last_pass() {
                let sources = PassSources {
                    direct: sources
                        .direct
                        .filter(|_| !job.settings.lightmap_borrows_direct()),
                    ..sources
                };
                world.set_budget(spatial_budget(
                    &texels,
                    job.settings.budget,
                    sources,
                    bake_id,
                )?);
            }
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
        // The finish (dilation, EXR, preview) runs on --threads threads, as the gather does.
        let finish = || finish_with(&texels, std::slice::from_ref(&dir), &job.out, job.finish);
        let written = match rayon::ThreadPoolBuilder::new()
            .num_threads(job.threads.max(1))
            .thread_name(|i| format!("guidebake-finish-{i}"))
            .build()
        {
            Ok(pool) => pool.install(finish),
            Err(_) => finish(),
        }?;
        report.seconds.write_pages = clock.elapsed().as_secs_f64();
        report.rho = written.rho;
        report.pages = written.pages;
        report.non_finite_pixels = written.non_finite_pixels;
        report.seam_jump = written.seam_jump;
        report.edge_jump = written.edge_jump;
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
    let (first, passes) = (job.settings.first_pass(), job.settings.last_pass());
    match only_pass {
        Some(b) if b < first || b > passes => {
            Err(BakeError::Settings(SettingsError::new(format!(
                "--pass {b}: this bake has passes {first}..={passes} (--transport series makes pass \
             0 of the direct light and one pass per bounce, other transports one pass)"
            ))))
        }
        Some(b) => Ok(b..=b),
        None if job.shard.count > 1 && passes > first => {
            Err(BakeError::Settings(SettingsError::new(format!(
                "--shard {}/{} with --transport series --bounces {passes}: each series pass needs \
                 the whole previous pass, so shard the passes one by one: `bake --pass B --shard \
                 {}/{}` for B = {first}..={passes}, each pass followed by `merge --pass B` over \
                 its shards (docs/farm.md)",
                job.shard.index, job.shard.count, job.shard.index, job.shard.count
            ))))
        }
        None => Ok(first..=passes),
    }
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

/// Every tile's texel count, in file order: what [`tiles_to_bake`] splits the world by.
fn texel_counts(texels: &TexelFile) -> impl Iterator<Item = u32> + Clone + '_ {
    texels.tiles().iter().map(|t| t.texel_count)
}

/// Texels in the tiles of `shard`.
fn shard_texels(texels: &TexelFile, shard: Shard) -> u64 {
    tiles_to_bake(texel_counts(texels), shard, &HashSet::new())
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
    let last = pass == job.settings.last_pass();
    let batches = (job.settings.combine == Combine::Global && last)
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
    // So do the directional coefficients, when kept (one per texel, or the K iterations'
    // means for global weights).
    let directional = (job.settings.directional == Directional::ShL1 && last)
        .then(|| {
            let per_texel = if job.settings.combine == Combine::Global {
                job.settings.iterations
            } else {
                1
            };
            open_directional(
                dir,
                bake_id,
                texels.header().texel_count,
                per_texel,
                !done.is_empty(),
            )
        })
        .transpose()?;
    let todo = tiles_to_bake(
        texel_counts(texels),
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
        baker: TileBaker::new(world, job.settings.for_pass(pass))
            .keep_directional(last)
            .direct_only(pass == DIRECT_PASS)
            .texel_direct(!job.settings.borrows_direct(pass))
            .writes_guide_seeds(job.settings.writes_guide_seeds(pass)),
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
            directional: directional.as_ref(),
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

/// The result files a previous-pass image is built from: the pass's, and the direct pass's
/// when the pass borrowed its direct light ([`BakeSettings::borrows_direct`]).
#[derive(Clone, Copy)]
struct PassSources<'p> {
    results: &'p Path,
    direct: Option<&'p Path>,
}

impl PassSources<'_> {
    /// The pass's result file and the direct pass's, opened for `texels`' bake `bake_id`.
    fn open(
        self,
        texels: &TexelFile,
        bake_id: u64,
    ) -> Result<(ResultFile, Option<ResultFile>), BakeError> {
        let open = |path: &Path| {
            ResultFile::open(path, false, Some((texels.header().texel_count, bake_id)))
                .map(|(results, _)| results)
        };
        Ok((open(self.results)?, self.direct.map(open).transpose()?))
    }
}

/// Where a pass image goes, and the radius its gathered light is filtered over (0: none;
/// [`BakeSettings::lookup_filter`]).
#[derive(Clone, Copy)]
struct PassImage<'p> {
    path: &'p Path,
    filter: u32,
    /// Each triangle's lightmap corners: one table for every image of the bake.
    triangles: &'p TriangleUvs,
}

/// The filter a pass image of pass `pass` is built with: the lookups of a gather pass are
/// filtered; the direct pass's light is not.
fn lookup_filter(settings: &BakeSettings, pass: u32) -> u32 {
    if settings.filters_lookups(pass) {
        settings.lookup_filter
    } else {
        0
    }
}

/// Builds the image (at `target`) of the gather-only and total irradiance in a pass's result
/// file (plus the direct pass's total, when the pass borrowed it), its gathered light filtered
/// when `target` asks, and which side of each triangle its texels bake, and maps it for the
/// next pass (series transport). Tile by tile on `threads` threads, the same bytes on any
/// number ([`PreviousPass::build`]).
fn previous_pass(
    texels: &TexelFile,
    sources: PassSources<'_>,
    target: PassImage<'_>,
    bake_id: u64,
    threads: usize,
    report: &mut BakeReport,
) -> Result<PreviousPass, BakeError> {
    let clock = Instant::now();
    let (results, direct) = sources.open(texels, bake_id)?;
    let source = ResultTiles {
        texels,
        results: &results,
        direct: direct.as_ref(),
        filter: target.filter > 0,
    };
    let build = || {
        PreviousPass::build(
            target.path,
            texels.pages(),
            &source,
            target.filter,
            target.triangles,
        )
    };
    let built = match rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .thread_name(|i| format!("guidebake-pass-image-{i}"))
        .build()
    {
        Ok(pool) => pool.install(build),
        Err(_) => build(),
    };
    let previous = built.map_err(|e| match e {
        BuildError::Image(e) => file_error(&e.path, e.what),
        BuildError::Source(e) => e,
    })?;
    report.seconds.previous_pass_images += clock.elapsed().as_secs_f64();
    report.pass_image_bytes = report.pass_image_bytes.max(previous.bytes());
    report.filter_window_bytes = report
        .filter_window_bytes
        .max(previous.filter_window_bytes());
    Ok(previous)
}

/// A pass's results, tile by tile of the texel file, as a pass image's source: each baked
/// texel's gather-only layer and its total (with the direct pass's, where the pass borrowed
/// it), and the texels inside geometry.
struct ResultTiles<'a> {
    texels: &'a TexelFile,
    results: &'a ResultFile,
    direct: Option<&'a ResultFile>,
    /// Whether the lookups' filter needs each texel's surfel.
    filter: bool,
}

impl Source for ResultTiles<'_> {
    type Error = BakeError;

    fn tile_count(&self) -> usize {
        self.texels.tiles().len()
    }

    fn rect(&self, tile: usize) -> TileRect {
        let t = &self.texels.tiles()[tile];
        TileRect {
            page: t.page,
            x: t.x,
            y: t.y,
            width: t.width,
            height: t.height,
        }
    }

    fn bounds(&self) -> (u64, u64) {
        let cells = |from: u32, len: u32| u64::from((from + len).div_ceil(CELL) - from / CELL);
        let blocks = self
            .texels
            .tiles()
            .iter()
            .map(|t| cells(t.x, t.width) * cells(t.y, t.height))
            .sum();
        (blocks, self.texels.header().texel_count)
    }

    fn read_tile(&self, tile: usize, out: &mut Vec<SourceTexel>) -> Result<u32, BakeError> {
        let record = &self.texels.tiles()[tile];
        let n = record.texel_count as usize;
        let mut results = vec![TexelResult::default(); n];
        self.results.read(record.first_texel, &mut results)?;
        let mut direct = vec![TexelResult::default(); n];
        if let Some(d) = self.direct {
            d.read(record.first_texel, &mut direct)?;
        }
        out.clear();
        let tile_texels = self.texels.tile_texels(tile).iter().zip(&results);
        for ((texel, r), d) in tile_texels.zip(&direct) {
            let baked = r.flags & FLAG_BAKED != 0;
            let inside = !baked && texel.flags & FLAG_INSIDE != 0;
            if !baked && !inside {
                continue;
            }
            let surfel = (baked && self.filter)
                .then(|| {
                    let (position, normal) = (texel.position(), texel.normal());
                    Surfel::new(
                        position,
                        normal,
                        texel.spacing(),
                        r.gathered,
                        r.rel_std_error,
                    )
                })
                .flatten();
            out.push(SourceTexel {
                pixel: (u32::from(texel.pixel[0]), u32::from(texel.pixel[1])),
                baked,
                filled: false,
                inside,
                gathered: r.gathered,
                total: core::array::from_fn(|c| r.total[c] + d.total[c]),
                surfel,
            });
        }
        self.texels.release_tile(tile);
        Ok(record.page)
    }
}

/// The spatial budget of a pass after `sources`' gather pass ([`SpatialBudget`]).
fn spatial_budget(
    texels: &TexelFile,
    budget: Budget,
    sources: PassSources<'_>,
    bake_id: u64,
) -> Result<Option<SpatialBudget>, BakeError> {
    if budget == Budget::Uniform {
        return Ok(None);
    }
    let (results, direct) = sources.open(texels, bake_id)?;
    Ok(SpatialBudget::from_results(
        budget,
        texels,
        &results,
        direct.as_ref(),
    )?)
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

/// The BVH preset for this run: by the rays it will trace (its texels × samples × passes ×
/// [`RAYS_PER_SAMPLE`]) against the world's triangles ([`Preset::for_rays`]).
fn run_preset(
    job: &BakeJob,
    texels: &TexelFile,
    scene: &Scene,
    passes: &std::ops::RangeInclusive<u32>,
) -> Preset {
    let samples = shard_texels(texels, job.shard) as f64 * f64::from(job.settings.spp);
    let passes = f64::from(passes.end() + 1 - passes.start());
    Preset::for_rays(scene.triangles.len(), samples * passes * RAYS_PER_SAMPLE)
}

/// Rays a gather sample traces, about: its gather ray and a shadow ray (series and path
/// transport both trace at least these two; path tracing traces more).
const RAYS_PER_SAMPLE: f64 = 2.0;

/// Whether the texel file records the lights it was prepared under
/// ([`Scene::lighting_fingerprint`]) and they are not `scene`'s: `prepare` decided which
/// sides are seen, and which texels lie inside geometry, under those lights.
#[must_use]
pub fn lights_differ(header: &crate::texels::Header, scene: &Scene) -> bool {
    header.lighting != 0 && header.lighting != scene.lighting_fingerprint()
}

/// The texel file must have been prepared from `scene`: the same triangles, at the same
/// positions ([`Scene::geometry_fingerprint`], recorded in the header). Their lightmap UVs
/// come from the file's triangle table, so the scene's own UV sets (or their absence, on a
/// scene `prepare --unwrap` gave UVs) do not matter.
fn check_scene_matches(texels: &TexelFile, scene: &Scene) -> Result<(), BakeError> {
    let header = texels.header();
    match scene.geometry_differs(header.triangle_count as usize, header.geometry) {
        None => Ok(()),
        Some(what) => Err(BakeError::Mismatch(format!(
            "{}: the texel file was prepared from {what}; run `guidebake prepare` again or give \
             the scene it was prepared from",
            texels.path().display(),
        ))),
    }
}
