//! The shards' work directories read back for the finish and the merge: each shard's
//! manifest checked against the texel file, the tiles every shard baked and the split they
//! cover, the batch files and Müller's global weights (`--combine global`), and the
//! identity the pages carry.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use crate::bake::error::BakeError;
use crate::bake::settings::MAX_ITERATIONS;
use crate::bake::shard::Split;
use crate::bake::workdir::{Manifest, pass_files, read_manifest};
use crate::output::exr_pages::{LightmapIdentity, TEXEL_FILE_KEY, TEXELS_KEY};
use crate::output::journal::{Journal, TileRecord, dedup_tiles};
use crate::output::result_file::{BatchFile, FLAG_BAKED, ResultFile, TexelResult};
use crate::texels::TexelFile;
use guidebake_kernels::estimator::{
    IterationVariance, RhoAccumulator, TexelEstimate, Welford, combine_weighted, plain_average,
};

/// The journal records of every tile from the shards' work (each tile once), or an error
/// naming a tile no shard has baked.
pub(super) fn every_tile(
    texels: &TexelFile,
    shards: &[ShardWork],
) -> Result<Vec<TileRecord>, BakeError> {
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

/// Which shard owns each tile ([`Split`]), checked against the shards' journals: a shard
/// whose journal holds another shard's tile was split differently (by an older guidebake,
/// which split tiles modulo the shard count) and is refused.
pub(super) fn split_of(texels: &TexelFile, shards: &[ShardWork]) -> Result<Split, BakeError> {
    let split = Split::new(
        texels.tiles().iter().map(|t| t.texel_count),
        shards.len() as u32,
    );
    for (index, shard) in shards.iter().enumerate() {
        if let Some(r) = shard.records.iter().find(|r| split.owner(r.tile) != index) {
            return Err(BakeError::Mismatch(format!(
                "{}: shard {index} of {} holds tile {}, which shard {} owns: the work directory \
                 was split another way (by an older guidebake?); bake this shard again",
                shard.dir.display(),
                shards.len(),
                r.tile,
                split.owner(r.tile),
            )));
        }
    }
    Ok(split)
}

/// The shards' batch files when the bake combines with global weights (in shard order).
pub(super) fn open_batch_files(
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
pub(super) struct GlobalWeights {
    pub(super) weights: [f64; MAX_ITERATIONS],
    pub(super) rho: f64,
}

impl GlobalWeights {
    /// A texel's irradiance combined with the global weights (zero when it has no samples).
    pub(super) fn combine(&self, batches: &[Welford]) -> [f64; 3] {
        match combine_weighted(batches, &self.weights) {
            TexelEstimate::Value(e) => e.rgb,
            TexelEstimate::NoSamples { .. } => [0.0; 3],
        }
    }
}

/// Streams every shard's batches twice: the per-iteration variances give the weights, then the
/// weighted and unweighted luminance sums give ρ. Exact sums: any shard split, same bits.
pub(super) fn global_weights(
    texels: &TexelFile,
    shards: &[ShardWork],
    split: &Split,
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
            let owner = split.owner(t as u32);
            shards[owner].results.read(tile.first_texel, &mut results)?;
            files[owner].read(tile.first_texel, &mut batches)?;
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

/// The work directory `dir` (its `manifest`) must be a bake of `texels`: the texel file
/// identity its manifest records ([`BakeRecord::texels`](super::workdir::BakeRecord::texels))
/// is `texels`' (a manifest of an older guidebake records none: its result files' texel count
/// is all that is checked).
pub(super) fn check_texels(
    dir: &Path,
    manifest: &Manifest,
    texels: &TexelFile,
) -> Result<(), BakeError> {
    let Some(record) = &manifest.record else {
        return Ok(());
    };
    let given = format!("{:016x}", texels.identity());
    if record.texels == given {
        return Ok(());
    }
    Err(BakeError::Mismatch(format!(
        "{}: baked for the texel file {} (identity {}), not {} (identity {given}): give the texel \
         file it was baked from",
        dir.display(),
        manifest.texels.display(),
        record.texels,
        texels.path().display()
    )))
}

/// What made the lightmap, for its pages' headers: the texel file (its identity and name),
/// the scene's fingerprints, the lights and the settings the shards' `manifest` records.
pub(super) fn lightmap_identity(texels: &TexelFile, manifest: &Manifest) -> LightmapIdentity {
    let name = texels.path().file_name().map_or_else(
        || texels.path().display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let mut identity = LightmapIdentity::default()
        .with(TEXELS_KEY, &format!("{:016x}", texels.identity()))
        .with(TEXEL_FILE_KEY, &name)
        .with("geometry", &format!("{:016x}", texels.header().geometry));
    identity = match &manifest.record {
        Some(record) => {
            let join = |m: &std::collections::BTreeMap<String, String>| {
                m.iter()
                    .map(|(k, v)| format!("{k} {v}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            identity
                .with("materials", &record.materials)
                .with(
                    "lights",
                    &format!("{} ({})", record.lighting, join(&record.lights)),
                )
                .with("settings", &join(&record.options))
        }
        None => identity.with("settings", &manifest.settings),
    };
    identity.with("guidebake", env!("CARGO_PKG_VERSION"))
}

/// One shard's finished work, opened for the final pass.
pub(super) struct ShardWork {
    pub(super) manifest: Manifest,
    pub(super) dir: PathBuf,
    /// The opened pass's results (the last pass's for the pages).
    pub(super) results: ResultFile,
    /// The opened pass's journal records.
    records: Vec<TileRecord>,
}

/// Opens pass `pass` (default: the last) of the work directories in shard order and checks
/// they belong to one bake.
pub(super) fn open_shards(
    texels: &TexelFile,
    dirs: &[PathBuf],
    pass: Option<u32>,
) -> Result<Vec<ShardWork>, BakeError> {
    let mut shards = Vec::new();
    for dir in dirs {
        let manifest = read_manifest(&dir.join("manifest.json"))?;
        check_texels(dir, &manifest, texels)?;
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
