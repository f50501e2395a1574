//! The reference lightmap errors are measured against.
//!
//! None of the benchmark scenes has a closed-form lightmap, so the reference is a bake with
//! many more samples than any measured run, made with the unbiased baseline estimator
//! (cosine-weighted gather, plain average, no ρ), so that no guiding or combination under test
//! is measured against itself, and by default with the `path` transport (unidirectional path
//! tracing from every gather hit, paths of at most as many bounces as the measured runs): an
//! unbiased estimate of the same light transport. Runs with the bake's default `series`
//! transport then include its bias (the previous pass's lightmap looked up at each hit) as
//! well as the estimators' noise and bias; `--reference-transport series` measures them
//! against a series reference instead, which isolates the estimators (the bake's own
//! setting, where the paper's guiding learns from smooth lightmap lookups, not from paths).
//!
//! A reference costs minutes, so it is cached on disk: `ref-KEY.exr` (its pages) and
//! `ref-KEY.json`, where KEY hashes the scene (its loaded triangles, materials and lights), the
//! texel file (header and every record) and the reference's settings. The JSON is written
//! last, through a temporary name: a reference whose JSON exists and names the same key is
//! complete and is reused.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::BenchError;
use super::harness::Bench;
use super::method::Method;
use crate::bake::settings::{BakeSettings, GuideTarget, Transport};
use crate::output::atomic;
use crate::output::fnv1a64;
use crate::output::readback::read_lightmap;
use crate::scene::Scene;
use crate::texels::TexelFile;
use crate::transport::emitters::EmitterSelection;

/// The seed of every reference bake (the measured runs use seeds from 1).
pub const REFERENCE_SEED: u32 = 0x5eed_0000;

/// The reference in use.
#[derive(Clone, Debug)]
pub struct Reference {
    /// What it is, for the reports.
    pub info: ReferenceInfo,
    /// Its value per texel id (`None` for invalid texels).
    pub values: Vec<Option<[f32; 3]>>,
}

/// How the reference was made: written into the summary and the cache's JSON.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInfo {
    /// `bake`: a high-sample bake (no scene here has an analytic lightmap).
    pub kind: String,
    /// The cache key in full (scene, texel file and settings).
    pub key: String,
    /// Its settings, as the bake prints them.
    pub settings: String,
    /// Rays per texel.
    pub spp: u32,
    /// Wall-clock seconds the reference bake took (when it was made).
    pub bake_seconds: f64,
    /// The first page of the cached reference.
    pub path: PathBuf,
    /// Whether this run found it in the cache.
    #[serde(default)]
    pub cached: bool,
}

/// The reference's settings: the unbiased baseline at `spp` with `transport`.
pub fn reference_settings(
    spp: u32,
    iterations: u32,
    transport: Transport,
    bounces: u32,
) -> BakeSettings {
    // Emitters picked in proportion to power, whatever the bake's default selection: every
    // selection is unbiased, and the references cached before `local` keep their key. The
    // baseline learns no guide: the guide's target is the one its key has always had.
    BakeSettings {
        emitter_selection: EmitterSelection::Power,
        guide_target: GuideTarget::Radiance,
        ..Method::baseline().settings(spp, iterations, transport, bounces, REFERENCE_SEED)
    }
}

/// A hash of what the scene is, for the cache key (not of its path).
pub fn scene_id(scene: &Scene) -> u64 {
    let text = format!(
        "{:?}|{:?}|{:?}|{:?}|{:?}",
        scene.triangles, scene.materials, scene.lights, scene.sun, scene.sky
    );
    fnv1a64(text.as_bytes())
}

/// A hash of the texel file's header and records.
pub fn texel_file_id(texels: &TexelFile) -> u64 {
    let header = fnv1a64(bytemuck::bytes_of(texels.header()));
    let records = fnv1a64(bytemuck::cast_slice(texels.texels()));
    header ^ records.rotate_left(17)
}

/// The cached reference for `bench` with `settings`, baked into `cache` first if needed.
///
/// # Errors
/// [`BenchError`] when the cache cannot be written or the bake fails.
pub fn reference(
    bench: &Bench<'_>,
    cache: &Path,
    settings: BakeSettings,
) -> Result<Reference, BenchError> {
    // The version changes with what a bake computes for the same settings (v3: series
    // passes read the previous pass's total irradiance on the side its texels bake; v4,
    // series only — path references stay valid: pass 1 reads a direct pass 0; v5, series
    // only: the lightmap takes its direct light from pass 0).
    let version = match settings.transport {
        Transport::Series => 5,
        Transport::Path => 3,
    };
    let key = format!(
        "guidebake bench reference v{version}; scene {:016x}; texels {:016x}; settings {settings:?}",
        scene_id(bench.scene),
        texel_file_id(bench.texels)
    );
    let stem = format!("ref-{:016x}", fnv1a64(key.as_bytes()));
    let out = cache.join(format!("{stem}.exr"));
    let json = cache.join(format!("{stem}.json"));
    if let Some(mut info) = read_info(&json).filter(|i| i.key == key)
        && let Ok(values) = read_lightmap(bench.texels, &out)
    {
        info.cached = true;
        eprintln!(
            "reference: cached {} ({} spp)",
            info.path.display(),
            info.spp
        );
        return Ok(Reference { info, values });
    }
    std::fs::create_dir_all(cache).map_err(|e| BenchError::file(cache, e))?;
    eprintln!(
        "reference: baking {} spp into {} (cached for later runs)",
        settings.spp,
        out.display()
    );
    let clock = Instant::now();
    let baked = bench.bake_to(settings, &out)?;
    let info = ReferenceInfo {
        kind: "bake".into(),
        key,
        settings: format!("{settings:?}"),
        spp: settings.spp,
        bake_seconds: clock.elapsed().as_secs_f64(),
        path: out,
        cached: false,
    };
    let text = serde_json::to_string_pretty(&info).map_err(|e| BenchError::file(&json, e))?;
    atomic::write(&json, text).map_err(|e| BenchError::file(&json, e))?;
    Ok(Reference {
        info,
        values: baked.values,
    })
}

fn read_info(path: &Path) -> Option<ReferenceInfo> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}
