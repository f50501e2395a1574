//! Lightmap pages as OpenEXR files: the last step of a bake and of `guidebake merge`.
//!
//! A [`PageImage`] holds one atlas page: irradiance RGB, which pixels hold a texel, and any
//! auxiliary channels (`--aux`). Before writing, [`PageImage::dilate`] pushes the irradiance of
//! covered pixels into the empty pixels around them, so bilinear lookups at chart borders do
//! not blend in black (every production baker pads its charts; the number of passes is the
//! padding width in pixels). Non-finite values are replaced by zero and counted — NaN and ∞
//! never reach an output. Each page is written to a temporary name in the same directory and
//! renamed, so a page that exists is complete.

use std::path::{Path, PathBuf};

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, LineOrder,
    SmallVec, WritableImage,
};

/// One atlas page of a lightmap.
#[derive(Clone, Debug, PartialEq)]
pub struct PageImage {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
    covered: Vec<bool>,
    aux: Vec<(String, Vec<f32>)>,
}

/// What went wrong writing a page; names the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {what}")]
pub struct PageWriteError {
    /// The page file.
    pub path: PathBuf,
    /// What failed.
    pub what: String,
}

impl PageImage {
    /// A black, uncovered page of `width` × `height` pixels.
    ///
    /// # Panics
    /// If the page is empty.
    pub fn new(width: u32, height: u32) -> Self {
        assert!(
            width > 0 && height > 0,
            "a lightmap page has at least one pixel"
        );
        let n = width as usize * height as usize;
        Self {
            width: width as usize,
            height: height as usize,
            rgb: vec![[0.0; 3]; n],
            covered: vec![false; n],
            aux: Vec::new(),
        }
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width as u32, self.height as u32)
    }

    /// Adds an auxiliary channel (zero everywhere) and returns its index for [`Self::set_aux`].
    pub fn add_aux_channel(&mut self, name: &str) -> usize {
        self.aux.push((name.to_owned(), vec![0.0; self.rgb.len()]));
        self.aux.len() - 1
    }

    /// Sets the irradiance of pixel (`x`, `y`) and marks it covered. Returns `false` (and
    /// stores zero) when the value is not finite, so the caller can count it.
    ///
    /// # Panics
    /// If the pixel lies outside the page (the texel file's validation guarantees it does not).
    pub fn set(&mut self, x: u32, y: u32, rgb: [f32; 3]) -> bool {
        let i = self.index(x, y);
        let finite = rgb.iter().all(|c| c.is_finite());
        self.rgb[i] = if finite { rgb } else { [0.0; 3] };
        self.covered[i] = true;
        finite
    }

    /// Sets auxiliary channel `channel` at (`x`, `y`); non-finite values become zero and
    /// return `false`.
    ///
    /// # Panics
    /// If the pixel lies outside the page or the channel does not exist.
    pub fn set_aux(&mut self, channel: usize, x: u32, y: u32, value: f32) -> bool {
        let i = self.index(x, y);
        let finite = value.is_finite();
        self.aux[channel].1[i] = if finite { value } else { 0.0 };
        finite
    }

    /// The irradiance at (`x`, `y`).
    pub fn get(&self, x: u32, y: u32) -> [f32; 3] {
        self.rgb[self.index(x, y)]
    }

    /// Whether a texel was written at (`x`, `y`) (dilation does not cover pixels).
    pub fn is_covered(&self, x: u32, y: u32) -> bool {
        self.covered[self.index(x, y)]
    }

    fn index(&self, x: u32, y: u32) -> usize {
        assert!(
            (x as usize) < self.width && (y as usize) < self.height,
            "pixel off the page"
        );
        y as usize * self.width + x as usize
    }

    /// Pads charts by `passes` pixels: in each pass every pixel that is neither covered nor
    /// already filled takes the mean irradiance of its filled 8-neighbours. Returns how many
    /// pixels were filled.
    pub fn dilate(&mut self, passes: u32) -> usize {
        let mut filled = self.covered.clone();
        let mut total = 0;
        for _ in 0..passes {
            let mut next = Vec::new();
            for y in 0..self.height {
                for x in 0..self.width {
                    if !filled[y * self.width + x]
                        && let Some(mean) = self.neighbour_mean(&filled, x, y)
                    {
                        next.push((y * self.width + x, mean));
                    }
                }
            }
            if next.is_empty() {
                break;
            }
            total += next.len();
            for (i, rgb) in next {
                self.rgb[i] = rgb;
                filled[i] = true;
            }
        }
        total
    }

    fn neighbour_mean(&self, filled: &[bool], x: usize, y: usize) -> Option<[f32; 3]> {
        let (mut sum, mut n) = ([0.0f32; 3], 0u32);
        for ny in y.saturating_sub(1)..=(y + 1).min(self.height - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(self.width - 1) {
                let i = ny * self.width + nx;
                if filled[i] {
                    (0..3).for_each(|c| sum[c] += self.rgb[i][c]);
                    n += 1;
                }
            }
        }
        (n > 0).then(|| sum.map(|s| s / n as f32))
    }

    /// Writes the page as a 32-bit float EXR (channels R, G, B, then the auxiliary ones;
    /// ZIP-compressed scanlines) to a temporary name beside `path`, then renames it.
    ///
    /// # Errors
    /// [`PageWriteError`] naming `path` when encoding, writing or renaming fails; no partial
    /// file is left behind.
    pub fn write_exr(&self, path: &Path) -> Result<(), PageWriteError> {
        let tmp = temporary_name(path);
        let fail = |what: String| PageWriteError {
            path: path.to_owned(),
            what,
        };
        let result = self.encode(&tmp).and_then(|()| {
            std::fs::rename(&tmp, path).map_err(|e| format!("cannot rename into place: {e}"))
        });
        if let Err(what) = result {
            let _ = std::fs::remove_file(&tmp);
            return Err(fail(what));
        }
        Ok(())
    }

    fn encode(&self, tmp: &Path) -> Result<(), String> {
        let plane = |c: usize| FlatSamples::F32(self.rgb.iter().map(|p| p[c]).collect());
        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        channels.push(AnyChannel::new("R", plane(0)));
        channels.push(AnyChannel::new("G", plane(1)));
        channels.push(AnyChannel::new("B", plane(2)));
        for (name, values) in &self.aux {
            channels.push(AnyChannel::new(
                name.as_str(),
                FlatSamples::F32(values.clone()),
            ));
        }
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::named("lightmap"),
            // Blocks are compressed in parallel; an increasing line order makes the writer
            // put them in the file in order, so the same lightmap is the same bytes whatever
            // the threads' timing (with `Unspecified` the order follows completion).
            Encoding {
                line_order: LineOrder::Increasing,
                ..Encoding::SMALL_FAST_LOSSLESS
            },
            AnyChannels::sort(channels),
        );
        Image::from_layer(layer)
            .write()
            .to_file(tmp)
            .map_err(|e| format!("cannot write EXR: {e}"))
    }
}

impl PageImage {
    /// Writes a tone-mapped sRGB preview (Reinhard, exposure set so the median covered
    /// pixel's luminance maps to ½: a few very bright texels, such as a sunlit patch or a
    /// surface facing the sky, do not darken the rest) as a PNG, through a temporary name.
    ///
    /// # Errors
    /// [`PreviewError`](crate::preview::PreviewError) naming the file.
    pub fn write_preview(&self, path: &Path) -> Result<(), crate::preview::PreviewError> {
        let covered: Vec<&[f32; 3]> = self
            .rgb
            .iter()
            .zip(&self.covered)
            .filter(|(_, c)| **c)
            .map(|(p, _)| p)
            .collect();
        let mean = covered
            .iter()
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .sum::<f32>()
            / covered.len().max(1) as f32;
        let exposure = if mean > 0.0 && mean.is_finite() {
            1.0 / mean
        } else {
            1.0
        };
        let bytes: Vec<u8> = self
            .rgb
            .iter()
            .flat_map(|p| crate::preview::tonemap_reinhard(*p, exposure))
            .collect();
        crate::preview::write_png_rgb8(path, self.width as u32, self.height as u32, &bytes)
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

/// `DIR/.NAME.tmp-PID`: a temporary name in the target's own directory, so the rename that
/// publishes it is atomic.
pub fn temporary_name(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |s| s.to_string_lossy());
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
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
