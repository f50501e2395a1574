//! The work directory of a bake (`OUT.exr.bake/`, `OUT.exr.shard-I-of-N/`, `OUT.exr.merged/`):
//! its manifest and the per-pass result files and journals, every file name spelled once.
//! The life of a work directory is described in [`super::run`].

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::directional::DirectionalFile;
use super::error::{BakeError, file_error};
use super::shard::Shard;
use crate::output::atomic::temporary_name;
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
