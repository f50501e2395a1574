//! What one tile of the lightmap reads: each texel's combined value from the shards'
//! results (ρ or the weights applied, the direct pass's estimate added: [`with_direct`]), its
//! directional coefficients, and the window of neighbouring tiles a denoiser reads
//! ([`TileGrid`], [`denoise_tile`]).

use std::path::Path;

use crate::bake::directional::{self, DirectionalFile, SH_CHANNELS, ShL1};
use crate::bake::error::BakeError;
use crate::bake::settings::DIRECT_PASS;
use crate::bake::shard::Split;
use crate::bake::workdir::{directional_file, merged_results, pass_files};
use crate::output::denoise::{Denoiser, NoisyTexel, Window};
use crate::output::result_file::{BatchFile, FLAG_BAKED, ResultFile, TexelResult};
use crate::texels::TexelFile;
use guidebake_kernels::estimator::{Weighted, Welford, luminance_f32};

use super::*;

/// Where the pages' values come from: the shards' results (or batches, with global weights),
/// times ρ.
pub(super) struct TileSource<'a> {
    pub(super) texels: &'a TexelFile,
    pub(super) shards: &'a [ShardWork],
    /// Which shard baked each tile.
    pub(super) split: &'a Split,
    pub(super) batches: Option<&'a [BatchFile]>,
    pub(super) global: Option<&'a GlobalWeights>,
    /// The shards' directional files, if the bake kept them.
    pub(super) directional: Option<&'a [DirectionalFile]>,
    /// The direct pass's results, when the lightmap takes its direct light from them
    /// ([`open_direct_results`]).
    pub(super) direct: Option<&'a ResultFile>,
    pub(super) rho: f64,
    pub(super) k: usize,
}

/// A baked texel's irradiance as the page shows it, and its result record.
pub(super) type TexelValue = Option<([f32; 3], TexelResult)>;

impl TileSource<'_> {
    /// Tile `t`'s texels in file order: irradiance × ρ and the result, `None` if not baked;
    /// plus the direct pass's estimate when the lightmap takes its direct light from it
    /// ([`with_direct`]).
    pub(super) fn values(&self, t: usize) -> Result<Vec<TexelValue>, BakeError> {
        let tile = &self.texels.tiles()[t];
        let mut results = vec![TexelResult::default(); tile.texel_count as usize];
        let owner = self.split.owner(t as u32);
        self.shards[owner]
            .results
            .read(tile.first_texel, &mut results)?;
        let mut direct = Vec::new();
        if let Some(file) = self.direct {
            direct.resize(results.len(), TexelResult::default());
            file.read(tile.first_texel, &mut direct)?;
        }
        let mut batches = Vec::new();
        if let (Some(files), Some(_)) = (self.batches, self.global) {
            batches.resize(results.len() * self.k, Welford::new());
            files[owner].read(tile.first_texel, &mut batches)?;
        }
        let k = self.k;
        Ok(results
            .into_iter()
            .enumerate()
            .map(|(i, r)| {
                if r.flags & FLAG_BAKED == 0 {
                    return None;
                }
                let irradiance = match self.global {
                    Some(g) => g.combine(&batches[i * k..(i + 1) * k]),
                    None => r.irradiance.map(f64::from),
                };
                let rgb = irradiance.map(|c| (c * self.rho) as f32);
                Some(match direct.get(i) {
                    Some(d) => with_direct(rgb, r, d),
                    None => (rgb, r),
                })
            })
            .collect())
    }
}

/// A texel of a lightmap that takes its direct light from the direct pass (`--direct-spp`):
/// the last pass's gathered light (`rgb`, after ρ, which corrects that pass's combination
/// alone) plus the direct pass's plain average, which needs no correction. The two
/// estimates are independent, so their variances add: the relative standard error is of the
/// sum, `total` the sum's plain average and `samples` the gather's.
pub(super) fn with_direct(
    rgb: [f32; 3],
    r: TexelResult,
    d: &TexelResult,
) -> ([f32; 3], TexelResult) {
    if d.flags & FLAG_BAKED == 0 {
        return (rgb, r);
    }
    let sum = |a: [f32; 3], b: [f32; 3]| core::array::from_fn(|c| a[c] + b[c]);
    let sd = |e: f32, v: [f32; 3]| f64::from(e) * f64::from(luminance_f32(v));
    let total = sum(r.total, d.total);
    let variance = sd(r.rel_std_error, r.total).powi(2) + sd(d.rel_std_error, d.total).powi(2);
    let mean = f64::from(luminance_f32(total));
    let rel_std_error = if mean > 0.0 {
        (variance.sqrt() / mean) as f32
    } else {
        0.0
    };
    let result = TexelResult {
        total,
        rel_std_error: if rel_std_error.is_finite() {
            rel_std_error
        } else {
            0.0
        },
        ..r
    };
    (sum(rgb, d.total), result)
}

/// The direct pass's results, when the shards' manifests say the lightmap takes its direct
/// light from them (`--direct-spp`, [`Manifest::direct_apart`]): a bake of one work directory
/// reads its own pass 0, a sharded one the merged pass 0 that its pass 1 read.
pub(super) fn open_direct_results(
    texels: &TexelFile,
    shards: &[ShardWork],
    out: &Path,
) -> Result<Option<ResultFile>, BakeError> {
    let first = &shards[0].manifest;
    if !first.direct_apart {
        return Ok(None);
    }
    let own = pass_files(&shards[0].dir, DIRECT_PASS).0;
    let path = if shards.len() == 1 && own.exists() {
        own
    } else {
        merged_results(out, DIRECT_PASS)
    };
    let expected = Some((texels.header().texel_count, first.bake_id));
    Ok(Some(ResultFile::open(&path, false, expected)?.0))
}

impl TileSource<'_> {
    /// Tile `t`'s directional coefficients in file order, times ρ (zero for texels not baked);
    /// empty when the bake kept none. With global weights the iterations' means are combined
    /// with the weights the irradiance gets, from the batch file.
    pub(super) fn directional(&self, t: usize) -> Result<Vec<[f32; 12]>, BakeError> {
        let Some(files) = self.directional else {
            return Ok(Vec::new());
        };
        let tile = &self.texels.tiles()[t];
        let n = tile.texel_count as usize;
        let owner = self.split.owner(t as u32);
        let file = &files[owner];
        let combined: Vec<ShL1> = match (self.batches, self.global) {
            (Some(batches), Some(g)) => {
                let k = self.k;
                let mut means = vec![ShL1::default(); n * k];
                file.read(tile.first_texel, &mut means)?;
                let mut b = vec![Welford::new(); n * k];
                batches[owner].read(tile.first_texel, &mut b)?;
                let weights = Weighted(&g.weights);
                (0..n)
                    .map(|i| {
                        let range = i * k..(i + 1) * k;
                        directional::combine(&means[range.clone()], &b[range], &weights)
                    })
                    .collect()
            }
            _ => {
                let mut out = vec![ShL1::default(); n];
                file.read(tile.first_texel, &mut out)?;
                out
            }
        };
        Ok(combined.iter().map(|sh| sh.scaled(self.rho)).collect())
    }
}

/// The shards' directional files when the bake kept them (in shard order).
pub(super) fn open_directional_files(
    texels: &TexelFile,
    shards: &[ShardWork],
) -> Result<Option<Vec<DirectionalFile>>, BakeError> {
    let first = &shards[0].manifest;
    if !first.directional {
        return Ok(None);
    }
    let per_texel = if first.combine_global {
        first.iterations
    } else {
        1
    };
    let mut files = Vec::new();
    for shard in shards {
        let (file, _) = DirectionalFile::open_with(
            &directional_file(&shard.dir),
            false,
            per_texel,
            Some((texels.header().texel_count, shard.manifest.bake_id)),
        )?;
        files.push(file);
    }
    Ok(Some(files))
}

/// The tiles of one page by the grid cells (of the texel file's tile size) they overlap, to
/// find the tiles under a window.
pub(super) struct TileGrid {
    cell: u32,
    cells: std::collections::HashMap<(u32, u32), Vec<usize>>,
}

impl TileGrid {
    pub(super) fn new(texels: &TexelFile, page: u32) -> Self {
        let cell = texels.header().tile_size.max(1);
        let mut cells: std::collections::HashMap<(u32, u32), Vec<usize>> = Default::default();
        for (t, tile) in texels.tiles().iter().enumerate() {
            if tile.page != page || tile.width == 0 || tile.height == 0 {
                continue;
            }
            for cy in tile.y / cell..=(tile.y + tile.height - 1) / cell {
                for cx in tile.x / cell..=(tile.x + tile.width - 1) / cell {
                    cells.entry((cx, cy)).or_default().push(t);
                }
            }
        }
        Self { cell, cells }
    }

    /// The tiles overlapping pixels [x0, x1) × [y0, y1), each once, in file order.
    fn overlapping(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> Vec<usize> {
        let mut found: Vec<usize> = (y0 / self.cell..=(y1 - 1) / self.cell)
            .flat_map(|cy| (x0 / self.cell..=(x1 - 1) / self.cell).map(move |cx| (cx, cy)))
            .filter_map(|c| self.cells.get(&c))
            .flatten()
            .copied()
            .collect();
        found.sort_unstable();
        found.dedup();
        found
    }
}

/// Filtered irradiance per texel of a tile, and its directional coefficients (empty when the
/// bake kept none).
pub(super) type Denoised = (Vec<Option<[f32; 3]>>, Vec<[f32; 12]>);

/// Denoises tile `t` (its `values` and directional coefficients `sh`, empty if none): builds
/// the window of the tile and its halo from the tiles around it, filters it — the
/// coefficients with the irradiance's weights ([`Denoiser::denoise_with`]) — and returns the
/// filtered values per texel of the tile.
pub(super) fn denoise_tile(
    source: &TileSource<'_>,
    grid: &TileGrid,
    filter: &dyn Denoiser,
    t: usize,
    (values, sh): (&[TexelValue], &[[f32; 12]]),
) -> Result<Denoised, BakeError> {
    let texels = source.texels;
    let tile = texels.tiles()[t];
    let page = texels.pages()[tile.page as usize];
    let halo = filter.halo();
    let x0 = tile.x.saturating_sub(halo);
    let y0 = tile.y.saturating_sub(halo);
    let x1 = (tile.x + tile.width + halo).min(page.width);
    let y1 = (tile.y + tile.height + halo).min(page.height);
    let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let mut window = Window {
        width: w,
        height: h,
        texels: vec![None; w * h],
    };
    let count = if sh.is_empty() { 0 } else { SH_CHANNELS.len() };
    let mut extra = vec![0.0f32; w * h * count];
    let mut place =
        |records: &[crate::texels::TexelRecord], values: &[TexelValue], sh: &[[f32; 12]]| {
            for (i, (texel, v)) in records.iter().zip(values).enumerate() {
                let [x, y] = texel.pixel.map(u32::from);
                if !(x0..x1).contains(&x) || !(y0..y1).contains(&y) {
                    continue;
                }
                let at = (y - y0) as usize * w + (x - x0) as usize;
                if let Some(noisy) = v.as_ref().and_then(|(rgb, r)| noisy_texel(texel, *rgb, r)) {
                    window.texels[at] = Some(noisy);
                    if let Some(c) = sh.get(i) {
                        extra[at * count..(at + 1) * count].copy_from_slice(c);
                    }
                }
            }
        };
    for n in grid.overlapping(x0, y0, x1, y1) {
        if n == t {
            place(texels.tile_texels(t), values, sh);
        } else {
            let neighbour = source.values(n)?;
            let neighbour_sh = source.directional(n)?;
            place(texels.tile_texels(n), &neighbour, &neighbour_sh);
            texels.release_tile(n);
        }
    }
    let (filtered, extra) = filter.denoise_with(&window, &extra, count);
    let mut rgb = Vec::with_capacity(values.len());
    let mut coefficients = Vec::with_capacity(sh.len());
    for (i, texel) in texels.tile_texels(t).iter().enumerate() {
        let [x, y] = texel.pixel.map(u32::from);
        let at = (y - y0) as usize * w + (x - x0) as usize;
        rgb.push(filtered[at]);
        if i < sh.len() {
            let mut c = sh[i];
            if filtered[at].is_some() {
                c.copy_from_slice(&extra[at * count..(at + 1) * count]);
            }
            coefficients.push(c);
        }
    }
    Ok((rgb, coefficients))
}

/// A baked texel with its guides, or `None` when its value is not finite (it is then
/// written as the page writer treats it, and takes no part in the filter).
pub(super) fn noisy_texel(
    texel: &crate::texels::TexelRecord,
    rgb: [f32; 3],
    r: &TexelResult,
) -> Option<NoisyTexel> {
    if !rgb.iter().all(|c| c.is_finite()) {
        return None;
    }
    let sd = r.rel_std_error * luminance_f32(rgb);
    let variance = if sd.is_finite() { sd * sd } else { 0.0 };
    let spacing = texel.spacing();
    Some(NoisyTexel {
        rgb,
        variance,
        position: texel.position(),
        normal: texel.normal(),
        spacing,
    })
}
