//! Lightmap pages as OpenEXR files: the last step of a bake and of `guidebake merge`.
//!
//! The bake writes its pages through a [`PageStream`], which never holds a page image: a
//! scratch file beside the page, dilation on a rolling window of rows, EXR blocks and PNG rows
//! read from it on demand (docs/farm.md). [`PageImage`], the page in memory, is the
//! reference it is tested against byte for byte, and what small pages (the bench's read-back
//! tests) use.
//!
//! A [`PageImage`] holds one atlas page: irradiance RGB, which pixels hold a texel, and any
//! auxiliary channels (`--aux`). Before writing, [`PageImage::dilate`] pushes the irradiance of
//! covered pixels into the empty pixels around them, so bilinear lookups at chart borders do
//! not blend in black (every production baker pads its charts; the number of passes is the
//! padding width in pixels). Non-finite values are replaced by zero and counted — NaN and ∞
//! never reach an output. Each page is written to a temporary name in the same directory and
//! renamed, so a page that exists is complete.

use std::path::{Path, PathBuf};

use exr::prelude::{Image, Layer, LayerAttributes, WritableImage};
use guidebake_kernels::estimator::luminance_f32;

use crate::atomic::temporary_name;

mod dilation;
mod encode;
mod identity;
mod page_image;

pub use identity::{
    IDENTITY_ATTRIBUTE, LightmapIdentity, TEXEL_FILE_KEY, TEXELS_KEY, read_identity,
};
pub use page_image::PageImage;

use dilation::*;
use encode::*;

/// What went wrong writing a page; names the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {what}")]
pub struct PageWriteError {
    /// The page file.
    pub path: PathBuf,
    /// What failed.
    pub what: String,
}

/// One atlas page written without holding its image: pixels go to a scratch file beside the
/// page (one record of `1 + channels` `f32` per pixel: covered, then the EXR channels in the
/// file's order), tile by tile through positioned reads and writes; [`Self::finish`] dilates
/// it on a rolling window of rows, streams the EXR's blocks from it, and streams the PNG
/// preview row by row. The EXR holds the same bytes as a [`PageImage`] of the same pixels
/// (tested); memory is a few rows of the page, whatever its height — no page image, and the
/// scratch file is file-backed, left to the page cache.
pub struct PageStream {
    scratch: std::fs::File,
    scratch_path: PathBuf,
    width: usize,
    height: usize,
    /// Channel names in the EXR's order (sorted), R, G, B among them.
    names: Vec<String>,
    /// Record index of R, G, B.
    rgb: [usize; 3],
    /// Record index of each auxiliary channel, in the order they were given.
    aux: Vec<usize>,
    /// Record indices dilation fills: R, G, B, then the dilated auxiliary channels.
    dilated: Vec<usize>,
    /// Pixels whose values were not finite, replaced by zero.
    non_finite: u64,
    /// What made the page, written into its header ([`LightmapIdentity`]).
    identity: Option<LightmapIdentity>,
}

/// Record slot of the covered flag (1.0 where a texel was written).
const COVERED: usize = 0;
/// Bytes of compressed preview held before they go out as one PNG `IDAT` chunk.
const PNG_CHUNK_BYTES: usize = 1 << 20;

/// The pixels of one rectangle of a [`PageStream`], read from and written back to its
/// scratch file.
pub struct PageRect {
    x: usize,
    y: usize,
    width: usize,
    height: usize,
    stride: usize,
    records: Vec<f32>,
}

impl PageStream {
    /// A black, uncovered page of `width` × `height` pixels with auxiliary channels `aux`
    /// (zero everywhere), of which those named in `dilated` are dilated as the irradiance is
    /// (as [`PageImage::add_dilated_channel`]), its scratch file at `scratch` (created sparse;
    /// removed by [`Self::finish`] or on drop).
    ///
    /// # Errors
    /// [`PageWriteError`] naming the scratch file when it cannot be created.
    ///
    /// # Panics
    /// If the page is empty.
    pub fn create(
        scratch: &Path,
        width: u32,
        height: u32,
        aux: &[&str],
        dilated: &[&str],
    ) -> Result<Self, PageWriteError> {
        assert!(
            width > 0 && height > 0,
            "a lightmap page has at least one pixel"
        );
        let mut names: Vec<String> = ["R", "G", "B"]
            .into_iter()
            .chain(aux.iter().copied())
            .map(str::to_owned)
            .collect();
        names.sort_by(|a, b| a.as_bytes().cmp(b.as_bytes()));
        let slot = |name: &str| 1 + names.iter().position(|n| n == name).expect("a channel");
        let rgb = ["R", "G", "B"].map(slot);
        let dilated = rgb
            .into_iter()
            .chain(aux.iter().filter(|a| dilated.contains(a)).map(|a| slot(a)))
            .collect();
        let aux = aux.iter().map(|a| slot(a)).collect();
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(scratch)
            .map_err(|e| {
                page_error(
                    scratch,
                    format!("cannot create the page's scratch file: {e}"),
                )
            })?;
        let stream = Self {
            scratch: file,
            scratch_path: scratch.to_owned(),
            width: width as usize,
            height: height as usize,
            rgb,
            aux,
            dilated,
            names,
            non_finite: 0,
            identity: None,
        };
        let bytes = (stream.width * stream.height * stream.stride() * 4) as u64;
        stream
            .scratch
            .set_len(bytes)
            .map_err(|e| page_error(scratch, format!("cannot size the scratch file: {e}")))?;
        Ok(stream)
    }

    /// Writes `identity` into the page's header ([`LightmapIdentity`]).
    pub fn set_identity(&mut self, identity: LightmapIdentity) {
        self.identity = Some(identity);
    }

    /// `f32`s per pixel record.
    fn stride(&self) -> usize {
        1 + self.names.len()
    }

    fn scratch_error(&self, what: &str, e: std::io::Error) -> PageWriteError {
        page_error(
            &self.scratch_path,
            format!("cannot {what} the scratch file: {e}"),
        )
    }

    /// Reads `n` records from pixel index `first` into `out`.
    fn read_records(&self, first: usize, out: &mut [f32]) -> Result<(), PageWriteError> {
        use std::os::unix::fs::FileExt;
        let offset = (first * self.stride() * 4) as u64;
        self.scratch
            .read_exact_at(bytemuck::cast_slice_mut(out), offset)
            .map_err(|e| self.scratch_error("read", e))
    }

    fn write_records(&self, first: usize, records: &[f32]) -> Result<(), PageWriteError> {
        use std::os::unix::fs::FileExt;
        let offset = (first * self.stride() * 4) as u64;
        self.scratch
            .write_all_at(bytemuck::cast_slice(records), offset)
            .map_err(|e| self.scratch_error("write", e))
    }

    /// The pixels of the rectangle at (`x`, `y`) of `width` × `height`, as they are now.
    ///
    /// # Errors
    /// [`PageWriteError`] when the scratch file cannot be read.
    ///
    /// # Panics
    /// If the rectangle leaves the page.
    pub fn rect(
        &self,
        x: u32,
        y: u32,
        width: u32,
        height: u32,
    ) -> Result<PageRect, PageWriteError> {
        let (x, y, w, h) = (x as usize, y as usize, width as usize, height as usize);
        assert!(
            x + w <= self.width && y + h <= self.height,
            "rectangle off the page"
        );
        let stride = self.stride();
        let mut records = vec![0.0; w * h * stride];
        for row in 0..h {
            let line = &mut records[row * w * stride..(row + 1) * w * stride];
            self.read_records((y + row) * self.width + x, line)?;
        }
        Ok(PageRect {
            x,
            y,
            width: w,
            height: h,
            stride,
            records,
        })
    }

    /// Writes a rectangle back.
    ///
    /// # Errors
    /// [`PageWriteError`] when the scratch file cannot be written.
    pub fn put_rect(&self, rect: &PageRect) -> Result<(), PageWriteError> {
        let row_len = rect.width * rect.stride;
        for row in 0..rect.height {
            let line = &rect.records[row * row_len..(row + 1) * row_len];
            self.write_records((rect.y + row) * self.width + rect.x, line)?;
        }
        Ok(())
    }

    /// Sets the irradiance of pixel (`x`, `y`) of `rect` (page coordinates) and marks it
    /// covered, then its auxiliary channels `aux` (in [`Self::create`]'s order). Non-finite
    /// values are stored as zero; a pixel whose irradiance is not finite is counted.
    ///
    /// # Panics
    /// If the pixel lies outside the rectangle.
    pub fn set(&mut self, rect: &mut PageRect, x: u32, y: u32, rgb: [f32; 3], aux: &[f32]) {
        let (x, y) = (x as usize, y as usize);
        assert!(
            (rect.x..rect.x + rect.width).contains(&x)
                && (rect.y..rect.y + rect.height).contains(&y),
            "pixel off the rectangle"
        );
        let at = ((y - rect.y) * rect.width + (x - rect.x)) * rect.stride;
        let record = &mut rect.records[at..at + rect.stride];
        let finite = rgb.iter().all(|c| c.is_finite());
        for (slot, c) in self.rgb.iter().zip(rgb) {
            record[*slot] = if finite { c } else { 0.0 };
        }
        record[COVERED] = 1.0;
        for (slot, v) in self.aux.iter().zip(aux) {
            record[*slot] = if v.is_finite() { *v } else { 0.0 };
        }
        if !finite {
            self.non_finite += 1;
        }
    }

    /// Replaces the irradiance of the covered pixel (`x`, `y`) and its auxiliary channels
    /// from the `aux_from`-th on (in [`Self::create`]'s order) with `aux` (a seam stitched
    /// after its tile was written). Non-finite values are stored as zero; a pixel whose
    /// irradiance is not finite is counted.
    ///
    /// # Errors
    /// [`PageWriteError`] when the scratch file cannot be read or written.
    ///
    /// # Panics
    /// If the pixel lies outside the page or the channels beyond its auxiliary ones.
    pub fn set_channels(
        &mut self,
        x: u32,
        y: u32,
        rgb: [f32; 3],
        aux_from: usize,
        aux: &[f32],
    ) -> Result<(), PageWriteError> {
        let (x, y) = (x as usize, y as usize);
        assert!(x < self.width && y < self.height, "pixel off the page");
        let mut record = vec![0.0f32; self.stride()];
        self.read_records(y * self.width + x, &mut record)?;
        let finite = rgb.iter().all(|c| c.is_finite());
        for (slot, c) in self.rgb.iter().zip(rgb) {
            record[*slot] = if finite { c } else { 0.0 };
        }
        for (slot, v) in self.aux[aux_from..aux_from + aux.len()].iter().zip(aux) {
            record[*slot] = if v.is_finite() { *v } else { 0.0 };
        }
        if !finite {
            self.non_finite += 1;
        }
        self.write_records(y * self.width + x, &record)
    }

    /// Pixels with non-finite values replaced by zero so far.
    pub fn non_finite_pixels(&self) -> u64 {
        self.non_finite
    }

    /// Dilates by `passes` pixels (as [`PageImage::dilate`]), writes the EXR at `path` and
    /// the tone-mapped PNG preview at `preview` (as [`PageImage::write_exr`] and
    /// [`PageImage::write_preview`]), and removes the scratch file.
    ///
    /// # Errors
    /// [`PageWriteError`] naming the file at fault; no partial page or preview is left.
    ///
    /// The dilation runs in bands in parallel; then the EXR and the preview, which only read
    /// the dilated scratch file, are written side by side (the EXR's blocks compressed in
    /// parallel by the exr crate, in increasing line order): the same bytes at any thread
    /// count.
    pub fn finish(self, passes: u32, path: &Path, preview: &Path) -> Result<(), PageWriteError> {
        let luminance = self.dilate(passes)?;
        let tmp = temporary_name(path);
        let (written, previewed) = rayon::join(
            || {
                self.encode(&tmp)
                    .and_then(|()| {
                        std::fs::rename(&tmp, path)
                            .map_err(|e| format!("cannot rename into place: {e}"))
                    })
                    .map_err(|what| page_error(path, what))
            },
            || self.write_preview(preview, luminance),
        );
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            // A page that failed leaves no preview either.
            if previewed.is_ok() {
                let _ = std::fs::remove_file(preview);
            }
            return Err(e);
        }
        previewed
    }

    /// Dilates the scratch file in place, band by band in parallel (rayon's current pool);
    /// returns the sum and count of the covered pixels' luminance (row-major, as
    /// [`PageImage::write_preview`] sums).
    ///
    /// The page is cut into bands of [`DILATION_BAND_ROWS`] rows, dilated `threads` at a time.
    /// Each band runs its own [`DilationWindow`] over its rows and `passes` rows of halo above
    /// and below: after `passes` passes a row depends only on the rows within `passes` of it,
    /// so the band's own rows come out as one window over the whole page makes them (the same
    /// bits, tested). A band writes only its own rows; its halo rows are read by this thread
    /// before any band of the batch starts (and the top halo of a batch's first band before
    /// the previous batch starts), so no band reads a row another has dilated. Memory: per
    /// band in flight its window, `2 passes` halo rows and its covered pixels' luminance —
    /// whatever the page's height.
    fn dilate(&self, passes: u32) -> Result<(f32, usize), PageWriteError> {
        use rayon::prelude::*;
        let p = passes as usize;
        let band_rows = DILATION_BAND_ROWS.max(p).max(1);
        let bands: Vec<(usize, usize)> = (0..self.height)
            .step_by(band_rows)
            .map(|y0| (y0, (y0 + band_rows).min(self.height)))
            .collect();
        let threads = rayon::current_num_threads().max(1);
        let (mut sum, mut count) = (0.0f32, 0usize);
        // The undilated rows above the next batch's first band.
        let mut carry: Vec<Vec<f32>> = Vec::new();
        for batch in bands.chunks(threads) {
            let mut halos = Vec::with_capacity(batch.len());
            for (i, &(y0, y1)) in batch.iter().enumerate() {
                let top = if i == 0 {
                    std::mem::take(&mut carry)
                } else {
                    self.read_rows(y0.saturating_sub(p)..y0)?
                };
                let bottom = self.read_rows(y1..(y1 + p).min(self.height))?;
                halos.push((top, bottom));
            }
            let end = batch.last().map_or(0, |b| b.1);
            if end < self.height {
                carry = self.read_rows(end.saturating_sub(p)..end)?;
            }
            let luminances: Vec<Result<Vec<f32>, PageWriteError>> = batch
                .par_iter()
                .zip(halos)
                .map(|(&(y0, y1), (top, bottom))| self.dilate_band(p, y0..y1, top, bottom))
                .collect();
            for band in luminances {
                for l in band? {
                    sum += l;
                    count += 1;
                }
            }
        }
        Ok((sum, count))
    }

    /// Rows `rows` of the scratch file, one record vector each.
    fn read_rows(&self, rows: std::ops::Range<usize>) -> Result<Vec<Vec<f32>>, PageWriteError> {
        rows.map(|y| {
            let mut row = vec![0.0f32; self.width * self.stride()];
            self.read_records(y * self.width, &mut row).map(|()| row)
        })
        .collect()
    }

    /// Dilates rows `rows` in place, from them and the undilated halo rows `top` (just above)
    /// and `bottom` (just below); returns the luminance of their covered pixels, row-major.
    fn dilate_band(
        &self,
        passes: usize,
        rows: std::ops::Range<usize>,
        top: Vec<Vec<f32>>,
        bottom: Vec<Vec<f32>>,
    ) -> Result<Vec<f32>, PageWriteError> {
        let stride = self.stride();
        let first = rows.start - top.len();
        let last = rows.end + bottom.len() - 1;
        let mut window =
            DilationWindow::starting_at(first, passes, self.width, stride, self.dilated.clone());
        let mut luminance = Vec::new();
        let mut failure = None;
        let mut emit = |y: usize, row: &[f32], changed: bool| {
            if changed && rows.contains(&y) && failure.is_none() {
                failure = self.write_records(y * self.width, row).err();
            }
        };
        for (k, row) in top.into_iter().enumerate() {
            window.push(first + k, row, false, &mut emit);
        }
        for y in rows.clone() {
            let mut row = vec![0.0f32; self.width * stride];
            self.read_records(y * self.width, &mut row)?;
            for record in row.chunks_exact(stride).filter(|r| r[COVERED] != 0.0) {
                luminance.push(luminance_f32(self.rgb.map(|s| record[s])));
            }
            window.push(y, row, y == last, &mut emit);
        }
        for (k, row) in bottom.into_iter().enumerate() {
            let y = rows.end + k;
            window.push(y, row, y == last, &mut emit);
        }
        failure.map_or(Ok(luminance), Err)
    }

    /// Writes the EXR to `tmp` as [`PageImage::encode`] does, its blocks read from the
    /// scratch file as the writer asks for them.
    fn encode(&self, tmp: &Path) -> Result<(), String> {
        let failure = std::sync::Mutex::new(None);
        let mut attributes = LayerAttributes::named("lightmap");
        if let Some(identity) = &self.identity {
            identity.write_into(&mut attributes);
        }
        let layer = Layer::new(
            (self.width, self.height),
            attributes,
            page_encoding(),
            StreamedChannels {
                page: self,
                failure: &failure,
            },
        );
        Image::from_layer(layer)
            .write()
            .to_file(tmp)
            .map_err(|e| format!("cannot write EXR: {e}"))?;
        match failure.into_inner().unwrap_or(None) {
            Some(e) => Err(e.to_string()),
            None => Ok(()),
        }
    }

    fn write_preview(&self, path: &Path, (sum, count): (f32, usize)) -> Result<(), PageWriteError> {
        let mean = sum / count.max(1) as f32;
        let exposure = if mean > 0.0 && mean.is_finite() {
            1.0 / mean
        } else {
            1.0
        };
        let stride = self.stride();
        let mut row = vec![0.0f32; self.width * stride];
        let mut bytes = Vec::with_capacity(self.width * 3);
        let tmp = temporary_name(path);
        let written = (|| -> Result<(), String> {
            let file = std::fs::File::create(&tmp).map_err(|e| format!("cannot create: {e}"))?;
            let mut encoder = png::Encoder::new(
                std::io::BufWriter::new(file),
                self.width as u32,
                self.height as u32,
            );
            // The settings `image` uses for a PNG (what `write_png_rgb8` wrote).
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            encoder.set_compression(png::Compression::Balanced);
            encoder.set_filter(png::Filter::Adaptive);
            let mut header = encoder.write_header().map_err(|e| e.to_string())?;
            let mut stream = header
                .stream_writer_with_size(PNG_CHUNK_BYTES)
                .map_err(|e| e.to_string())?;
            for y in 0..self.height {
                self.read_records(y * self.width, &mut row)
                    .map_err(|e| e.to_string())?;
                bytes.clear();
                bytes.extend(row.chunks_exact(stride).flat_map(|r| {
                    crate::preview::tonemap_reinhard(self.rgb.map(|s| r[s]), exposure)
                }));
                std::io::Write::write_all(&mut stream, &bytes).map_err(|e| e.to_string())?;
            }
            stream.finish().map_err(|e| e.to_string())?;
            header.finish().map_err(|e| e.to_string())?;
            std::fs::rename(&tmp, path).map_err(|e| format!("cannot rename into place: {e}"))
        })();
        written.map_err(|what| {
            let _ = std::fs::remove_file(&tmp);
            page_error(path, format!("cannot write the PNG preview: {what}"))
        })
    }
}

impl Drop for PageStream {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.scratch_path);
    }
}

fn page_error(path: &Path, what: String) -> PageWriteError {
    PageWriteError {
        path: path.to_owned(),
        what,
    }
}

/// The file of page `page` of `page_count`: `OUT.exr` itself for a single page, otherwise
/// `OUT.page{N}.exr` beside it.
pub fn page_path(out: &Path, page: u32, page_count: u32) -> PathBuf {
    if page_count <= 1 {
        return out.to_owned();
    }
    let stem = out
        .file_stem()
        .map_or_else(|| "lightmap".into(), |s| s.to_string_lossy());
    let ext = out
        .extension()
        .map_or_else(|| "exr".into(), |s| s.to_string_lossy());
    out.with_file_name(format!("{stem}.page{page}.{ext}"))
}

/// The tone-mapped atlas preview of the page at `page`: `NAME.atlas.png` beside `NAME.exr`
/// (a name of its own, so a view rendered as `NAME.png` does not replace it).
pub fn preview_path(page: &Path) -> PathBuf {
    page.with_extension("atlas.png")
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::{Vec2, read_all_flat_layers_from_file};

    #[test]
    fn exr_round_trips_rgb_and_aux_channels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lm.exr");
        let mut page = PageImage::new(5, 3);
        let aux = page.add_aux_channel("samples");
        assert!(page.set(1, 2, [0.25, 1e5, 1e-4]));
        assert!(page.set_aux(aux, 1, 2, 256.0));
        page.write_exr(&path).unwrap();

        let image = read_all_flat_layers_from_file(&path).unwrap();
        let layer = &image.layer_data[0];
        assert_eq!(layer.size, Vec2(5, 3));
        let channel = |name: &str| {
            let c = layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name == *name)
                .unwrap();
            c.sample_data.values_as_f32().collect::<Vec<f32>>()
        };
        let at = 2 * 5 + 1;
        assert_eq!(channel("R")[at], 0.25);
        assert_eq!(channel("G")[at], 1e5);
        assert_eq!(channel("B")[at], 1e-4);
        assert_eq!(channel("samples")[at], 256.0);
        assert_eq!(channel("R")[0], 0.0);
        let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(leftovers.len(), 1, "no temporary file is left behind");
    }

    #[test]
    fn non_finite_values_never_reach_the_page() {
        let mut page = PageImage::new(2, 2);
        assert!(!page.set(0, 0, [f32::NAN, 1.0, 1.0]));
        assert!(!page.set(1, 0, [f32::INFINITY, 1.0, 1.0]));
        assert_eq!(page.get(0, 0), [0.0; 3]);
        assert_eq!(page.get(1, 0), [0.0; 3]);
        let aux = page.add_aux_channel("x");
        assert!(!page.set_aux(aux, 0, 1, f32::NEG_INFINITY));
    }

    #[test]
    fn dilation_pads_charts_without_touching_covered_pixels() {
        let mut page = PageImage::new(5, 1);
        page.set(1, 0, [2.0, 2.0, 2.0]);
        page.set(2, 0, [4.0, 4.0, 4.0]);
        assert_eq!(page.dilate(1), 2);
        assert_eq!(page.get(0, 0), [2.0; 3]);
        assert_eq!(page.get(3, 0), [4.0; 3]);
        assert_eq!(page.get(4, 0), [0.0; 3], "one pass pads one pixel");
        assert!(!page.is_covered(0, 0));
        let mut wider = PageImage::new(5, 1);
        wider.set(1, 0, [2.0, 2.0, 2.0]);
        wider.set(2, 0, [4.0, 4.0, 4.0]);
        assert_eq!(
            wider.dilate(3),
            3,
            "filled pixels are sources for later passes"
        );
        assert_eq!(wider.get(4, 0), [4.0; 3]);
        assert_eq!(wider.get(2, 0), [4.0; 3]);
    }

    #[test]
    fn dilated_channels_take_the_irradiance_sources() {
        // A ragged chart whose dilated channel holds each texel's red value and whose plain
        // channel holds 1: after two passes every padding pixel's dilated value is its red
        // (the same neighbours, the same sums), and the plain channel's padding stays 0.
        let mut page = PageImage::new(7, 6);
        let dilated = page.add_dilated_channel("SH0.R");
        let plain = page.add_aux_channel("samples");
        let chart = [
            (2, 1, 0.5),
            (3, 1, 1.25),
            (2, 2, 3.0),
            (4, 3, 7.5),
            (3, 2, 0.125),
        ];
        for (x, y, v) in chart {
            page.set(x, y, [v, 2.0 * v, 0.0]);
            page.set_aux(dilated, x, y, v);
            page.set_aux(plain, x, y, 1.0);
        }
        let filled = page.dilate(2);
        assert!(filled > 20, "{filled} padding pixels");
        let (mut padding, mut empty) = (0, 0);
        for y in 0..6 {
            for x in 0..7 {
                let i = page.index(x, y);
                let (sh, samples) = (page.aux[dilated].1[i], page.aux[plain].1[i]);
                assert_eq!(sh.to_bits(), page.get(x, y)[0].to_bits(), "({x}, {y})");
                if page.is_covered(x, y) {
                    assert_eq!(samples, 1.0);
                } else if page.get(x, y)[0] != 0.0 {
                    padding += 1;
                    assert_eq!(samples, 0.0, "({x}, {y}): a plain channel is not dilated");
                } else {
                    empty += 1;
                }
            }
        }
        assert!(
            padding > 20 && empty > 0,
            "{padding} padding, {empty} empty"
        );
    }

    #[test]
    fn a_failed_write_names_the_file_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing-dir").join("lm.exr");
        let err = PageImage::new(1, 1).write_exr(&path).unwrap_err();
        assert!(err.to_string().contains("lm.exr"), "{err}");
        assert!(!path.exists());
    }

    #[test]
    fn previews_are_tone_mapped_pngs() {
        let dir = tempfile::tempdir().unwrap();
        let mut page = PageImage::new(3, 2);
        page.set(0, 0, [1e5, 1e5, 1e5]);
        page.set(1, 0, [1e-4, 1e-4, 1e-4]);
        let path = dir.path().join("lm.png");
        page.write_preview(&path).unwrap();
        let png = image::open(&path).unwrap().to_rgb8();
        assert_eq!(png.dimensions(), (3, 2));
        assert!(png.get_pixel(0, 0)[0] > png.get_pixel(1, 0)[0]);
        assert_eq!(png.get_pixel(2, 1).0, [0, 0, 0]);
    }

    /// A page of `width` × `height` with charts of random rectangles (some values not finite),
    /// written both ways: as a [`PageImage`] and streamed through a [`PageStream`] in random
    /// rectangles. Returns the two EXRs' bytes and the two previews' pixels.
    fn both_ways(
        width: u32,
        height: u32,
        aux: &[&str],
        dilated: &[&str],
        seed: u64,
    ) -> [(Vec<u8>, Vec<u8>); 2] {
        let [a, b, _] = both_ways_on(1, 12, width, height, aux, dilated, seed);
        [a, b]
    }

    /// [`both_ways`] with `rects` charts, the stream finished on a pool of `threads`; the
    /// third pair is the stream's EXR and PNG file bytes.
    fn both_ways_on(
        threads: usize,
        rects: usize,
        width: u32,
        height: u32,
        aux: &[&str],
        dilated: &[&str],
        seed: u64,
    ) -> [(Vec<u8>, Vec<u8>); 3] {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut next = |n: u32| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng % u64::from(n)) as u32
        };
        let mut image = PageImage::new(width, height);
        let channels: Vec<usize> = aux
            .iter()
            .map(|a| {
                if dilated.contains(a) {
                    image.add_dilated_channel(a)
                } else {
                    image.add_aux_channel(a)
                }
            })
            .collect();
        let scratch = dir.path().join("scratch");
        let mut stream = PageStream::create(&scratch, width, height, aux, dilated).unwrap();
        let mut non_finite = 0;
        for _ in 0..rects {
            let (w, h) = (1 + next(width.min(40)), 1 + next(height.min(40)));
            let (x0, y0) = (next(width - w + 1), next(height - h + 1));
            let mut rect = stream.rect(x0, y0, w, h).unwrap();
            for y in y0..y0 + h {
                for x in x0..x0 + w {
                    if next(4) == 0 {
                        continue; // a hole inside the chart
                    }
                    let mut rgb = [next(1000) as f32 * 0.37, next(7) as f32, 1e-4];
                    if next(50) == 0 {
                        rgb[1] = f32::NAN;
                    }
                    let values: Vec<f32> = aux.iter().map(|_| next(100) as f32 - 50.0).collect();
                    non_finite += u64::from(!image.set(x, y, rgb));
                    for (c, v) in channels.iter().zip(&values) {
                        image.set_aux(*c, x, y, *v);
                    }
                    stream.set(&mut rect, x, y, rgb, &values);
                }
            }
            stream.put_rect(&rect).unwrap();
        }
        assert_eq!(stream.non_finite_pixels(), non_finite);
        image.dilate(DILATION);
        let (a, b) = (dir.path().join("a.exr"), dir.path().join("b.exr"));
        image.write_exr(&a).unwrap();
        image.write_preview(&a.with_extension("png")).unwrap();
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| stream.finish(DILATION, &b, &b.with_extension("png")))
            .unwrap();
        assert!(
            !dir.path().join("scratch").exists(),
            "the scratch file is removed"
        );
        let pixels = |p: &Path| image::open(p).unwrap().to_rgb8().into_raw();
        let files = (
            std::fs::read(&b).unwrap(),
            std::fs::read(b.with_extension("png")).unwrap(),
        );
        let [a, b] = [a, b].map(|p| (std::fs::read(&p).unwrap(), pixels(&p.with_extension("png"))));
        [a, b, files]
    }

    #[test]
    fn the_parallel_finish_writes_the_same_bytes_at_any_thread_count() {
        // Tall pages: many dilation bands, charts across their borders, batches of bands
        // (threads at a time) with a carried halo; wide rows with directional channels.
        let aux = ["SH0.R", "SH1x.G", "samples"];
        for (seed, (w, h), rects, aux, dilated) in [
            (11, (70, 700), 80, &[][..], &[][..]),
            (12, (33, 1031), 120, &aux[..], &aux[..2]),
            (13, (300, 130), 40, &aux[..1], &aux[..1]),
            (14, (9, 65), 10, &[][..], &[][..]),
        ] {
            let mut first = None;
            for threads in [1, 2, 3, 7] {
                let [(exr_a, png_a), (exr_b, png_b), files] =
                    both_ways_on(threads, rects, w, h, aux, dilated, seed);
                assert!(
                    exr_a == exr_b,
                    "EXR bytes differ from the page image: {w}x{h}, {threads} threads"
                );
                assert!(
                    png_a == png_b,
                    "preview pixels differ from the page image: {w}x{h}, {threads} threads"
                );
                match &first {
                    None => first = Some(files),
                    Some(one) => assert!(
                        *one == files,
                        "EXR or PNG bytes differ between 1 and {threads} threads: {w}x{h}"
                    ),
                }
            }
        }
    }

    const DILATION: u32 = 2;

    #[test]
    fn a_streamed_page_is_the_page_image_byte_for_byte() {
        let aux = [
            "samples",
            "rel_std_error",
            "validity",
            "P.X",
            "N.Z",
            "SH0.R",
            "SH1z.B",
        ];
        let sh = &aux[5..];
        for (seed, (w, h), aux, dilated) in [
            (1, (64, 48), &aux[..], sh),
            (2, (300, 257), &aux[..2], &[][..]),
            (3, (1, 1), &[][..], &[][..]),
            (4, (5, 90), &[][..], &[][..]),
            (5, (513, 3), &aux[..], sh),
            (6, (37, 41), &aux[4..], &aux[4..]),
        ] {
            let [(exr_a, png_a), (exr_b, png_b)] = both_ways(w, h, aux, dilated, seed);
            assert!(exr_a == exr_b, "EXR bytes differ: {w}x{h} seed {seed}");
            assert!(png_a == png_b, "preview pixels differ: {w}x{h} seed {seed}");
        }
    }

    #[test]
    fn page_paths() {
        assert_eq!(
            page_path(Path::new("o/lm.exr"), 0, 1),
            Path::new("o/lm.exr")
        );
        assert_eq!(
            page_path(Path::new("o/lm.exr"), 2, 3),
            Path::new("o/lm.page2.exr")
        );
    }
}
