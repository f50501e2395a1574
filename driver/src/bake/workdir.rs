//! The work directory of a bake (`OUT.exr.bake/`, `OUT.exr.shard-I-of-N/`, `OUT.exr.merged/`):
//! its manifest and the per-pass result files and journals, every file name spelled once.
//! The life of a work directory is described in [`super::run`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::directional::DirectionalFile;
use super::error::{BakeError, file_error};
use super::shard::Shard;
use crate::atomic::temporary_name;
use crate::output::journal::{Journal, TileRecord, dedup_tiles};
use crate::output::result_file::{BatchFile, ResultFile};

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
    /// The last pass (series transport's bounces), the lightmap.
    pub passes: u32,
    /// The first pass: 0 for series transport's direct pass, 1 for path tracing
    /// ([`BakeSettings::first_pass`](super::settings::BakeSettings::first_pass)).
    #[serde(default = "one")]
    pub first_pass: u32,
    /// Whether the final pass combines the kept batches with global weights
    /// (`--combine global`).
    pub combine_global: bool,
    /// Learning iterations (batches per texel in the batch file).
    pub iterations: u32,
    /// Whether the last pass kept directional coefficients (`--directional sh-l1`,
    /// [`directional_file`]).
    #[serde(default)]
    pub directional: bool,
    /// Whether the lightmap takes its direct light from the direct pass (`--direct-spp`,
    /// [`BakeSettings::lightmap_borrows_direct`](super::settings::BakeSettings::lightmap_borrows_direct)):
    /// the finish adds that pass's estimate to the last pass's.
    #[serde(default)]
    pub direct_apart: bool,
    /// The settings, for people.
    pub settings: String,
    /// Everything that changes the bake's bits, by name, so that `--resume` of a different
    /// bake names what differs; `None` in a manifest an older guidebake wrote.
    #[serde(default)]
    pub record: Option<BakeRecord>,
}

/// What a bake is made of, as its manifest records it: the settings by option, the texel
/// file's identity, the scene's geometry and materials fingerprints and its lights. Any
/// difference changes [`Manifest::bake_id`] too; this says which.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeRecord {
    /// The settings by the `bake` options that set them
    /// ([`BakeSettings::options`](super::settings::BakeSettings::options), and `--aux`).
    pub options: BTreeMap<String, String>,
    /// The texel file's identity ([`TexelFile::identity`](crate::texels::TexelFile::identity)), hex.
    pub texels: String,
    /// [`Scene::geometry_fingerprint`](crate::scene::Scene::geometry_fingerprint), hex.
    pub geometry: String,
    /// [`Scene::materials_fingerprint`](crate::scene::Scene::materials_fingerprint), hex.
    pub materials: String,
    /// [`Scene::lighting_fingerprint`](crate::scene::Scene::lighting_fingerprint), hex.
    pub lighting: String,
    /// The lights described by the options that set them
    /// ([`Scene::light_entries`](crate::scene::Scene::light_entries)).
    pub lights: BTreeMap<String, String>,
    /// The guidebake that wrote the manifest (not compared).
    pub version: String,
}

impl BakeRecord {
    /// The record of a bake of `options` (by the options that set them) over `texels` and
    /// `scene`, written by this guidebake.
    #[must_use]
    pub fn new(
        options: BTreeMap<String, String>,
        texels: &crate::texels::TexelFile,
        scene: &crate::scene::Scene,
    ) -> Self {
        Self {
            options,
            texels: format!("{:016x}", texels.identity()),
            geometry: format!("{:016x}", scene.geometry_fingerprint()),
            materials: format!("{:016x}", scene.materials_fingerprint()),
            lighting: format!("{:016x}", scene.lighting_fingerprint()),
            lights: scene
                .light_entries()
                .into_iter()
                .map(|(k, v)| (k.to_owned(), v))
                .collect(),
            version: env!("CARGO_PKG_VERSION").to_owned(),
        }
    }

    /// What differs from `earlier` (a bake of the texel file `earlier_texels`) to this one
    /// (of `texels`), one phrase each: `--spp was 256, now 64`.
    #[must_use]
    pub fn differences(
        &self,
        earlier: &BakeRecord,
        earlier_texels: &Path,
        texels: &Path,
    ) -> Vec<String> {
        let mut out = Vec::new();
        let changed = |a: &BTreeMap<String, String>, b: &BTreeMap<String, String>| {
            let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
            keys.into_iter()
                .filter_map(|k| {
                    let (was, now) = (a.get(k), b.get(k));
                    (was != now).then(|| {
                        let show =
                            |v: Option<&String>| v.map_or("not set", |v| v.as_str()).to_owned();
                        format!("{k} was {}, now {}", show(was), show(now))
                    })
                })
                .collect::<Vec<_>>()
        };
        out.extend(changed(&earlier.options, &self.options));
        let lights = changed(&earlier.lights, &self.lights);
        let lights_named = !lights.is_empty();
        out.extend(lights);
        if !lights_named && earlier.lighting != self.lighting {
            out.push(format!(
                "the lights differ (fingerprint {}, now {})",
                earlier.lighting, self.lighting
            ));
        }
        if earlier.texels != self.texels {
            out.push(format!(
                "the texel file was {} ({}), now {} ({})",
                earlier_texels.display(),
                earlier.texels,
                texels.display(),
                self.texels
            ));
        }
        if earlier.geometry != self.geometry {
            out.push(format!(
                "the scene's geometry differs (fingerprint {}, now {})",
                earlier.geometry, self.geometry
            ));
        }
        if earlier.materials != self.materials {
            out.push(format!(
                "the scene's materials differ: albedo, emission, textures, normals or texture \
                 UVs (fingerprint {}, now {})",
                earlier.materials, self.materials
            ));
        }
        out
    }
}

/// Manifests written before series bakes had a direct pass began at pass 1.
fn one() -> u32 {
    1
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

/// Creates the work directory and its manifest, or, with `resume`, checks that the one there
/// belongs to this bake. A run of one pass (`only_pass`) continues the work directory its
/// earlier passes left without `--resume`, unless its own pass has begun there.
pub(super) fn open_work(
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
            let differences = match (&found.record, &manifest.record) {
                (Some(earlier), Some(now)) => {
                    now.differences(earlier, &found.texels, &manifest.texels)
                }
                _ => Vec::new(),
            };
            let what = if found.record.is_none() {
                " (an older guidebake made it, and its manifest does not say what of: other \
                 settings, texel file or scene)"
                    .to_owned()
            } else if differences.is_empty() {
                " (other settings, texel file or scene)".to_owned()
            } else {
                format!(": {}", differences.join("; "))
            };
            return Err(BakeError::Mismatch(format!(
                "{}: --resume of a different bake{what}; delete {} to start over",
                dir.display(),
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
pub(super) fn retire_work(dir: &Path) -> Result<(), BakeError> {
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
pub(super) fn open_pass(
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
pub(super) fn open_batches(
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

/// The directional coefficients of the last pass in a work directory.
pub fn directional_file(dir: &Path) -> PathBuf {
    dir.join("directional.bin")
}

/// Opens the directional file (`per_texel` records per texel; `resume`: the one a resumed
/// pass wrote into), or creates it.
pub(super) fn open_directional(
    dir: &Path,
    bake_id: u64,
    texel_count: u64,
    per_texel: u32,
    resume: bool,
) -> Result<DirectionalFile, BakeError> {
    let path = directional_file(dir);
    if resume && path.exists() {
        let (file, _) =
            DirectionalFile::open_with(&path, true, per_texel, Some((texel_count, bake_id)))?;
        return Ok(file);
    }
    Ok(DirectionalFile::create_with(
        &path,
        texel_count,
        per_texel,
        bake_id,
    )?)
}

/// The previous-pass image built from pass `pass` for the next pass's gathers
/// ([`crate::transport::series::PreviousPass`]); disposable, rebuilt from the result file.
pub(super) fn pass_image(dir: &Path, pass: u32) -> PathBuf {
    dir.join(format!("indirect.{pass}.bin"))
}

/// The result file and journal of pass `pass` in a work directory.
pub(super) fn pass_files(dir: &Path, pass: u32) -> (PathBuf, PathBuf) {
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
