//! The end of a bake: ρ or the global weights reduced over every tile of the shards' work
//! directories, then the pages written ([`finish`]); and the merge of one series pass of every
//! shard into the next pass's input ([`merge_pass`]). Shards and merging: docs/farm.md.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use super::directional::{self, DirectionalFile, SH_CHANNELS, ShL1};
use super::error::{BakeError, file_error};
use super::settings::{DIRECT_PASS, MAX_ITERATIONS, SettingsError};
use super::shard::Split;
use super::workdir::{
    Manifest, directional_file, merged_dir, merged_results, pass_files, read_manifest,
};
use crate::atomic::temporary_name;
use crate::output::denoise::{ATrous, Denoiser, NoisyTexel, Window};
use crate::output::exr_pages::{
    LightmapIdentity, PageStream, TEXEL_FILE_KEY, TEXELS_KEY, page_path,
};
use crate::output::journal::{Journal, TileRecord, dedup_tiles, rho_sums};
use crate::output::result_file::{BatchFile, FLAG_BAKED, ResultFile, TexelResult};
use crate::output::seams::{
    EdgePoint, PageFacts, Pixel, Written as PixelWritten, edge_system, mean_relative_jump,
    pixels_read, read_seam_file, seam_file_path, stitch_channels,
};
use crate::texels::TexelFile;
use guidebake_kernels::estimator::{
    IterationVariance, RhoAccumulator, TexelEstimate, Weighted, Welford, combine_weighted,
    luminance_f32, plain_average,
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
    /// Seam texel pairs found (with `--seams stitch`).
    pub seam_pairs: u64,
    /// Mean relative jump across the seam texel pairs before and after stitching.
    pub seam_jump: Option<[f64; 2]>,
    /// Seam edge points stitched, those left out (a tap beyond the padding or on a
    /// non-finite texel), and the texels held at their values to keep the irradiance
    /// non-negative.
    pub edge_points: [u64; 3],
    /// Mean relative jump between the two sides' bilinear values at the seam edge points,
    /// before and after stitching.
    pub edge_jump: Option<[f64; 2]>,
}

/// How the pages are finished.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Denoise {
    /// The estimates as baked (the default: the lightmap is the estimator's output, whose
    /// error `guidebake bench` measures, with no filter bias and nothing blurred).
    #[default]
    Off,
    /// The edge-aware À-Trous filter, per tile with a halo (docs/lightmaps.md; `on` is its
    /// older spelling).
    #[value(alias = "on")]
    Atrous,
    /// Intel Open Image Denoise's `RTLightmap` network, per island of each tile's window
    /// (a build with the `oidn` feature; scripts/oidn/fetch.sh).
    Oidn,
}

/// Whether seams are stitched ([`crate::output::seams`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Seams {
    /// Each chart keeps its own estimates (the default, as for `--denoise`).
    #[default]
    Off,
    /// Seam texels are fitted to agree by least squares.
    Stitch,
}

/// What [`finish_with`] does to the pages beyond writing the estimates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FinishOptions {
    /// Denoise.
    pub denoise: Denoise,
    /// Stitch seams (after denoising).
    pub seams: Seams,
}

/// The final streaming pass: reduces ρ over every tile of the work directories (one per
/// shard; together they must cover every tile exactly once), then writes each page — results
/// times ρ, dilated — as EXR. Used by an unsharded bake and by `guidebake merge`.
///
/// # Errors
/// A [`BakeError`] naming the work directory or page: a shard missing, shards of different
/// bakes, a tile not baked, a page that cannot be written.
pub fn finish(texels: &TexelFile, dirs: &[PathBuf], out: &Path) -> Result<Written, BakeError> {
    finish_with(texels, dirs, out, FinishOptions::default())
}

/// [`finish`], denoising the pages (with [`ATrous`] or OIDN) and stitching their seams as `options`
/// ask. Both run on the merged results (the filter tile by tile with a halo, the stitch on
/// the border texels once every tile is written), so n shards still give the bytes of one
/// bake.
///
/// # Errors
/// As [`finish`].
pub fn finish_with(
    texels: &TexelFile,
    dirs: &[PathBuf],
    out: &Path,
    options: FinishOptions,
) -> Result<Written, BakeError> {
    match options.denoise {
        Denoise::Off => finish_filtered(texels, dirs, out, None, options.seams),
        Denoise::Atrous => {
            finish_filtered(texels, dirs, out, Some(&ATrous::default()), options.seams)
        }
        Denoise::Oidn => {
            let oidn = oidn_denoiser()?;
            finish_filtered(texels, dirs, out, Some(&oidn), options.seams)
        }
    }
}

/// The OIDN denoiser, or why there is none: a build without the `oidn` feature, or a library
/// that cannot make its CPU device.
#[cfg(feature = "oidn")]
fn oidn_denoiser() -> Result<crate::output::denoise::Oidn, BakeError> {
    crate::output::denoise::Oidn::new()
        .map_err(|e| SettingsError::new(format!("--denoise oidn: {e}")).into())
}

/// The OIDN denoiser, or why there is none: a build without the `oidn` feature.
#[cfg(not(feature = "oidn"))]
fn oidn_denoiser() -> Result<ATrous, BakeError> {
    Err(SettingsError::new(crate::output::denoise::OIDN_MISSING.into()).into())
}

/// [`finish_with`] with any [`Denoiser`] (or none): where another filter plugs in.
///
/// # Errors
/// As [`finish`].
pub fn finish_filtered(
    texels: &TexelFile,
    dirs: &[PathBuf],
    out: &Path,
    filter: Option<&dyn Denoiser>,
    seams: Seams,
) -> Result<Written, BakeError> {
    let shards = open_shards(texels, dirs, None)?;
    let first = &shards[0].manifest;
    let all = every_tile(texels, &shards)?;
    let split = split_of(texels, &shards)?;
    let batches = open_batch_files(texels, &shards)?;
    let global = batches
        .as_deref()
        .map(|files| global_weights(texels, &shards, &split, files))
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
    let directional = open_directional_files(texels, &shards)?;
    let direct = open_direct_results(texels, &shards, out)?;
    let source = TileSource {
        texels,
        shards: &shards,
        split: &split,
        batches: batches.as_deref(),
        directional: directional.as_deref(),
        direct: direct.as_ref(),
        global: global.as_ref(),
        rho,
        k: first.iterations as usize,
    };
    let extra = if first.directional {
        SH_CHANNELS.len()
    } else {
        0
    };
    let mut seams = match seams {
        Seams::Stitch => {
            let extra_from = if first.aux { AUX_CHANNELS.len() } else { 0 };
            Some(SeamWork::load(texels, extra, extra_from)?)
        }
        Seams::Off => None,
    };
    let mut pending = Vec::new();
    let identity = lightmap_identity(texels, first);
    let page_count = texels.pages().len() as u32;
    for (page, size) in texels.pages().iter().enumerate() {
        let path = page_path(out, page as u32, page_count);
        let mut aux: Vec<&str> = Vec::new();
        if first.aux {
            aux.extend(AUX_CHANNELS);
        }
        if first.directional {
            aux.extend(SH_CHANNELS);
        }
        // The directional coefficients are padded as the irradiance is (the same sources).
        let dilated = if first.directional {
            &SH_CHANNELS[..]
        } else {
            &[][..]
        };
        let mut image = PageStream::create(
            &temporary_name(&path.with_extension("pixels")),
            size.width,
            size.height,
            &aux,
            dilated,
        )?;
        image.set_identity(identity.clone());
        let grid = filter.map(|_| TileGrid::new(texels, page as u32));
        // The tiles' values are read and denoised in parallel, a few per thread at a time
        // (each from the merged results alone), then written in file order by this thread:
        // the same page at any thread count, and memory a batch of tiles.
        let tiles: Vec<usize> = texels
            .tiles()
            .iter()
            .enumerate()
            .filter(|(_, t)| t.page as usize == page)
            .map(|(t, _)| t)
            .collect();
        let batch = 4 * rayon::current_num_threads().max(1);
        let prepare = |t: usize| -> Result<_, BakeError> {
            let values = source.values(t)?;
            let mut sh = source.directional(t)?;
            let denoised = match (filter, &grid) {
                (Some(f), Some(grid)) => {
                    let (rgb, coefficients) = denoise_tile(&source, grid, f, t, (&values, &sh))?;
                    sh = coefficients;
                    Some(rgb)
                }
                _ => None,
            };
            Ok((values, sh, denoised))
        };
        for (t, prepared) in tiles.chunks(batch).flat_map(|chunk| {
            use rayon::prelude::*;
            let prepared: Vec<_> = chunk.par_iter().map(|&t| prepare(t)).collect();
            chunk.iter().copied().zip(prepared)
        }) {
            let (values, sh, denoised) = prepared?;
            let tile = &texels.tiles()[t];
            let mut rect = image.rect(tile.x, tile.y, tile.width, tile.height)?;
            for (i, (texel, v)) in texels.tile_texels(t).iter().zip(&values).enumerate() {
                let Some((rgb, r)) = v else {
                    continue;
                };
                let [x, y] = texel.pixel.map(u32::from);
                let rgb = denoised.as_ref().and_then(|d| d[i]).unwrap_or(*rgb);
                if let Some(seams) = &mut seams {
                    let sd = r.rel_std_error * luminance_f32(rgb);
                    let extra = sh.get(i).map_or(&[][..], |c| &c[..]);
                    seams.record([page as u32, x, y], rgb, sd * sd, extra);
                }
                let [px, py, pz] = texel.position;
                let [nx, ny, nz] = texel.normal;
                // In AUX_CHANNELS' order (with --aux), then SH_CHANNELS' (with --directional).
                let mut aux = Vec::with_capacity(AUX_CHANNELS.len() + SH_CHANNELS.len());
                if first.aux {
                    aux.extend([
                        r.samples as f32,
                        r.rel_std_error,
                        1.0,
                        px,
                        py,
                        pz,
                        nx,
                        ny,
                        nz,
                    ]);
                }
                if let Some(sh) = sh.get(i) {
                    aux.extend(sh);
                }
                image.set(&mut rect, x, y, rgb, &aux);
            }
            image.put_rect(&rect)?;
            texels.release_tile(t);
        }
        pending.push((image, path));
        if seams.is_none() {
            finish_pages(&mut pending, &mut written)?;
        }
    }
    if let Some(mut seams) = seams {
        let stitched = seams.stitch(&mut pending)?;
        written.seam_pairs = seams.pairs.len() as u64;
        written.seam_jump = Some(stitched.pair_jump);
        written.edge_points = [stitched.points, stitched.skipped, stitched.held].map(|n| n as u64);
        written.edge_jump = Some(stitched.edge_jump);
    }
    finish_pages(&mut pending, &mut written)?;
    Ok(written)
}

/// Dilates and writes the `pending` pages (in order) and their previews.
fn finish_pages(
    pending: &mut Vec<(PageStream, PathBuf)>,
    written: &mut Written,
) -> Result<(), BakeError> {
    for (image, path) in pending.drain(..) {
        written.non_finite_pixels += image.non_finite_pixels();
        let preview = crate::output::exr_pages::preview_path(&path);
        image.finish(DILATION_PIXELS, &path, &preview)?;
        written.pages.push(path);
        written.previews.push(preview);
    }
    Ok(())
}

/// The seam samples of a texel file and, as the pages are written, the values of the
/// pixels their measures and the stitch read.
struct SeamWork {
    /// The pixels recorded: the pairs' and those the edge points read ([`pixels_read`]).
    pixels: Vec<Pixel>,
    /// The texel pairs, as indices into `pixels`.
    pairs: Vec<(u32, u32)>,
    /// The edge points.
    points: Vec<EdgePoint>,
    /// Index into `pixels` by pixel.
    index: std::collections::HashMap<Pixel, u32>,
    /// Per pixel, whether a texel was written there.
    covered: Vec<bool>,
    /// The channels written, `stride` per pixel: irradiance, then the directional ones
    /// (NaN until recorded).
    values: Vec<f32>,
    stride: usize,
    /// Their luminance's squared standard errors.
    variances: Vec<f32>,
    /// Page sizes.
    pages: Vec<(u32, u32)>,
    /// The page's auxiliary channel where the extra channels begin.
    extra_from: usize,
}

/// What [`SeamWork::stitch`] did.
struct Stitched {
    pair_jump: [f64; 2],
    edge_jump: [f64; 2],
    points: usize,
    skipped: usize,
    held: usize,
}

impl SeamWork {
    /// The samples of the seam file beside the texel file, with `extra` channels per pixel
    /// beside the irradiance (the directional ones, which are stitched alike).
    fn load(texels: &TexelFile, extra: usize, extra_from: usize) -> Result<Self, BakeError> {
        let path = seam_file_path(texels.path());
        let samples = read_seam_file(&path).map_err(|what| file_error(&path, what))?;
        let mut index = std::collections::HashMap::new();
        let mut pixels = Vec::new();
        let mut id = |p: Pixel| {
            *index.entry(p).or_insert_with(|| {
                pixels.push(p);
                pixels.len() as u32 - 1
            })
        };
        let pairs = samples.pairs.iter().map(|p| (id(p.a), id(p.b))).collect();
        for p in pixels_read(&samples.points, DILATION_PIXELS) {
            id(p);
        }
        let stride = 3 + extra;
        let n = pixels.len();
        Ok(Self {
            pixels,
            pairs,
            points: samples.points,
            index,
            covered: vec![false; n],
            values: vec![f32::NAN; n * stride],
            stride,
            variances: vec![0.0; n],
            pages: texels.pages().iter().map(|p| (p.width, p.height)).collect(),
            extra_from,
        })
    }

    /// Records what was written at `pixel`: irradiance, its luminance's variance and the
    /// extra channels.
    fn record(&mut self, pixel: Pixel, rgb: [f32; 3], variance: f32, extra: &[f32]) {
        if let Some(&i) = self.index.get(&pixel) {
            let i = i as usize;
            self.covered[i] = true;
            let v = &mut self.values[i * self.stride..(i + 1) * self.stride];
            v[..3].copy_from_slice(&rgb);
            for (slot, e) in v[3..]
                .iter_mut()
                .zip(extra.iter().chain(std::iter::repeat(&0.0)))
            {
                *slot = *e;
            }
            self.variances[i] = variance;
        }
    }

    fn rgb(&self, i: usize) -> [f32; 3] {
        let v = &self.values[i * self.stride..];
        [v[0], v[1], v[2]]
    }

    /// Stitches the recorded values along the edge points ([`EdgeStitch`]) and writes them
    /// into the pages (before they are dilated); returns the jumps before and after.
    fn stitch(&mut self, pages: &mut [(PageStream, PathBuf)]) -> Result<Stitched, BakeError> {
        let all: Vec<[f32; 3]> = (0..self.pixels.len()).map(|i| self.rgb(i)).collect();
        let pair_before = mean_relative_jump(&all, &self.pairs);
        let system = edge_system(&self.points, &*self, DILATION_PIXELS);
        let unknowns: Vec<usize> = system
            .pixels
            .iter()
            .map(|p| self.index[p] as usize)
            .collect();
        let rgb_of =
            |work: &Self| -> Vec<[f32; 3]> { unknowns.iter().map(|&i| work.rgb(i)).collect() };
        let edge_before = system.edge_jump(&rgb_of(self));
        let variance: Vec<f32> = unknowns.iter().map(|&i| self.variances[i]).collect();
        let mut channels: Vec<Vec<f32>> = (0..self.stride)
            .map(|c| {
                let at = |i: &usize| self.values[i * self.stride + c];
                unknowns.iter().map(at).collect()
            })
            .collect();
        let held = stitch_channels(&system, &variance, &mut channels);
        for (c, channel) in channels.iter().enumerate() {
            for (&i, v) in unknowns.iter().zip(channel) {
                self.values[i * self.stride + c] = *v;
            }
        }
        for &i in &unknowns {
            let [page, x, y] = self.pixels[i];
            let v = &self.values[i * self.stride..(i + 1) * self.stride];
            pages[page as usize].0.set_channels(
                x,
                y,
                [v[0], v[1], v[2]],
                self.extra_from,
                &v[3..],
            )?;
        }
        let edge_after = system.edge_jump(&rgb_of(self));
        let all: Vec<[f32; 3]> = (0..self.pixels.len()).map(|i| self.rgb(i)).collect();
        Ok(Stitched {
            pair_jump: [pair_before, mean_relative_jump(&all, &self.pairs)],
            edge_jump: [edge_before, edge_after],
            points: system.points(),
            skipped: system.skipped,
            held,
        })
    }
}

impl PageFacts for SeamWork {
    fn size(&self, page: u32) -> Option<(u32, u32)> {
        self.pages.get(page as usize).copied()
    }

    fn written(&self, p: Pixel) -> PixelWritten {
        match self.index.get(&p).map(|&i| i as usize) {
            Some(i) if self.covered[i] => {
                if self.values[i * self.stride..(i + 1) * self.stride]
                    .iter()
                    .all(|v| v.is_finite())
                {
                    PixelWritten::Texel
                } else {
                    PixelWritten::NonFinite
                }
            }
            _ => PixelWritten::Empty,
        }
    }
}

/// Where the pages' values come from: the shards' results (or batches, with global weights),
/// times ρ.
struct TileSource<'a> {
    texels: &'a TexelFile,
    shards: &'a [ShardWork],
    /// Which shard baked each tile.
    split: &'a Split,
    batches: Option<&'a [BatchFile]>,
    global: Option<&'a GlobalWeights>,
    /// The shards' directional files, if the bake kept them.
    directional: Option<&'a [DirectionalFile]>,
    /// The direct pass's results, when the lightmap takes its direct light from them
    /// ([`open_direct_results`]).
    direct: Option<&'a ResultFile>,
    rho: f64,
    k: usize,
}

/// A baked texel's irradiance as the page shows it, and its result record.
type TexelValue = Option<([f32; 3], TexelResult)>;

impl TileSource<'_> {
    /// Tile `t`'s texels in file order: irradiance × ρ and the result, `None` if not baked;
    /// plus the direct pass's estimate when the lightmap takes its direct light from it
    /// ([`with_direct`]).
    fn values(&self, t: usize) -> Result<Vec<TexelValue>, BakeError> {
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
fn with_direct(rgb: [f32; 3], r: TexelResult, d: &TexelResult) -> ([f32; 3], TexelResult) {
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
fn open_direct_results(
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
    fn directional(&self, t: usize) -> Result<Vec<[f32; 12]>, BakeError> {
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
fn open_directional_files(
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
struct TileGrid {
    cell: u32,
    cells: std::collections::HashMap<(u32, u32), Vec<usize>>,
}

impl TileGrid {
    fn new(texels: &TexelFile, page: u32) -> Self {
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
type Denoised = (Vec<Option<[f32; 3]>>, Vec<[f32; 12]>);

/// Denoises tile `t` (its `values` and directional coefficients `sh`, empty if none): builds
/// the window of the tile and its halo from the tiles around it, filters it — the
/// coefficients with the irradiance's weights ([`Denoiser::denoise_with`]) — and returns the
/// filtered values per texel of the tile.
fn denoise_tile(
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
fn noisy_texel(
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

/// Which shard owns each tile ([`Split`]), checked against the shards' journals: a shard
/// whose journal holds another shard's tile was split differently (by an older guidebake,
/// which split tiles modulo the shard count) and is refused.
fn split_of(texels: &TexelFile, shards: &[ShardWork]) -> Result<Split, BakeError> {
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
    // The pass is checked against the first shard's manifest before any pass file is opened.
    if let Some(dir) = dirs.first() {
        let m = read_manifest(&dir.join("manifest.json"))?;
        if pass < m.first_pass || pass >= m.passes {
            return Err(BakeError::Settings(SettingsError::new(format!(
                "merge --pass {pass}: the bake has passes {}..={}; passes before the last are \
                 merged into a result file, the last into pages by `merge` with --pass {} or \
                 without --pass",
                m.first_pass, m.passes, m.passes
            ))));
        }
    }
    let shards = open_shards(texels, dirs, Some(pass))?;
    let first = &shards[0].manifest;
    every_tile(texels, &shards)?;
    let split = split_of(texels, &shards)?;
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
            shards[split.owner(t as u32)]
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
fn check_texels(dir: &Path, manifest: &Manifest, texels: &TexelFile) -> Result<(), BakeError> {
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
fn lightmap_identity(texels: &TexelFile, manifest: &Manifest) -> LightmapIdentity {
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

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicBool;

    use glam::Vec3;

    use super::*;
    use crate::bake::run::{BakeJob, bake};
    use crate::bake::settings::{BakeSettings, Transport};
    use crate::bake::shard::Shard;
    use crate::bake::workdir::work_dir;
    use crate::demo::{Face, scene_of_faces};
    use crate::output::seams::prepare_seams;
    use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};
    use crate::scene::{Material, Scene};

    const DENOISE: FinishOptions = FinishOptions {
        denoise: Denoise::Atrous,
        seams: Seams::Off,
    };
    const BOTH: FinishOptions = FinishOptions {
        denoise: Denoise::Atrous,
        seams: Seams::Stitch,
    };

    /// The wall between the rooms: x ∈ [WALL, WALL + THICK].
    const WALL: f32 = 2.0;
    const THICK: f32 = 0.05;

    /// Two closed rooms side by side, x ∈ [0, 2] lit by its emissive ceiling and
    /// x ∈ [2.05, 4.05] dark, parted by a thin wall; the floor is two faces (two charts, a
    /// seam at x = 1), the second of which runs on beneath the wall into the dark room.
    fn two_rooms() -> Scene {
        let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
        let end = 2.0 * WALL + THICK;
        let dark = WALL + THICK;
        let face = |origin: Vec3, u: Vec3, v: Vec3, material: u32| Face {
            origin,
            u,
            v,
            material,
        };
        let faces = vec![
            face(Vec3::ZERO, z * 2.0, x, 0),            // floor, +y, x < 1
            face(Vec3::X, z * 2.0, x * (end - 1.0), 0), // floor, x > 1
            face(Vec3::new(0.0, 2.0, 0.0), x * WALL, z * 2.0, 1), // lit ceiling, −y
            face(Vec3::new(dark, 2.0, 0.0), x * WALL, z * 2.0, 0), // dark ceiling
            face(Vec3::ZERO, y * 2.0, z * 2.0, 0),      // x = 0, +x
            face(Vec3::new(end, 0.0, 0.0), z * 2.0, y * 2.0, 0), // x = end, −x
            face(Vec3::ZERO, x * WALL, y * 2.0, 0),     // z = 0, lit
            face(Vec3::new(dark, 0.0, 0.0), x * WALL, y * 2.0, 0), // z = 0, dark
            face(Vec3::new(0.0, 0.0, 2.0), y * 2.0, x * WALL, 0), // z = 2, lit
            face(Vec3::new(dark, 0.0, 2.0), y * 2.0, x * WALL, 0), // z = 2, dark
            face(Vec3::new(WALL, 0.0, 0.0), z * 2.0, y * 2.0, 0), // the wall, lit side
            face(Vec3::new(dark, 0.0, 0.0), y * 2.0, z * 2.0, 0), // the wall, dark side
        ];
        let materials = vec![
            Material {
                name: "walls".into(),
                base_color_texture: None,
                albedo: Vec3::splat(0.6),
                emission: Vec3::ZERO,
            },
            Material {
                name: "light".into(),
                base_color_texture: None,
                albedo: Vec3::splat(0.5),
                emission: Vec3::splat(2.0),
            },
        ];
        scene_of_faces(&[("rooms", faces)], materials)
    }

    struct Rooms {
        dir: tempfile::TempDir,
        scene: Scene,
        texels: PathBuf,
    }

    impl Rooms {
        fn new() -> Self {
            let dir = tempfile::tempdir().unwrap();
            let scene = two_rooms();
            let texels = dir.path().join("rooms.texels");
            let options = PrepareOptions {
                resolution: Resolution::TexelsPerUnit(10.0),
                layout: Layout::Shared,
            };
            prepare(&scene, &texels, options).unwrap();
            prepare_seams(&scene, &texels).unwrap();
            Self { dir, scene, texels }
        }

        fn job(&self, out: &str, shard: Shard, finish: FinishOptions) -> BakeJob {
            BakeJob {
                texels: self.texels.clone(),
                out: self.dir.path().join(out),
                settings: BakeSettings {
                    spp: 32,
                    transport: Transport::Path,
                    ..Default::default()
                },
                threads: 2,
                shard,
                resume: false,
                aux: true,
                finish,
            }
        }

        fn bake(&self, job: &BakeJob) -> crate::bake::run::BakeReport {
            bake(job, &self.scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap()
        }
    }

    #[test]
    fn denoised_and_stitched_shards_merge_to_the_bytes_of_one_bake() {
        let rooms = Rooms::new();
        let whole = rooms.job("whole.exr", Shard::WHOLE, BOTH);
        rooms.bake(&whole);
        let mut dirs = Vec::new();
        for index in [1, 0] {
            let job = rooms.job("sharded.exr", Shard { index, count: 2 }, BOTH);
            rooms.bake(&job);
            dirs.push(work_dir(&job.out, job.shard));
        }
        let texels = TexelFile::open(&rooms.texels).unwrap();
        let merged = rooms.dir.path().join("merged.exr");
        finish_with(&texels, &dirs, &merged, BOTH).unwrap();
        assert!(std::fs::read(&whole.out).unwrap() == std::fs::read(&merged).unwrap());
        let raw = rooms.dir.path().join("raw.exr");
        finish_with(&texels, &dirs, &raw, FinishOptions::default()).unwrap();
        assert!(std::fs::read(&raw).unwrap() != std::fs::read(&merged).unwrap());
    }

    #[test]
    fn the_parallel_finish_writes_the_same_bytes_at_any_thread_count() {
        // Denoised and stitched: tiles prepared in parallel batches, pages dilated in bands.
        let rooms = Rooms::new();
        let whole = rooms.job("whole.exr", Shard::WHOLE, BOTH);
        rooms.bake(&whole);
        let mut dirs = Vec::new();
        for index in [0, 1] {
            let job = rooms.job("kept.exr", Shard { index, count: 2 }, BOTH);
            rooms.bake(&job);
            dirs.push(work_dir(&job.out, job.shard));
        }
        let texels = TexelFile::open(&rooms.texels).unwrap();
        let page = |p: &Path| {
            (
                std::fs::read(p).unwrap(),
                std::fs::read(crate::output::exr_pages::preview_path(p)).unwrap(),
            )
        };
        let expected = page(&whole.out);
        for threads in [1, 2, 3, 5] {
            let out = rooms.dir.path().join(format!("t{threads}.exr"));
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| finish_with(&texels, &dirs, &out, BOTH))
                .unwrap();
            assert!(
                page(&out) == expected,
                "EXR or PNG bytes differ at {threads} threads"
            );
        }
    }

    #[test]
    fn a_thin_wall_keeps_the_dark_room_dark_after_denoising() {
        let rooms = Rooms::new();
        let (raw, denoised) = (
            rooms.job("raw.exr", Shard::WHOLE, FinishOptions::default()),
            rooms.job("denoised.exr", Shard::WHOLE, DENOISE),
        );
        rooms.bake(&raw);
        rooms.bake(&denoised);
        let texels = TexelFile::open(&rooms.texels).unwrap();
        let read = |out: &Path| crate::output::readback::read_lightmap(&texels, out).unwrap();
        let (before, after) = (read(&raw.out), read(&denoised.out));
        let spacing = 0.1;
        let (mut dark, mut lit_sum, mut lit_sum_raw, mut lit) = (0, 0.0f64, 0.0f64, 0);
        for (i, texel) in texels.texels().iter().enumerate() {
            let (Some(b), Some(a)) = (before[i], after[i]) else {
                continue;
            };
            let p = texel.position();
            if p.x > WALL + THICK + 2.0 * spacing {
                // The dark room, two texels or more from the wall: no light reaches it.
                dark += 1;
                assert_eq!(b, [0.0; 3], "raw dark texel {i} at {p}");
                assert_eq!(a, [0.0; 3], "denoised dark texel {i} at {p} took light");
            } else if p.x < WALL - 2.0 * spacing {
                lit += 1;
                lit_sum += f64::from(a[0]);
                lit_sum_raw += f64::from(b[0]);
            }
        }
        assert!(dark > 500 && lit > 500, "{dark} dark, {lit} lit texels");
        let (mean, mean_raw) = (lit_sum / lit as f64, lit_sum_raw / lit as f64);
        assert!(mean_raw > 0.5, "the lit room is lit: {mean_raw}");
        assert!(
            (mean - mean_raw).abs() < 0.03 * mean_raw,
            "the filter keeps the lit room's mean: {mean_raw} → {mean}"
        );
    }

    #[test]
    fn stitching_closes_the_floor_seam() {
        let rooms = Rooms::new();
        let stitched = FinishOptions {
            denoise: Denoise::Off,
            seams: Seams::Stitch,
        };
        // Baked in two shards (whose work stays) and merged, to read what the stitch did.
        let mut dirs = Vec::new();
        for index in [0, 1] {
            let job = rooms.job("stitched.exr", Shard { index, count: 2 }, stitched);
            rooms.bake(&job);
            dirs.push(work_dir(&job.out, job.shard));
        }
        let texels = TexelFile::open(&rooms.texels).unwrap();
        let out = rooms.dir.path().join("merged.exr");
        let written = finish_with(&texels, &dirs, &out, stitched).unwrap();
        let [before, after] = written.edge_jump.expect("seams were stitched");
        let [points, skipped, _] = written.edge_points;
        assert!(
            points >= 40 && skipped == 0,
            "{points} points, {skipped} left out"
        );
        assert!(before > 0.02, "the raw jumps at the edge: {before}");
        assert!(
            after < before / 8.0,
            "mean relative edge jump {before} → {after}"
        );
        let [pairs_before, pairs_after] = written.seam_jump.expect("seams were stitched");
        assert!(
            pairs_before > 0.02,
            "the raw texel-pair jumps: {pairs_before}"
        );
        assert!(
            pairs_after < pairs_before,
            "texel-pair jump {pairs_before} → {pairs_after}"
        );
        let pairs = read_seam_file(&seam_file_path(&rooms.texels))
            .unwrap()
            .pairs;
        assert!(pairs.len() >= 20, "{} pairs", pairs.len());
        // Only the floor's cut at x = 1 is a seam (faces meet at right angles elsewhere): the
        // pairs' texels lie on it.
        let at: std::collections::HashMap<Pixel, Vec3> = texels
            .texels()
            .iter()
            .map(|t| {
                (
                    [t.page, u32::from(t.pixel[0]), u32::from(t.pixel[1])],
                    t.position(),
                )
            })
            .collect();
        for p in &pairs {
            let (a, b) = (at[&p.a], at[&p.b]);
            assert!(
                (a.x - 1.0).abs() < 0.2 && (b.x - 1.0).abs() < 0.2,
                "{a} {b}"
            );
            assert!(
                a.y.abs() < 1e-3 && b.y.abs() < 1e-3,
                "on the floor: {a} {b}"
            );
        }
    }
}
