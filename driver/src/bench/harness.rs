//! The measuring loops: every method at every sample count and seed (the ladder), and the
//! interleaved equal-sample runs of the Figure-5 overhead.
//!
//! Each measurement is one whole `guidebake bake` as a user runs it — open the texel file,
//! build the BVH, gather, apply ρ, write the EXR pages — timed by the wall clock around it,
//! with the bake's own time per phase beside it. The pages are then read back at every valid
//! texel and deleted.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use clap::ValueEnum;
use serde::Serialize;

use super::BenchError;
use super::method::{Method, serialize_value_name, value_name};
use super::metrics::{ErrorStats, compare};
use crate::bake::finish::FinishOptions;
use crate::bake::run::{BakeJob, BakeReport, bake};
use crate::bake::settings::{BakeSettings, EmitterSampling, Guiding, Transport};
use crate::bake::shard::Shard;
use crate::bake::workdir::work_dir;
use crate::output::readback::read_lightmap;
use crate::scene::Scene;
use crate::texels::TexelFile;
use crate::transport::emitters::EmitterSelection;

/// What the loops need: the scene, its texels, where to bake, how many threads.
pub struct Bench<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The texel file's path.
    pub texels_path: &'a Path,
    /// The texel file, open for reading back.
    pub texels: &'a TexelFile,
    /// A scratch directory for the runs' lightmaps.
    pub scratch: PathBuf,
    /// Worker threads of every measured bake.
    pub threads: usize,
    /// Worker threads of the reference bakes ([`BenchConfig::reference_threads`]).
    ///
    /// [`BenchConfig::reference_threads`]: super::BenchConfig::reference_threads
    pub reference_threads: usize,
    /// Emitter sampling of the measured bakes ([`Self::bake_scratch`]).
    pub light: LightSampling,
    /// Ctrl-C.
    pub cancel: &'a AtomicBool,
}

/// How a bake lights emissive triangles: the bake's `--emitters` and
/// `--emitter-selection`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LightSampling {
    /// Next-event estimation, hits, or both with MIS.
    pub emitters: EmitterSampling,
    /// How next-event estimation picks an emitter.
    pub selection: EmitterSelection,
}

/// One bake as measured.
#[derive(Clone, Debug)]
pub struct Baked {
    /// Wall-clock seconds of the whole bake.
    pub wall_s: f64,
    /// CPU seconds of the whole bake, every thread (user + system): on a machine shared
    /// with other work this moves far less than the wall time.
    pub cpu_s: f64,
    /// The bake's own report (phases, rays, ρ).
    pub report: BakeReport,
    /// The lightmap read back, per texel id.
    pub values: Vec<Option<[f32; 3]>>,
}

impl Bench<'_> {
    /// Bakes `settings` to `out` (its pages are left there) on the measured bakes' threads
    /// and reads the lightmap back.
    ///
    /// # Errors
    /// [`BenchError`] when the bake fails, is interrupted, or its pages cannot be read.
    pub fn bake_to(&self, settings: BakeSettings, out: &Path) -> Result<Baked, BenchError> {
        self.bake_on(settings, out, self.threads)
    }

    /// [`Self::bake_to`] on `threads` worker threads.
    ///
    /// # Errors
    /// As [`Self::bake_to`].
    pub fn bake_on(
        &self,
        settings: BakeSettings,
        out: &Path,
        threads: usize,
    ) -> Result<Baked, BenchError> {
        let dir = work_dir(out, Shard::WHOLE);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| BenchError::file(&dir, e))?;
        }
        let job = BakeJob {
            texels: self.texels_path.to_owned(),
            out: out.to_owned(),
            settings,
            threads,
            shard: Shard::WHOLE,
            resume: false,
            aux: false,
            finish: FinishOptions::default(),
        };
        let clock = Instant::now();
        let cpu = process_cpu_s();
        let report = bake(&job, self.scene, self.cancel, &mut |_, _| {})?;
        let cpu_s = (process_cpu_s() - cpu).max(0.0);
        let wall_s = clock.elapsed().as_secs_f64();
        if report.interrupted || self.cancel.load(Ordering::Relaxed) {
            let _ = std::fs::remove_dir_all(&dir);
            return Err(BenchError::Interrupted);
        }
        let values = read_lightmap(self.texels, out)?;
        Ok(Baked {
            wall_s,
            cpu_s,
            report,
            values,
        })
    }

    /// Bakes `settings` in the scratch directory (with `selection`, the method's emitter
    /// selection where it sets one, else the bench's), reads it back, and deletes its pages.
    ///
    /// # Errors
    /// As [`Self::bake_to`].
    pub fn bake_scratch(
        &self,
        settings: BakeSettings,
        selection: Option<EmitterSelection>,
    ) -> Result<Baked, BenchError> {
        let settings = BakeSettings {
            emitters: self.light.emitters,
            emitter_selection: selection.unwrap_or(self.light.selection),
            ..settings
        };
        let out = self.scratch.join("run.exr");
        let baked = self.bake_to(settings, &out);
        if let Ok(b) = &baked {
            for page in &b.report.pages {
                let _ = std::fs::remove_file(page);
                let _ = std::fs::remove_file(crate::output::exr_pages::preview_path(page));
            }
        }
        baked
    }
}

/// CPU seconds this process has used (user + system, every thread), from `/proc/self/stat`
/// in clock ticks of 1/100 s; 0 where that file does not exist.
fn process_cpu_s() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    let Some((_, rest)) = stat.rsplit_once(')') else {
        return 0.0;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (tick(11) + tick(12)) / 100.0
}

/// One run of the ladder: a CSV row.
#[derive(Clone, Debug, Serialize)]
pub struct RunRecord {
    /// Method label (`guiding/combine/rho`).
    pub method: String,
    /// `--guiding`.
    pub guiding: String,
    /// `--combine`.
    pub combine: String,
    /// ρ applied.
    pub rho: bool,
    /// Rays per texel.
    pub spp: u32,
    /// Iterations of the last pass: `--iterations`, or 1 where it bakes in one set
    /// ([`BakeSettings::needs_iterations`]).
    pub iterations: u32,
    /// Seed.
    pub seed: u32,
    /// Wall-clock seconds of the whole bake.
    pub wall_s: f64,
    /// CPU seconds of the whole bake (every thread, user + system; 0 where unknown).
    pub cpu_s: f64,
    /// Seconds opening the texel file.
    pub open_s: f64,
    /// Seconds building the BVH.
    pub bvh_s: f64,
    /// Seconds of the gather.
    pub gather_s: f64,
    /// Seconds applying ρ and writing the pages.
    pub write_s: f64,
    /// Gather rays.
    pub gather_rays: u64,
    /// Shadow rays.
    pub shadow_rays: u64,
    /// Gather and shadow rays per second of the gather.
    pub rays_per_s: f64,
    /// Guided cluster-iterations over all learning iterations after the first (0 unguided).
    pub guided_fraction: f64,
    /// ρ as applied (1 without).
    pub rho_value: f64,
    /// Errors against the reference.
    #[serde(flatten)]
    pub error: ErrorStats,
}

impl RunRecord {
    fn new(method: Method, settings: &BakeSettings, baked: &Baked, error: ErrorStats) -> Self {
        let r = &baked.report;
        let c = &r.counters;
        RunRecord {
            method: method.label(),
            guiding: value_name(&method.guiding),
            combine: value_name(&method.combine),
            rho: method.rho,
            spp: settings.spp,
            iterations: settings.for_pass(settings.last_pass()).iterations,
            seed: settings.seed,
            wall_s: baked.wall_s,
            cpu_s: baked.cpu_s,
            open_s: r.seconds.open_texels,
            bvh_s: r.seconds.build_bvh,
            gather_s: r.seconds.gather,
            write_s: r.seconds.write_pages,
            gather_rays: c.gather_rays,
            shadow_rays: c.shadow_rays,
            rays_per_s: r.rays_per_second,
            guided_fraction: guided_fraction(r),
            rho_value: r.rho,
            error,
        }
    }
}

/// Guided cluster-iterations over the cluster-iterations that learned a guide (those after
/// the first, in the passes that guide: `--guided-passes`): how much of the guided passes the
/// guide actually steered (0 for `--guiding off`).
fn guided_fraction(report: &BakeReport) -> f64 {
    let c = &report.counters;
    let learnable = c.iterations_learnable();
    if learnable == 0 {
        0.0
    } else {
        c.iterations_guided as f64 / learnable as f64
    }
}

/// The ladder: which methods, sample counts and seeds.
#[derive(Clone, Debug, Serialize)]
pub struct Ladder {
    /// Methods, in the order run.
    #[serde(skip)]
    pub methods: Vec<Method>,
    /// Rays per texel, ascending.
    pub spp: Vec<u32>,
    /// Seeds.
    pub seeds: Vec<u32>,
    /// Learning iterations of every bake.
    pub iterations: u32,
    /// Light transport of every bake.
    #[serde(serialize_with = "serialize_value_name")]
    pub transport: Transport,
    /// Bounces of every bake.
    pub bounces: u32,
}

/// Runs the ladder, interleaving the methods at each (seed, spp) so that a change of load on
/// the machine falls on all of them alike.
///
/// # Errors
/// [`BenchError`] from a bake or the comparison.
pub fn run_ladder(
    bench: &Bench<'_>,
    ladder: &Ladder,
    reference: &[Option<[f32; 3]>],
) -> Result<Vec<RunRecord>, BenchError> {
    let total = ladder.methods.len() * ladder.spp.len() * ladder.seeds.len();
    let mut records = Vec::with_capacity(total);
    for &seed in &ladder.seeds {
        for &spp in &ladder.spp {
            for &method in &ladder.methods {
                let settings = method.settings(
                    spp,
                    ladder.iterations,
                    ladder.transport,
                    ladder.bounces,
                    seed,
                );
                let baked = bench.bake_scratch(settings, method.levers.selection)?;
                let error = compare(&baked.values, reference)?;
                let record = RunRecord::new(method, &settings, &baked, error);
                eprintln!(
                    "[{:>3}/{total}] {:<24} spp {:>5} seed {seed}: {:>7.3} s, RMSE {:.4e}, relMSE {:.4e}",
                    records.len() + 1,
                    record.method,
                    spp,
                    record.wall_s,
                    record.error.rmse,
                    record.error.rel_mse
                );
                records.push(record);
            }
        }
    }
    Ok(records)
}

/// One bake of the overhead measurement.
#[derive(Clone, Debug, Serialize)]
pub struct OverheadRecord {
    /// `--guiding`.
    pub guiding: String,
    /// Repeat index.
    pub repeat: u32,
    /// Rays per texel.
    pub spp: u32,
    /// Wall-clock seconds of the whole bake.
    pub wall_s: f64,
    /// Seconds of the gather.
    pub gather_s: f64,
    /// Gather and shadow rays.
    pub rays: u64,
    /// Guided cluster-iterations over all learning iterations after the first.
    pub guided_fraction: f64,
    /// CPU seconds of the whole bake (every thread, user + system).
    pub cpu_s: f64,
    /// Seconds spent building guides (`guide_build_ns` of the stats, summed over threads).
    pub guide_build_s: f64,
    /// Seconds spent warping samples through guides (`warp_ns`, summed over threads).
    pub warp_s: f64,
}

/// The Figure-5 measurement: every `--guiding` mode at `spp` with the bake's defaults
/// otherwise, `repeats` times, interleaved, the order
/// rotated every repeat so that no mode always runs first; every bake with `transport` at
/// `bounces`.
///
/// # Errors
/// [`BenchError`] from a bake.
pub fn run_overhead(
    bench: &Bench<'_>,
    spp: u32,
    iterations: u32,
    transport: Transport,
    bounces: u32,
    repeats: u32,
) -> Result<Vec<OverheadRecord>, BenchError> {
    let modes = Guiding::value_variants();
    let mut records = Vec::new();
    for repeat in 0..repeats {
        for i in 0..modes.len() {
            let guiding = modes[(i + repeat as usize) % modes.len()];
            let method = Method {
                guiding,
                ..Method::default_bake()
            };
            let settings = method.settings(spp, iterations, transport, bounces, 1);
            let baked = bench.bake_scratch(settings, None)?;
            let c = &baked.report.counters;
            let record = OverheadRecord {
                guiding: value_name(&guiding),
                repeat,
                spp,
                wall_s: baked.wall_s,
                gather_s: baked.report.seconds.gather,
                rays: c.gather_rays + c.shadow_rays,
                guided_fraction: guided_fraction(&baked.report),
                cpu_s: baked.cpu_s,
                guide_build_s: c.guide_build_ns as f64 * 1e-9,
                warp_s: c.warp_ns as f64 * 1e-9,
            };
            eprintln!(
                "overhead {}/{repeats} {:<9} spp {spp}: gather {:.3} s, wall {:.3} s",
                repeat + 1,
                record.guiding,
                record.gather_s,
                record.wall_s
            );
            records.push(record);
        }
    }
    Ok(records)
}
