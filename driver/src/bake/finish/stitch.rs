//! The seams stitched while the pages are written (`--seams stitch`, docs/lightmaps.md): the
//! bilinear values at the seam edge points `prepare` found made to agree, per page, from the
//! pixels the page stream reads back ([`SeamWork`]).

use std::path::PathBuf;

use crate::bake::error::{BakeError, file_error};
use crate::output::exr_pages::PageStream;
use crate::output::seams::{
    EdgePoint, PageFacts, Pixel, Written as PixelWritten, edge_system, mean_relative_jump,
    pixels_read, read_seam_file, seam_file_path, stitch_channels,
};
use crate::texels::TexelFile;

use super::*;

/// The seam samples of a texel file and, as the pages are written, the values of the
/// pixels their measures and the stitch read.
pub(super) struct SeamWork {
    /// The pixels recorded: the pairs' and those the edge points read ([`pixels_read`]).
    pixels: Vec<Pixel>,
    /// The texel pairs, as indices into `pixels`.
    pub(super) pairs: Vec<(u32, u32)>,
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
pub(super) struct Stitched {
    pub(super) pair_jump: [f64; 2],
    pub(super) edge_jump: [f64; 2],
    pub(super) points: usize,
    pub(super) skipped: usize,
    pub(super) held: usize,
}

impl SeamWork {
    /// The samples of the seam file beside the texel file, with `extra` channels per pixel
    /// beside the irradiance (the directional ones, which are stitched alike).
    pub(super) fn load(
        texels: &TexelFile,
        extra: usize,
        extra_from: usize,
    ) -> Result<Self, BakeError> {
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
    pub(super) fn record(&mut self, pixel: Pixel, rgb: [f32; 3], variance: f32, extra: &[f32]) {
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
    pub(super) fn stitch(
        &mut self,
        pages: &mut [(PageStream, PathBuf)],
    ) -> Result<Stitched, BakeError> {
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
