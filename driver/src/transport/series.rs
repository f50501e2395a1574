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
//! [`PreviousPass`] holds the pass's image: only the pixels that hold texels, both layers in
//! 12 bytes, found through a table of 8×8-pixel cells per page (`transport/pass_image.rs`),
//! in a file of the work directory that is memory-mapped (file-backed pages, not anonymous
//! memory) and built on every core straight from the pass's result files
//! ([`PreviousPass::build`]; its source is `bake/run.rs`'s `ResultTiles`), or by
//! [`PreviousPassWriter`] from pixels set one by one (tests). Lookups are bilinear over the baked pixels among the four (weights
//! renormalised). The bake's images hold no dilation: a lookup is read only where the texel
//! under it is baked, and then only baked pixels count; [`PreviousPass::from_pixels`] (a baked
//! lightmap, for `render`) dilates [`DILATION`] rings, which a lookup reads where none of its
//! four pixels is baked.
//!
//! Deviations and limits: detail finer than a texel where the texels agree — soft shadows,
//! gradients within [`SMOOTH_RATIO`] — is averaged (the lightmap's resolution error, which
//! the `path` transport does not have).

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use memmap2::{Mmap, MmapMut};

use crate::scene::Scene;
use crate::texels::{PageRecord, TileRect, TriangleRecord};
use crate::transport::emitters::luminance;
use crate::transport::lookup_filter::Surfel;
use crate::transport::pass_image::{self, Built, CELL, Layout, Source, SourceTexel, View};

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

/// One pixel of a dense image before it is packed ([`PreviousPass::from_pixels`]):
/// gather-only irradiance (0..3), its generation (3; 0: empty, 1: a baked texel, g + 1:
/// filled by dilation ring g), total irradiance (4..7), and 1 where a texel inside geometry
/// lies (7).
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

/// An image's bytes: a memory-mapped file, or a buffer (memory images).
#[derive(Debug)]
enum Storage {
    Mapped(Mmap),
    Owned(Vec<u64>),
}

impl Storage {
    fn bytes(&self) -> &[u8] {
        match self {
            Storage::Mapped(m) => &m[..],
            Storage::Owned(v) => bytemuck::cast_slice(v),
        }
    }
}

/// The previous pass's irradiance, looked up by triangle and barycentrics.
#[derive(Debug)]
pub struct PreviousPass {
    storage: Storage,
    layout: Layout,
    built: Built,
    triangles: TriangleUvs,
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

/// Why a pass image could not be built: its file, or its source.
#[derive(Debug)]
pub enum BuildError<E> {
    /// Writing or mapping the image failed.
    Image(PassImageError),
    /// The source could not be read.
    Source(E),
}

/// Each triangle's page and pixel-space corners, from the texel file's triangle table (the
/// lightmap `prepare` rasterised, whatever UVs the scene carries), and its texel size from the
/// scene's positions; `None` for triangles without lightmap UVs. 40 bytes a triangle, shared
/// by every pass image of a bake (a clone is a reference).
#[derive(Clone, Debug)]
pub struct TriangleUvs(std::sync::Arc<[Option<TriangleUv>]>);

impl TriangleUvs {
    /// The table of `scene`'s triangles, `records` the texel file's triangle table.
    pub fn new(scene: &Scene, records: &[TriangleRecord]) -> Self {
        let uv = |(t, r): (&crate::scene::Triangle, &TriangleRecord)| {
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
        };
        Self(scene.triangles.iter().zip(records).map(uv).collect())
    }

    fn get(&self, prim: u32) -> Option<&TriangleUv> {
        self.0.get(prim as usize)?.as_ref()
    }
}

impl PreviousPass {
    /// A lightmap held in memory: `images[p]` is page `p`'s pixels, row-major, RGB, `None`
    /// for a pixel no texel covers; both layers hold it, and [`DILATION`] rings around the
    /// covered pixels are filled. For rendering a baked lightmap, and tests.
    ///
    /// # Panics
    /// If the pages hold 2³² − 2 pixels or more with a value (the image's 32-bit indices).
    pub fn from_pixels(
        scene: &Scene,
        triangles: &[TriangleRecord],
        pages: &[PageRecord],
        images: &[Vec<Option<Vec3>>],
    ) -> Self {
        let dense: Vec<Vec<Pixel>> = pages
            .iter()
            .enumerate()
            .map(|(p, size)| {
                let n = size.width as usize * size.height as usize;
                let mut pixels = vec![[0.0; 8]; n];
                for (px, c) in pixels.iter_mut().zip(images.get(p).into_iter().flatten()) {
                    if let Some(c) = c {
                        *px = [c.x, c.y, c.z, 1.0, c.x, c.y, c.z, 0.0];
                    }
                }
                dilate(&mut pixels, *size);
                pixels
            })
            .collect();
        let source = DenseSource::new(pages, &dense);
        let (blocks, texels) = source.bounds();
        let layout = Layout::new(pages, blocks, texels).expect("a memory image within u32 texels");
        let mut words = vec![0u64; layout.bytes() / 8];
        let Ok(built) =
            pass_image::build(&layout, &source, bytemuck::cast_slice_mut(&mut words), 0);
        Self {
            storage: Storage::Owned(words),
            layout,
            built,
            triangles: TriangleUvs::new(scene, triangles),
            pass: 0,
        }
    }

    /// Builds the image of `source` (its gathered light filtered over `filter` texels; 0:
    /// none) into a file at `path`, on the current rayon pool, and maps it. The filter holds
    /// a band of rows in memory while it runs ([`pass_image::build`]), no file.
    ///
    /// # Errors
    /// [`BuildError::Image`] when a file cannot be created, sized or mapped, or the
    /// source holds more than 32-bit indices reach; [`BuildError::Source`] when it cannot be
    /// read.
    pub fn build<S: Source>(
        path: &Path,
        pages: &[PageRecord],
        source: &S,
        filter: u32,
        triangles: &TriangleUvs,
    ) -> Result<Self, BuildError<S::Error>> {
        let err = |path: &Path, what: String| {
            BuildError::Image(PassImageError {
                path: path.to_owned(),
                what,
            })
        };
        let (blocks, texels) = source.bounds();
        let layout = Layout::new(pages, blocks, texels).ok_or_else(|| {
            err(
                path,
                format!("{texels} texels: more than one pass image holds (2^32 - 2)"),
            )
        })?;
        let (file, mut map) =
            create_mapped(path, layout.bytes(), "pass image").map_err(BuildError::Image)?;
        let built =
            pass_image::build(&layout, source, &mut map, filter).map_err(BuildError::Source)?;
        // No flush: the file is this run's scratch, read back through the page cache.
        drop(map);
        let used = built.bytes(&layout).max(8) as u64;
        file.set_len(used).map_err(|e| {
            err(
                path,
                format!("cannot cut the pass image to {used} bytes: {e}"),
            )
        })?;
        // SAFETY: the file was created by this process in its own work directory and is not
        // resized or written through any other handle while mapped (the work directory's
        // invariant, crate::output); it is at least `built.bytes` long, which `View` checks.
        let map = unsafe { Mmap::map(&file) }
            .map_err(|e| err(path, format!("cannot remap the pass image: {e}")))?;
        // The lookups land anywhere in the image: a page the kernel let go is read back
        // alone, not with the 128 KiB of readahead around it that a world larger than memory
        // would evict again at once. Only a hint: a failure changes nothing but speed.
        let _ = map.advise(memmap2::Advice::Random);
        Ok(Self {
            storage: Storage::Mapped(map),
            layout,
            built,
            triangles: triangles.clone(),
            pass: 0,
        })
    }

    fn view(&self) -> View<'_> {
        View::new(&self.layout, self.built, self.storage.bytes())
    }

    /// Bytes the image holds (its file's length, for a mapped one).
    pub fn bytes(&self) -> u64 {
        self.built.bytes(&self.layout) as u64
    }

    /// Bytes the lookups' filter held at most while it built the image (0: unfiltered).
    pub fn filter_window_bytes(&self) -> u64 {
        (self.built.filter_surfels * size_of::<Surfel>()) as u64
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
        let Some(t) = self.triangles.get(prim) else {
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
        let tap = self.view().tap(page, pixel[0], pixel[1]);
        if !tap.baked {
            return 0.0;
        }
        luminance(tap.total - tap.gathered).max(0.0)
    }

    /// Whether triangle `prim`'s texels bake its winding's `front` side (or its back, when
    /// `front` is false): then its total irradiance holds the direct light arriving there.
    pub fn bakes_side(&self, prim: u32, front: bool) -> bool {
        matches!(self.triangles.get(prim), Some(t) if t.front == front)
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
        matches!(self.triangles.get(prim), Some(tri) if t > texels * tri.texel)
    }

    /// Bilinear filter around `uv` (pixel centres at +0.5) over the baked pixels among its
    /// four, weights renormalised; over the dilated ones only where none is baked (a point in
    /// a chart's padding). A dilated pixel may mix two charts that lie close in the atlas, so
    /// a hit inside a chart never reads one. [`Lookup::baked`] only where the pixel the point
    /// lies in is baked and no pixel with weight is marked inside geometry.
    fn bilinear(&self, page: u32, uv: Vec2) -> Lookup {
        let view = self.view();
        let Some((w, h)) = self.layout.page_size(page) else {
            return Lookup::default();
        };
        let (w, h) = (i64::from(w), i64::from(h));
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
            (view.tap(page, x as u32, y as u32), wgt)
        });
        let any_baked = taps.iter().any(|(px, wgt)| px.baked && *wgt > 0.0);
        let (mut gathered, mut total, mut weight) = (Vec3::ZERO, Vec3::ZERO, 0.0f32);
        let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
        let (mut glo, mut ghi) = (f32::INFINITY, 0.0f32);
        for (px, wgt) in taps {
            let usable = if any_baked { px.baked } else { px.filled };
            if usable && wgt > 0.0 {
                let (t, g) = (px.total, px.gathered);
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
        let inside = taps.iter().any(|(px, wgt)| px.inside && *wgt > 0.0);
        let baked = nearest.0.baked && !inside;
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

/// Writes a pass image file from pixels set one by one: [`Self::set`] every baked texel,
/// then [`Self::finish`]. With [`Self::with_filter`], [`Self::describe`] every baked texel too,
/// and the gathered light is filtered ([`crate::transport::lookup_filter`]). Holds the pixels
/// in memory until then: for tests and small images; the bake builds its images from its
/// result files ([`PreviousPass::build`]).
pub struct PreviousPassWriter {
    path: PathBuf,
    pages: Vec<PageRecord>,
    texels: BTreeMap<(u32, u32, u32), SourceTexel>,
    filter: u32,
}

/// Creates (or truncates) a file of `bytes` zero bytes (at least 8) at `path` and maps it.
fn create_mapped(path: &Path, bytes: usize, what: &str) -> Result<(File, MmapMut), PassImageError> {
    let err = |what: String| PassImageError {
        path: path.to_owned(),
        what,
    };
    let bytes = bytes.max(8) as u64;
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
    let map = unsafe { MmapMut::map_mut(&file) }
        .map_err(|e| err(format!("cannot map the {what}: {e}")))?;
    Ok((file, map))
}

impl PreviousPassWriter {
    /// A writer of the image file at `path` for `pages` (created by [`Self::finish`]).
    ///
    /// # Errors
    /// None now; kept for the callers that create files.
    pub fn create(path: &Path, pages: &[PageRecord]) -> Result<Self, PassImageError> {
        Ok(Self {
            path: path.to_owned(),
            pages: pages.to_vec(),
            texels: BTreeMap::new(),
            filter: 0,
        })
    }

    /// Filters the gathered light over `radius` texels when the image is finished (0: no
    /// filter), from the texels [`Self::describe`] records.
    ///
    /// # Errors
    /// None now; kept for the callers.
    pub fn with_filter(mut self, radius: u32) -> Result<Self, PassImageError> {
        self.filter = radius;
        Ok(self)
    }

    /// The texel at (`x`, `y`) of `page`, if that pixel is on its page.
    fn texel(&mut self, page: u32, (x, y): (u32, u32)) -> Option<&mut SourceTexel> {
        let size = self.pages.get(page as usize)?;
        (x < size.width && y < size.height).then(|| {
            self.texels.entry((page, y, x)).or_insert(SourceTexel {
                pixel: (x, y),
                ..SourceTexel::default()
            })
        })
    }

    /// Records what the filter needs of texel (`x`, `y`) of page `page`
    /// ([`Self::with_filter`]; nothing without a filter, or off the page).
    pub fn describe(&mut self, page: u32, pixel: (u32, u32), surfel: Surfel) {
        if self.filter > 0
            && let Some(t) = self.texel(page, pixel)
        {
            t.surfel = Some(surfel);
        }
    }

    /// Records texel (`x`, `y`) of page `page`: its gather-only and total irradiance.
    /// Non-finite values and pixels off the page are ignored.
    pub fn set(&mut self, page: u32, pixel: (u32, u32), gathered: [f32; 3], total: [f32; 3]) {
        let finite = gathered.iter().chain(&total).all(|c| c.is_finite());
        if let (true, Some(t)) = (finite, self.texel(page, pixel)) {
            (t.baked, t.gathered, t.total) = (true, gathered, total);
        }
    }

    /// Marks texel (`x`, `y`) of page `page` as lying inside geometry: not baked, and a
    /// lookup with weight on it is not read ([`Lookup::baked`]).
    pub fn mark_inside(&mut self, page: u32, pixel: (u32, u32)) {
        if let Some(t) = self.texel(page, pixel) {
            t.inside = true;
        }
    }

    /// Builds the image file and maps it for lookups.
    ///
    /// # Errors
    /// [`PassImageError`] when the file cannot be written or mapped.
    pub fn finish(
        self,
        scene: &Scene,
        triangles: &[TriangleRecord],
    ) -> Result<PreviousPass, PassImageError> {
        // Tiles of one band of cells each.
        let mut tiles: Vec<(u32, Vec<SourceTexel>)> = Vec::new();
        for (&(page, y, _), t) in &self.texels {
            if tiles.last().is_none_or(|(p, band)| {
                *p != page || band.first().is_some_and(|b| b.pixel.1 / CELL != y / CELL)
            }) {
                tiles.push((page, Vec::new()));
            }
            tiles.last_mut().expect("pushed above").1.push(*t);
        }
        let source = TileList::new(&self.pages, tiles);
        let image = PreviousPass::build(
            &self.path,
            &self.pages,
            &source,
            self.filter,
            &TriangleUvs::new(scene, triangles),
        );
        image.map_err(|e| match e {
            BuildError::Image(e) => e,
            BuildError::Source(never) => match never {},
        })
    }
}

/// A source held in memory: tiles of one band of cells of one page each.
struct TileList {
    tiles: Vec<(u32, Vec<SourceTexel>)>,
    /// Each page's width.
    widths: Vec<u32>,
    blocks: u64,
    texels: u64,
}

impl TileList {
    fn new(pages: &[PageRecord], tiles: Vec<(u32, Vec<SourceTexel>)>) -> Self {
        let across = |p: u32| pages.get(p as usize).map_or(0, |s| s.width.div_ceil(CELL));
        Self {
            blocks: tiles.iter().map(|(p, _)| u64::from(across(*p))).sum(),
            texels: tiles.iter().map(|(_, t)| t.len() as u64).sum(),
            widths: pages.iter().map(|p| p.width).collect(),
            tiles,
        }
    }
}

impl Source for TileList {
    type Error = std::convert::Infallible;

    fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    fn rect(&self, tile: usize) -> TileRect {
        let (page, texels) = &self.tiles[tile];
        let top = texels.first().map_or(0, |t| t.pixel.1 / CELL * CELL);
        let width = self.widths.get(*page as usize).copied().unwrap_or(0);
        TileRect {
            page: *page,
            x: 0,
            y: top,
            width,
            height: CELL,
        }
    }

    fn bounds(&self) -> (u64, u64) {
        (self.blocks, self.texels)
    }

    fn read_tile(
        &self,
        tile: usize,
        out: &mut Vec<SourceTexel>,
    ) -> Result<u32, std::convert::Infallible> {
        let (page, texels) = &self.tiles[tile];
        out.clear();
        out.extend_from_slice(texels);
        Ok(*page)
    }
}

/// The source of [`PreviousPass::from_pixels`]: dense, dilated pages, a band of cells a tile.
struct DenseSource<'a> {
    pages: &'a [PageRecord],
    dense: &'a [Vec<Pixel>],
    /// Every band: page and first row.
    bands: Vec<(u32, u32)>,
}

impl<'a> DenseSource<'a> {
    fn new(pages: &'a [PageRecord], dense: &'a [Vec<Pixel>]) -> Self {
        let bands = pages
            .iter()
            .enumerate()
            .flat_map(|(p, s)| {
                (0..s.height)
                    .step_by(CELL as usize)
                    .map(move |y| (p as u32, y))
            })
            .collect();
        Self {
            pages,
            dense,
            bands,
        }
    }
}

impl Source for DenseSource<'_> {
    type Error = std::convert::Infallible;

    fn tile_count(&self) -> usize {
        self.bands.len()
    }

    fn rect(&self, tile: usize) -> TileRect {
        let (page, y) = self.bands[tile];
        let size = self.pages[page as usize];
        TileRect {
            page,
            x: 0,
            y,
            width: size.width,
            height: CELL.min(size.height - y),
        }
    }

    fn bounds(&self) -> (u64, u64) {
        let blocks = self
            .bands
            .iter()
            .map(|&(p, _)| u64::from(self.pages[p as usize].width.div_ceil(CELL)))
            .sum();
        let content = |px: &&Pixel| px[GENERATION] > 0.0 || px[INSIDE] == 1.0;
        let texels = self.dense.iter().flatten().filter(content).count() as u64;
        (blocks, texels)
    }

    fn read_tile(
        &self,
        tile: usize,
        out: &mut Vec<SourceTexel>,
    ) -> Result<u32, std::convert::Infallible> {
        out.clear();
        let (page, top) = self.bands[tile];
        let w = self.pages[page as usize].width;
        let h = self.pages[page as usize].height;
        for y in top..(top + CELL).min(h) {
            for x in 0..w {
                let px = self.dense[page as usize][(y * w + x) as usize];
                if px[GENERATION] > 0.0 || px[INSIDE] == 1.0 {
                    out.push(SourceTexel {
                        pixel: (x, y),
                        baked: px[GENERATION] == 1.0,
                        filled: px[GENERATION] > 1.0,
                        inside: px[INSIDE] == 1.0,
                        gathered: [px[0], px[1], px[2]],
                        total: [px[4], px[5], px[6]],
                        surfel: None,
                    });
                }
            }
        }
        Ok(page)
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
        let view = image.view();
        for i in 0..16 {
            let p = view.tap(0, i % 4, i / 4);
            let (g, t) = (p.gathered.x, p.total.x);
            // The page's corners have no texel opposite them in the window: left alone.
            let corner = matches!((i % 4, i / 4), (0 | 3, 0 | 3));
            assert!(
                corner == (g == 1.0 || g == 3.0),
                "pixel {i}: gathered {g}, filtered: {}",
                !corner
            );
            assert!(
                (t - g - 10.0 * (i % 4) as f32).abs() < 1e-3,
                "pixel {i}: direct moved"
            );
        }
        // Radius 0 leaves the values.
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
        let image = w.finish(&scene, &meshes).unwrap();
        let p = image.view().tap(0, 0, 0);
        assert_eq!((p.gathered.x, p.total.x), (1.0, 2.0));
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
        // The inside texels are marked, and hold no value: the bake's image is not dilated.
        let px = pass.view().tap(0, 1, 1);
        assert!(px.inside && !px.filled && !px.baked, "{px:?}");
        assert!(!pass.view().tap(0, 2, 1).inside);
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
