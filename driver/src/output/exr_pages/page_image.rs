//! [`PageImage`]: one atlas page in memory (irradiance RGB, coverage, auxiliary channels),
//! dilated and written whole; the reference [`super::PageStream`] is tested against byte for
//! byte, and what small pages use.

use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, FlatSamples, Image, Layer, LayerAttributes, SmallVec, WritableImage,
};
use guidebake_kernels::estimator::luminance_f32;

use super::*;

/// One atlas page of a lightmap.
#[derive(Clone, Debug, PartialEq)]
pub struct PageImage {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
    covered: Vec<bool>,
    /// Auxiliary channels: name, values, whether dilation fills them as the irradiance.
    pub(super) aux: Vec<(String, Vec<f32>, bool)>,
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
        self.aux
            .push((name.to_owned(), vec![0.0; self.rgb.len()], false));
        self.aux.len() - 1
    }

    /// Adds an auxiliary channel that [`Self::dilate`] fills as it fills the irradiance (each
    /// padding pixel the mean of the same neighbours), e.g. directional coefficients.
    pub fn add_dilated_channel(&mut self, name: &str) -> usize {
        self.aux
            .push((name.to_owned(), vec![0.0; self.rgb.len()], true));
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

    pub(super) fn index(&self, x: u32, y: u32) -> usize {
        assert!(
            (x as usize) < self.width && (y as usize) < self.height,
            "pixel off the page"
        );
        y as usize * self.width + x as usize
    }

    /// Pads charts by `passes` pixels: in each pass every pixel that is neither covered nor
    /// already filled takes the mean irradiance of its filled 8-neighbours (and the mean of
    /// the same neighbours in each dilated auxiliary channel). Returns how many pixels were
    /// filled.
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
            for (i, values) in next {
                self.rgb[i] = [values[0], values[1], values[2]];
                let dilated = self.aux.iter_mut().filter(|a| a.2);
                for (channel, v) in dilated.zip(&values[3..]) {
                    channel.1[i] = *v;
                }
                filled[i] = true;
            }
        }
        total
    }

    /// The means of the irradiance, then of each dilated auxiliary channel, over the filled
    /// 8-neighbours of (`x`, `y`); `None` without any.
    fn neighbour_mean(&self, filled: &[bool], x: usize, y: usize) -> Option<Vec<f32>> {
        let dilated: Vec<&Vec<f32>> = self.aux.iter().filter(|a| a.2).map(|a| &a.1).collect();
        let mut sum = vec![0.0f32; 3 + dilated.len()];
        let mut n = 0u32;
        for ny in y.saturating_sub(1)..=(y + 1).min(self.height - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(self.width - 1) {
                let i = ny * self.width + nx;
                if filled[i] {
                    (0..3).for_each(|c| sum[c] += self.rgb[i][c]);
                    for (s, channel) in sum[3..].iter_mut().zip(&dilated) {
                        *s += channel[i];
                    }
                    n += 1;
                }
            }
        }
        (n > 0).then(|| sum.into_iter().map(|s| s / n as f32).collect())
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
        for (name, values, _) in &self.aux {
            channels.push(AnyChannel::new(
                name.as_str(),
                FlatSamples::F32(values.clone()),
            ));
        }
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::named("lightmap"),
            page_encoding(),
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
        let mean =
            covered.iter().map(|p| luminance_f32(**p)).sum::<f32>() / covered.len().max(1) as f32;
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
