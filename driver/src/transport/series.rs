//! Series transport's memory of the previous pass (docs/bake.md, the `series` transport; the
//! paper's production setting, §1 and §3): pass b's gather rays, where they hit a surface,
//! bring back albedo/π × the *indirect* irradiance pass b−1 baked there, looked up in pass
//! b−1's lightmap through the hit triangle's lightmap UVs.
//!
//! What is stored per texel is the gather-only irradiance (the final gather's samples
//! `L π / q` without the texel's own next-event estimate), averaged over all iterations with
//! equal weights: every iteration's estimator is unbiased, so their plain average is too, and
//! no ρ is needed. Direct light at the hit is connected explicitly by the caller, so it is
//! never counted twice.
//!
//! [`PreviousPass`] holds one dense RGB image per atlas page, in a file of the work directory
//! that is memory-mapped (file-backed pages, not anonymous memory), written by
//! [`PreviousPassWriter`]: pixels of baked texels first, then [`DILATION`] rings of
//! dilation so bilinear lookups near chart borders do not fetch black. Lookups are bilinear
//! over covered pixels only (weights renormalised), so a hit at a chart's edge is not darkened
//! by the empty atlas around it.
//!
//! Deviations and limits: a lightmap stores one side of a surface, so a two-sided wall hit
//! from its back reads its front's irradiance; detail finer than a texel is averaged (the
//! lightmap's resolution error, which the `path` transport does not have).

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use memmap2::{Mmap, MmapMut};

use crate::scene::Scene;
use crate::texels::{MeshRecord, PageRecord};

/// Rings of pixels filled around every chart from their covered neighbours.
pub const DILATION: u32 = 4;

/// One pixel of a pass image: gather-only irradiance and its generation (0: empty, 1: a
/// baked texel, g + 1: filled by dilation ring g).
type Pixel = [f32; 4];

/// Where a triangle's lightmap lies: its page and its corners in pixel coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TriangleUv {
    page: u32,
    corners: [Vec2; 3],
}

/// The pixel images' bytes: a memory-mapped file, or a buffer (tests).
#[derive(Debug)]
enum Storage {
    Mapped(Mmap),
    Owned(Vec<Pixel>),
}

/// The previous pass's gather-only irradiance, looked up by triangle and barycentrics.
#[derive(Debug)]
pub struct PreviousPass {
    storage: Storage,
    pages: Vec<PageRecord>,
    /// First pixel of each page in the storage.
    offsets: Vec<usize>,
    triangles: Vec<Option<TriangleUv>>,
}

/// Why a pass image could not be written or mapped.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {what}")]
pub struct PassImageError {
    /// The pass image file.
    pub path: PathBuf,
    /// What failed.
    pub what: String,
}

fn page_offsets(pages: &[PageRecord]) -> (Vec<usize>, usize) {
    let mut offsets = Vec::with_capacity(pages.len());
    let mut total = 0usize;
    for p in pages {
        offsets.push(total);
        total += p.width as usize * p.height as usize;
    }
    (offsets, total)
}

/// Each triangle's page and pixel-space corners, from the scene's lightmap UVs and the texel
/// file's mesh layout (`pixel = uv · scale + offset`); `None` for triangles without UVs.
fn triangle_uvs(scene: &Scene, meshes: &[MeshRecord]) -> Vec<Option<TriangleUv>> {
    scene
        .triangles
        .iter()
        .map(|t| {
            let m = meshes.get(t.mesh as usize)?;
            let (s, o) = (Vec2::from(m.uv_scale), Vec2::from(m.uv_offset));
            let uv = t.lightmap_uv?;
            Some(TriangleUv {
                page: m.page,
                corners: uv.map(|v| v * s + o),
            })
        })
        .collect()
}

impl PreviousPass {
    /// A pass image held in memory: `images[p]` is page `p`'s pixels, row-major, RGB, `None`
    /// for a pixel no texel covers. For tests and small worlds.
    pub fn from_pixels(
        scene: &Scene,
        meshes: &[MeshRecord],
        pages: &[PageRecord],
        images: &[Vec<Option<Vec3>>],
    ) -> Self {
        let (offsets, total) = page_offsets(pages);
        let mut pixels = vec![[0.0; 4]; total];
        for (p, image) in images.iter().enumerate() {
            for (i, px) in image.iter().enumerate() {
                if let Some(c) = px {
                    pixels[offsets[p] + i] = [c.x, c.y, c.z, 1.0];
                }
            }
        }
        let mut pass = Self {
            storage: Storage::Owned(Vec::new()),
            pages: pages.to_vec(),
            offsets,
            triangles: triangle_uvs(scene, meshes),
        };
        for (p, size) in pages.iter().enumerate() {
            let o = pass.offsets[p];
            let n = size.width as usize * size.height as usize;
            dilate(&mut pixels[o..o + n], *size);
        }
        pass.storage = Storage::Owned(pixels);
        pass
    }

    fn pixels(&self) -> &[Pixel] {
        match &self.storage {
            Storage::Mapped(m) => bytemuck::cast_slice(&m[..]),
            Storage::Owned(v) => v,
        }
    }

    /// The previous pass's indirect irradiance at barycentrics (`b1`, `b2`) of triangle
    /// `prim` (weights of its second and third vertices); zero off the atlas.
    pub fn irradiance(&self, prim: u32, b1: f32, b2: f32) -> Vec3 {
        let Some(Some(t)) = self.triangles.get(prim as usize) else {
            return Vec3::ZERO;
        };
        let [a, b, c] = t.corners;
        let uv = a * (1.0 - b1 - b2) + b * b1 + c * b2;
        self.bilinear(t.page, uv)
    }

    /// Bilinear filter over the covered pixels around `uv` (pixel centres at +0.5).
    fn bilinear(&self, page: u32, uv: Vec2) -> Vec3 {
        let Some(size) = self.pages.get(page as usize) else {
            return Vec3::ZERO;
        };
        let pixels = self.pixels();
        let base = self.offsets[page as usize];
        let (w, h) = (size.width as i64, size.height as i64);
        let p = uv - Vec2::splat(0.5);
        if !p.is_finite() {
            return Vec3::ZERO;
        }
        let (x0, y0) = (p.x.floor(), p.y.floor());
        let (fx, fy) = (p.x - x0, p.y - y0);
        let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
        for (dx, dy, wgt) in [
            (0, 0, (1.0 - fx) * (1.0 - fy)),
            (1, 0, fx * (1.0 - fy)),
            (0, 1, (1.0 - fx) * fy),
            (1, 1, fx * fy),
        ] {
            let x = (x0 as i64 + dx).clamp(0, w - 1);
            let y = (y0 as i64 + dy).clamp(0, h - 1);
            let px = pixels[base + (y * w + x) as usize];
            if px[3] > 0.0 && wgt > 0.0 {
                sum += Vec3::new(px[0], px[1], px[2]) * wgt;
                weight += wgt;
            }
        }
        if weight > 0.0 {
            sum / weight
        } else {
            Vec3::ZERO
        }
    }
}

/// Fills [`DILATION`] rings of empty pixels around the covered ones with the mean of their
/// covered (or earlier-filled) 8-neighbours. In place: ring g reads only generations ≤ g.
fn dilate(pixels: &mut [Pixel], size: PageRecord) {
    let (w, h) = (size.width as usize, size.height as usize);
    for ring in 1..=DILATION {
        let generation = ring as f32;
        for y in 0..h {
            for x in 0..w {
                if pixels[y * w + x][3] != 0.0 {
                    continue;
                }
                let (mut sum, mut n) = ([0.0f32; 3], 0.0f32);
                for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                    for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                        let q = pixels[ny * w + nx];
                        if q[3] > 0.0 && q[3] <= generation {
                            sum = [sum[0] + q[0], sum[1] + q[1], sum[2] + q[2]];
                            n += 1.0;
                        }
                    }
                }
                if n > 0.0 {
                    pixels[y * w + x] = [sum[0] / n, sum[1] / n, sum[2] / n, generation + 1.0];
                }
            }
        }
    }
}

/// Writes a pass image file: [`Self::set`] every baked texel, then [`Self::finish`].
pub struct PreviousPassWriter {
    path: PathBuf,
    map: MmapMut,
    pages: Vec<PageRecord>,
    offsets: Vec<usize>,
}

impl PreviousPassWriter {
    /// Creates (or truncates) the image file at `path` for `pages`, zero-filled (sparse).
    ///
    /// # Errors
    /// [`PassImageError`] when the file cannot be created, sized or mapped.
    pub fn create(path: &Path, pages: &[PageRecord]) -> Result<Self, PassImageError> {
        let err = |what: String| PassImageError {
            path: path.to_owned(),
            what,
        };
        let (offsets, total) = page_offsets(pages);
        let bytes = (total.max(1) * size_of::<Pixel>()) as u64;
        let file: File = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)
            .map_err(|e| err(format!("cannot create the pass image: {e}")))?;
        file.set_len(bytes)
            .map_err(|e| err(format!("cannot size the pass image to {bytes} bytes: {e}")))?;
        // SAFETY: the file was just created by this process in its own work directory and is
        // not resized or written through any other handle while mapped (the work directory's
        // invariant, crate::output).
        let map = unsafe { MmapMut::map_mut(&file) }
            .map_err(|e| err(format!("cannot map the pass image: {e}")))?;
        Ok(Self {
            path: path.to_owned(),
            map,
            pages: pages.to_vec(),
            offsets,
        })
    }

    /// Records texel (`x`, `y`) of page `page`: its gather-only irradiance. Non-finite values
    /// and pixels off the page are ignored.
    pub fn set(&mut self, page: u32, x: u32, y: u32, rgb: [f32; 3]) {
        let Some(size) = self.pages.get(page as usize) else {
            return;
        };
        if x >= size.width || y >= size.height || !rgb.iter().all(|c| c.is_finite()) {
            return;
        }
        let i = self.offsets[page as usize] + (y * size.width + x) as usize;
        let pixels: &mut [Pixel] = bytemuck::cast_slice_mut(&mut self.map[..]);
        pixels[i] = [rgb[0], rgb[1], rgb[2], 1.0];
    }

    /// Dilates every page, flushes, and maps the image for lookups.
    ///
    /// # Errors
    /// [`PassImageError`] when flushing or remapping fails.
    pub fn finish(
        mut self,
        scene: &Scene,
        meshes: &[MeshRecord],
    ) -> Result<PreviousPass, PassImageError> {
        {
            let pixels: &mut [Pixel] = bytemuck::cast_slice_mut(&mut self.map[..]);
            for (p, size) in self.pages.iter().enumerate() {
                let o = self.offsets[p];
                let n = size.width as usize * size.height as usize;
                dilate(&mut pixels[o..o + n], *size);
            }
        }
        let path = self.path.clone();
        let err = |what: String| PassImageError {
            path: path.clone(),
            what,
        };
        self.map
            .flush()
            .map_err(|e| err(format!("cannot flush the pass image: {e}")))?;
        let map = self
            .map
            .make_read_only()
            .map_err(|e| err(format!("cannot remap the pass image: {e}")))?;
        Ok(PreviousPass {
            storage: Storage::Mapped(map),
            pages: self.pages,
            offsets: self.offsets,
            triangles: triangle_uvs(scene, meshes),
        })
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;
    use crate::scene::{Material, Mesh, Sky, Triangle};

    /// One triangle whose UVs span the 4×4 page's lower-left half.
    fn scene() -> (Scene, Vec<MeshRecord>, Vec<PageRecord>) {
        let tri = Triangle {
            positions: [Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: [Vec3::Z; 3],
            lightmap_uv: Some([Vec2::ZERO, Vec2::X, Vec2::Y]),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        let scene = Scene {
            path: PathBuf::from("<test>"),
            meshes: vec![Mesh {
                name: "m".into(),
                first_triangle: 0,
                triangle_count: 1,
                has_lightmap_uvs: true,
            }],
            triangles: vec![tri],
            materials: vec![Material {
                name: "m".into(),
                base_color_texture: None,
                albedo: Vec3::ONE,
                emission: Vec3::ZERO,
            }],
            lights: Vec::new(),
            sun: None,
            sky: Sky::None,
            degenerate_triangles: 0,
        };
        let meshes = vec![MeshRecord {
            first_triangle: 0,
            triangle_count: 1,
            page: 0,
            flags: 1,
            uv_scale: [4.0, 4.0],
            uv_offset: [0.0, 0.0],
        }];
        (
            scene,
            meshes,
            vec![PageRecord {
                width: 4,
                height: 4,
            }],
        )
    }

    #[test]
    fn a_constant_chart_reads_back_constant_everywhere_on_its_triangle() {
        let (scene, meshes, pages) = scene();
        let c = Vec3::new(1.0, 2.0, 3.0);
        // Only the pixels whose centres lie in the triangle are covered.
        let image: Vec<Option<Vec3>> = (0..16)
            .map(|i| ((i % 4) + (i / 4) < 4).then_some(c))
            .collect();
        let pass = PreviousPass::from_pixels(&scene, &meshes, &pages, &[image]);
        for (b1, b2) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.3, 0.3), (0.5, 0.5)] {
            let e = pass.irradiance(0, b1, b2);
            assert!((e - c).abs().max_element() < 1e-6, "({b1}, {b2}): {e}");
        }
        assert_eq!(pass.irradiance(7, 0.2, 0.2), Vec3::ZERO, "no such triangle");
    }

    #[test]
    fn lookups_interpolate_and_the_file_matches_memory() {
        let (scene, meshes, pages) = scene();
        let image: Vec<Option<Vec3>> = (0..16).map(|i| Some(Vec3::splat((i % 4) as f32))).collect();
        let mem = PreviousPass::from_pixels(&scene, &meshes, &pages, std::slice::from_ref(&image));
        // Halfway between pixel centres 1 and 2 of a row: the mean of 1 and 2.
        let e = mem.bilinear(0, Vec2::new(2.0, 1.5));
        assert!((e.x - 1.5).abs() < 1e-6, "{e}");
        let dir = tempfile::tempdir().unwrap();
        let mut w = PreviousPassWriter::create(&dir.path().join("pass.bin"), &pages).unwrap();
        for (i, px) in image.iter().enumerate() {
            w.set(0, (i % 4) as u32, (i / 4) as u32, px.unwrap().to_array());
        }
        w.set(0, 9, 9, [1.0; 3]);
        w.set(0, 0, 0, [f32::NAN; 3]);
        let file = w.finish(&scene, &meshes).unwrap();
        for (b1, b2) in [(0.1, 0.2), (0.6, 0.3), (0.0, 0.0)] {
            let (a, b) = (mem.irradiance(0, b1, b2), file.irradiance(0, b1, b2));
            assert!((a - b).abs().max_element() < 1e-6 || (b1, b2) == (0.0, 0.0));
            assert!(b.is_finite());
        }
    }

    #[test]
    fn dilation_fills_rings_around_charts_and_no_further() {
        let size = PageRecord {
            width: 12,
            height: 1,
        };
        let mut px = vec![[0.0; 4]; 12];
        px[0] = [2.0, 2.0, 2.0, 1.0];
        dilate(&mut px, size);
        for (x, p) in px.iter().enumerate() {
            if x as u32 <= DILATION {
                assert_eq!(p[0], 2.0, "pixel {x}");
                assert_eq!(p[3], x as f32 + 1.0, "pixel {x} filled by ring {x}");
            } else {
                assert_eq!(p[3], 0.0, "pixel {x} is beyond the dilation");
            }
        }
    }
}
