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
//!
//! The reference's own noise is part of every error measured against it:
//! `E[(x − r)²] = E[(x − μ)²] + Var r` for a run `x` independent of `r`. A path reference 16×
//! a run's samples holds much of the error of a good series bake: path transport is about four
//! times as noisy per sample (on the Veach rooms at 256², 256 spp, about half the default's
//! relative MSE; docs/references.md, "The reference's own noise"). `--reference-noise` bakes a twin
//! (the same settings, seed [`TWIN_SEED`]), measures the runs against the mean of the two and
//! estimates that mean's noise ([`ReferenceNoise`]); subtracted from a run's error it leaves the
//! run's error against the truth. The tables print the errors with the noise in.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::BenchError;
use super::harness::Bench;
use super::method::Method;
use super::metrics::{CompareError, compare};
use crate::atomic;
use crate::bake::settings::{BakeSettings, GuideTarget, Transport};
use crate::hash::fnv1a64;
use crate::output::readback::read_lightmap;
use crate::scene::Scene;
use crate::texels::TexelFile;
use crate::transport::emitters::EmitterSelection;

/// The seed of every reference bake (the measured runs use seeds from 1).
pub const REFERENCE_SEED: u32 = 0x5eed_0000;

/// The seed of the reference's twin (`--reference-noise`), which measures the reference's noise.
pub const TWIN_SEED: u32 = REFERENCE_SEED + 1;

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
    // baseline learns no guide: the guide's target and `--min-gain` are the ones its key has
    // always had.
    BakeSettings {
        emitter_selection: EmitterSelection::Power,
        guide_target: GuideTarget::Radiance,
        min_gain: 150,
        ..Method::baseline().settings(spp, iterations, transport, bounces, REFERENCE_SEED)
    }
}

/// The twin's settings: the reference's, with [`TWIN_SEED`].
pub fn twin_settings(reference: BakeSettings) -> BakeSettings {
    BakeSettings {
        seed: TWIN_SEED,
        ..reference
    }
}

/// The reference's own noise: its part of every run's error (`--reference-noise`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReferenceNoise {
    /// Its part of every run's relative MSE.
    pub rel_mse: f64,
    /// Its part of every run's MSE.
    pub mse: f64,
    /// The twin.
    pub twin: ReferenceInfo,
}

impl ReferenceNoise {
    /// The mean of `reference` and `twin` (an independent bake with the same settings but the
    /// seed: twice the samples), which the runs are measured against then, and that mean's
    /// noise. Per value `m − r = (r' − r) / 2` and `E[(r' − r)²] = 2 Var r`, so
    /// `E[(m − r)²] = Var r / 2 = Var m`: the noise is `r`'s error against `m`, weighted by
    /// `m` as a run's relative MSE is (the weight moves with `m`'s noise by about its relative
    /// error, a second-order effect). Texels either lacks are left out of the mean.
    ///
    /// # Errors
    /// [`CompareError`] when the two cannot be compared.
    pub fn estimate(
        reference: Reference,
        twin: Reference,
    ) -> Result<(Reference, Self), CompareError> {
        if reference.values.len() != twin.values.len() {
            return Err(CompareError::new(format!(
                "a reference of {} texels and a twin of {}",
                reference.values.len(),
                twin.values.len()
            )));
        }
        let values: Vec<Option<[f32; 3]>> = reference
            .values
            .iter()
            .zip(&twin.values)
            .map(|(a, b)| Some(mean((*a)?, (*b)?)))
            .collect();
        let e = compare(&reference.values, &values)?;
        let noise = Self {
            rel_mse: e.rel_mse,
            mse: e.rmse * e.rmse,
            twin: twin.info,
        };
        Ok((
            Reference {
                info: reference.info,
                values,
            },
            noise,
        ))
    }
}

fn mean(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|c| 0.5 * a[c] + 0.5 * b[c])
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
    // only: the lightmap takes its direct light from pass 0; v6 and v4: an unguided pass
    // gathers each texel's samples as one presorted set, not one per iteration).
    let version = match settings.transport {
        Transport::Series => 6,
        Transport::Path => 4,
    };
    let key = format!(
        "guidebake bench reference v{version}; scene {:016x}; texels {:016x}; settings {}",
        scene_id(bench.scene),
        texel_file_id(bench.texels),
        settings.identity()
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
    let baked = bench.bake_on(settings, &out, bench.reference_threads)?;
    let info = ReferenceInfo {
        kind: "bake".into(),
        key,
        settings: settings.identity(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::rng::SampleRng;

    /// `truth` with uniform noise of mean 0 and relative standard deviation `sigma` on every
    /// channel, from the sample stream `stream`.
    fn lightmap(truth: &[f64], sigma: f64, stream: u64) -> Vec<Option<[f32; 3]>> {
        let mut rng = SampleRng::new(0, stream, 0, 0);
        let mut noise = |t: f64| (f64::from(rng.unit()) - 0.5) * sigma * t * 12f64.sqrt();
        truth
            .iter()
            .map(|&t| Some([0; 3].map(|_| (t + noise(t)) as f32)))
            .collect()
    }

    fn reference(values: Vec<Option<[f32; 3]>>, seed: u32) -> Reference {
        Reference {
            info: ReferenceInfo {
                kind: "bake".into(),
                key: format!("test {seed}"),
                settings: String::new(),
                spp: 16,
                bake_seconds: 0.0,
                path: PathBuf::new(),
                cached: false,
            },
            values,
        }
    }

    #[test]
    fn the_twin_takes_the_references_noise_out_of_a_runs_error() {
        let truth: Vec<f64> = (0..40_000)
            .map(|i| 0.5 + f64::from(i % 97) / 20.0)
            .collect();
        let exact: Vec<_> = truth.iter().map(|&t| Some([t as f32; 3])).collect();
        // A run twice as noisy as each reference bake: their mean holds a ninth of its error.
        let run = lightmap(&truth, 0.10, 1);
        let a = reference(lightmap(&truth, 0.05, 2), 0);
        let b = reference(lightmap(&truth, 0.05, 3), 1);
        let (mean, noise) = ReferenceNoise::estimate(a, b).unwrap();
        assert_eq!(mean.info.key, "test 0");
        let against_truth = compare(&run, &exact).unwrap();
        let against_mean = compare(&run, &mean.values).unwrap();
        let raw = against_mean.rel_mse / against_truth.rel_mse;
        assert!(
            raw > 1.1,
            "the reference's noise is in the raw error: {raw}"
        );
        let net = (against_mean.rel_mse - noise.rel_mse) / against_truth.rel_mse;
        assert!((net - 1.0).abs() < 0.02, "relative MSE: {net}");
        let mse = |e: &crate::bench::metrics::ErrorStats| e.rmse * e.rmse;
        let net = (mse(&against_mean) - noise.mse) / mse(&against_truth);
        assert!((net - 1.0).abs() < 0.02, "MSE: {net}");
        assert_eq!(noise.twin.key, "test 1");
    }

    #[test]
    fn the_twin_differs_from_the_reference_by_its_seed_alone() {
        let reference = reference_settings(4096, 4, Transport::Path, 3);
        let twin = twin_settings(reference);
        assert_ne!(twin.seed, reference.seed);
        assert_eq!(
            BakeSettings {
                seed: reference.seed,
                ..twin
            },
            reference
        );
    }
}
