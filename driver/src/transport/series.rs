//! Series transport's memory of the previous pass (docs/bake.md, the `series` transport; the
//! paper's production setting, §1 and §3): pass b's gather rays, where they hit a surface,
//! bring back albedo/π × the irradiance pass b−1 baked there, looked up in pass b−1's
//! lightmap through the hit triangle's lightmap UVs. Pass 1 reads pass 0, the direct light
//! alone ([`DIRECT_PASS`](crate::bake::settings::DIRECT_PASS)), so no gather pass traces a
//! shadow ray at a far hit.
//!
//! Two layers are stored per texel, each the plain average over all iterations (every
//! iteration's estimator is unbiased, so their plain average is too, and no ρ is needed):
//! - the **total** irradiance, direct and gathered: read where a ray hits the side of a
//!   surface its texels bake, farther than [`NEAR_FIELD_TEXELS`] of them
//!   ([`PreviousPass::reads_total`]), in place of next-event estimation there — no shadow
//!   ray at the hit, and the direct light it brings is the average of the texel's whole
//!   bake rather than one sample;
//! - the **gather-only** irradiance (the final gather's samples `L π / q` without the
//!   texel's own next-event estimate and the emission its rays hit): read near the ray's
//!   origin, where a texel's blur of direct light would show, while the caller connects the
//!   hit's direct light explicitly, so it is never counted twice — but not within
//!   [`NEAR_PATH_TEXELS`], where the caller carries the hit's light one bounce on and reads
//!   the pass before the previous one there (memory holds both passes' images).
//!
//! **Leak-free lookups** (docs/bake.md, "Where series reads the lightmap"). A lookup is only
//! read where the texels it interpolates truly describe the surface at the hit
//! ([`Lookup::baked`], [`Lookup::smooth`]): on the side the texels describe (not the far side
//! of a thin wall, whose texels hold the light of the space behind it), where none of the
//! texels it interpolates lies inside geometry (their baked neighbours hold the light of the
//! open space beside a closed gap, not the gap's) and the one the hit lies in is baked, over
//! baked texels (not a chart's padding, whose values are the dilation's), agreeing within
//! [`SMOOTH_RATIO`] (not across a shadow edge or the doorway light enters by). Elsewhere the
//! caller connects the hit's direct light and carries the rest one bounce on, to where the pass
//! before the previous one is read by the same rules (`transport/path.rs`).
//!
//! [`PreviousPass`] holds one dense RGB image per atlas page, in a file of the work directory
//! that is memory-mapped (file-backed pages, not anonymous memory), written by
//! [`PreviousPassWriter`]: pixels of baked texels first, then [`DILATION`] rings of
//! dilation. Lookups are bilinear over the baked pixels among the four (weights
//! renormalised), over the dilated ones only where none is baked.
//!
//! Deviations and limits: detail finer than a texel where the texels agree — soft shadows,
//! gradients within [`SMOOTH_RATIO`] — is averaged (the lightmap's resolution error, which
//! the `path` transport does not have).

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use memmap2::{Mmap, MmapMut};

use crate::scene::Scene;
use crate::texels::{PageRecord, TriangleRecord};
use crate::transport::emitters::luminance;
use crate::transport::lookup_filter::{Surfel, filter_page};

/// Rings of pixels filled around every chart from their covered neighbours.
pub const DILATION: u32 = 4;

/// Texels of the hit's lightmap within which a hit connects its direct light rather than
/// reading the total ([`PreviousPass::reads_total`]): so near, one texel's blur is a large
/// part of what the gathering point sees (corners, where the neighbouring wall's direct
/// light changes within a texel). Chosen by the RMSE against a path reference of the three
/// converted scenes (docs/series.md, "Series reads the total"): at 4 it is within 0.4 %
/// of connecting every hit; at 0 up to 7.7 % above it.
pub const NEAR_FIELD_TEXELS: f32 = 4.0;

/// Texels of the hit's lightmap within which a gather's hit reads neither layer
/// ([`PreviousPass::reads_gathered`]): there the texels a lookup interpolates lie as far from
/// the hit as the gathering point does, and a point on a chart's edge (a partial texel, in the
/// corner two surfaces make) reads the other surface's blur of the corner's light. The hit's
/// direct light is connected and the rest carried one bounce on, to a vertex that reads the
/// pass before the previous one (`transport/path.rs`), so the texel still gets exactly B
/// bounces. On the level zdm2 (768², a sun and a sky, 256 spp, 2 seeds, 2026-11-30) this took
/// 87 % of the default bake's per-texel bias out, and its relative MSE fell 1.70× at equal
/// samples; on the converted rooms, which carry no such bias, it changed by 0.99–1.04×
/// (docs/series.md, "Why guiding gained little on the level").
pub const NEAR_PATH_TEXELS: f32 = 1.0;

/// One pixel of a pass image: gather-only irradiance (0..3), its generation (3; 0: empty,
/// 1: a baked texel, g + 1: filled by dilation ring g), total irradiance (4..7), and 1 where a
/// texel inside geometry lies (7; its values are the dilation's).
type Pixel = [f32; 8];

/// Index of the generation in a [`Pixel`].
const GENERATION: usize = 3;

/// Index of the inside-geometry mark in a [`Pixel`].
const INSIDE: usize = 7;

/// A lookup reads a layer only where the baked texels it interpolates agree within this ratio
/// (luminance): where light changes several-fold within a texel or two — the edge of a shadow,
/// the doorway light enters a room by — a texel's average is far from the value at the hit,
/// and the gather computes the light there another way (one bounce on from the hit). Chosen
/// by relative MSE against path references at equal time (docs/bake.md, "Where series reads
/// the lightmap"): 1.5 traced paths at 31–47 % of the hits of the Veach rooms and doubled
/// their error at equal samples; 2, 3 and 4 are within 10 % of each other, 3 the best. With
/// such hits carried one bounce on instead, 2 and 1.5 still lose (docs/bake.md).
pub const SMOOTH_RATIO: f32 = 3.0;

/// What a lookup brings back: both layers at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lookup {
    /// Gather-only irradiance: what arrives at the point without its direct light.
    pub gathered: Vec3,
    /// Total irradiance: direct and gathered.
    pub total: Vec3,
    /// Whether the texel the point lies in is baked and none of the four it interpolates
    /// lies inside geometry. Else the values describe the baked neighbours of a texel inside
    /// geometry (or the dilation), not the point: a surface in a closed gap beside a lit one
    /// would read the lit one's light.
    pub baked: bool,
    /// Whether the total is read from baked texels that agree within [`SMOOTH_RATIO`]: only
    /// then does it stand for the irradiance at the point.
    pub smooth: bool,
    /// The same for the gather-only layer.
    pub gathered_smooth: bool,
}

/// Where a triangle's lightmap lies: its page, its corners in pixel coordinates, the world
/// length of one of its texels, and whether its texels bake its winding's front side.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TriangleUv {
    page: u32,
    corners: [Vec2; 3],
    texel: f32,
    front: bool,
}

/// The pixel images' bytes: a memory-mapped file, or a buffer (tests).
#[derive(Debug)]
enum Storage {
    Mapped(Mmap),
    Owned(Vec<Pixel>),
}

/// The previous pass's irradiance, looked up by triangle and barycentrics.
#[derive(Debug)]
pub struct PreviousPass {
    storage: Storage,
    pages: Vec<PageRecord>,
    /// First pixel of each page in the storage.
    offsets: Vec<usize>,
    triangles: Vec<Option<TriangleUv>>,
    /// The series pass it holds.
    pass: u32,
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

/// Each triangle's page and pixel-space corners, from the texel file's triangle table (the
/// lightmap `prepare` rasterised, whatever UVs the scene carries), and its texel size from the
/// scene's positions; `None` for triangles without lightmap UVs.
fn triangle_uvs(scene: &Scene, records: &[TriangleRecord]) -> Vec<Option<TriangleUv>> {
    scene
        .triangles
        .iter()
        .zip(records)
        .map(|(t, r)| {
            let (page, corners) = r.pixel_uv()?;
            let [a, b, c] = corners;
            let pixels = 0.5 * (b - a).perp_dot(c - a).abs();
            let texel = (t.area() / pixels).sqrt();
            Some(TriangleUv {
                page,
                corners,
                texel: if texel.is_finite() {
                    texel
                } else {
                    f32::INFINITY
                },
                front: !r.texels_face_back(),
            })
        })
        .collect()
}

impl PreviousPass {
    /// A lightmap held in memory: `images[p]` is page `p`'s pixels, row-major, RGB, `None`
    /// for a pixel no texel covers; both layers hold it. For rendering a baked lightmap, and
    /// tests.
    pub fn from_pixels(
        scene: &Scene,
        triangles: &[TriangleRecord],
        pages: &[PageRecord],
        images: &[Vec<Option<Vec3>>],
    ) -> Self {
        let (offsets, total) = page_offsets(pages);
        let mut pixels = vec![[0.0; 8]; total];
        for (p, image) in images.iter().enumerate() {
            for (i, px) in image.iter().enumerate() {
                if let Some(c) = px {
                    pixels[offsets[p] + i] = [c.x, c.y, c.z, 1.0, c.x, c.y, c.z, 0.0];
                }
            }
        }
        let mut pass = Self {
            storage: Storage::Owned(Vec::new()),
            pages: pages.to_vec(),
            offsets,
            triangles: triangle_uvs(scene, triangles),
            pass: 0,
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

    /// The same image, holding series pass `pass` (0: the direct pass): its light has made
    /// at most `pass` bounces.
    #[must_use]
    pub fn of_pass(self, pass: u32) -> Self {
        Self { pass, ..self }
    }

    /// The series pass it holds ([`Self::of_pass`]).
    pub fn pass(&self) -> u32 {
        self.pass
    }

    /// Both layers of the previous pass at barycentrics (`b1`, `b2`) of triangle `prim`
    /// (weights of its second and third vertices); zero off the atlas.
    pub fn lookup(&self, prim: u32, b1: f32, b2: f32) -> Lookup {
        let Some(Some(t)) = self.triangles.get(prim as usize) else {
            return Lookup::default();
        };
        let [a, b, c] = t.corners;
        let uv = a * (1.0 - b1 - b2) + b * b1 + c * b2;
        self.bilinear(t.page, uv)
    }

    /// The total irradiance at barycentrics (`b1`, `b2`) of triangle `prim`: the lightmap's
    /// value there.
    pub fn irradiance(&self, prim: u32, b1: f32, b2: f32) -> Vec3 {
        self.lookup(prim, b1, b2).total
    }

    /// The luminance of the direct light the previous pass held at texel `pixel` of page
    /// `page` (its total less its gather-only layer: the direct pass's estimate, which every
    /// later pass borrows); 0 where no texel was baked there.
    pub fn direct_luminance_at(&self, page: u32, pixel: [u32; 2]) -> f32 {
        let Some(size) = self.pages.get(page as usize) else {
            return 0.0;
        };
        let [x, y] = pixel;
        if x >= size.width || y >= size.height {
            return 0.0;
        }
        let px = self.pixels()[self.offsets[page as usize] + (y * size.width + x) as usize];
        if px[GENERATION] != 1.0 {
            return 0.0;
        }
        let direct = Vec3::new(px[4] - px[0], px[5] - px[1], px[6] - px[2]);
        luminance(direct).max(0.0)
    }

    /// Whether triangle `prim`'s texels bake its winding's `front` side (or its back, when
    /// `front` is false): then its total irradiance holds the direct light arriving there.
    pub fn bakes_side(&self, prim: u32, front: bool) -> bool {
        matches!(self.triangles.get(prim as usize), Some(Some(t)) if t.front == front)
    }

    /// Whether a ray that hit triangle `prim` on its `front` (or back) side after travelling
    /// `t` reads the total irradiance there: the side its texels bake, and farther than
    /// [`NEAR_FIELD_TEXELS`] of its texels.
    pub fn reads_total(&self, prim: u32, front: bool, t: f32) -> bool {
        self.bakes_side(prim, front) && self.beyond(prim, t, NEAR_FIELD_TEXELS)
    }

    /// Whether a ray that hit triangle `prim` after travelling `t` may read the gather-only
    /// layer there: farther than [`NEAR_PATH_TEXELS`] of its texels.
    pub fn reads_gathered(&self, prim: u32, t: f32) -> bool {
        self.beyond(prim, t, NEAR_PATH_TEXELS)
    }

    /// Whether `t` is more than `texels` of triangle `prim`'s texels (false off the atlas).
    fn beyond(&self, prim: u32, t: f32, texels: f32) -> bool {
        matches!(self.triangles.get(prim as usize), Some(Some(tri)) if t > texels * tri.texel)
    }

    /// Bilinear filter around `uv` (pixel centres at +0.5) over the baked pixels among its
    /// four, weights renormalised; over the dilated ones only where none is baked (a point in
    /// a chart's padding). A dilated pixel may mix two charts that lie close in the atlas, so
    /// a hit inside a chart never reads one. [`Lookup::baked`] only where the pixel the point
    /// lies in is baked and no pixel with weight is marked inside geometry.
    fn bilinear(&self, page: u32, uv: Vec2) -> Lookup {
        let Some(size) = self.pages.get(page as usize) else {
            return Lookup::default();
        };
        let pixels = self.pixels();
        let base = self.offsets[page as usize];
        let (w, h) = (size.width as i64, size.height as i64);
        let p = uv - Vec2::splat(0.5);
        if !p.is_finite() {
            return Lookup::default();
        }
        let (x0, y0) = (p.x.floor(), p.y.floor());
        let (fx, fy) = (p.x - x0, p.y - y0);
        let taps = [
            (0, 0, (1.0 - fx) * (1.0 - fy)),
            (1, 0, fx * (1.0 - fy)),
            (0, 1, (1.0 - fx) * fy),
            (1, 1, fx * fy),
        ]
        .map(|(dx, dy, wgt)| {
            let x = (x0 as i64 + dx).clamp(0, w - 1);
            let y = (y0 as i64 + dy).clamp(0, h - 1);
            (pixels[base + (y * w + x) as usize], wgt)
        });
        let any_baked = taps
            .iter()
            .any(|(px, wgt)| px[GENERATION] == 1.0 && *wgt > 0.0);
        let (mut gathered, mut total, mut weight) = (Vec3::ZERO, Vec3::ZERO, 0.0f32);
        let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
        let (mut glo, mut ghi) = (f32::INFINITY, 0.0f32);
        for (px, wgt) in taps {
            let usable = if any_baked {
                px[GENERATION] == 1.0
            } else {
                px[GENERATION] > 0.0
            };
            if usable && wgt > 0.0 {
                let t = Vec3::new(px[4], px[5], px[6]);
                let g = Vec3::new(px[0], px[1], px[2]);
                gathered += g * wgt;
                (glo, ghi) = (glo.min(luminance(g)), ghi.max(luminance(g)));
                total += t * wgt;
                weight += wgt;
                let lum = luminance(t);
                (lo, hi) = (lo.min(lum), hi.max(lum));
            }
        }
        // The texel the point lies in (the largest weight; the first on a tie) is baked:
        // conservative rasterisation bakes every texel a chart touches, so it is unbaked only
        // inside geometry. And no texel with weight lies inside geometry: the baked texels
        // beside one hold the light of open space, not of the closed gap the point may be in.
        let nearest = taps
            .iter()
            .fold(taps[0], |n, t| if t.1 > n.1 { *t } else { n });
        let inside = taps.iter().any(|(px, wgt)| px[INSIDE] == 1.0 && *wgt > 0.0);
        let baked = nearest.0[GENERATION] == 1.0 && !inside;
        if weight > 0.0 {
            Lookup {
                gathered: gathered / weight,
                total: total / weight,
                baked,
                smooth: baked && hi <= SMOOTH_RATIO * lo,
                gathered_smooth: baked && ghi <= SMOOTH_RATIO * glo,
            }
        } else {
            Lookup::default()
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
                if pixels[y * w + x][GENERATION] != 0.0 {
                    continue;
                }
                let (mut sum, mut n) = ([0.0f32; 8], 0.0f32);
                for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                    for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                        let q = pixels[ny * w + nx];
                        if q[GENERATION] > 0.0 && q[GENERATION] <= generation {
                            for (s, v) in sum.iter_mut().zip(q) {
                                *s += v;
                            }
                            n += 1.0;
                        }
                    }
                }
                if n > 0.0 {
                    let mut filled = sum.map(|v| v / n);
                    filled[GENERATION] = generation + 1.0;
                    filled[INSIDE] = pixels[y * w + x][INSIDE];
                    pixels[y * w + x] = filled;
                }
            }
        }
    }
}

/// Writes a pass image file: [`Self::set`] every baked texel, then [`Self::finish`]. With
/// [`Self::with_filter`], [`Self::describe`] every baked texel too, and the gathered light is
/// filtered before the dilation ([`crate::transport::lookup_filter`]).
pub struct PreviousPassWriter {
    path: PathBuf,
    map: MmapMut,
    pages: Vec<PageRecord>,
    offsets: Vec<usize>,
    filter: Option<SurfelFile>,
}

/// The lookups' filter's texels, in a file beside the pass image (file-backed pages, so a
/// world of any size keeps bounded memory), removed when the image is finished.
struct SurfelFile {
    path: PathBuf,
    map: MmapMut,
    radius: u32,
}

/// Creates (or truncates) a file of `count` zeroed `T`s at `path` and maps it.
fn create_mapped<T>(path: &Path, count: usize, what: &str) -> Result<MmapMut, PassImageError> {
    let err = |what: String| PassImageError {
        path: path.to_owned(),
        what,
    };
    let bytes = (count.max(1) * size_of::<T>()) as u64;
    let file: File = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(path)
        .map_err(|e| err(format!("cannot create the {what}: {e}")))?;
    file.set_len(bytes)
        .map_err(|e| err(format!("cannot size the {what} to {bytes} bytes: {e}")))?;
    // SAFETY: the file was just created by this process in its own work directory and is
    // not resized or written through any other handle while mapped (the work directory's
    // invariant, crate::output).
    unsafe { MmapMut::map_mut(&file) }.map_err(|e| err(format!("cannot map the {what}: {e}")))
}

impl PreviousPassWriter {
    /// Creates (or truncates) the image file at `path` for `pages`, zero-filled (sparse).
    ///
    /// # Errors
    /// [`PassImageError`] when the file cannot be created, sized or mapped.
    pub fn create(path: &Path, pages: &[PageRecord]) -> Result<Self, PassImageError> {
        let (offsets, total) = page_offsets(pages);
        let map = create_mapped::<Pixel>(path, total, "pass image")?;
        Ok(Self {
            path: path.to_owned(),
            map,
            pages: pages.to_vec(),
            offsets,
            filter: None,
        })
    }

    /// Filters the gathered light over `radius` texels before the image is finished (0: no
    /// filter), from the texels [`Self::describe`] records in a file beside the image
    /// (`.surfels`).
    ///
    /// # Errors
    /// [`PassImageError`] when that file cannot be created, sized or mapped.
    pub fn with_filter(mut self, radius: u32) -> Result<Self, PassImageError> {
        if radius == 0 {
            return Ok(self);
        }
        let path = self.path.with_extension("surfels");
        let (_, count) = page_offsets(&self.pages);
        let map = create_mapped::<Surfel>(&path, count, "lookup filter's texel file")?;
        self.filter = Some(SurfelFile { path, map, radius });
        Ok(self)
    }

    /// Records what the filter needs of texel (`x`, `y`) of page `page`
    /// ([`Self::with_filter`]; nothing without a filter, or off the page).
    pub fn describe(&mut self, page: u32, pixel: (u32, u32), surfel: Surfel) {
        let (Some(i), Some(filter)) = (self.index(page, pixel), &mut self.filter) else {
            return;
        };
        let surfels: &mut [Surfel] = bytemuck::cast_slice_mut(&mut filter.map[..]);
        surfels[i] = surfel;
    }

    /// Where pixel (`x`, `y`) of page `page` lies in the image; `None` off the pages.
    fn index(&self, page: u32, (x, y): (u32, u32)) -> Option<usize> {
        let size = self.pages.get(page as usize)?;
        (x < size.width && y < size.height)
            .then(|| self.offsets[page as usize] + (y * size.width + x) as usize)
    }

    /// Records texel (`x`, `y`) of page `page`: its gather-only and total irradiance.
    /// Non-finite values and pixels off the page are ignored.
    pub fn set(&mut self, page: u32, pixel: (u32, u32), gathered: [f32; 3], total: [f32; 3]) {
        let finite = gathered.iter().chain(&total).all(|c| c.is_finite());
        let (Some(i), true) = (self.index(page, pixel), finite) else {
            return;
        };
        let pixels: &mut [Pixel] = bytemuck::cast_slice_mut(&mut self.map[..]);
        let [g, t] = [gathered, total];
        pixels[i] = [g[0], g[1], g[2], 1.0, t[0], t[1], t[2], 0.0];
    }

    /// Marks texel (`x`, `y`) of page `page` as lying inside geometry: not baked, filled by
    /// the dilation, and a lookup with weight on it is not read ([`Lookup::baked`]).
    pub fn mark_inside(&mut self, page: u32, pixel: (u32, u32)) {
        let Some(i) = self.index(page, pixel) else {
            return;
        };
        let pixels: &mut [Pixel] = bytemuck::cast_slice_mut(&mut self.map[..]);
        pixels[i][INSIDE] = 1.0;
    }

    /// Dilates every page, flushes, and maps the image for lookups.
    ///
    /// # Errors
    /// [`PassImageError`] when flushing or remapping fails.
    pub fn finish(
        mut self,
        scene: &Scene,
        triangles: &[TriangleRecord],
    ) -> Result<PreviousPass, PassImageError> {
        {
            let pixels: &mut [Pixel] = bytemuck::cast_slice_mut(&mut self.map[..]);
            for (p, size) in self.pages.iter().enumerate() {
                let o = self.offsets[p];
                let n = size.width as usize * size.height as usize;
                if let Some(filter) = &self.filter {
                    let surfels: &[Surfel] = bytemuck::cast_slice(&filter.map[..]);
                    let page = (size.width as usize, size.height as usize);
                    filter_page(&surfels[o..o + n], page, filter.radius, |i, change| {
                        let px = &mut pixels[o + i];
                        // Only where the image holds the texel (`set` refused non-finite ones).
                        if px[GENERATION] == 1.0 {
                            for c in 0..3 {
                                px[c] += change[c];
                                px[4 + c] += change[c];
                            }
                        }
                    });
                }
                dilate(&mut pixels[o..o + n], *size);
            }
        }
        if let Some(filter) = self.filter.take() {
            drop(filter.map);
            std::fs::remove_file(&filter.path).map_err(|e| PassImageError {
                path: filter.path.clone(),
                what: format!("cannot remove the lookup filter's texel file: {e}"),
            })?;
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
            triangles: triangle_uvs(scene, triangles),
            pass: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::lightmapped_triangle;
    use crate::texels::{LIGHTMAPPED, SEEN_BACK, SEEN_FRONT, TEXELS_BACK};

    /// One triangle whose UVs span the 4×4 page's lower-left half.
    fn scene() -> (Scene, Vec<TriangleRecord>, Vec<PageRecord>) {
        lightmapped_triangle(1.0, 1.0)
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
        let e = mem.bilinear(0, Vec2::new(2.0, 1.5)).total;
        assert!((e.x - 1.5).abs() < 1e-6, "{e}");
        let dir = tempfile::tempdir().unwrap();
        let mut w = PreviousPassWriter::create(&dir.path().join("pass.bin"), &pages).unwrap();
        // The file's total layer is twice its gather-only layer, which is the memory image.
        for (i, px) in image.iter().enumerate() {
            let g = px.unwrap();
            w.set(
                0,
                ((i % 4) as u32, (i / 4) as u32),
                g.to_array(),
                (g * 2.0).to_array(),
            );
        }
        w.set(0, (9, 9), [1.0; 3], [1.0; 3]);
        w.set(0, (0, 0), [f32::NAN; 3], [1.0; 3]);
        w.set(0, (1, 0), [1.0; 3], [f32::INFINITY; 3]);
        let file = w.finish(&scene, &meshes).unwrap();
        for (b1, b2) in [(0.1, 0.2), (0.6, 0.3), (0.0, 0.0)] {
            let (a, b) = (mem.irradiance(0, b1, b2), file.lookup(0, b1, b2));
            let near = |x: Vec3, y: Vec3| (x - y).abs().max_element() < 1e-6;
            assert!(near(a, b.gathered) || (b1, b2) == (0.0, 0.0), "{a} {b:?}");
            assert!(
                near(a * 2.0, b.total) || (b1, b2) == (0.0, 0.0),
                "{a} {b:?}"
            );
            assert!(b.gathered.is_finite() && b.total.is_finite());
        }
        // The direct light at a texel: its total less its gather-only layer (pixel (1, 1)
        // holds 1 and 2); none off the page, none where no texel was baked (the rejected
        // (0, 0)), none in the memory image, whose layers are the same.
        assert!((file.direct_luminance_at(0, [1, 1]) - 1.0).abs() < 1e-5);
        assert_eq!(file.direct_luminance_at(0, [0, 0]), 0.0);
        assert_eq!(file.direct_luminance_at(0, [9, 9]), 0.0);
        assert_eq!(file.direct_luminance_at(3, [0, 0]), 0.0);
        assert_eq!(mem.direct_luminance_at(0, [1, 1]), 0.0);
    }

    #[test]
    fn a_filtered_image_moves_the_total_by_the_gathered_change_and_removes_its_texel_file() {
        let (scene, meshes, pages) = scene();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pass.bin");
        let mut w = PreviousPassWriter::create(&path, &pages)
            .unwrap()
            .with_filter(2)
            .unwrap();
        assert!(path.with_extension("surfels").exists());
        // Every pixel of the 4×4 page on one plane: gathered 1 or 3 alternately (noise 2,
        // so they mix), direct light 10 · x on top.
        for i in 0..16u32 {
            let (x, y) = (i % 4, i / 4);
            let g = if (x + y) % 2 == 0 { 1.0 } else { 3.0 };
            let direct = 10.0 * x as f32;
            w.set(0, (x, y), [g; 3], [g + direct; 3]);
            let at = Vec3::new(x as f32, y as f32, 0.0);
            let s = Surfel::new(at, Vec3::Z, 1.0, [g; 3], 2.0 / g).unwrap();
            w.describe(0, (x, y), s);
        }
        let image = w.finish(&scene, &meshes).unwrap();
        assert!(
            !path.with_extension("surfels").exists(),
            "texel file left behind"
        );
        let px = image.pixels();
        for (i, p) in px.iter().enumerate().take(16) {
            let (g, t) = (p[0], p[4]);
            // The page's corners have no texel opposite them in the window: left alone.
            let corner = matches!((i % 4, i / 4), (0 | 3, 0 | 3));
            assert!(
                corner == (g == 1.0 || g == 3.0),
                "pixel {i}: gathered {g}, filtered: {}",
                !corner
            );
            assert!(
                (t - g - 10.0 * (i % 4) as f32).abs() < 1e-4,
                "pixel {i}: direct moved"
            );
        }
        // Radius 0 writes no texel file and leaves the values.
        let mut w = PreviousPassWriter::create(&path, &pages)
            .unwrap()
            .with_filter(0)
            .unwrap();
        w.set(0, (0, 0), [1.0; 3], [2.0; 3]);
        w.describe(
            0,
            (0, 0),
            Surfel::new(Vec3::ZERO, Vec3::Z, 1.0, [1.0; 3], 1.0).unwrap(),
        );
        assert!(!path.with_extension("surfels").exists());
        let image = w.finish(&scene, &meshes).unwrap();
        assert_eq!((image.pixels()[0][0], image.pixels()[0][4]), (1.0, 2.0));
    }

    #[test]
    fn a_lookup_by_baked_pixels_never_reads_the_dilated_ones_beside_them() {
        let (scene, triangles, pages) = scene();
        // Column 0 baked 1, column 2 baked 5; column 1 (and 3) left to the dilation, which
        // mixes the two charts there.
        let image: Vec<Option<Vec3>> = (0..16)
            .map(|i| match i % 4 {
                0 => Some(Vec3::ONE),
                2 => Some(Vec3::splat(5.0)),
                _ => None,
            })
            .collect();
        let pass = PreviousPass::from_pixels(&scene, &triangles, &pages, &[image]);
        // Between the centres of columns 0 and 1: only column 0 is baked there.
        let e = pass.bilinear(0, Vec2::new(1.0, 1.5)).total;
        assert_eq!(e, Vec3::ONE, "read the dilated column");
        // In column 3, whose taps are columns 3 and (clamped) 3: dilated only, read them.
        let e = pass.bilinear(0, Vec2::new(3.9, 1.5)).total;
        assert!(e.x > 1.0, "{e}");
    }

    #[test]
    fn a_lookup_is_read_only_where_the_texel_it_lies_in_is_baked() {
        let (scene, triangles, pages) = scene();
        // Column 0 baked and lit (4), column 1 unbaked (and unmarked: the texel under a hit
        // decides alone), column 2 baked and as lit: every baked tap agrees.
        let image: Vec<Option<Vec3>> = (0..16)
            .map(|i| match i % 4 {
                0 => Some(Vec3::splat(4.0)),
                2 => Some(Vec3::splat(4.0)),
                _ => None,
            })
            .collect();
        let pass = PreviousPass::from_pixels(&scene, &triangles, &pages, &[image]);
        // In column 0, nearer its centre than column 1's: read, smooth (one baked tap).
        let l = pass.bilinear(0, Vec2::new(0.9, 1.5));
        assert!(l.baked && l.smooth && l.gathered_smooth, "{l:?}");
        assert_eq!(l.total, Vec3::splat(4.0));
        // In column 1, though columns 0 and 2 beside it are baked and agree: not read.
        for x in [1.1, 1.5, 1.9] {
            let l = pass.bilinear(0, Vec2::new(x, 1.5));
            assert!(!l.baked && !l.smooth && !l.gathered_smooth, "x {x}: {l:?}");
            // The value still averages the baked taps alone (a render reads it).
            assert_eq!(l.total, Vec3::splat(4.0), "x {x}");
        }
        // In column 2, nearer its centre: read again.
        assert!(pass.bilinear(0, Vec2::new(2.2, 1.5)).baked);
    }

    #[test]
    fn a_lookup_with_weight_on_a_texel_inside_geometry_is_not_read() {
        let (scene, triangles, pages) = scene();
        let dir = tempfile::tempdir().unwrap();
        let mut w = PreviousPassWriter::create(&dir.path().join("pass.bin"), &pages).unwrap();
        // Columns 0, 2 and 3 baked and equally lit; column 1 inside geometry.
        for y in 0..4 {
            for x in [0, 2, 3] {
                w.set(0, (x, y), [1.0; 3], [4.0; 3]);
            }
            w.mark_inside(0, (1, y));
        }
        w.mark_inside(0, (9, 9));
        let pass = w.finish(&scene, &triangles).unwrap();
        // The dilation fills the inside texels and keeps their mark.
        let px = pass.pixels()[4 + 1];
        assert!(px[GENERATION] > 1.0 && px[INSIDE] == 1.0, "{px:?}");
        assert_eq!(pass.pixels()[4 + 2][INSIDE], 0.0);
        // In column 2 but with weight on column 1: not read, though every baked tap agrees.
        let l = pass.bilinear(0, Vec2::new(2.2, 1.5));
        assert!(!l.baked && !l.smooth && !l.gathered_smooth, "{l:?}");
        assert_eq!(l.total, Vec3::splat(4.0));
        // Between the centres of columns 2 and 3: read.
        let l = pass.bilinear(0, Vec2::new(2.6, 1.5));
        assert!(l.baked && l.smooth && l.gathered_smooth, "{l:?}");
        // On column 0's centre, no weight on column 1: read.
        assert!(pass.bilinear(0, Vec2::new(0.5, 1.5)).baked);
    }

    #[test]
    fn dilation_fills_rings_around_charts_and_no_further() {
        let size = PageRecord {
            width: 12,
            height: 1,
        };
        let mut px = vec![[0.0; 8]; 12];
        px[0] = [2.0, 2.0, 2.0, 1.0, 3.0, 3.0, 3.0, 0.0];
        dilate(&mut px, size);
        for (x, p) in px.iter().enumerate() {
            if x as u32 <= DILATION {
                assert_eq!((p[0], p[4]), (2.0, 3.0), "pixel {x}: both layers");
                assert_eq!(
                    p[GENERATION],
                    x as f32 + 1.0,
                    "pixel {x} filled by ring {x}"
                );
            } else {
                assert_eq!(p[GENERATION], 0.0, "pixel {x} is beyond the dilation");
            }
        }
    }

    #[test]
    fn a_triangle_bakes_the_side_its_texels_face() {
        let (scene, mut triangles, pages) = scene();
        let image = vec![None; 16];
        let pass =
            PreviousPass::from_pixels(&scene, &triangles, &pages, std::slice::from_ref(&image));
        assert!(pass.bakes_side(0, true) && !pass.bakes_side(0, false));
        assert!(
            !pass.bakes_side(1, true) && !pass.bakes_side(1, false),
            "no such triangle"
        );
        // Seen from the back only: its texels describe the back.
        triangles[0].flags = LIGHTMAPPED | SEEN_BACK | TEXELS_BACK;
        let pass =
            PreviousPass::from_pixels(&scene, &triangles, &pages, std::slice::from_ref(&image));
        assert!(pass.bakes_side(0, false) && !pass.bakes_side(0, true));
        // Seen from both sides, its texels describing the front.
        triangles[0].flags = LIGHTMAPPED | SEEN_FRONT | SEEN_BACK;
        let pass =
            PreviousPass::from_pixels(&scene, &triangles, &pages, std::slice::from_ref(&image));
        assert!(pass.bakes_side(0, true) && !pass.bakes_side(0, false));
        // No lightmap UVs: no side is baked.
        triangles[0] = TriangleRecord::unmapped(SEEN_FRONT);
        let pass = PreviousPass::from_pixels(&scene, &triangles, &pages, &[image]);
        assert!(!pass.bakes_side(0, true) && !pass.bakes_side(0, false));
    }
}
