//! Reading a baked lightmap back, texel by texel: the value written at each valid texel's
//! pixel of its EXR page (dilation only fills pixels no texel covers, so these are the bake's
//! results, times ρ when it was applied).

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
struct Page {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

fn read_page(path: &Path) -> Result<Page, ReadbackError> {
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
