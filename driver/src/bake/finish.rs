//! The end of a bake: ρ or the global weights reduced over every tile of the shards' work
//! directories, then the pages written ([`finish`]); and the merge of one series pass of every
//! shard into the next pass's input ([`merge_pass`]). Shards and merging: docs/farm.md.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use super::run::{BakeError, file_error};
use super::settings::{MAX_ITERATIONS, SettingsError};
use super::workdir::{Manifest, merged_dir, merged_results, pass_files, read_manifest};
use crate::output::atomic::temporary_name;
use crate::output::exr_pages::{PageStream, page_path};
use crate::output::journal::{Journal, TileRecord, dedup_tiles, rho_sums};
use crate::output::result_file::{BatchFile, FLAG_BAKED, ResultFile, TexelResult};
use crate::texels::TexelFile;
use guidebake_kernels::estimator::{
    IterationVariance, RhoAccumulator, TexelEstimate, Welford, combine_weighted, plain_average,
};

/// Pixels of padding around every chart in the written pages.
pub const DILATION_PIXELS: u32 = 2;

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
        (true, None) => rho_sums(&all).rho(),
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
