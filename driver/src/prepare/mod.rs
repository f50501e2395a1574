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
//!    square becomes a square cell sized for the requested texel density, cells are packed
//!    (largest first, 2-texel gutter, [`pack`]) onto pages of at most 4096². `Auto` (default)
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

use glam::Vec2;

use crate::scene::Scene;
use crate::texels::{PageRecord, TexelFileError};
use facing::FacingReport;

pub mod facing;
mod layout;
pub mod pack;
mod raster;
pub mod shell;
pub mod unwrap;
mod uv_check;
pub use crate::scene::gltf_write::Lightmap;
pub use unwrap::{Unwrap, UnwrapError};
pub use uv_check::{ATLAS_TEST_SIZE, NotAtlas, SELF_OVERLAP_SHARE, uv_set_problem};

use layout::*;
use raster::*;
use uv_check::*;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Triangle;
    use glam::Vec3;
    use guidebake_kernels::presort::CurveOrder;

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
        // A room alone too big for a page is an error naming it, and how many more are; the
        // density it suggests fits every mesh.
        let e = unwrap_layout(&s, Resolution::TexelsPerUnit(450.0), &[true, true]).unwrap_err();
        let message = e.to_string();
        assert!(
            message.contains("mesh 'room' (and 1 other mesh) unwraps to"),
            "{message}"
        );
        let fit = suggested_density(&message);
        assert!(fit < 450.0, "{message}");
        unwrap_layout(&s, Resolution::TexelsPerUnit(fit), &[true, true])
            .unwrap_or_else(|e| panic!("{fit} texels/unit, suggested by '{message}': {e}"));
    }

    /// The density a refusal suggests: the number after its last `--texels-per-unit`.
    fn suggested_density(message: &str) -> f32 {
        message
            .rsplit("--texels-per-unit ")
            .next()
            .and_then(|t| t.split(' ').next())
            .and_then(|t| t.parse().ok())
            .unwrap_or_else(|| panic!("names no density: {message}"))
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
            let fit = suggested_density(&message);
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
