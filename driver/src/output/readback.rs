//! Reading a baked lightmap back — the other half of [`super::exr_pages`]: texel by texel, the
//! value written at each valid texel's pixel of its EXR page (dilation only fills pixels no
//! texel covers, so these are the bake's results, times ρ when it was applied); or one channel
//! of a page, pixel by pixel. Used by the bench and the tests.

use std::path::{Path, PathBuf};

use crate::output::exr_pages::page_path;
use crate::texels::{FLAG_VALID, TexelFile};

/// Why a lightmap could not be read back; names the page.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {what}")]
pub struct ReadbackError {
    /// The page file.
    pub path: PathBuf,
    /// What is wrong.
    pub what: String,
}

/// One RGB page as read from its EXR.
#[derive(Clone, Debug, PartialEq)]
pub struct Page {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The pixels' R, G, B, row by row.
    pub rgb: Vec<[f32; 3]>,
}

/// The R, G, B channels of the EXR page at `path` (its first layer).
///
/// # Errors
/// [`ReadbackError`] when the file cannot be read or is not an RGB image.
pub fn read_page(path: &Path) -> Result<Page, ReadbackError> {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |size, _| Page {
            width: size.width(),
            height: size.height(),
            rgb: vec![[0.0; 3]; size.width() * size.height()],
        },
        |page: &mut Page, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            page.rgb[pos.y() * page.width + pos.x()] = [r, g, b];
        },
    )
    .map_err(|e| ReadbackError {
        path: path.to_owned(),
        what: format!("cannot read the lightmap page: {e}"),
    })?;
    Ok(image.layer_data.channel_data.pixels)
}

/// Channel `name` (e.g. `R`, or an auxiliary channel) of the single-layer EXR page at `path`,
/// row by row.
///
/// # Errors
/// [`ReadbackError`] when the file cannot be read or has no channel `name`.
pub fn read_channel(path: &Path, name: &str) -> Result<Vec<f32>, ReadbackError> {
    let error = |what: String| ReadbackError {
        path: path.to_owned(),
        what,
    };
    let image = exr::prelude::read_first_flat_layer_from_file(path)
        .map_err(|e| error(format!("cannot read the lightmap page: {e}")))?;
    let channel = image
        .layer_data
        .channel_data
        .list
        .iter()
        .find(|c| c.name == *name)
        .ok_or_else(|| error(format!("no channel {name}")))?;
    Ok(channel.sample_data.values_as_f32().collect())
}

/// The lightmap written at `out` for `texels`, one entry per texel id: `Some(rgb)` for a valid
/// texel, `None` for the others.
///
/// # Errors
/// [`ReadbackError`] when a page is missing, unreadable, or smaller than the texel file says.
pub fn read_lightmap(
    texels: &TexelFile,
    out: &Path,
) -> Result<Vec<Option<[f32; 3]>>, ReadbackError> {
    let page_count = texels.pages().len() as u32;
    let mut pages = Vec::with_capacity(page_count as usize);
    for (i, size) in texels.pages().iter().enumerate() {
        let path = page_path(out, i as u32, page_count);
        let page = read_page(&path)?;
        if (page.width, page.height) != (size.width as usize, size.height as usize) {
            return Err(ReadbackError {
                path,
                what: format!(
                    "{}×{} pixels, but the texel file's page {i} is {}×{}",
                    page.width, page.height, size.width, size.height
                ),
            });
        }
        pages.push(page);
    }
    Ok(texels
        .texels()
        .iter()
        .map(|t| {
            if t.flags & FLAG_VALID == 0 {
                return None;
            }
            let page = pages.get(t.page as usize)?;
            let [x, y] = t.pixel.map(usize::from);
            (x < page.width && y < page.height).then(|| page.rgb[y * page.width + x])
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo::ajar_room;
    use crate::output::exr_pages::PageImage;
    use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};

    #[test]
    fn every_valid_texel_reads_back_what_was_written_at_its_pixel() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("room.texels");
        let options = PrepareOptions {
            resolution: Resolution::TexelsPerUnit(4.0),
            layout: Layout::Shared,
        };
        prepare(&ajar_room(), &path, options).unwrap();
        let texels = TexelFile::open(&path).unwrap();
        assert_eq!(texels.pages().len(), 1);
        let page = texels.pages()[0];
        let mut image = PageImage::new(page.width, page.height);
        let value = |id: usize| [id as f32, 0.5, -(id as f32)];
        for (id, t) in texels.texels().iter().enumerate() {
            image.set(u32::from(t.pixel[0]), u32::from(t.pixel[1]), value(id));
        }
        image.dilate(2);
        let out = dir.path().join("lightmap.exr");
        image.write_exr(&out).unwrap();
        let back = read_lightmap(&texels, &out).unwrap();
        assert_eq!(back.len(), texels.texels().len());
        let mut valid = 0;
        for (id, (t, v)) in texels.texels().iter().zip(&back).enumerate() {
            if t.flags & FLAG_VALID == 0 {
                assert!(v.is_none());
            } else {
                assert_eq!(*v, Some(value(id)), "texel {id}");
                valid += 1;
            }
        }
        assert!(valid > 100);
        let missing = read_lightmap(&texels, &dir.path().join("absent.exr")).unwrap_err();
        assert!(missing.to_string().contains("absent.exr"));
    }
}
