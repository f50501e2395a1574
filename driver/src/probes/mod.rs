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
//!
//! [`bake_probes`] runs them in order: placement, then the clusters in batches on every core,
//! each batch's records written in file order as it completes (what is held is the probes'
//! positions, one batch's results and the coarse grid's SH), then the volume. Every random
//! number derives from (seed, probe id, iteration, sample): the file is the same bytes on any
//! thread count.

pub mod field;
pub mod file;
pub mod gather;
pub mod placement;
pub mod sh;
pub mod view;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use self::file::{FLAG_DERINGED, FLAG_GUIDED, FLAG_PATH, ProbeHeader, ProbeRecord, ProbeWriter};
use self::gather::{GatherCount, GatherSettings, ProbeTransport, gather_cluster};
use self::placement::{PlacementReport, PlacementSettings, place};
use crate::bake::settings::Transport;
use crate::bvh::Preset;
use crate::render::Lightmap;
use crate::scene::Scene;
use crate::texels::{SEEN_BACK, SEEN_FRONT, TexelFile};
use crate::transport::world::World;

/// Clusters gathered between two writes of the probe file.
const BATCH_CLUSTERS: usize = 256;

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
    /// Rays of the inside-geometry test.
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
    /// Ctrl-C: nothing was published.
    #[error("stopped: the probe file was not written")]
    Interrupted,
}

/// Places and bakes the probes of the level `texels` was prepared from, writes them to
/// `out` (and the volume beside it), and reports what it did. `lightmap` is what gather hits
/// read under [`ProbeTransport::Lightmap`]; without one they trace paths.
///
/// # Errors
/// [`ProbeError`]: a spacing the level cannot take, a file that cannot be written, Ctrl-C.
/// Nothing is left behind on failure.
pub fn bake_probes(
    scene: &Scene,
    texels: &TexelFile,
    lightmap: Option<&Lightmap>,
    out: &Path,
    settings: &ProbeSettings,
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
    let header = ProbeHeader {
        flags: if settings.dering { FLAG_DERINGED } else { 0 }
            | if gather.transport == ProbeTransport::Path {
                FLAG_PATH
            } else {
                0
            }
            | if gather.guiding && gather.iterations > 1 {
                FLAG_GUIDED
            } else {
                0
            },
        spp: gather.schedule().iter().sum(),
        fine_spacing: placement.grid.fine,
        coarse_spacing: placement.grid.spacing(),
        seed: gather.seed,
    };
    let mut writer = ProbeWriter::create(out, header).map_err(ProbeError::Write)?;
    let clusters: Vec<_> = placement.clusters().collect();
    report.clusters = clusters.len() as u64;
    let mut errors = Vec::with_capacity(placement.probes.len());
    let mut coarse_sh = settings.volume.then(Vec::new);
    let mut count = GatherCount::default();
    for batch in clusters.chunks(BATCH_CLUSTERS) {
        if cancel.load(Ordering::Relaxed) {
            writer.abandon();
            return Err(ProbeError::Interrupted);
        }
        let done: Vec<_> = batch
            .par_iter()
            .map(|range| {
                let positions: Vec<_> = placement.probes[range.clone()]
                    .iter()
                    .map(|p| p.position)
                    .collect();
                gather_cluster(&world, lightmap, &positions, range.start as u64, &gather)
            })
            .collect();
        for (range, (lights, c)) in batch.iter().zip(done) {
            count.add(&c);
            for (probe, light) in placement.probes[range.clone()].iter().zip(lights) {
                let sh = if settings.dering {
                    light.sh.deringed()
                } else {
                    light.sh
                };
                let record = ProbeRecord {
                    position: probe.position,
                    spacing: probe.spacing,
                    relative_error: light.relative_error,
                    sh,
                };
                if let Err(e) = writer.push(&record) {
                    writer.abandon();
                    return Err(ProbeError::Write(e));
                }
                errors.push(light.relative_error);
                if let (Some(v), Some(point)) = (coarse_sh.as_mut(), probe.coarse_point()) {
                    v.push((point, sh));
                }
            }
        }
    }
    writer.finish().map_err(ProbeError::Write)?;
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

fn record_placement(report: &mut ProbeReport, p: &PlacementReport) {
    report.lattice_candidates = p.lattice_candidates;
    report.listed_candidates = p.listed_candidates;
    report.probes = p.placed;
    report.skipped_inside_geometry = p.inside_geometry;
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
