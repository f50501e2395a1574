//! `prepare`: rasterize a scene's lightmap UV charts into texel tiles (docs/ARCHITECTURE.md, "The bake, as data flows").
//!
//! The paper (Silvennoinen & Sloan 2019, §2.1) bakes lightmap texels, each with a world
//! position and normal, grouped into clusters; it assumes the texels exist. This module makes
//! them from glTF `TEXCOORD_1`:
//!
//! 1. **Layout.** Every mesh gets a map `pixel = uv · scale + offset` onto an atlas page
//!    ([`MeshLayout`]). *Shared* layout: all meshes already share one atlas (the converted
//!    Bitterli scenes, made with xatlas) — page 0, `scale` = page size. *Per-mesh* layout:
//!    every mesh has its own 0..1 UVs (the vinc3r Cornell box) — each mesh's UV bounding
//!    square becomes a square cell sized for the requested texel density, cells are shelf
//!    packed (largest first, 2-texel gutter) onto pages of at most 4096². `Auto` (default)
//!    takes the shared layout unless texel centres of different meshes overlap in UV space.
//! 2. **Centres.** A texel whose centre lies inside a triangle (edge functions, inclusive)
//!    takes that triangle; where several do, the first in scene order wins.
//! 3. **Conservative pass.** A texel still empty but overlapped by a triangle (separating
//!    axis test of the texel square against the UV triangle) takes that triangle's point
//!    *closest to the texel centre* and is flagged [`FLAG_PARTIAL`], so thin triangles and
//!    chart borders keep texels. Deviation: the public write-ups on lightmap rasterisation clip the triangle
//!    to the texel and spreads samples over the clipped polygons; we store one point and the
//!    footprint axes instead, so the bake can still spread ray origins over the texel.
//! 4. **Records.** Position and normal are interpolated with the barycentrics of that point
//!    (clamped to the triangle, so every position lies on its triangle); the normal is the
//!    interpolated vertex normal, or the geometric normal where the source has none, turned
//!    to the side of the two-sided surface that sees the scene ([`crate::prepare::facing`]); the
//!    footprint axes dP/du, dP/dv are the world-space change over one texel step, from the
//!    inverse of the triangle's UV Jacobian.
//! 5. **Tiles.** 32×32-texel tiles of each page in Morton (Z-order) order of their tile
//!    coordinates: charts are spatially coherent in UV, and Z-order keeps neighbouring tiles
//!    near each other in the file. Empty tiles are not stored.
//!
//! Resolution: `--texels-per-unit D` (texels along one world unit), `--size W×H` (shared:
//! the page size; per-mesh: the single page the packing must fit), or, when neither is
//! given, a budget of one 1024×1024 page — the resolution the converted scenes' atlases
//! were made for (scenes/README.md).
//!
//! Memory: one page's ownership grid (4 bytes per texel) at a time, plus one tile.
//!
//! Meshes without lightmap UVs (or all meshes) can get them from xatlas first
//! ([`prepare_with`], [`unwrap`]): their atlas and the other meshes' UV squares are packed
//! onto pages, every triangle's UVs are rewritten as page UVs ([`Lightmap`]), and those are
//! rasterised as above — the same UVs `--write-gltf` gives the engine.
//!
//! **A UV set that is not a lightmap atlas counts as missing** (docs/levels.md, "UV sets
//! that are not lightmap atlases"): an OBJ's one UV set is usually the texture's, tiling
//! far outside [0, 1] and mapping many faces onto the same texture space. Under
//! `--unwrap missing` a mesh whose UVs leave [0, 1], have no area, or overlap themselves
//! ([`uv_set_problem`]: more than [`SELF_OVERLAP_SHARE`] of the cells of a coarse
//! [`ATLAS_TEST_SIZE`]² raster covered twice, each triangle counting only the cells whose
//! centre lies inside it by a margin, so triangles sharing an edge never count twice) is
//! unwrapped too; the report says why, per mesh ([`NotAtlas`]).
//!
//! An atlas that cannot fit says what would: the page size the charts packed into at the
//! lowest density tried, or the density that fits the pages.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use guidebake_kernels::presort::CurveOrder;
use rayon::prelude::*;

use crate::scene::{Scene, Triangle};
use crate::texels::{
    FLAG_INSIDE, FLAG_PARTIAL, FLAG_VALID, PageRecord, TILE_SIZE, TexelFileError, TexelRecord,
    TexelWriter, TileRect, TriangleRecord,
};
use facing::{FacingReport, Visibility, seen_sides};

pub mod facing;
pub mod shell;
pub mod unwrap;
pub use unwrap::{Unwrap, UnwrapError};

/// Largest page edge `prepare` creates.
pub const MAX_PAGE: u32 = 16384;
/// Page edge used by the per-mesh packer when no `--size` is given.
pub const PACK_PAGE: u32 = 4096;
/// Default budget: one page of this edge.
pub const DEFAULT_PAGE: u32 = 1024;
const GUTTER: u32 = 2;
const PARTIAL_BIT: u32 = 1 << 31;

/// How big the lightmap is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Resolution {
    /// One 1024×1024 page's worth of texels (see the module docs).
    Default,
    /// Texels per world unit along an edge.
    TexelsPerUnit(f32),
    /// Page size in texels.
    Size(u32, u32),
}

/// Which atlas layout to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Layout {
    /// Shared unless meshes overlap in UV space.
    Auto,
    /// All meshes already share one atlas.
    Shared,
    /// Every mesh has its own UV square; pack them.
    PerMesh,
}

/// Options of [`prepare`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrepareOptions {
    /// Resolution.
    pub resolution: Resolution,
    /// Layout.
    pub layout: Layout,
}

/// What [`prepare`] did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PrepareReport {
    /// Texels written.
    pub texels: u64,
    /// Of those, texels whose centre no triangle covers (conservative pass).
    pub partial_texels: u64,
    /// Tiles written.
    pub tiles: u64,
    /// Page sizes.
    pub pages: Vec<(u32, u32)>,
    /// `true` when the per-mesh packing was used.
    pub per_mesh_layout: bool,
    /// Texels per world unit (derived when a size was given).
    pub texels_per_unit: f32,
    /// Meshes without lightmap UVs (they get no texels).
    pub meshes_without_lightmap_uvs: Vec<String>,
    /// Triangles skipped because their UV triangle has zero area.
    pub uv_degenerate_triangles: u64,
    /// Triangles whose texels face against their winding: the side that sees the scene
    /// ([`crate::prepare::facing`]).
    pub flipped_triangles: u64,
    /// Of the texels, those inside geometry ([`FLAG_INSIDE`]): not baked, filled by the
    /// lightmap's dilation.
    pub inside_texels: u64,
    /// Which sides of the triangles face open space ([`crate::prepare::facing`]).
    pub facing: FacingReport,
    /// What the unwrapper did, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unwrap: Option<UnwrapReport>,
    /// Meshes whose UV set is not a lightmap atlas, and why ([`uv_set_problem`]).
    pub not_atlas: Vec<NotAtlas>,
    /// Textures the scene's loader could not read (filled in by the `prepare` command,
    /// which loads the scene; [`crate::scene::LoadNotes`]).
    pub missing_textures: Vec<crate::scene::MissingTexture>,
    /// The triangles of each role but `baked`, and the `--role` rules that matched nothing
    /// (filled in by the `prepare` command, which applies them; [`crate::scene::roles`]).
    pub roles: crate::scene::RoleReport,
    /// A shell that keeps the sun and sky out of the level, if one does ([`shell`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shell: Option<shell::Shell>,
}

/// A mesh whose own UV set is not a lightmap atlas ([`uv_set_problem`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NotAtlas {
    /// The mesh.
    pub mesh: String,
    /// Why, e.g. "leaves [0, 1] (u -32.25..97.5, v -177..111.75)".
    pub reason: String,
    /// Whether it was unwrapped (under `--unwrap missing`; `never` keeps it as it is).
    pub unwrapped: bool,
}

/// Edge of the coarse raster [`uv_set_problem`] tests a UV set for overlaps on.
pub const ATLAS_TEST_SIZE: u32 = 256;
/// A UV set overlaps itself when more than this share of the raster cells it covers are
/// covered twice or more.
pub const SELF_OVERLAP_SHARE: f64 = 0.01;
/// How far outside [0, 1] an atlas's UVs may stray (rounding of exporters).
const UV_RANGE_SLACK: f32 = 1e-3;
/// How far inside a triangle, in cells, a cell centre must lie to count for it: a centre on
/// the edge two triangles share counts for neither.
const INSIDE_MARGIN: f32 = 1e-3;

/// Why the UV set of the triangles `triangles` (one mesh's, all with UVs) is not a lightmap
/// atlas, or `None` when it is one: its UVs leave [0, 1] (by more than rounding), it has no
/// area, or it overlaps itself (module docs). Cost: the triangles' bounding boxes on an
/// [`ATLAS_TEST_SIZE`]² raster (64 KiB).
#[must_use]
pub fn uv_set_problem(triangles: &[Triangle]) -> Option<String> {
    let uvs = || triangles.iter().filter_map(|t| t.lightmap_uv);
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    let mut area = 0.0f64;
    for uv in uvs() {
        for v in uv {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        area += f64::from(uv_area(&uv).abs());
    }
    if lo.min_element() < -UV_RANGE_SLACK || hi.max_element() > 1.0 + UV_RANGE_SLACK {
        return Some(format!(
            "leaves [0, 1] (u {}..{}, v {}..{})",
            lo.x, hi.x, lo.y, hi.y
        ));
    }
    if area.is_nan() || area <= 0.0 {
        return Some("has no area".into());
    }
    const N: u32 = ATLAS_TEST_SIZE;
    let mut count = vec![0u8; (N * N) as usize];
    for uv in uvs() {
        let q = uv.map(|v| v * N as f32);
        let orientation = (q[1] - q[0]).perp_dot(q[2] - q[0]);
        if orientation == 0.0 || !orientation.is_finite() {
            continue;
        }
        let sign = orientation.signum();
        // Per edge: the inward unit normal's distance function.
        let edges = [0, 1, 2].map(|i| {
            let (a, b) = (q[i], q[(i + 1) % 3]);
            let len = (b - a).length();
            (a, (b - a) * (sign / len))
        });
        let (x0, x1, y0, y1) = pixel_range(&q, (N, N));
        for y in y0..y1 {
            for x in x0..x1 {
                let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                if edges
                    .iter()
                    .all(|(a, e)| e.perp_dot(c - *a) > INSIDE_MARGIN)
                {
                    let n = &mut count[(y * N + x) as usize];
                    *n = n.saturating_add(1);
                }
            }
        }
    }
    let covered = count.iter().filter(|&&n| n > 0).count();
    let twice = count.iter().filter(|&&n| n > 1).count();
    if covered > 0 && twice as f64 > SELF_OVERLAP_SHARE * covered as f64 {
        return Some(format!(
            "overlaps itself ({:.1} % of the area it covers is covered twice or more)",
            100.0 * twice as f64 / covered as f64
        ));
    }
    None
}

/// The meshes of `scene` whose UV set is not a lightmap atlas; under [`Unwrap::Missing`]
/// they are added to `selected` (the meshes to unwrap).
fn not_atlas_meshes(scene: &Scene, unwrap: Unwrap, selected: &mut [bool]) -> Vec<NotAtlas> {
    if unwrap == Unwrap::Always {
        return Vec::new();
    }
    let problems: Vec<Option<String>> = scene
        .meshes
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            if selected[i] || !m.has_lightmap_uvs || m.triangle_count == 0 {
                return None;
            }
            let first = m.first_triangle as usize;
            uv_set_problem(&scene.triangles[first..first + m.triangle_count as usize])
        })
        .collect();
    let mut out = Vec::new();
    for (i, problem) in problems.into_iter().enumerate() {
        if let Some(reason) = problem {
            let unwrapped = unwrap == Unwrap::Missing;
            selected[i] |= unwrapped;
            out.push(NotAtlas {
                mesh: scene.meshes[i].name.clone(),
                reason,
                unwrapped,
            });
        }
    }
    out
}

/// What the unwrapper did ([`prepare_with`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UnwrapReport {
    /// Meshes that got their lightmap UVs from xatlas.
    pub meshes: Vec<String>,
    /// Charts xatlas made.
    pub charts: u32,
    /// Sizes of the xatlas atlases (one, or one per mesh when one atlas would not fit a page).
    pub atlases: Vec<(u32, u32)>,
    /// Seconds spent in xatlas (charting and packing).
    pub seconds: f64,
    /// Triangles of the unwrapped meshes too small for xatlas ([`unwrap::TINY_AREA`]):
    /// they get no texels.
    pub tiny_triangles: u64,
    /// Texels written / total page area.
    pub utilisation: f64,
}

/// Why `prepare` failed.
#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    /// Writing the texel file failed.
    #[error(transparent)]
    Texels(#[from] TexelFileError),
    /// No mesh has lightmap UVs.
    #[error("{path}: no mesh has lightmap UVs (TEXCOORD_1); meshes without: {}", meshes.join(", "))]
    NoLightmapUvs {
        /// The scene file.
        path: PathBuf,
        /// Every mesh name.
        meshes: Vec<String>,
    },
    /// The options cannot be met.
    #[error("{path}: {message}")]
    Resolution {
        /// The scene file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Nothing was rasterized.
    #[error("{path}: no texel is covered at this resolution")]
    NoTexels {
        /// The scene file.
        path: PathBuf,
    },
    /// The unwrapper failed on a mesh.
    #[error(transparent)]
    Unwrap(#[from] UnwrapError),
}

/// Where a mesh's lightmap UVs land on the atlas: `pixel = uv · uv_scale + uv_offset` on
/// `page` (continuous pixel coordinates). Each triangle's result is what the texel file's
/// triangle table holds ([`TriangleRecord`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct MeshLayout {
    /// Atlas page.
    page: u32,
    /// 1 when the mesh has lightmap UVs (and texels), else 0.
    flags: u32,
    /// UV → pixel scale.
    uv_scale: [f32; 2],
    /// UV → pixel offset.
    uv_offset: [f32; 2],
}

/// Per-mesh UV statistics.
#[derive(Clone, Copy, Debug)]
struct MeshUv {
    world_area: f64,
    uv_area: f64,
    lo: Vec2,
    hi: Vec2,
}

fn uv_area(uv: &[Vec2; 3]) -> f32 {
    0.5 * (uv[1] - uv[0]).perp_dot(uv[2] - uv[0])
}

fn mesh_uv_stats(scene: &Scene) -> Vec<Option<MeshUv>> {
    let mut out: Vec<Option<MeshUv>> = vec![None; scene.meshes.len()];
    for (i, t) in scene.triangles.iter().enumerate() {
        let Some(uv) = t.lightmap_uv.filter(|_| scene.role(i).has_texels()) else {
            continue;
        };
        let s = out[t.mesh as usize].get_or_insert(MeshUv {
            world_area: 0.0,
            uv_area: 0.0,
            lo: Vec2::splat(f32::INFINITY),
            hi: Vec2::splat(f32::NEG_INFINITY),
        });
        s.world_area += f64::from(t.area());
        s.uv_area += f64::from(uv_area(&uv).abs());
        for v in uv {
            s.lo = s.lo.min(v);
            s.hi = s.hi.max(v);
        }
    }
    out
}

/// Writes the texel file for `scene` to `out` from the scene's own lightmap UVs
/// ([`prepare_with`] and [`Unwrap::Never`]).
///
/// # Errors
/// [`PrepareError`] when no mesh has lightmap UVs, the resolution cannot be met, nothing is
/// covered, or writing fails (then no file is left at `out`).
pub fn prepare(
    scene: &Scene,
    out: &Path,
    opts: PrepareOptions,
) -> Result<PrepareReport, PrepareError> {
    prepare_with(scene, out, opts, Unwrap::Never).map(|(report, _)| report)
}

/// Where every triangle's texels are: the layout `prepare` rasterised, as UVs of the page
/// (0..1 across it) — what `--write-gltf` writes as `TEXCOORD_1`.
#[derive(Clone, Debug, PartialEq)]
pub struct Lightmap {
    /// Page sizes in texels.
    pub pages: Vec<(u32, u32)>,
    /// Per mesh: its page.
    pub mesh_page: Vec<u32>,
    /// Per triangle: its UVs on its mesh's page, `None` where it has no texels.
    pub uv: Vec<Option<[Vec2; 3]>>,
}

impl Lightmap {
    /// The layout of `records` applied to the scene's own UVs.
    fn of_records(scene: &Scene, pages: &[PageRecord], meshes: &[MeshLayout]) -> Self {
        let uv = scene
            .triangles
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let m = &meshes[t.mesh as usize];
                let p = pages[m.page as usize];
                let size = Vec2::new(p.width as f32, p.height as f32);
                pixel_uv(t, m)
                    .filter(|_| m.flags != 0 && scene.role(i).has_texels())
                    .map(|q| q.map(|v| v / size))
            })
            .collect();
        Self {
            pages: pages.iter().map(|p| (p.width, p.height)).collect(),
            mesh_page: meshes.iter().map(|m| m.page).collect(),
            uv,
        }
    }

    /// The layout a texel file holds (its triangle table's pixel UVs over its pages), for
    /// `scene`, the scene it was prepared from (the caller checks that: `render`'s
    /// `Lightmap::load` does): what `prepare --write-gltf` wrote, without preparing again.
    /// A mesh none of whose triangles has texels is given page 0 (it is written without
    /// `TEXCOORD_1`).
    #[must_use]
    pub fn of_texel_file(texels: &crate::texels::TexelFile, scene: &Scene) -> Self {
        let pages: Vec<(u32, u32)> = texels.pages().iter().map(|p| (p.width, p.height)).collect();
        let mut mesh_page = vec![None; scene.meshes.len()];
        let uv = texels
            .triangles()
            .iter()
            .zip(&scene.triangles)
            .map(|(record, t)| {
                let (page, q) = record.pixel_uv()?;
                let &(w, h) = pages.get(page as usize)?;
                mesh_page[t.mesh as usize].get_or_insert(page);
                Some(q.map(|v| v / Vec2::new(w as f32, h as f32)))
            })
            .collect();
        Self {
            pages,
            mesh_page: mesh_page.into_iter().map(|p| p.unwrap_or(0)).collect(),
            uv,
        }
    }
}

/// Writes the texel file for `scene` to `out`, first giving the meshes `unwrap` selects
/// lightmap UVs from xatlas ([`unwrap`]); returns the report and the layout rasterised.
///
/// # Errors
/// As [`prepare`], and [`PrepareError::Unwrap`] naming a mesh xatlas cannot unwrap.
pub fn prepare_with(
    scene: &Scene,
    out: &Path,
    opts: PrepareOptions,
    unwrap: Unwrap,
) -> Result<(PrepareReport, Lightmap), PrepareError> {
    prepare_reporting(scene, out, opts, unwrap, &mut |_| {})
}

/// A step of [`prepare_reporting`], reported as it begins (the command line prints them: a
/// level takes seconds).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrepareStage {
    /// xatlas charts and packs this many meshes.
    Unwrapping {
        /// Meshes given UVs.
        meshes: usize,
    },
    /// Rays find which side of each surface faces open space (`facing`).
    SeenSides {
        /// Triangles of the scene.
        triangles: usize,
    },
    /// The texels of one page are rasterised and written.
    Rasterising {
        /// The page, from 0.
        page: usize,
        /// Pages in all.
        pages: usize,
    },
}

/// [`prepare_with`], telling `stage` each step as it begins.
///
/// # Errors
/// As [`prepare_with`].
pub fn prepare_reporting(
    scene: &Scene,
    out: &Path,
    opts: PrepareOptions,
    unwrap: Unwrap,
    stage: &mut dyn FnMut(PrepareStage),
) -> Result<(PrepareReport, Lightmap), PrepareError> {
    if scene.triangles.len() >= (PARTIAL_BIT - 1) as usize {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!(
                "{} triangles; prepare supports fewer than 2^31",
                scene.triangles.len()
            ),
        });
    }
    let mut selected = unwrap.meshes(scene);
    let not_atlas = not_atlas_meshes(scene, unwrap, &mut selected);
    if selected.iter().any(|&u| u) {
        stage(PrepareStage::Unwrapping {
            meshes: selected.iter().filter(|&&u| u).count(),
        });
        let (unwrapped, pages, meshes, tpu, mut unwrap_report) =
            unwrap_layout(scene, opts.resolution, &selected)?;
        let lightmap = Lightmap::of_records(&unwrapped, &pages, &meshes);
        let mut report = rasterise(&unwrapped, out, &pages, &meshes, tpu, false, stage)?;
        let area: f64 = pages
            .iter()
            .map(|p| f64::from(p.width) * f64::from(p.height))
            .sum();
        unwrap_report.utilisation = report.texels as f64 / area;
        report.unwrap = Some(unwrap_report);
        report.not_atlas = not_atlas;
        return Ok((report, lightmap));
    }
    let stats = mesh_uv_stats(scene);
    if stats.iter().all(Option::is_none) {
        return Err(PrepareError::NoLightmapUvs {
            path: scene.path.clone(),
            meshes: scene.meshes.iter().map(|m| m.name.clone()).collect(),
        });
    }
    let per_mesh = match opts.layout {
        Layout::Shared => false,
        Layout::PerMesh => true,
        Layout::Auto => meshes_overlap(scene, &stats),
    };
    let (pages, meshes, tpu) = if per_mesh {
        per_mesh_layout(scene, &stats, opts.resolution)?
    } else {
        shared_layout(scene, &stats, opts.resolution)?
    };
    let mut report = rasterise(scene, out, &pages, &meshes, tpu, per_mesh, stage)?;
    report.not_atlas = not_atlas;
    Ok((report, Lightmap::of_records(scene, &pages, &meshes)))
}

/// Rasterises `scene`'s lightmap UVs through the layout `pages` and `meshes` into `out`.
fn rasterise(
    scene: &Scene,
    out: &Path,
    pages: &[PageRecord],
    meshes: &[MeshLayout],
    tpu: f32,
    per_mesh: bool,
    stage: &mut dyn FnMut(PrepareStage),
) -> Result<PrepareReport, PrepareError> {
    stage(PrepareStage::SeenSides {
        triangles: scene.triangles.len(),
    });
    let (visibility, facing) = seen_sides(scene).map_err(|e| PrepareError::Resolution {
        path: scene.path.clone(),
        message: format!("cannot trace the scene to orient its surfaces: {e}"),
    })?;
    let mut shell =
        shell::find_shell(scene, &visibility).map_err(|e| PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!("cannot trace the scene to look for a shell around it: {e}"),
        })?;
    let triangles = triangle_records(scene, meshes, visibility.sides());
    let mut w = TexelWriter::create(out, pages, &triangles, tpu)?;
    w.set_lighting(scene.lighting_fingerprint());
    w.set_geometry(scene.geometry_fingerprint());
    let mut report = PrepareReport {
        texels: 0,
        partial_texels: 0,
        tiles: 0,
        pages: pages.iter().map(|p| (p.width, p.height)).collect(),
        per_mesh_layout: per_mesh,
        texels_per_unit: tpu,
        meshes_without_lightmap_uvs: scene
            .meshes_without_lightmap_uvs()
            .into_iter()
            .map(str::to_owned)
            .collect(),
        uv_degenerate_triangles: 0,
        inside_texels: 0,
        flipped_triangles: triangles.iter().filter(|t| t.texels_face_back()).count() as u64,
        facing,
        unwrap: None,
        not_atlas: Vec::new(),
        missing_textures: Vec::new(),
        roles: crate::scene::RoleReport::default(),
        shell: None,
    };
    for (page_index, page) in pages.iter().enumerate() {
        stage(PrepareStage::Rasterising {
            page: page_index,
            pages: pages.len(),
        });
        let raster = PageRaster::new(&triangles, page_index as u32, *page, &mut report);
        if let Some(shell) = &mut shell {
            let (on, all) = raster.texels_of(&shell.mask);
            shell.texels += on;
            shell.atlas_texels += all;
        }
        raster.emit_tiles(scene, &triangles, &visibility, &mut w, &mut report)?;
    }
    if report.texels == 0 {
        return Err(PrepareError::NoTexels {
            path: scene.path.clone(),
        });
    }
    w.finish()?;
    report.shell = shell;
    Ok(report)
}

fn shared_layout(
    scene: &Scene,
    stats: &[Option<MeshUv>],
    res: Resolution,
) -> Result<(Vec<PageRecord>, Vec<MeshLayout>, f32), PrepareError> {
    let (wa, ua) = stats
        .iter()
        .flatten()
        .fold((0.0, 0.0), |a, s| (a.0 + s.world_area, a.1 + s.uv_area));
    let density = (wa / ua.max(1e-30)).sqrt(); // world units per UV unit
    let (w, h) = match res {
        Resolution::Size(w, h) => (w, h),
        Resolution::Default => (DEFAULT_PAGE, DEFAULT_PAGE),
        Resolution::TexelsPerUnit(d) => {
            let side = (f64::from(d) * density).ceil();
            check_side(scene, side)?;
            (side as u32, side as u32)
        }
    };
    check_side(scene, f64::from(w.max(h)))?;
    let tpu = (f64::from(w).min(f64::from(h)) / density) as f32;
    let page = PageRecord {
        width: w,
        height: h,
    };
    let meshes = stats
        .iter()
        .map(|s| MeshLayout {
            page: 0,
            flags: u32::from(s.is_some()),
            uv_scale: [w as f32, h as f32],
            uv_offset: [0.0; 2],
        })
        .collect();
    Ok((vec![page], meshes, tpu))
}

fn check_side(scene: &Scene, side: f64) -> Result<(), PrepareError> {
    if !(1.0..=f64::from(MAX_PAGE)).contains(&side) {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!(
                "a page of {side} texels is outside 1..={MAX_PAGE}; choose a smaller --texels-per-unit or --size"
            ),
        });
    }
    Ok(())
}

/// Edge in texels of the square that holds mesh `s`'s own UVs at density `d`.
fn cell_side(s: &MeshUv, d: f64) -> f64 {
    let ext = f64::from((s.hi - s.lo).max_element().max(1e-12));
    // The UV bounding square scaled to `side` texels holds uv_area·side²/ext² texels.
    d * (s.world_area / s.uv_area.max(1e-30)).sqrt() * ext
}

/// Cell edge of each mesh at density `d`, `None` for meshes without UVs; clamped to what a
/// page of edge `max` holds (an asked-for density is checked first, by [`check_cells`]).
fn cells(stats: &[Option<MeshUv>], d: f64, max: u32) -> Vec<Option<u32>> {
    stats
        .iter()
        .map(|s| s.map(|s| (cell_side(&s, d).ceil() as u32).clamp(2, max - 2 * GUTTER)))
        .collect()
}

/// Refuses an asked-for density at which a mesh's own UVs need a square larger than a page of
/// edge `max`: [`cells`] would clamp it and bake that mesh at a lower density than asked,
/// silently — and at `--texels-per-unit 1e30` fill a 4096² page per mesh.
fn check_cells(
    scene: &Scene,
    stats: &[Option<MeshUv>],
    d: f64,
    max: u32,
) -> Result<(), PrepareError> {
    if !(d.is_finite() && d > 0.0) {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!("{d} texels/unit is not a positive density"),
        });
    }
    let room = f64::from(max - 2 * GUTTER);
    for (mesh, s) in scene.meshes.iter().zip(stats) {
        let Some(s) = s else { continue };
        let side = cell_side(s, d);
        if side.is_nan() || side > room {
            return Err(PrepareError::Resolution {
                path: scene.path.clone(),
                message: format!(
                    "mesh '{}' needs a square of {side:.4e} texels at {d:.4e} texels/unit, more than a page of {max}x{max}; --texels-per-unit {:.4} or less fits",
                    mesh.name,
                    0.95 * d * room / side
                ),
            });
        }
    }
    Ok(())
}

/// A cell's place: (page, x, y).
type Place = (u32, u32, u32);

/// Shelf packing of square cells: returns per mesh (page, x, y) and the number of pages.
fn shelf_pack(cells: &[Option<u32>], page: (u32, u32)) -> (Vec<Option<Place>>, u32) {
    shelf_pack_rects(
        &cells.iter().map(|c| c.map(|c| (c, c))).collect::<Vec<_>>(),
        page,
    )
}

/// Shelf packing of `(width, height)` rectangles, tallest first, each with a [`GUTTER`] on
/// every side: returns per rectangle (page, x, y) and the number of pages.
fn shelf_pack_rects(rects: &[Option<(u32, u32)>], page: (u32, u32)) -> (Vec<Option<Place>>, u32) {
    let mut order: Vec<usize> = (0..rects.len()).filter(|&i| rects[i].is_some()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(rects[i].map(|(w, h)| (h, w))));
    let mut out = vec![None; rects.len()];
    let (mut p, mut x, mut y, mut shelf) = (0u32, 0u32, 0u32, 0u32);
    for i in order {
        let (w, h) = rects[i].unwrap_or((0, 0));
        let (sw, sh) = (w + 2 * GUTTER, h + 2 * GUTTER);
        if x + sw > page.0 {
            x = 0;
            y += shelf;
            shelf = 0;
        }
        if y + sh > page.1 {
            p += 1;
            x = 0;
            y = 0;
            shelf = 0;
        }
        out[i] = Some((p, x + GUTTER, y + GUTTER));
        x += sw;
        shelf = shelf.max(sh);
    }
    (out, p + 1)
}

fn per_mesh_layout(
    scene: &Scene,
    stats: &[Option<MeshUv>],
    res: Resolution,
) -> Result<(Vec<PageRecord>, Vec<MeshLayout>, f32), PrepareError> {
    let sum_ratio: f64 = stats
        .iter()
        .flatten()
        .map(|s| s.world_area / s.uv_area.max(1e-30))
        .sum();
    let (mut d, page, one_page) = match res {
        Resolution::TexelsPerUnit(d) => (f64::from(d), (PACK_PAGE, PACK_PAGE), false),
        Resolution::Default => (
            f64::from(DEFAULT_PAGE) / sum_ratio.sqrt(),
            (PACK_PAGE, PACK_PAGE),
            false,
        ),
        Resolution::Size(w, h) => (f64::from(w.min(h)) / sum_ratio.sqrt(), (w, h), true),
    };
    check_side(scene, f64::from(page.0.max(page.1)))?;
    if page.0.min(page.1) <= 2 * GUTTER + 2 {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!("page {}x{} is too small to pack meshes", page.0, page.1),
        });
    }
    let max = page.0.min(page.1);
    if let Resolution::TexelsPerUnit(_) = res {
        check_cells(scene, stats, d, max)?;
    }
    let (places, cs, n) = loop {
        let cs = cells(stats, d, max);
        let (places, n) = shelf_pack(&cs, page);
        if !one_page || n == 1 || d < 1e-9 {
            break (places, cs, n);
        }
        d *= 0.95;
    };
    if n > 4096 {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!(
                "{n} pages needed at {d:.4} texels/unit; --texels-per-unit {:.4} or less fits 4096",
                fitting_density(d, n)
            ),
        });
    }
    let meshes = (0..scene.meshes.len())
        .map(|i| {
            let (page, scale, offset) = match (places[i], cs[i], stats[i]) {
                (Some((p, x, y)), Some(c), Some(s)) => {
                    let k = c as f32 / (s.hi - s.lo).max_element().max(1e-12);
                    (p, [k, k], [x as f32 - s.lo.x * k, y as f32 - s.lo.y * k])
                }
                _ => (0, [0.0; 2], [0.0; 2]),
            };
            MeshLayout {
                page,
                flags: u32::from(stats[i].is_some()),
                uv_scale: scale,
                uv_offset: offset,
            }
        })
        .collect();
    // Without --size, a single page shrinks to what the packing used (32-texel multiples).
    let used = if one_page || n > 1 {
        page
    } else {
        let extent = |f: fn(&(u32, u32, u32), u32) -> u32| {
            places
                .iter()
                .zip(&cs)
                .filter_map(|(p, c)| Some(f(&(*p)?, (*c)?)))
                .max()
                .unwrap_or(1)
        };
        let w = extent(|p, c| p.1 + c + GUTTER)
            .next_multiple_of(TILE_SIZE)
            .min(page.0);
        let h = extent(|p, c| p.2 + c + GUTTER)
            .next_multiple_of(TILE_SIZE)
            .min(page.1);
        (w, h)
    };
    let pages = vec![
        PageRecord {
            width: used.0,
            height: used.1
        };
        n as usize
    ];
    Ok((pages, meshes, d as f32))
}

/// Share of a page the charts are taken to fill when `prepare` derives the density of an
/// unwrap from a page budget (xatlas's own estimate takes 0.75; the padding of many small
/// charts costs more).
const UNWRAP_FILL: f64 = 0.6;

/// The scene with page UVs on every triangle that gets texels, its layout records, the
/// density, and what the unwrapper did.
type Unwrapped = (Scene, Vec<PageRecord>, Vec<MeshLayout>, f32, UnwrapReport);

/// Unwraps the `selected` meshes with xatlas into one atlas (one per mesh when one would
/// not fit a page), packs it with the other meshes' UV squares ([`cells`]) onto pages, and
/// returns the scene with every triangle's UVs rewritten as page UVs.
fn unwrap_layout(
    scene: &Scene,
    res: Resolution,
    selected: &[bool],
) -> Result<Unwrapped, PrepareError> {
    let stats = mesh_uv_stats(scene);
    let kept: Vec<Option<MeshUv>> = stats
        .iter()
        .zip(selected)
        .map(|(s, &u)| if u { None } else { *s })
        .collect();
    let to_unwrap: Vec<usize> = (0..selected.len()).filter(|&i| selected[i]).collect();
    let area: f64 = scene
        .triangles
        .iter()
        .enumerate()
        .filter(|&(i, t)| {
            (selected[t.mesh as usize] || kept[t.mesh as usize].is_some())
                && scene.role(i).has_texels()
        })
        .map(|(_, t)| f64::from(t.area()))
        .sum();
    let resolution_error = |message: String| PrepareError::Resolution {
        path: scene.path.clone(),
        message,
    };
    let (page, one_page) = match res {
        Resolution::Size(w, h) => ((w, h), true),
        _ => ((PACK_PAGE, PACK_PAGE), false),
    };
    check_side(scene, f64::from(page.0.max(page.1)))?;
    if page.0.min(page.1) <= 2 * GUTTER + 2 * unwrap::PADDING + 2 {
        return Err(resolution_error(format!(
            "page {}x{} is too small to pack charts",
            page.0, page.1
        )));
    }
    let mut d = match res {
        Resolution::TexelsPerUnit(d) => f64::from(d),
        Resolution::Default => f64::from(DEFAULT_PAGE) * (UNWRAP_FILL / area).sqrt(),
        Resolution::Size(w, h) => (f64::from(w) * f64::from(h) * UNWRAP_FILL / area).sqrt(),
    };
    let max_texels = 4096.0 * f64::from(PACK_PAGE) * f64::from(PACK_PAGE);
    if !(d.is_finite() && d > 0.0) || area * d * d / UNWRAP_FILL > max_texels {
        return Err(resolution_error(format!(
            "{:.3e} m² at {d} texels/unit needs more than 4096 pages of {PACK_PAGE}²; --texels-per-unit {:.4} or less fits",
            area,
            0.95 * (max_texels * UNWRAP_FILL / area).sqrt()
        )));
    }
    let max = page.0.min(page.1) - 2 * GUTTER;
    let fits =
        |a: &unwrap::Packed| a.width + 2 * GUTTER <= page.0 && a.height + 2 * GUTTER <= page.1;
    if let Resolution::TexelsPerUnit(_) = res {
        check_cells(scene, &kept, d, max)?;
    }
    let mut charted = unwrap::Charted::new(scene, &to_unwrap)?;
    let mut per_mesh_seconds = 0.0;
    let mut tries = 0;
    // The smallest atlas packed so far (area, width, height, density, charts) and the tries
    // since it last shrank by 3 %: past a point the charts' padding, not their area, sets the
    // atlas's size, and the density drops faster to find that floor.
    let mut smallest: Option<(u64, u32, u32, f64, u32)> = None;
    let mut stalled = 0;
    let lowest = d * 1e-4;
    // The error when the charts fit no page of the size: the smallest atlas seen (`w`×`h` at
    // density `at`) names the page that would hold them.
    let no_fit = |w: u32, h: u32, at: f64, charts: u32| {
        // 5 % spare: the packer's placement varies with the density.
        let fit =
            |v: u32| ((f64::from(v) * 1.05).ceil() as u32 + 2 * GUTTER).next_multiple_of(TILE_SIZE);
        resolution_error(format!(
            "the {} charts do not fit one {}x{} page at any density tried: at {at:.4e} texels/unit they pack into {w}x{h} texels, so the smallest page that holds them is about {}x{} (--size {}x{}); or leave out --size and prepare picks pages for --texels-per-unit",
            charts,
            page.0,
            page.1,
            fit(w),
            fit(h),
            fit(w),
            fit(h)
        ))
    };
    let (atlases, cs, places, n) = loop {
        tries += 1;
        if tries > 100 || d < lowest {
            let (_, w, h, at, charts) = smallest.unwrap_or((0, page.0, page.1, d, 0));
            return Err(no_fit(w, h, at, charts));
        }
        let one = charted.pack(scene, d as f32, max)?;
        if one_page && tries == 1 && !fits(&one) {
            // Before shrinking step by step: at the lowest density tried every chart is a
            // texel or two and the padding alone sets the atlas's size. When even that atlas
            // does not fit, no density will (a million-triangle level's charts at 1024²
            // took 12 minutes of tries to say so).
            let floor = charted.pack(scene, lowest as f32, max)?;
            if !fits(&floor) {
                return Err(no_fit(floor.width, floor.height, lowest, floor.charts));
            }
        }
        let area = u64::from(one.width) * u64::from(one.height);
        match smallest {
            Some((best, ..)) if area as f64 > 0.97 * best as f64 => stalled += 1,
            _ => stalled = 0,
        }
        if smallest.is_none_or(|(best, ..)| area < best) {
            smallest = Some((area, one.width, one.height, d, one.charts));
        }
        let atlases = if fits(&one) {
            vec![one]
        } else if one_page {
            d *= 0.98
                * (f64::from(page.0) / f64::from(one.width + 2 * GUTTER))
                    .min(f64::from(page.1) / f64::from(one.height + 2 * GUTTER));
            if stalled >= 3 {
                d *= 0.5;
            }
            continue;
        } else {
            // Too big for one page: an atlas per mesh, each on one page.
            let mut atlases = Vec::with_capacity(to_unwrap.len());
            for &m in &to_unwrap {
                let mut c = unwrap::Charted::new(scene, &[m])?;
                let a = c.pack(scene, d as f32, max)?;
                per_mesh_seconds += c.seconds();
                if !fits(&a) {
                    let shrink = (f64::from(page.0) / f64::from(a.width + 2 * GUTTER))
                        .min(f64::from(page.1) / f64::from(a.height + 2 * GUTTER));
                    return Err(resolution_error(format!(
                        "mesh '{}' unwraps to {}x{} texels at {d:.4} texels/unit, more than a page of {}x{}; --texels-per-unit {:.4} or less fits",
                        scene.meshes[m].name,
                        a.width,
                        a.height,
                        page.0,
                        page.1,
                        0.95 * d * shrink
                    )));
                }
                atlases.push(a);
            }
            atlases
        };
        let cs = cells(&kept, d, max);
        let rects: Vec<Option<(u32, u32)>> = atlases
            .iter()
            .map(|a| Some((a.width, a.height)))
            .chain(cs.iter().map(|c| c.map(|c| (c, c))))
            .collect();
        let (places, n) = shelf_pack_rects(&rects, page);
        if one_page && n > 1 {
            d *= 0.95;
            continue;
        }
        if n > 4096 {
            return Err(resolution_error(format!(
                "{n} pages needed at {d:.4} texels/unit; --texels-per-unit {:.4} or less fits 4096",
                fitting_density(d, n)
            )));
        }
        break (atlases, cs, places, n);
    };
    let rect_sizes: Vec<(u32, u32)> = atlases
        .iter()
        .map(|a| (a.width, a.height))
        .chain(cs.iter().map(|c| c.map_or((0, 0), |c| (c, c))))
        .collect();
    // Without --size, a single page shrinks to what the packing used (32-texel multiples).
    let used = if one_page || n > 1 {
        page
    } else {
        let extent = |f: &dyn Fn(Place, (u32, u32)) -> u32| {
            places
                .iter()
                .zip(&rect_sizes)
                .filter_map(|(p, &r)| Some(f((*p)?, r)))
                .max()
                .unwrap_or(1)
        };
        let w = extent(&|p, r| p.1 + r.0 + GUTTER);
        let h = extent(&|p, r| p.2 + r.1 + GUTTER);
        (
            w.next_multiple_of(TILE_SIZE).min(page.0),
            h.next_multiple_of(TILE_SIZE).min(page.1),
        )
    };
    let mut out = scene.clone();
    let mut mesh_page = vec![0u32; scene.meshes.len()];
    let mut pixels: Vec<Option<[Vec2; 3]>> = vec![None; scene.triangles.len()];
    for (a, place) in atlases.iter().zip(&places) {
        let (p, x, y) = place.unwrap_or((0, 0, 0));
        let at = Vec2::new(x as f32, y as f32);
        for (m, uvs) in &a.meshes {
            mesh_page[*m] = p;
            let first = scene.meshes[*m].first_triangle as usize;
            for (k, q) in uvs.iter().enumerate() {
                pixels[first + k] = q.map(|q| q.map(|v| v + at));
            }
        }
    }
    for (i, ((c, s), place)) in cs
        .iter()
        .zip(&kept)
        .zip(&places[atlases.len()..])
        .enumerate()
    {
        let (Some(c), Some(s), Some((p, x, y))) = (c, s, place) else {
            continue;
        };
        mesh_page[i] = *p;
        let k = *c as f32 / (s.hi - s.lo).max_element().max(1e-12);
        let offset = Vec2::new(*x as f32 - s.lo.x * k, *y as f32 - s.lo.y * k);
        let m = &scene.meshes[i];
        let range = m.first_triangle as usize..(m.first_triangle + m.triangle_count) as usize;
        for (px, t) in pixels[range.clone()]
            .iter_mut()
            .zip(&scene.triangles[range])
        {
            *px = t.lightmap_uv.map(|q| q.map(|v| v * k + offset));
        }
    }
    let size = Vec2::new(used.0 as f32, used.1 as f32);
    for (t, px) in out.triangles.iter_mut().zip(&pixels) {
        t.lightmap_uv = px.map(|q| q.map(|v| v / size));
    }
    let mut records = Vec::with_capacity(out.meshes.len());
    let mut ignored = 0;
    for (i, m) in out.meshes.iter_mut().enumerate() {
        let range = m.first_triangle as usize..(m.first_triangle + m.triangle_count) as usize;
        let uvs = &pixels[range];
        ignored += if selected[i] {
            uvs.iter().filter(|q| q.is_none()).count() as u64
        } else {
            0
        };
        m.has_lightmap_uvs = selected[i] || uvs.iter().all(Option::is_some);
        records.push(MeshLayout {
            page: mesh_page[i],
            flags: u32::from(selected[i] || kept[i].is_some()),
            uv_scale: [size.x, size.y],
            uv_offset: [0.0; 2],
        });
    }
    let pages = vec![
        PageRecord {
            width: used.0,
            height: used.1
        };
        n as usize
    ];
    let report = UnwrapReport {
        meshes: to_unwrap
            .iter()
            .map(|&m| scene.meshes[m].name.clone())
            .collect(),
        charts: atlases.iter().map(|a| a.charts).sum(),
        atlases: atlases.iter().map(|a| (a.width, a.height)).collect(),
        seconds: charted.seconds() + per_mesh_seconds,
        tiny_triangles: ignored,
        utilisation: 0.0,
    };
    Ok((out, pages, records, d as f32, report))
}

/// A density at which what needed `n` pages at density `d` needs at most 4096 (pages hold
/// area, which goes with the square of the density; 5 % spare for the packing).
fn fitting_density(d: f64, n: u32) -> f64 {
    0.95 * d * (4096.0 / f64::from(n)).sqrt()
}

/// `true` when texel centres of a 512² test grid are covered by triangles of two meshes.
fn meshes_overlap(scene: &Scene, stats: &[Option<MeshUv>]) -> bool {
    const N: u32 = 512;
    let outside = stats
        .iter()
        .flatten()
        .any(|s| s.lo.min_element() < -1e-3 || s.hi.max_element() > 1.0 + 1e-3);
    if outside {
        return true;
    }
    let mut owner = vec![u32::MAX; (N * N) as usize];
    let (mut covered, mut conflicts) = (0u64, 0u64);
    for t in &scene.triangles {
        let Some(uv) = t.lightmap_uv else { continue };
        let q = uv.map(|v| v * N as f32);
        for_each_centre(&q, (N, N), |x, y| {
            let o = &mut owner[(y * N + x) as usize];
            if *o == u32::MAX {
                *o = t.mesh;
                covered += 1;
            } else if *o != t.mesh {
                conflicts += 1;
            }
        });
    }
    conflicts * 100 > covered
}

/// Calls `f(x, y)` for every pixel whose centre lies inside (or on) the triangle `q`.
fn for_each_centre(q: &[Vec2; 3], size: (u32, u32), mut f: impl FnMut(u32, u32)) {
    let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let (x0, x1, y0, y1) = pixel_range(q, size);
    for y in y0..y1 {
        for x in x0..x1 {
            let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            if barycentric(q, c, area).iter().all(|&l| l >= 0.0) {
                f(x, y);
            }
        }
    }
}

/// Pixel index ranges `[x0, x1) × [y0, y1)` of the triangle's bounding box, clipped.
fn pixel_range(q: &[Vec2; 3], size: (u32, u32)) -> (u32, u32, u32, u32) {
    let lo = q[0].min(q[1]).min(q[2]);
    let hi = q[0].max(q[1]).max(q[2]);
    let clip = |v: f32, n: u32| v.clamp(0.0, n as f32) as u32;
    (
        clip(lo.x.floor(), size.0),
        clip(hi.x.floor() + 1.0, size.0),
        clip(lo.y.floor(), size.1),
        clip(hi.y.floor() + 1.0, size.1),
    )
}

/// Barycentrics of `c` in the 2D triangle `q` whose doubled signed area is `area`.
fn barycentric(q: &[Vec2; 3], c: Vec2, area: f32) -> [f32; 3] {
    let l0 = (q[1] - c).perp_dot(q[2] - c) / area;
    let l1 = (q[2] - c).perp_dot(q[0] - c) / area;
    [l0, l1, 1.0 - l0 - l1]
}

/// Separating-axis test: does the triangle overlap the open unit square at (x, y)?
fn overlaps_square(q: &[Vec2; 3], x: u32, y: u32) -> bool {
    let lo = Vec2::new(x as f32, y as f32);
    let corners = [lo, lo + Vec2::X, lo + Vec2::ONE, lo + Vec2::Y];
    let (tlo, thi) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
    if thi.x <= lo.x || thi.y <= lo.y || tlo.x >= lo.x + 1.0 || tlo.y >= lo.y + 1.0 {
        return false;
    }
    for i in 0..3 {
        let e = q[(i + 1) % 3] - q[i];
        let n = e.perp();
        let tri = [q[0].dot(n), q[1].dot(n), q[2].dot(n)];
        let (tmin, tmax) = (
            tri[0].min(tri[1]).min(tri[2]),
            tri[0].max(tri[1]).max(tri[2]),
        );
        let sq = corners.map(|c| c.dot(n));
        let (smin, smax) = (
            sq[0].min(sq[1]).min(sq[2]).min(sq[3]),
            sq[0].max(sq[1]).max(sq[2]).max(sq[3]),
        );
        if smax <= tmin || smin >= tmax {
            return false;
        }
    }
    true
}

/// Closest point of the 2D triangle `q` to `c`, as clamped barycentrics.
fn closest_barycentric(q: &[Vec2; 3], c: Vec2, area: f32) -> [f32; 3] {
    let b = barycentric(q, c, area);
    if b.iter().all(|&l| l >= 0.0) {
        return b;
    }
    let mut best = ([1.0, 0.0, 0.0], f32::INFINITY);
    for i in 0..3 {
        let (a, e) = (q[i], q[(i + 1) % 3] - q[i]);
        let t = ((c - a).dot(e) / e.length_squared().max(1e-30)).clamp(0.0, 1.0);
        let d = (a + e * t).distance_squared(c);
        if d < best.1 {
            let mut l = [0.0; 3];
            l[i] = 1.0 - t;
            l[(i + 1) % 3] = t;
            best = (l, d);
        }
    }
    best.0
}

/// A triangle's UVs in page pixel coordinates.
fn pixel_uv(t: &Triangle, m: &MeshLayout) -> Option<[Vec2; 3]> {
    let (s, o) = (Vec2::from(m.uv_scale), Vec2::from(m.uv_offset));
    t.lightmap_uv.map(|uv| uv.map(|v| v * s + o))
}

/// The texel file's triangle table: each triangle's UVs through its mesh's layout (where the
/// mesh has texels) and the sides it is seen from (`sides`, [`Visibility::sides`]).
fn triangle_records(scene: &Scene, meshes: &[MeshLayout], sides: &[u32]) -> Vec<TriangleRecord> {
    scene
        .triangles
        .iter()
        .zip(sides)
        .enumerate()
        .map(|(i, (t, &seen))| {
            let m = &meshes[t.mesh as usize];
            let role = scene.role(i);
            let record = match pixel_uv(t, m).filter(|_| m.flags != 0 && role.has_texels()) {
                Some(q) if q.iter().all(|v| v.is_finite()) => {
                    TriangleRecord::lightmapped(m.page, q, seen)
                }
                _ => TriangleRecord::unmapped(seen),
            };
            record.with_role(role)
        })
        .collect()
}

/// Ownership grid of one page: `triangle + 1` (0 empty), high bit = partial.
struct PageRaster {
    page: u32,
    size: PageRecord,
    owner: Vec<u32>,
}

impl PageRaster {
    /// Texels of the page owned by a triangle `mask` names, and texels in all.
    fn texels_of(&self, mask: &[bool]) -> (u64, u64) {
        self.owner
            .iter()
            .filter(|&&o| o != 0)
            .fold((0, 0), |(on, all), &o| {
                let t = ((o & !PARTIAL_BIT) - 1) as usize;
                (
                    on + u64::from(mask.get(t).copied().unwrap_or(false)),
                    all + 1,
                )
            })
    }
}

impl PageRaster {
    fn new(
        triangles: &[TriangleRecord],
        page: u32,
        size: PageRecord,
        report: &mut PrepareReport,
    ) -> Self {
        let dims = (size.width, size.height);
        let mut owner = vec![0u32; size.width as usize * size.height as usize];
        // The page's triangles in pixel space, once for both passes; UV-degenerate ones counted.
        let mut on_page: Vec<(u32, [Vec2; 3])> = Vec::new();
        for (i, t) in triangles.iter().enumerate() {
            let Some((_, q)) = t.pixel_uv().filter(|&(p, _)| p == page) else {
                continue;
            };
            let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
            if area == 0.0 || !area.is_finite() {
                report.uv_degenerate_triangles += 1;
                continue;
            }
            on_page.push((i as u32 + 1, q));
        }
        // Pass 1: texel centres covered by a triangle (the first triangle wins).
        for &(id, q) in &on_page {
            for_each_centre(&q, dims, |x, y| {
                let o = &mut owner[y as usize * size.width as usize + x as usize];
                if *o == 0 {
                    *o = id;
                }
            });
        }
        // Pass 2: texels left empty that a triangle still overlaps, marked partial.
        for &(id, q) in &on_page {
            let (x0, x1, y0, y1) = pixel_range(&q, dims);
            for y in y0..y1 {
                for x in x0..x1 {
                    let o = &mut owner[y as usize * size.width as usize + x as usize];
                    if *o == 0 && overlaps_square(&q, x, y) {
                        *o = id | PARTIAL_BIT;
                    }
                }
            }
        }
        Self { page, size, owner }
    }

    fn emit_tiles(
        &self,
        scene: &Scene,
        triangles: &[TriangleRecord],
        visibility: &Visibility,
        w: &mut TexelWriter,
        report: &mut PrepareReport,
    ) -> Result<(), PrepareError> {
        let (tw, th) = (
            self.size.width.div_ceil(TILE_SIZE),
            self.size.height.div_ceil(TILE_SIZE),
        );
        let mut order: Vec<(u64, u32, u32)> = (0..th)
            .flat_map(|ty| (0..tw).map(move |tx| (CurveOrder::Morton.key([tx, ty]), tx, ty)))
            .collect();
        order.sort_unstable();
        let mut buf = Vec::with_capacity((TILE_SIZE * TILE_SIZE) as usize);
        for (_, tx, ty) in order {
            let rect = TileRect {
                page: self.page,
                x: tx * TILE_SIZE,
                y: ty * TILE_SIZE,
                width: TILE_SIZE.min(self.size.width - tx * TILE_SIZE),
                height: TILE_SIZE.min(self.size.height - ty * TILE_SIZE),
            };
            buf.clear();
            for y in rect.y..rect.y + rect.height {
                for x in rect.x..rect.x + rect.width {
                    let o = self.owner[y as usize * self.size.width as usize + x as usize];
                    if o == 0 {
                        continue;
                    }
                    let tri = (o & !PARTIAL_BIT) - 1;
                    let partial = o & PARTIAL_BIT != 0;
                    let record = texel_record(scene, triangles, self.page, tri, x, y, partial);
                    buf.push(record);
                    report.partial_texels += u64::from(partial);
                }
            }
            buf.par_iter_mut().for_each(|t| {
                if visibility.inside_geometry(t) {
                    t.flags = (t.flags & !FLAG_VALID) | FLAG_INSIDE;
                }
            });
            report.inside_texels +=
                buf.iter().filter(|t| t.flags & FLAG_INSIDE != 0).count() as u64;
            if !buf.is_empty() {
                w.push_tile(rect, &buf)?;
                report.tiles += 1;
                report.texels += buf.len() as u64;
            }
        }
        Ok(())
    }
}

/// The record of texel (x, y) owned by triangle `tri`: its normal on the side the triangle is
/// seen from ([`TriangleRecord::texels_face_back`]).
fn texel_record(
    scene: &Scene,
    triangles: &[TriangleRecord],
    page: u32,
    tri: u32,
    x: u32,
    y: u32,
    partial: bool,
) -> TexelRecord {
    let t = &scene.triangles[tri as usize];
    let record = &triangles[tri as usize];
    let q = record.pixel_uv().map_or([Vec2::ZERO; 3], |(_, q)| q);
    let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
    let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let l = clamp_barycentric(closest_barycentric(&q, c, area));
    let p = t.positions;
    let position = p[0] * l[0] + p[1] * l[1] + p[2] * l[2];
    let geometric = t.geometric_normal();
    let side = if record.texels_face_back() { -1.0 } else { 1.0 };
    let n = (t.normals[0] * l[0] + t.normals[1] * l[1] + t.normals[2] * l[2])
        .normalize_or(geometric)
        * side;
    // dP/dq = [p1-p0, p2-p0] · [q1-q0, q2-q0]^-1
    let (e1, e2) = (q[1] - q[0], q[2] - q[0]);
    let (f1, f2) = (p[1] - p[0], p[2] - p[0]);
    let inv = 1.0 / area;
    let dpdu = (f1 * e2.y - f2 * e1.y) * inv;
    let dpdv = (f2 * e1.x - f1 * e2.x) * inv;
    let finite_or_zero = |v: Vec3| if v.is_finite() { v } else { Vec3::ZERO };
    TexelRecord {
        position: position.to_array(),
        normal: n.to_array(),
        dpdu: finite_or_zero(dpdu).to_array(),
        dpdv: finite_or_zero(dpdv).to_array(),
        page,
        pixel: [x as u16, y as u16],
        triangle: tri,
        flags: FLAG_VALID | if partial { FLAG_PARTIAL } else { 0 },
    }
}

/// Clamps barycentrics into the triangle (rounding can leave −1e-7) and renormalizes.
fn clamp_barycentric(l: [f32; 3]) -> [f32; 3] {
    let l = l.map(|v| v.max(0.0));
    let s = l[0] + l[1] + l[2];
    if s > 0.0 {
        l.map(|v| v / s)
    } else {
        [1.0, 0.0, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Triangles with these lightmap UVs (positions on a plane, irrelevant here).
    fn with_uvs(uvs: &[[Vec2; 3]]) -> Vec<Triangle> {
        uvs.iter()
            .map(|&uv| Triangle {
                positions: uv.map(|v| v.extend(0.0)),
                normals: [Vec3::Z; 3],
                lightmap_uv: Some(uv),
                texture_uv: None,
                colour: None,
                mesh: 0,
                material: 0,
            })
            .collect()
    }

    /// An n×n grid of quads over `cell(i, j)`'s UV square, two triangles each, split along
    /// the diagonal (which runs through raster cell centres).
    fn grid(n: u32, cell: impl Fn(u32, u32) -> (Vec2, f32)) -> Vec<[Vec2; 3]> {
        let mut out = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (o, s) = cell(i, j);
                let [a, b, c, d] = [o, o + Vec2::X * s, o + Vec2::ONE * s, o + Vec2::Y * s];
                out.push([a, b, c]);
                out.push([a, c, d]);
            }
        }
        out
    }

    #[test]
    fn a_uv_set_is_an_atlas_unless_it_leaves_the_unit_square_overlaps_itself_or_has_no_area() {
        let step = 1.0 / 16.0;
        let atlas = grid(16, |i, j| (Vec2::new(i as f32, j as f32) * step, step));
        assert_eq!(uv_set_problem(&with_uvs(&atlas)), None);
        // Wound the other way (a mirrored chart) it is still one.
        let mirrored: Vec<_> = atlas.iter().map(|&[a, b, c]| [a, c, b]).collect();
        assert_eq!(uv_set_problem(&with_uvs(&mirrored)), None);
        // One quad's worth of overlap in 256 quads (< 1 %) is tolerated.
        let mut nearly = atlas.clone();
        nearly.extend_from_slice(&atlas[..2]);
        assert_eq!(uv_set_problem(&with_uvs(&nearly)), None);
        // Every quad on the whole square: a tiling texture set squeezed into [0, 1].
        let tiled = grid(16, |_, _| (Vec2::ZERO, 1.0));
        let problem = uv_set_problem(&with_uvs(&tiled)).unwrap();
        assert!(problem.starts_with("overlaps itself (100.0 %"), "{problem}");
        // Half the quads twice: 50 %.
        let mut doubled = grid(16, |i, j| (Vec2::new(i as f32, j as f32) * step, step));
        doubled.extend(grid(16, |i, j| {
            (Vec2::new((i / 2) as f32 * 2.0, j as f32) * step, step)
        }));
        let problem = uv_set_problem(&with_uvs(&doubled)).unwrap();
        assert!(
            problem.contains("(100.0 %") || problem.contains("overlaps itself"),
            "{problem}"
        );
        // Texture coordinates tiling outside [0, 1].
        let outside = grid(4, |i, j| (Vec2::new(i as f32 - 2.0, j as f32 * 3.0), 1.0));
        let problem = uv_set_problem(&with_uvs(&outside)).unwrap();
        assert_eq!(problem, "leaves [0, 1] (u -2..2, v 0..10)");
        // Within rounding of [0, 1] is inside.
        let edge = [[
            Vec2::new(-1e-4, 0.0),
            Vec2::new(1.0001, 0.0),
            Vec2::new(0.0, 1.0),
        ]];
        assert_eq!(uv_set_problem(&with_uvs(&edge)), None);
        let flat = [[Vec2::splat(0.5); 3]];
        assert_eq!(uv_set_problem(&with_uvs(&flat)).unwrap(), "has no area");
    }

    #[test]
    fn square_overlap_and_closest_point() {
        let q = [
            Vec2::new(0.2, 0.2),
            Vec2::new(5.0, 0.3),
            Vec2::new(0.3, 0.4),
        ];
        assert!(overlaps_square(&q, 0, 0));
        assert!(overlaps_square(&q, 3, 0));
        let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
        // Centre (3.5, 0.5) is outside the thin sliver; its closest point lies on it.
        let l = closest_barycentric(&q, Vec2::new(3.5, 0.5), area);
        assert!(l.iter().all(|&v| v >= 0.0) && (l.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let p = q[0] * l[0] + q[1] * l[1] + q[2] * l[2];
        assert!((p.x - 3.5).abs() < 0.1, "{p}");
        // A far square does not overlap.
        assert!(!overlaps_square(&q, 3, 2));
        let tilted = [
            Vec2::new(0.0, 0.0),
            Vec2::new(4.0, 4.0),
            Vec2::new(0.0, 4.0),
        ];
        assert!(!overlaps_square(&tilted, 3, 0), "below the diagonal");
        assert!(
            !overlaps_square(&tilted, 2, 1),
            "only touching the diagonal"
        );
        assert!(overlaps_square(&tilted, 1, 2), "above the diagonal");
    }

    /// Two closed 4 m rooms as two meshes without lightmap UVs.
    fn two_rooms() -> Scene {
        let mut triangles = Vec::new();
        for (mesh, corner) in [(0, Vec3::splat(-2.0)), (1, Vec3::new(8.0, -2.0, -2.0))] {
            for (c, u, v) in crate::test_support::inward_box_faces(corner, 4.0) {
                triangles.extend(crate::test_support::quad(c, u, v, 0).map(|t| Triangle {
                    lightmap_uv: None,
                    mesh,
                    ..t
                }));
            }
        }
        let mut s = Scene::of_triangles("room", triangles, vec![]);
        s.meshes[0].triangle_count = 12;
        s.meshes.push(crate::scene::Mesh {
            name: "other room".into(),
            first_triangle: 12,
            triangle_count: 12,
            has_lightmap_uvs: false,
        });
        s
    }

    #[test]
    fn a_world_too_big_for_a_page_spills_onto_more() {
        let s = two_rooms();
        // 2 × 96 m² at 300 texels per unit: 17.3M texels, more than one 4096² page holds;
        // each room's 8.6M fit one.
        let (scene, pages, meshes, tpu, report) =
            unwrap_layout(&s, Resolution::TexelsPerUnit(300.0), &[true, true]).unwrap();
        assert_eq!(tpu, 300.0);
        assert_eq!(report.atlases.len(), 2, "{report:?}");
        assert_eq!(pages.len(), 2);
        assert_ne!(meshes[0].page, meshes[1].page);
        assert!(
            scene
                .triangles
                .iter()
                .all(|t| t.lightmap_uv.is_some_and(|q| q
                    .iter()
                    .all(|v| v.cmpge(Vec2::ZERO).all() && v.cmple(Vec2::ONE).all())))
        );
        // A room alone too big for a page is an error naming it.
        let e = unwrap_layout(&s, Resolution::TexelsPerUnit(450.0), &[true, true]).unwrap_err();
        assert!(e.to_string().contains("mesh 'room' unwraps to"), "{e}");
    }

    /// Two 10 m squares with their own UVs over the unit square, as two meshes.
    fn two_uv_squares() -> Scene {
        let mut triangles = Vec::new();
        for mesh in 0..2 {
            let c = Vec3::new(20.0 * mesh as f32, 0.0, 0.0);
            let [a, b] = crate::test_support::quad(c, Vec3::X * 10.0, Vec3::Y * 10.0, 0);
            let uv = |t: &Triangle| t.positions.map(|p| Vec2::new(p.x - c.x, p.y) / 10.0);
            triangles.extend([a, b].map(|t| Triangle {
                lightmap_uv: Some(uv(&t)),
                mesh,
                ..t
            }));
        }
        let mut s = Scene::of_triangles("squares", triangles, vec![]);
        s.meshes[0].triangle_count = 2;
        s.meshes[0].has_lightmap_uvs = true;
        s.meshes.push(crate::scene::Mesh {
            name: "second".into(),
            first_triangle: 2,
            triangle_count: 2,
            has_lightmap_uvs: true,
        });
        s
    }

    #[test]
    fn a_density_past_what_a_page_holds_for_a_mesh_is_an_error_naming_one_that_fits() {
        // The per-mesh layout clamped each mesh's square to a page: at 10³⁰ texels per unit
        // every mesh silently filled a 4096² page (a fuzz input took 18 s without a sanitizer).
        let s = two_uv_squares();
        let stats = mesh_uv_stats(&s);
        let (_, meshes, tpu) =
            per_mesh_layout(&s, &stats, Resolution::TexelsPerUnit(40.0)).unwrap();
        assert_eq!(tpu, 40.0);
        assert_eq!(meshes[1].uv_scale, [400.0; 2], "10 m at 40 texels/unit");
        for d in [500.0, 1e30, f32::MAX, f32::NAN, 0.0, -1.0] {
            let e = per_mesh_layout(&s, &stats, Resolution::TexelsPerUnit(d)).unwrap_err();
            let message = e.to_string();
            assert!(message.contains("squares"), "names the scene: {message}");
            if !(d > 0.0 && d.is_finite()) {
                assert!(message.contains("not a positive density"), "{message}");
                continue;
            }
            assert!(
                message.contains("mesh 'squares' needs a square of"),
                "{message}"
            );
            let fit: f32 = message
                .rsplit("--texels-per-unit ")
                .next()
                .and_then(|r| r.split(' ').next())
                .and_then(|f| f.parse().ok())
                .unwrap_or_else(|| panic!("names a density: {message}"));
            let (_, meshes, _) = per_mesh_layout(&s, &stats, Resolution::TexelsPerUnit(fit))
                .unwrap_or_else(|e| panic!("the density it names, {fit}, fits: {e}"));
            assert!(meshes[0].uv_scale[0] > 0.9 * 4092.0, "{:?}", meshes[0]);
        }
        // The default and a page size still pick a density that fits.
        per_mesh_layout(&s, &stats, Resolution::Default).unwrap();
        per_mesh_layout(&s, &stats, Resolution::Size(64, 64)).unwrap();
    }

    #[test]
    fn charts_that_fit_no_page_of_the_size_are_an_error() {
        let s = two_rooms();
        // 12 charts with padding and gutters cannot share a 12×12 page.
        let e = unwrap_layout(&s, Resolution::Size(12, 12), &[true, true]).unwrap_err();
        assert!(e.to_string().contains("do not fit one 12x12 page"), "{e}");
    }

    /// `n` loose squares (no shared vertices, each facing its own way: one chart each) as one
    /// mesh without lightmap UVs.
    fn loose_squares(n: usize) -> Scene {
        let mut triangles = Vec::new();
        for i in 0..n {
            let c = Vec3::new((i % 32) as f32 * 2.0, (i / 32) as f32 * 2.0, 0.0);
            let a = i as f32 * 0.37;
            let (u, v) = (
                Vec3::new(a.cos(), a.sin(), 0.3),
                Vec3::new(-a.sin(), a.cos(), -0.2),
            );
            triangles.extend(crate::test_support::quad(c, u, v, 0).map(|t| Triangle {
                lightmap_uv: None,
                ..t
            }));
        }
        Scene::of_triangles("squares", triangles, vec![])
    }

    #[test]
    fn charts_too_many_for_the_page_at_any_density_are_an_error_naming_a_page_that_holds_them() {
        // 600 charts of at least a texel each, more than `PADDING` texels apart: more than a
        // 64×64 page holds at any density. The error comes from the first tries (the floor
        // packed at the lowest density) and names a page size that does hold them.
        let s = loose_squares(600);
        let start = std::time::Instant::now();
        let e = unwrap_layout(&s, Resolution::Size(64, 64), &[true]).unwrap_err();
        let message = e.to_string();
        assert!(message.contains("do not fit one 64x64 page"), "{message}");
        let size = message
            .split("--size ")
            .nth(1)
            .and_then(|r| r.split(')').next())
            .expect("names a --size");
        let (w, h) = size.split_once('x').unwrap();
        let (w, h): (u32, u32) = (w.parse().unwrap(), h.parse().unwrap());
        assert!(w > 64 || h > 64, "{message}");
        assert!(start.elapsed().as_secs_f64() < 30.0);
        unwrap_layout(&s, Resolution::Size(w, h), &[true])
            .unwrap_or_else(|e| panic!("the page it names, {w}x{h}, holds them: {e}"));
    }

    #[test]
    fn tiles_follow_the_kernels_morton_order() {
        let morton = |x, y| CurveOrder::Morton.key([x, y]);
        assert_eq!(morton(0, 0), 0);
        assert_eq!(morton(1, 0), 1);
        assert_eq!(morton(0, 1), 2);
        assert_eq!(morton(1, 1), 3);
        assert_eq!(morton(2, 0), 4);
    }
}
