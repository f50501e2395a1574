//! Light probes: the light a dynamic object (a character walking through the level) needs,
//! baked beside the lightmap with the same guided gather (docs/probes.md).
//!
//! - [`placement`]: where probes go — an adaptive lattice, fine near geometry, none inside it;
//!   probes a user lists; clusters of nearby probes.
//! - [`gather`]: each cluster's probes gather incident radiance over the sphere — one
//!   stratified set by default, or through one learned guide (paper §2.1–2.5 on the sphere) —
//!   with next-event estimation of the sun, the analytic lights and the emitters, hits reading
//!   the lightmap (or paths).
//! - [`sh`]: L2 spherical harmonics, their convention, irradiance and de-ringing.
//! - [`file`]: the probe file an engine reads, and the volume textures of the coarse grid.
//! - [`field`]: probes interpolated at any point, as an engine does.
//! - [`view`]: `render`'s probes and its lit test sphere.
//! - [`work`]: the work directory that keeps each finished batch, so that `--resume`
//!   continues a stopped bake, and the shards' (`--shard`, `--merge`).
//!
//! [`bake_probes`] runs them in order: placement, then the clusters in batches on every core,
//! each batch kept in the work directory as it completes (what is held is the probes'
//! positions, one batch's results and the coarse grid's SH), then the probe file assembled
//! from the batches in file order, then the volume. Every random number derives from (seed,
//! probe id, iteration, sample): the file is the same bytes on any thread count, a bake
//! stopped and resumed writes the same bytes as one never stopped, and N shards merged the
//! same bytes as one process.

pub mod field;
pub mod file;
pub mod gather;
pub mod placement;
pub mod sh;
pub mod view;
pub mod work;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use self::file::{FLAG_DERINGED, FLAG_GUIDED, FLAG_PATH, ProbeHeader, ProbeRecord, ProbeWriter};
use self::gather::{GatherCount, GatherSettings, ProbeTransport, gather_cluster};
use self::placement::{CoarseGrid, Placement, PlacementReport, PlacementSettings, place};
use self::sh::Sh9;
use self::work::{Batch, ProbeWork};
use crate::bake::settings::Transport;
use crate::bake::shard::Shard;
use crate::bake::workdir::BakeRecord;
use crate::bvh::Preset;
use crate::render::Lightmap;
use crate::scene::Scene;
use crate::texels::{SEEN_BACK, SEEN_FRONT, TexelFile};
use crate::transport::world::World;

/// Clusters a batch: gathered on every core together, then kept in the work directory.
pub const BATCH_CLUSTERS: usize = 256;

/// Everything a probe bake is told.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProbeSettings {
    /// Where probes go.
    pub placement: PlacementSettings,
    /// How they gather.
    pub gather: GatherSettings,
    /// Path vertices under `path` transport (and where the lightmap has nothing).
    pub bounces: u32,
    /// De-ring the SH before they are written.
    pub dering: bool,
    /// Write the coarse grid's volume textures beside the probe file.
    pub volume: bool,
}

/// What a probe bake did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ProbeReport {
    /// Lattice points considered.
    pub lattice_candidates: u64,
    /// Listed points considered (`--probe-points`).
    pub listed_candidates: u64,
    /// Probes placed and baked.
    pub probes: u64,
    /// Candidates skipped because they lie inside geometry.
    pub skipped_inside_geometry: u64,
    /// Clusters (guides learned).
    pub clusters: u64,
    /// Lattice cells cut because the direct light changes across them (`--refine light`).
    pub cells_cut_for_light: u64,
    /// Rays of placement: the inside-geometry test and the light's test.
    pub placement_rays: u64,
    /// Gather rays.
    pub gather_rays: u64,
    /// Shadow rays.
    pub shadow_rays: u64,
    /// Path continuation rays.
    pub path_rays: u64,
    /// Gather hits whose light was read from the lightmap.
    pub lightmap_reads: u64,
    /// Non-finite samples rejected.
    pub rejected_samples: u64,
    /// The median of the probes' relative standard errors (band-0 luminance).
    pub median_relative_error: f32,
    /// Seconds building the BVH, placing, gathering (and writing), writing the volume.
    pub seconds: ProbeSeconds,
    /// The files written.
    pub files: Vec<PathBuf>,
    /// Batches a stopped bake had finished (`--resume`); not in the stats, which are the
    /// same for a resumed bake as for one never stopped.
    #[serde(skip)]
    pub batches_resumed: u64,
}

/// Where a probe bake's time went.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ProbeSeconds {
    /// The BVH.
    pub build_bvh: f64,
    /// Placement, the inside-geometry test included.
    pub placement: f64,
    /// The gather, the probe file's writes included.
    pub gather: f64,
    /// The volume textures.
    pub volume: f64,
    /// All of it.
    pub total: f64,
}

/// Why a probe bake failed.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    /// The settings or the level cannot be baked (the message says why).
    #[error("{0}")]
    Invalid(String),
    /// A file could not be written (the message names it).
    #[error("{0}")]
    Write(String),
    /// The BVH could not be built.
    #[error(transparent)]
    Bvh(#[from] crate::bvh::BvhError),
    /// The work directory is another bake's, or is there without `--resume`; a merge's shards
    /// are not all of this bake, not all given, or not finished (the message names it).
    #[error("{0}")]
    Work(String),
    /// Ctrl-C (or the test hook [`WorkOptions::stop_after`]): the finished batches are kept.
    #[error(
        "interrupted after {done} of {total} batches; the work is kept in {}: run the same command with --resume to finish",
        dir.display()
    )]
    Interrupted {
        /// Batches in the work directory.
        done: u64,
        /// Batches in all.
        total: u64,
        /// The work directory.
        dir: PathBuf,
    },
}

/// How a probe bake keeps its work: the work directory (`--resume`, [`work`]).
#[derive(Clone, Debug)]
pub struct WorkOptions {
    /// Continue the work directory a stopped bake left, if it is this bake's.
    pub resume: bool,
    /// The texel file's path, for messages.
    pub texels: PathBuf,
    /// What the bake is made of ([`work::options`], [`BakeRecord::new`]).
    pub record: BakeRecord,
    /// Clusters a batch ([`BATCH_CLUSTERS`]).
    pub batch_clusters: usize,
    /// Stop as Ctrl-C does once this run has baked this many batches (tests).
    pub stop_after: Option<usize>,
    /// Bake only this shard's batches into its own work directory, and write no probe file
    /// (`--shard K/N`; [`work::owned`]).
    pub shard: Option<Shard>,
    /// Bake nothing: assemble the probe file from these shards' work directories
    /// (`--merge`).
    pub merge: Vec<PathBuf>,
}

/// Places and bakes the probes of the level `texels` was prepared from, writes them to
/// `out` (and the volume beside it), and reports what it did. `lightmap` is what gather hits
/// read under [`ProbeTransport::Lightmap`]; without one they trace paths. Each batch of
/// clusters is kept in the work directory as it finishes ([`work`]); the caller removes it
/// ([`work::retire`]) once it has written the stats. Under [`WorkOptions::shard`] only the
/// shard's batches are baked and nothing is written at `out`; under [`WorkOptions::merge`]
/// nothing is baked and the file is assembled from the shards' batches.
///
/// # Errors
/// [`ProbeError`]: a spacing the level cannot take, a work directory of another bake, a file
/// that cannot be written, Ctrl-C (the finished batches are kept). Nothing is left at `out`
/// on failure.
pub fn bake_probes(
    scene: &Scene,
    texels: &TexelFile,
    lightmap: Option<&Lightmap>,
    out: &Path,
    settings: &ProbeSettings,
    options: &WorkOptions,
    cancel: &AtomicBool,
) -> Result<ProbeReport, ProbeError> {
    let all = Instant::now();
    let mut report = ProbeReport::default();
    let clock = Instant::now();
    let records = texels.triangles();
    let traced = crate::scene::ids_where(records.len(), |t| records[t].role().traced());
    let corners = scene.triangle_positions();
    let mut world = World::tracing(scene, traced.as_deref(), Preset::DEFAULT)?;
    world.set_transport(Transport::Path, settings.bounces.max(1));
    report.seconds.build_bvh = clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    let sides: Vec<u32> = records
        .iter()
        .map(|t| t.flags & (SEEN_FRONT | SEEN_BACK))
        .collect();
    let placement = place(
        &world,
        &corners,
        traced.as_deref().unwrap_or_default(),
        &sides,
        &settings.placement,
    )
    .map_err(ProbeError::Invalid)?;
    if placement.probes.is_empty() {
        return Err(ProbeError::Invalid(format!(
            "no probe could be placed: all {} candidates lie inside geometry (are the texel file's seen sides right? docs/probes.md)",
            placement.report.lattice_candidates + placement.report.listed_candidates
        )));
    }
    record_placement(&mut report, &placement.report);
    report.seconds.placement = clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    let mut gather = settings.gather;
    if lightmap.is_none() {
        gather.transport = ProbeTransport::Path;
    }
    let clusters: Vec<_> = placement.clusters().collect();
    report.clusters = clusters.len() as u64;
    let batches: Vec<_> = clusters.chunks(options.batch_clusters.max(1)).collect();
    let counts = (report.probes, report.clusters, batches.len() as u64);
    let work = open_work(out, options, counts)?;
    let baker = Baker {
        world: &world,
        lightmap,
        placement: &placement,
        gather: &gather,
        dering: settings.dering,
    };
    report.batches_resumed = baker.bake_missing(&work, &batches, options, cancel)?;
    if options.shard.is_some() {
        report.seconds.gather = clock.elapsed().as_secs_f64();
        report.seconds.total = all.elapsed().as_secs_f64();
        return Ok(report);
    }
    let header = probe_header(settings, &gather, &placement.grid);
    let (count, mut errors, coarse_sh) =
        baker.assemble(&work, &batches, out, header, settings.volume)?;
    report.files.push(out.to_owned());
    record_gather(&mut report, &count, &mut errors);
    report.seconds.gather = clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    if let Some(sh) = coarse_sh {
        let values = file::coarse_values(&placement.grid, &sh);
        match file::write_volume(out, &placement.grid, &values) {
            Ok(paths) => report.files.extend(paths),
            Err(e) => {
                let _ = std::fs::remove_file(out);
                return Err(ProbeError::Write(e));
            }
        }
    }
    report.seconds.volume = clock.elapsed().as_secs_f64();
    report.seconds.total = all.elapsed().as_secs_f64();
    Ok(report)
}

/// The work directory of this bake (or shard), or the shards' for a merge, checked against
/// the bake `options` describes, which places `counts` (probes, clusters, batches).
fn open_work(
    out: &Path,
    options: &WorkOptions,
    counts: (u64, u64, u64),
) -> Result<ProbeWork, ProbeError> {
    let manifest = work::ProbeManifest::new(
        &options.texels,
        options.record.clone(),
        counts,
        options.shard,
    );
    if options.merge.is_empty() {
        let dir = work::work_dir(out, options.shard);
        work::open(&dir, &manifest, options.resume)
    } else {
        work::open_merge(&options.merge, &manifest)
    }
    .map_err(ProbeError::Work)
}

/// The probe file's header for a bake of `settings` gathering with `gather`.
fn probe_header(
    settings: &ProbeSettings,
    gather: &GatherSettings,
    grid: &CoarseGrid,
) -> ProbeHeader {
    let flag = |on: bool, f: u32| if on { f } else { 0 };
    ProbeHeader {
        flags: flag(settings.dering, FLAG_DERINGED)
            | flag(gather.transport == ProbeTransport::Path, FLAG_PATH)
            | flag(gather.guiding && gather.iterations > 1, FLAG_GUIDED),
        spp: gather.schedule().iter().sum(),
        fine_spacing: grid.fine,
        coarse_spacing: grid.spacing(),
        seed: gather.seed,
    }
}

/// What bakes a batch of clusters: the world, the lightmap, the probes, the gather.
struct Baker<'a> {
    world: &'a World,
    lightmap: Option<&'a Lightmap>,
    placement: &'a Placement,
    gather: &'a GatherSettings,
    dering: bool,
}

/// The clusters of a batch, as probe index ranges.
type Clusters = [std::ops::Range<usize>];

impl Baker<'_> {
    /// The positions of a batch's probes, in file order.
    fn positions(&self, batch: &Clusters) -> Vec<glam::Vec3> {
        batch
            .iter()
            .flat_map(|r| self.placement.probes[r.clone()].iter().map(|p| p.position))
            .collect()
    }

    /// Gathers a batch's clusters on every core; its records in file order.
    fn bake(&self, batch: &Clusters) -> Batch {
        let done: Vec<_> = batch
            .par_iter()
            .map(|range| {
                let positions: Vec<_> = self.placement.probes[range.clone()]
                    .iter()
                    .map(|p| p.position)
                    .collect();
                gather_cluster(
                    self.world,
                    self.lightmap,
                    &positions,
                    range.start as u64,
                    self.gather,
                )
            })
            .collect();
        let mut out = Batch::default();
        for (range, (lights, c)) in batch.iter().zip(done) {
            out.count.add(&c);
            for (probe, light) in self.placement.probes[range.clone()].iter().zip(lights) {
                out.records.push(ProbeRecord {
                    position: probe.position,
                    spacing: probe.spacing,
                    relative_error: light.relative_error,
                    sh: if self.dering {
                        light.sh.deringed()
                    } else {
                        light.sh
                    },
                });
            }
        }
        out
    }

    /// Bakes and keeps every batch (of the shard's, under `--shard`) the work directory
    /// lacks, in order; how many it had. Stops between batches on `cancel` (or after
    /// `options.stop_after` batches). A merge bakes nothing: a batch no shard holds is an
    /// error.
    fn bake_missing(
        &self,
        work: &ProbeWork,
        batches: &[&Clusters],
        options: &WorkOptions,
        cancel: &AtomicBool,
    ) -> Result<u64, ProbeError> {
        let (mut resumed, mut baked) = (0, 0);
        let mine = work::owned(options.shard, batches.len());
        for i in mine.clone() {
            if work.read(i, &self.positions(batches[i])).is_some() {
                resumed += 1;
                continue;
            }
            if !options.merge.is_empty() {
                return Err(ProbeError::Work(format!(
                    "batch {i} of {} is in none of the shards' work directories given ({}): finish the shard that bakes it (--resume) before merging",
                    batches.len(),
                    work::list(&options.merge)
                )));
            }
            if cancel.load(Ordering::Relaxed) || options.stop_after == Some(baked) {
                return Err(ProbeError::Interrupted {
                    done: (resumed + baked) as u64,
                    total: mine.len() as u64,
                    dir: work.dir().to_owned(),
                });
            }
            work.write(i, &self.bake(batches[i]))
                .map_err(ProbeError::Write)?;
            baked += 1;
        }
        Ok(resumed as u64)
    }

    /// Writes the probe file from the kept batches, in file order; what they counted, the
    /// probes' relative errors, and (with `volume`) the coarse grid's SH.
    fn assemble(
        &self,
        work: &ProbeWork,
        batches: &[&Clusters],
        out: &Path,
        header: ProbeHeader,
        volume: bool,
    ) -> Result<Assembled, ProbeError> {
        let mut writer = ProbeWriter::create(out, header).map_err(ProbeError::Write)?;
        let mut count = GatherCount::default();
        let mut errors = Vec::with_capacity(self.placement.probes.len());
        let mut coarse_sh = volume.then(Vec::new);
        for (i, batch) in batches.iter().enumerate() {
            let Some(done) = work.read(i, &self.positions(batch)) else {
                writer.abandon();
                return Err(ProbeError::Write(format!(
                    "{}: batch {i} vanished from the work directory while the probe file was written",
                    work.dir().display()
                )));
            };
            count.add(&done.count);
            let probes = batch.iter().flat_map(|r| &self.placement.probes[r.clone()]);
            for (probe, record) in probes.zip(&done.records) {
                if let Err(e) = writer.push(record) {
                    writer.abandon();
                    return Err(ProbeError::Write(e));
                }
                errors.push(record.relative_error);
                if let (Some(v), Some(point)) = (coarse_sh.as_mut(), probe.coarse_point()) {
                    v.push((point, record.sh));
                }
            }
        }
        writer.finish().map_err(ProbeError::Write)?;
        Ok((count, errors, coarse_sh))
    }
}

/// What [`Baker::assemble`] returns: the counts, the relative errors, the coarse grid's SH.
type Assembled = (GatherCount, Vec<f32>, Option<Vec<([u32; 3], Sh9)>>);

fn record_placement(report: &mut ProbeReport, p: &PlacementReport) {
    report.lattice_candidates = p.lattice_candidates;
    report.listed_candidates = p.listed_candidates;
    report.probes = p.placed;
    report.skipped_inside_geometry = p.inside_geometry;
    report.cells_cut_for_light = p.cells_cut_for_light;
    report.placement_rays = p.rays;
}

fn record_gather(report: &mut ProbeReport, c: &GatherCount, errors: &mut [f32]) {
    report.gather_rays = c.gather_rays;
    report.shadow_rays = c.shadow_rays;
    report.path_rays = c.path_rays;
    report.lightmap_reads = c.lightmap_reads;
    report.rejected_samples = c.rejected;
    errors.sort_by(f32::total_cmp);
    report.median_relative_error = errors.get(errors.len() / 2).copied().unwrap_or(0.0);
}
