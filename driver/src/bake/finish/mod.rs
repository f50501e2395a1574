//! The end of a bake: ρ or the global weights reduced over every tile of the shards' work
//! directories, then the pages written ([`finish`]); and the merge of one series pass of every
//! shard into the next pass's input ([`merge_pass`]). Shards and merging: docs/farm.md.

use std::path::{Path, PathBuf};

use super::directional::SH_CHANNELS;
use super::error::{BakeError, file_error};
use super::settings::SettingsError;
use super::workdir::{merged_dir, merged_results, read_manifest};
use crate::atomic::temporary_name;
use crate::output::denoise::{ATrous, Denoiser};
use crate::output::exr_pages::{PageStream, page_path};
use crate::output::journal::rho_sums;
use crate::output::result_file::{ResultFile, TexelResult};
use crate::texels::TexelFile;
use guidebake_kernels::estimator::luminance_f32;

mod shards;
mod stitch;
mod tiles;

use shards::*;
use stitch::*;
use tiles::*;

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

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicBool;

    use crate::output::seams::{Pixel, read_seam_file, seam_file_path};
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
