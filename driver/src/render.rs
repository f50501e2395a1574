//! `render`: a picture of the lit scene — what a user sees when the lightmap lands in a game.
//!
//! One eye ray per sub-pixel (2 × 2 stratified per pixel) is traced with the project's own
//! traversal ([`guidebake_kernels::traverse::intersect1`] over [`crate::bvh::Bvh`]). A hit on
//! a lightmapped triangle is shaded as a diffuse game surface shades a baked lightmap:
//! outgoing radiance `albedo × E / π` (the albedo at the hit, textured where the material
//! is: [`crate::scene::texture::HitAlbedo`]) with the irradiance `E` looked up bilinearly through
//! the triangle's lightmap UVs (the lookup of [`crate::transport::series::PreviousPass`]:
//! covered pixels only, weights renormalised, so chart borders do not fetch the empty
//! atlas), plus the material's emission seen from its front face. A ray that leaves the scene
//! sees the sky ([`crate::transport::sky::sky_radiance`]; the sun's disc is not drawn).
//! Triangles without lightmap UVs show their emission only (they have no baked light).
//!
//! The camera is the glTF file's first camera node (perspective or orthographic; glTF
//! cameras look along their local −Z with +Y up), or an automatic view. Where the scene
//! encloses open space — a game level, a room — the automatic view stands inside it
//! ([`Camera::inside`]; docs/levels.md, "Render from inside"): points of a grid over the
//! bounds are probed with rays, a point counts as inside when no ray meets a side that faces
//! no open space (it is not inside a wall), the rays downwards meet a floor, most
//! horizontal ones meet walls and at least half the walls they meet are lit in the lightmap
//! (a level closed in a shell that keeps the sun and sky out is dark inside: the view then
//! falls back to the overview, with a warning); the point with the widest view is lowered towards its floor,
//! looks along its longest horizontal sight line and steps back from it. Elsewhere (an
//! object, an open scene) the *overview* frames the scene's bounds from above one corner. A
//! closed room seen from outside would show only its outer walls, so the overview is a
//! *cutaway*: a lightmapped surface seen from the side its texels do not face
//! ([`crate::prepare::facing`]) is passed through, as a dollhouse view (on by default for the
//! overview, off for a glTF camera and the inside view; `--cutaway`).
//!
//! Tone mapping: exposure, then Reinhard's `x / (1 + x)` and the sRGB curve
//! ([`crate::preview::tonemap_reinhard`]); the automatic exposure maps the mean luminance of
//! the surface pixels to ½, as the lightmap previews do, and for the inside view their
//! log-average to an 18 % grey ([`View::key_exposure`], Reinhard et al. 2002's key), which
//! keeps both sunlit floors and the shade beside them readable. Views compared side by side (the
//! demo's baseline and guided) share one exposure. A view whose every surface is black has no
//! exposure to set ([`View::sees_light`]): `render` says so and writes nothing.

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};
use guidebake_kernels::estimator::luminance_f32;
use guidebake_kernels::packet::{Hit, Ray};
use guidebake_kernels::traverse::intersect1;
use rayon::prelude::*;

use crate::bvh::{Bvh, BvhError, Preset};
use crate::output::exr_pages::page_path;
use crate::output::exr_pages::{TEXEL_FILE_KEY, read_identity};
use crate::output::readback::read_page;
use crate::scene::Scene;
use crate::texels::{TexelFile, TriangleRecord};
use crate::transport::series::{Lookup, PreviousPass};
use crate::transport::sky::sky_radiance;

/// Sub-pixels per pixel along each axis (stratified, at the sub-pixel centres).
pub const SUBPIXELS: u32 = 2;
/// Vertical field of view of the automatic view, radians.
pub const AUTO_FOV: f32 = 0.75;
/// The luminance [`View::key_exposure`] maps the log-average to.
pub const KEY: f32 = 0.18;
/// Vertical field of view of the inside view, radians (about 65°, a game's).
pub const INSIDE_FOV: f32 = 1.13;
/// Points per axis of the grid [`Camera::inside`] probes (1000 points).
const INSIDE_GRID: usize = 10;
/// Rays from each probed point.
const INSIDE_RAYS: usize = 64;
/// Surfaces a cutaway ray may pass through before it is taken to see the sky.
const MAX_PASS_THROUGH: u32 = 64;

/// Why a view could not be rendered; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A lightmap page could not be read or does not fit the texel file.
    #[error("{path}: {what}")]
    Lightmap {
        /// The EXR page.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The scene does not match the texel file, or its camera is unusable.
    #[error("{path}: {what}")]
    Scene {
        /// The scene or texel file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The scene's BVH could not be built.
    #[error(transparent)]
    Bvh(#[from] BvhError),
}

/// How the camera projects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Perspective with `tan(yfov / 2)`.
    Perspective {
        /// Tangent of half the vertical field of view.
        tan_half_fov: f32,
    },
    /// Orthographic with half the view's height in world units.
    Orthographic {
        /// Half the view's height (glTF `ymag`).
        half_height: f32,
    },
}

/// A pinhole or orthographic camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit right vector.
    pub right: Vec3,
    /// Unit up vector (orthogonal to `forward` and `right`).
    pub up: Vec3,
    /// Projection.
    pub projection: Projection,
    /// Width / height the camera asks for (glTF `aspectRatio`), if it does.
    pub aspect: Option<f32>,
}

impl Camera {
    /// A perspective camera at `eye` looking at `target`, `up_hint` up, vertical field of view
    /// `fov` radians. Falls back to +Z as the up hint when `up_hint` is along the view.
    pub fn look_at(eye: Vec3, target: Vec3, up_hint: Vec3, fov: f32) -> Self {
        let forward = (target - eye).normalize_or(-Vec3::Z);
        let mut right = forward.cross(up_hint);
        if right.length_squared() < 1e-12 {
            right = forward.cross(Vec3::Z);
        }
        let right = right.normalize();
        Self {
            eye,
            forward,
            right,
            up: right.cross(forward),
            projection: Projection::Perspective {
                tan_half_fov: (fov / 2.0).tan(),
            },
            aspect: None,
        }
    }

    /// The automatic view: from above the (+x, +z) corner of the bounds, looking at their
    /// centre, far enough that the bounding sphere fits the narrower field of view of an
    /// image of `aspect` (width / height).
    pub fn framing(bounds: (Vec3, Vec3), aspect: f32) -> Self {
        let (lo, hi) = bounds;
        let centre = (lo + hi) / 2.0;
        let radius = ((hi - lo).length() / 2.0).max(1e-3);
        let narrow = if aspect < 1.0 {
            2.0 * ((AUTO_FOV / 2.0).tan() * aspect).atan()
        } else {
            AUTO_FOV
        };
        let distance = radius / (narrow / 2.0).sin();
        let direction = Vec3::new(0.55, 0.75, 1.0).normalize();
        Self::look_at(centre + direction * distance, centre, Vec3::Y, AUTO_FOV)
    }

    /// The automatic view from inside the open space `stage` encloses where `lightmap` lights
    /// it (module docs): [`Inside::Dark`] when points are enclosed but none sees lit walls,
    /// [`Inside::Open`] when no probed point is enclosed. Vertical field of view
    /// [`INSIDE_FOV`].
    #[must_use]
    pub fn inside(stage: &Stage<'_>, lightmap: &Lightmap) -> Inside {
        let (lo, hi) = stage.scene.bounds();
        let size = hi - lo;
        let reach = size.length().max(1e-3);
        let g = INSIDE_GRID as f32;
        let points: Vec<Vec3> = (0..INSIDE_GRID.pow(3))
            .map(|i| {
                let (x, y, z) = (
                    i % INSIDE_GRID,
                    (i / INSIDE_GRID) % INSIDE_GRID,
                    i / INSIDE_GRID / INSIDE_GRID,
                );
                lo + size * Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5) / g
            })
            .collect();
        let directions = sphere_directions(INSIDE_RAYS);
        // Per enclosed point: (score, point index, whether it sees lit walls).
        let candidates: Vec<(f32, usize, bool)> = points
            .par_iter()
            .enumerate()
            .filter_map(|(i, &p)| {
                let (mut horizontal, mut enclosed, mut lit, mut width) = (0u32, 0u32, 0u32, 0.0f32);
                for &d in &directions {
                    match stage.probe(p, d) {
                        Sight::Unseen => return None,
                        Sight::Escapes if d.y < -0.2 => return None,
                        Sight::Escapes => {
                            if d.y.abs() < 0.35 {
                                horizontal += 1;
                            }
                        }
                        Sight::Seen(hit) => {
                            if d.y.abs() < 0.35 {
                                horizontal += 1;
                                enclosed += 1;
                                width += hit.t.min(reach);
                                lit += u32::from(stage.lit(lightmap, &hit));
                            }
                        }
                    }
                }
                (enclosed * 4 >= horizontal * 3 && horizontal > 0)
                    .then(|| (width / horizontal as f32, i, lit * 2 >= enclosed))
            })
            .collect();
        if candidates.is_empty() {
            return Inside::Open;
        }
        // The best lit point; ties keep the lower index (deterministic).
        let Some(best) = candidates
            .into_iter()
            .filter(|&(_, _, lit)| lit)
            .reduce(|a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            })
        else {
            return Inside::Dark;
        };
        let (width, p) = (best.0, points[best.1]);
        // Lower the point towards its floor: a third of the way up to the ceiling (or to the
        // room's width where the sky is open above).
        let down = match stage.probe(p, -Vec3::Y) {
            Sight::Seen(hit) => hit.t,
            _ => 0.0,
        };
        let up = match stage.probe(p, Vec3::Y) {
            Sight::Seen(hit) => hit.t.min(width),
            _ => width,
        };
        let mut eye = p - Vec3::Y * (down - 0.3 * (down + up).min(width)).max(0.0);
        // Look along the longest horizontal sight line, from a step back.
        let sight = |eye: Vec3, d: Vec3| match stage.probe(eye, d) {
            Sight::Seen(hit) => hit.t,
            _ => 0.0,
        };
        let (mut look, mut far) = (Vec3::X, -1.0f32);
        for k in 0..32 {
            let a = k as f32 * std::f32::consts::TAU / 32.0;
            let d = Vec3::new(a.cos(), 0.0, a.sin());
            let t = sight(eye, d);
            if t > far {
                (look, far) = (d, t);
            }
        }
        eye -= look * 0.4 * sight(eye, -look);
        let target = eye + look - Vec3::Y * 0.12;
        Inside::View(Self::look_at(eye, target, Vec3::Y, INSIDE_FOV))
    }

    /// The ray through normalised image coordinates `sx`, `sy` ∈ [−1, 1] (right, up) of an
    /// image of `aspect` (width / height): (origin, unit direction).
    pub fn ray(&self, sx: f32, sy: f32, aspect: f32) -> (Vec3, Vec3) {
        match self.projection {
            Projection::Perspective { tan_half_fov } => {
                let d = self.forward
                    + self.right * (sx * tan_half_fov * aspect)
                    + self.up * (sy * tan_half_fov);
                (self.eye, d.normalize())
            }
            Projection::Orthographic { half_height } => {
                let o = self.eye
                    + self.right * (sx * half_height * aspect)
                    + self.up * (sy * half_height);
                (o, self.forward)
            }
        }
    }
}

/// The first camera of a glTF file's default scene (depth first, in node order), in world
/// space; `None` for other formats or a file without cameras.
///
/// # Errors
/// [`RenderError::Scene`] naming the file when it cannot be read as glTF, or the camera's
/// transform is degenerate.
pub fn gltf_camera(path: &Path) -> Result<Option<Camera>, RenderError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if !matches!(ext.as_deref(), Some("gltf" | "glb")) {
        return Ok(None);
    }
    let fail = |what: String| RenderError::Scene {
        path: path.to_owned(),
        what,
    };
    let gltf = gltf::Gltf::open(path).map_err(|e| fail(format!("cannot read glTF: {e}")))?;
    let doc = &gltf.document;
    let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
        return Ok(None);
    };
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(camera) = node.camera() {
            return camera_from_node(&camera, world).map(Some).ok_or_else(|| {
                fail(format!(
                    "camera node {} has a degenerate transform",
                    node.index()
                ))
            });
        }
        let children: Vec<_> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    Ok(None)
}

fn camera_from_node(camera: &gltf::Camera, world: Mat4) -> Option<Camera> {
    let eye = world.transform_point3(Vec3::ZERO);
    let forward = world.transform_vector3(-Vec3::Z).try_normalize()?;
    let up_hint = world.transform_vector3(Vec3::Y);
    let right = forward.cross(up_hint).try_normalize()?;
    let (projection, aspect) = match camera.projection() {
        gltf::camera::Projection::Perspective(p) => (
            Projection::Perspective {
                tan_half_fov: (p.yfov() / 2.0).tan(),
            },
            p.aspect_ratio(),
        ),
        gltf::camera::Projection::Orthographic(o) => (
            Projection::Orthographic {
                half_height: o.ymag(),
            },
            Some(o.xmag() / o.ymag()),
        ),
    };
    let valid = match projection {
        Projection::Perspective { tan_half_fov } => tan_half_fov.is_finite() && tan_half_fov > 0.0,
        Projection::Orthographic { half_height } => half_height.is_finite() && half_height > 0.0,
    };
    (valid && eye.is_finite()).then_some(Camera {
        eye,
        forward,
        right,
        up: right.cross(forward),
        projection,
        aspect: aspect.filter(|a| a.is_finite() && *a > 0.0),
    })
}

/// A baked lightmap, looked up by triangle and barycentrics.
pub struct Lightmap {
    lookup: PreviousPass,
}

impl Lightmap {
    /// Reads the lightmap pages `out` (`OUT.exr`, or `OUT.pageN.exr` for several pages) that
    /// a bake of `texels` over `scene` wrote. The texels' pixels are the covered ones.
    ///
    /// # Errors
    /// [`RenderError`] naming the file: the scene is not the texel file's, a page is missing,
    /// unreadable, baked for another texel file (the identity in its header; a page without
    /// one is read with a warning on stderr), of another size or without R, G, B channels.
    pub fn load(texels: &TexelFile, scene: &Scene, out: &Path) -> Result<Self, RenderError> {
        check_scene_matches(texels, scene)?;
        let pages = texels.pages();
        let mut covered: Vec<Vec<bool>> = pages
            .iter()
            .map(|p| vec![false; p.width as usize * p.height as usize])
            .collect();
        for t in 0..texels.tiles().len() {
            for texel in texels.tile_texels(t) {
                let page = &mut covered[texel.page as usize];
                let width = pages[texel.page as usize].width as usize;
                let [x, y] = texel.pixel.map(usize::from);
                page[y * width + x] = true;
            }
            texels.release_tile(t);
        }
        let mut images = Vec::with_capacity(pages.len());
        for (p, (size, covered)) in pages.iter().zip(covered).enumerate() {
            let path = page_path(out, p as u32, pages.len() as u32);
            if path.is_file() {
                check_lightmap_texels(&path, texels)?;
            }
            let rgb = read_rgb(&path, size.width as usize, size.height as usize)?;
            images.push(
                rgb.into_iter()
                    .zip(covered)
                    .map(|(c, k)| k.then_some(c))
                    .collect::<Vec<_>>(),
            );
        }
        Ok(Self {
            lookup: PreviousPass::from_pixels(scene, texels.triangles(), pages, &images),
        })
    }

    /// A lightmap of `texels` whose every covered pixel holds `irradiance` (tests).
    #[cfg(test)]
    fn uniform(texels: &TexelFile, scene: &Scene, irradiance: Vec3) -> Self {
        let pages = texels.pages();
        let images: Vec<Vec<Option<Vec3>>> = pages
            .iter()
            .map(|p| vec![Some(irradiance); p.width as usize * p.height as usize])
            .collect();
        Self {
            lookup: PreviousPass::from_pixels(scene, texels.triangles(), pages, &images),
        }
    }

    /// The irradiance at barycentrics (`b1`, `b2`) of triangle `prim`; zero without UVs.
    pub fn irradiance(&self, prim: u32, b1: f32, b2: f32) -> Vec3 {
        self.lookup.irradiance(prim, b1, b2)
    }

    /// The lightmap at barycentrics (`b1`, `b2`) of triangle `prim`, with whether a baked
    /// texel lies there ([`Lookup::baked`]): what a light probe's gather reads.
    pub fn lookup(&self, prim: u32, b1: f32, b2: f32) -> Lookup {
        self.lookup.lookup(prim, b1, b2)
    }

    /// Whether the lightmap describes triangle `prim`'s side `front` (its texels face it).
    pub fn bakes_side(&self, prim: u32, front: bool) -> bool {
        self.lookup.bakes_side(prim, front)
    }
}

/// The texel file must have been prepared from `scene`: the same triangles at the same
/// positions ([`Scene::geometry_fingerprint`], recorded in its header).
fn check_scene_matches(texels: &TexelFile, scene: &Scene) -> Result<(), RenderError> {
    let header = texels.header();
    match scene.geometry_differs(header.triangle_count as usize, header.geometry) {
        None => Ok(()),
        Some(what) => Err(RenderError::Scene {
            path: texels.path().to_owned(),
            what: format!(
                "the texel file was prepared from {what}; give the scene it was prepared from \
                 (or prepare and bake it again)"
            ),
        }),
    }
}

/// The lightmap page at `path` must have been baked for `texels`: the texel file identity in
/// its header ([`LightmapIdentity`]) is `texels`'. A page without one (an older guidebake's)
/// is read with a warning on stderr.
fn check_lightmap_texels(path: &Path, texels: &TexelFile) -> Result<(), RenderError> {
    let fail = |what: String| RenderError::Lightmap {
        path: path.to_owned(),
        what,
    };
    let Some(identity) = read_identity(path).map_err(fail)? else {
        eprintln!(
            "guidebake: warning: {}: the lightmap does not record the texel file it was baked for (an older \
             guidebake wrote it); rendering it with {} unchecked",
            path.display(),
            texels.path().display()
        );
        return Ok(());
    };
    let given = texels.identity();
    match identity.texels() {
        Some(made_for) if made_for == given => Ok(()),
        made_for => Err(fail(format!(
            "the lightmap was baked for the texel file {} (identity {}), not {} (identity \
             {given:016x}): render it with the texel file it was baked for, or bake this one",
            identity.get(TEXEL_FILE_KEY).unwrap_or("(not named)"),
            made_for.map_or_else(|| "unreadable".to_owned(), |id| format!("{id:016x}")),
            texels.path().display()
        ))),
    }
}

/// The R, G, B channels of an EXR page of `width` × `height`, checked.
fn read_rgb(path: &Path, width: usize, height: usize) -> Result<Vec<Vec3>, RenderError> {
    let fail = |what: String| RenderError::Lightmap {
        path: path.to_owned(),
        what,
    };
    if !path.is_file() {
        return Err(fail(
            "no such lightmap page (the bake's -o, with the texel file it baked)".into(),
        ));
    }
    let page = read_page(path).map_err(|e| fail(e.what))?;
    if (page.width, page.height) != (width, height) {
        return Err(fail(format!(
            "the page is {}×{}, the texel file's page {width}×{height}",
            page.width, page.height
        )));
    }
    Ok(page
        .rgb
        .into_iter()
        .map(|c| {
            let c = Vec3::from(c);
            if c.is_finite() { c } else { Vec3::ZERO }
        })
        .collect())
}

/// The scene prepared for eye rays: its BVH and, from the texel file, the sides each triangle
/// is seen from and whether it has lightmap UVs.
pub struct Stage<'s> {
    scene: &'s Scene,
    bvh: Bvh,
    triangles: Vec<TriangleRecord>,
}

impl<'s> Stage<'s> {
    /// Builds the BVH and reads every triangle's seen sides from `texels` (prepared from
    /// `scene`).
    ///
    /// # Errors
    /// [`RenderError::Bvh`] for a non-finite vertex; [`RenderError::Scene`] when `texels`
    /// was prepared from a scene of other geometry (another triangle count, or other
    /// positions).
    pub fn new(scene: &'s Scene, texels: &TexelFile) -> Result<Self, RenderError> {
        check_scene_matches(texels, scene)?;
        // The tree for the rays of a full-HD view or two ([`Preset::for_rays`]).
        let rays = 2.0 * 1920.0 * 1080.0 * (SUBPIXELS * SUBPIXELS) as f64;
        // What a player sees: the surfaces with texels (`scene::roles`); a sky shell is seen
        // through, to the sky.
        let drawn = crate::scene::ids_where(texels.triangles().len(), |t| {
            texels.triangles()[t].role().drawn()
        });
        let bvh = Bvh::build_over(
            &scene.triangle_positions(),
            drawn.as_deref(),
            Preset::for_rays(scene.triangles.len(), rays),
        )?;
        Ok(Self {
            scene,
            bvh,
            triangles: texels.triangles().to_vec(),
        })
    }
}

/// What [`Camera::inside`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Inside {
    /// The view from inside the enclosed space.
    View(Camera),
    /// The scene encloses open space, but no probed point inside sees lit walls: the space
    /// is dark in the lightmap (a closed shell keeps the sun and sky out).
    Dark,
    /// No probed point is enclosed (an object, an open scene).
    Open,
}

impl Inside {
    /// The inside view, if there is one.
    #[must_use]
    pub fn view(self) -> Option<Camera> {
        match self {
            Inside::View(camera) => Some(camera),
            Inside::Dark | Inside::Open => None,
        }
    }
}

/// What a probe ray from a point sees.
enum Sight {
    /// Nothing: it leaves the scene.
    Escapes,
    /// A side that faces open space: the ray's hit.
    Seen(Hit),
    /// A side that faces no open space: the point is inside geometry.
    Unseen,
}

impl Stage<'_> {
    fn probe(&self, org: Vec3, dir: Vec3) -> Sight {
        match intersect1(&self.bvh.wide(), &Ray::new(org, dir, 0.0, f32::INFINITY)) {
            None => Sight::Escapes,
            Some(hit) => {
                let prim = hit.prim as usize;
                let front = self.scene.triangles[prim].geometric_normal().dot(dir) < 0.0;
                if self.triangles[prim].seen_from(front) {
                    Sight::Seen(hit)
                } else {
                    Sight::Unseen
                }
            }
        }
    }

    /// Whether the surface a probe `hit` is lit: emissive, or with irradiance in `lightmap`.
    fn lit(&self, lightmap: &Lightmap, hit: &Hit) -> bool {
        let emission = self.scene.triangle_material(hit.prim as usize).emission;
        let irradiance = lightmap.irradiance(hit.prim, hit.u, hit.v);
        emission.max_element() > 0.0 || luminance_f32(irradiance.to_array()) > 0.0
    }
}

/// `n` directions spread evenly over the sphere (a Fibonacci lattice).
fn sphere_directions(n: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let a = golden * i as f32;
            Vec3::new(r * a.cos(), y, r * a.sin())
        })
        .collect()
}

/// How to render a view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewOptions {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pass through lightmapped surfaces seen from their unlit side.
    pub cutaway: bool,
}

/// A rendered view: linear radiance per pixel, and how many of its sub-pixels hit a surface.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB radiance, row-major from the top left.
    pub radiance: Vec<Vec3>,
    /// Sub-pixels (of [`SUBPIXELS`]²) that saw a surface rather than the sky.
    pub surface: Vec<u8>,
}

/// What a view draws besides the scene (`crate::probes::view`: the light probes and a
/// sphere they light): the nearest of its surfaces a ray meets before `tmax`, and the
/// radiance it sends back along the ray.
pub trait Overlay: Sync {
    /// The ray parameter and radiance of the first hit in (0, `tmax`), if any.
    fn hit(&self, org: Vec3, dir: Vec3, tmax: f32) -> Option<(f32, Vec3)>;
}

/// Renders `camera`'s view of `stage` lit by `lightmap`.
pub fn render(
    stage: &Stage<'_>,
    lightmap: &Lightmap,
    camera: &Camera,
    options: ViewOptions,
) -> View {
    render_with(stage, lightmap, camera, options, None)
}

/// [`render`], with `overlay`'s surfaces drawn where they are nearer than the scene's.
pub fn render_with(
    stage: &Stage<'_>,
    lightmap: &Lightmap,
    camera: &Camera,
    options: ViewOptions,
    overlay: Option<&dyn Overlay>,
) -> View {
    let (w, h) = (options.width.max(1), options.height.max(1));
    let aspect = w as f32 / h as f32;
    let pixels: Vec<(Vec3, u8)> = (0..w as usize * h as usize)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w as usize) as f32, (i / w as usize) as f32);
            let (mut sum, mut surface) = (Vec3::ZERO, 0u8);
            for s in 0..SUBPIXELS * SUBPIXELS {
                let ox = ((s % SUBPIXELS) as f32 + 0.5) / SUBPIXELS as f32;
                let oy = ((s / SUBPIXELS) as f32 + 0.5) / SUBPIXELS as f32;
                let sx = 2.0 * (x + ox) / w as f32 - 1.0;
                let sy = 1.0 - 2.0 * (y + oy) / h as f32;
                let (org, dir) = camera.ray(sx, sy, aspect);
                let (mut radiance, mut hit, t) = shade(stage, lightmap, org, dir, options.cutaway);
                if let Some((_, over)) = overlay.and_then(|o| o.hit(org, dir, t)) {
                    (radiance, hit) = (over, true);
                }
                sum += radiance;
                surface += u8::from(hit);
            }
            (sum / (SUBPIXELS * SUBPIXELS) as f32, surface)
        })
        .collect();
    let (radiance, surface) = pixels.into_iter().unzip();
    View {
        width: w,
        height: h,
        radiance,
        surface,
    }
}

/// The radiance seen along one eye ray, whether it saw a surface, and how far (∞ for the
/// sky).
fn shade(
    stage: &Stage<'_>,
    lightmap: &Lightmap,
    org: Vec3,
    dir: Vec3,
    cutaway: bool,
) -> (Vec3, bool, f32) {
    let view = stage.bvh.wide();
    let mut tmin = 0.0f32;
    for _ in 0..MAX_PASS_THROUGH {
        let Some(hit) = intersect1(&view, &Ray::new(org, dir, tmin, f32::INFINITY)) else {
            break;
        };
        let prim = hit.prim as usize;
        let triangle = &stage.scene.triangles[prim];
        let record = &stage.triangles[prim];
        let front = triangle.geometric_normal().dot(dir) < 0.0;
        if cutaway && !record.seen_from(front) {
            // Seen from a side that faces no open space: a cutaway passes through.
            tmin = hit.t + hit.t.abs().max(1.0) * 1e-5;
            continue;
        }
        let material = stage.scene.triangle_material(prim);
        let mut radiance = Vec3::ZERO;
        if front {
            radiance += material.emission;
        }
        if record.pixel_uv().is_some() {
            let e = lightmap.irradiance(hit.prim, hit.u, hit.v);
            let albedo = stage.scene.hit_albedo(prim).at(hit.u, hit.v);
            radiance += albedo * e / std::f32::consts::PI;
        }
        let finite = if radiance.is_finite() {
            radiance
        } else {
            Vec3::ZERO
        };
        return (finite, true, hit.t);
    }
    (sky_radiance(&stage.scene.sky, dir), false, f32::INFINITY)
}

impl View {
    /// The luminance of each pixel that sees only surfaces (every subpixel hit one).
    fn surface_luminances(&self) -> impl Iterator<Item = f64> + '_ {
        self.radiance
            .iter()
            .zip(&self.surface)
            .filter(|(_, s)| u32::from(**s) == SUBPIXELS * SUBPIXELS)
            .map(|(c, _)| f64::from(luminance_f32(c.to_array())))
    }

    /// Whether any pixel that sees only surfaces is lit (luminance above zero): a view whose
    /// every surface is black has no exposure to set.
    pub fn sees_light(&self) -> bool {
        self.surface_luminances().any(|l| l > 0.0)
    }

    /// Whether any pixel sees only surfaces (no sky).
    pub fn sees_surfaces(&self) -> bool {
        self.surface_luminances().next().is_some()
    }

    /// The exposure that maps the mean luminance of the pixels that see only surfaces to ½
    /// after Reinhard (1 when no surface is seen or the mean is not positive).
    pub fn auto_exposure(&self) -> f32 {
        let (sum, n) = self
            .surface_luminances()
            .fold((0.0f64, 0u64), |(sum, n), l| (sum + l, n + 1));
        let mean = (sum / n.max(1) as f64) as f32;
        if mean > 0.0 && mean.is_finite() {
            1.0 / mean
        } else {
            1.0
        }
    }

    /// The exposure that maps the log-average luminance of the pixels that see only surfaces
    /// to [`KEY`] (Reinhard et al. 2002's key value, an 18 % grey; 1 when no surface is
    /// seen): the inside view's, where sunlit patches next to shade would set the plain mean
    /// ([`Self::auto_exposure`]) so high that the shade is all one sees and the sun washes out.
    pub fn key_exposure(&self) -> f32 {
        let (sum, n) = self
            .surface_luminances()
            .fold((0.0f64, 0u64), |(sum, n), l| {
                (sum + (l.max(0.0) + 1e-4).ln(), n + 1)
            });
        let average = (sum / n.max(1) as f64).exp() as f32;
        if n > 0 && average.is_finite() && average > 1e-4 {
            KEY / average
        } else {
            1.0
        }
    }

    /// Tone-mapped 8-bit sRGB rows.
    pub fn to_rgb8(&self, exposure: f32) -> Vec<u8> {
        self.radiance
            .iter()
            .flat_map(|c| crate::preview::tonemap_reinhard(c.to_array(), exposure))
            .collect()
    }
}

/// Views of equal size side by side, left to right, with a `gap`-pixel black margin, as one
/// 8-bit image: (width, height, rows).
///
/// # Panics
/// If `views` is empty or the views differ in size.
pub fn side_by_side(views: &[&View], exposure: f32, gap: u32) -> (u32, u32, Vec<u8>) {
    let (w, h) = (views[0].width, views[0].height);
    assert!(
        views.iter().all(|v| (v.width, v.height) == (w, h)),
        "views of one size"
    );
    let total = w * views.len() as u32 + gap * (views.len() as u32 - 1);
    let mut rows = vec![0u8; total as usize * h as usize * 3];
    for (k, view) in views.iter().enumerate() {
        let bytes = view.to_rgb8(exposure);
        let x0 = k * (w + gap) as usize;
        for y in 0..h as usize {
            let src = &bytes[y * w as usize * 3..(y + 1) * w as usize * 3];
            let at = (y * total as usize + x0) * 3;
            rows[at..at + src.len()].copy_from_slice(src);
        }
    }
    (total, h, rows)
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::AtomicBool;

    use glam::Vec2;

    use super::*;
    use crate::bake::finish::FinishOptions;
    use crate::bake::run::{BakeJob, bake};
    use crate::bake::settings::{BakeSettings, Guiding};
    use crate::bake::shard::Shard;
    use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};
    use crate::preview::tonemap_reinhard;
    use crate::scene::{Material, Sky, Triangle};

    const ALBEDO: f32 = 0.5;
    const SKY: Vec3 = Vec3::new(0.2, 0.4, 0.8);

    /// A closed 4 m room (corner at the origin) lit by a sphere light, with a 1.5 m block
    /// standing in it at its −x, −z corner; prepared (unwrapped) into `dir`.
    fn room_with_a_block(dir: &Path) -> (Scene, TexelFile) {
        use crate::test_support::{inward_box_faces, quad};
        let mut triangles = Vec::new();
        for (o, u, v) in inward_box_faces(Vec3::ZERO, 4.0) {
            triangles.extend(quad(o, u, v, 0));
        }
        // The block's faces point out of it: swap the room's edges.
        for (o, u, v) in inward_box_faces(Vec3::new(0.25, 0.0, 0.25), 1.5) {
            triangles.extend(quad(o, v, u, 0));
        }
        let material = Material {
            name: "grey".into(),
            base_color_texture: None,
            albedo: Vec3::splat(ALBEDO),
            emission: Vec3::ZERO,
        };
        let mut scene = Scene::of_triangles("room", triangles, vec![material]);
        scene.lights.push(crate::scene::SceneLight::Sphere {
            center: Vec3::new(3.0, 3.0, 3.0),
            radius: 0.2,
            radiance: Vec3::splat(10.0),
        });
        let texels = dir.join("room.texels");
        let options = PrepareOptions {
            resolution: Resolution::Size(64, 64),
            layout: Layout::Auto,
        };
        crate::prepare::prepare_with(&scene, &texels, options, crate::prepare::Unwrap::Always)
            .unwrap();
        (scene, TexelFile::open(&texels).unwrap())
    }

    #[test]
    fn the_automatic_view_stands_inside_an_enclosed_room_and_looks_across_it() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, texels) = room_with_a_block(dir.path());
        let stage = Stage::new(&scene, &texels).unwrap();
        let lit = Lightmap::uniform(&texels, &scene, Vec3::ONE);
        let camera = Camera::inside(&stage, &lit)
            .view()
            .expect("the room encloses open space");
        let e = camera.eye;
        assert!(
            e.min_element() > 0.0 && e.max_element() < 4.0,
            "the eye {e} is in the room"
        );
        let in_block = e.x < 1.75 && e.z < 1.75 && e.y < 1.5;
        assert!(!in_block, "the eye {e} is not inside the block");
        assert!(e.y < 2.0, "the eye {e} is in the lower half of the room");
        assert!(
            camera.forward.y.abs() < 0.2,
            "{:?} looks across",
            camera.forward
        );
        // It looks along a long sight line: at least half the room's width before a wall.
        let ahead = match stage.probe(
            e,
            Vec3::new(camera.forward.x, 0.0, camera.forward.z).normalize(),
        ) {
            Sight::Seen(hit) => hit.t,
            _ => 0.0,
        };
        assert!(ahead > 2.0, "{ahead}");
        // From there every direction sees the room's walls from inside.
        for d in sphere_directions(64) {
            assert!(matches!(stage.probe(e, d), Sight::Seen(_)), "{d}");
        }
        // The same room, dark in its lightmap (as a level inside a shell that keeps the sun
        // and sky out): enclosed, but no view from inside.
        let dark = Lightmap::uniform(&texels, &scene, Vec3::ZERO);
        assert_eq!(Camera::inside(&stage, &dark), Inside::Dark);
    }

    #[test]
    fn the_key_exposure_maps_the_log_average_of_surface_pixels_to_an_18_percent_grey() {
        let full = (SUBPIXELS * SUBPIXELS) as u8;
        let view = View {
            width: 4,
            height: 1,
            // Luminances 0.1 and 10 (geometric mean 1), a sky pixel that does not count, and
            // a pixel that is half sky.
            radiance: vec![
                Vec3::splat(0.1),
                Vec3::splat(10.0),
                Vec3::splat(1000.0),
                Vec3::splat(500.0),
            ],
            surface: vec![full, full, 0, full / 2],
        };
        let e = view.key_exposure();
        assert!((e - KEY).abs() < 1e-3 * KEY, "{e}");
        // The plain mean would be 5.05: the shade at 0.1 would be nearly black.
        assert!((view.auto_exposure() - 1.0 / 5.05).abs() < 1e-4);
        assert!(view.sees_light());
        let black = View {
            radiance: vec![
                Vec3::ZERO,
                Vec3::ZERO,
                Vec3::splat(1000.0),
                Vec3::splat(500.0),
            ],
            ..view.clone()
        };
        assert!(
            !black.sees_light(),
            "the sky and half-sky pixels do not count"
        );
        assert!(black.sees_surfaces());
        let sky = View {
            surface: vec![0; 4],
            ..view
        };
        assert_eq!(sky.key_exposure(), 1.0);
        assert!(!sky.sees_light() && !sky.sees_surfaces());
    }

    #[test]
    fn an_open_scene_has_no_inside_view() {
        let dir = tempfile::tempdir().unwrap();
        let scene = plane();
        let texels = dir.path().join("plane.texels");
        let options = PrepareOptions {
            resolution: Resolution::Size(16, 16),
            layout: Layout::Shared,
        };
        prepare(&scene, &texels, options).unwrap();
        let texels = TexelFile::open(&texels).unwrap();
        let stage = Stage::new(&scene, &texels).unwrap();
        let lit = Lightmap::uniform(&texels, &scene, Vec3::ONE);
        assert_eq!(Camera::inside(&stage, &lit), Inside::Open);
    }

    /// A 4 m square ground plane (y = 0, facing +y) under a constant sky, its lightmap UVs
    /// the unit square.
    fn plane() -> Scene {
        let p = |u: Vec2| Vec3::new(u.x * 4.0 - 2.0, 0.0, 2.0 - u.y * 4.0);
        let tri = |uv: [Vec2; 3]| Triangle {
            positions: uv.map(p),
            normals: [Vec3::Y; 3],
            lightmap_uv: Some(uv),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        let (o, x, y, xy) = (Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE);
        let material = Material {
            name: "grey".into(),
            base_color_texture: None,
            albedo: Vec3::splat(ALBEDO),
            emission: Vec3::ZERO,
        };
        let mut scene = Scene::of_triangles(
            "plane",
            vec![tri([o, x, xy]), tri([o, xy, y])],
            vec![material],
        );
        scene.sky = Sky::Constant(SKY);
        scene
    }

    /// The plane prepared at 16 × 16 texels and baked (unguided: every gather ray sees the
    /// sky, so every texel's estimate is exactly πL up to rounding).
    fn baked_plane(dir: &Path) -> (Scene, TexelFile, PathBuf) {
        let scene = plane();
        assert!(scene.triangles[0].geometric_normal().dot(Vec3::Y) > 0.99);
        let texels = dir.join("plane.texels");
        let options = PrepareOptions {
            resolution: Resolution::Size(16, 16),
            layout: Layout::Shared,
        };
        prepare(&scene, &texels, options).unwrap();
        let out = dir.join("plane.exr");
        let job = BakeJob {
            texels: texels.clone(),
            out: out.clone(),
            settings: BakeSettings {
                spp: 16,
                iterations: 1,
                guiding: Guiding::Off,
                ..Default::default()
            },
            threads: 1,
            shard: Shard::WHOLE,
            resume: false,
            aux: false,
            finish: FinishOptions::default(),
        };
        bake(&job, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
        (scene, TexelFile::open(&texels).unwrap(), out)
    }

    fn close(a: [u8; 3], b: [u8; 3]) -> bool {
        a.iter().zip(&b).all(|(x, y)| x.abs_diff(*y) <= 1)
    }

    #[test]
    fn a_plane_under_a_constant_sky_renders_albedo_times_sky_and_the_sky_around_it() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, texels, out) = baked_plane(dir.path());
        let lightmap = Lightmap::load(&texels, &scene, &out).unwrap();
        let stage = Stage::new(&scene, &texels).unwrap();
        let options = ViewOptions {
            width: 64,
            height: 48,
            cutaway: true,
        };
        let camera = Camera::framing(scene.bounds(), 64.0 / 48.0);
        let view = render(&stage, &lightmap, &camera, options);
        // Radiance of a lit plane: albedo × E / π with E = πL.
        let surface = SKY * ALBEDO;
        let exposure = 2.0;
        let (want_surface, want_sky) = (
            tonemap_reinhard(surface.to_array(), exposure),
            tonemap_reinhard(SKY.to_array(), exposure),
        );
        let bytes = view.to_rgb8(exposure);
        let (mut plane_pixels, mut sky_pixels) = (0, 0);
        for (i, s) in view.surface.iter().enumerate() {
            let px = [bytes[3 * i], bytes[3 * i + 1], bytes[3 * i + 2]];
            match *s {
                4 => {
                    plane_pixels += 1;
                    assert!(
                        close(px, want_surface),
                        "pixel {i}: {px:?}, want {want_surface:?}"
                    );
                    let rel =
                        (view.radiance[i] - surface).abs().max_element() / surface.max_element();
                    assert!(
                        rel < 1e-3,
                        "pixel {i}: radiance {} want {surface}",
                        view.radiance[i]
                    );
                }
                0 => {
                    sky_pixels += 1;
                    assert_eq!(px, want_sky, "sky pixel {i}");
                }
                _ => {}
            }
        }
        let n = view.surface.len();
        assert!(
            plane_pixels > n / 8 && sky_pixels > n / 8,
            "{plane_pixels} plane, {sky_pixels} sky of {n}"
        );
        // The automatic exposure maps the surface's mean luminance to ½.
        let mean = luminance_f32(surface.to_array());
        assert!((view.auto_exposure() * mean - 1.0).abs() < 1e-3);
    }

    #[test]
    fn a_textured_plane_renders_its_texture_times_the_irradiance() {
        use crate::scene::BaseColorTexture;
        use crate::scene::texture::{Image, TextureOptions, Wrap};
        let dir = tempfile::tempdir().unwrap();
        let (mut scene, texels, out) = baked_plane(dir.path());
        // A 2×1 texture, black then white, clamped, across the plane's u (x from −2 to 2):
        // black where x < −1, white where x > 1, a linear ramp between the texel centres.
        let image = Image::from_srgb8("ramp".into(), 2, 1, 1, &[0, 255], TextureOptions::default());
        scene.materials[0].base_color_texture = Some(BaseColorTexture {
            image: std::sync::Arc::new(image.unwrap()),
            wrap: [Wrap::ClampToEdge; 2],
            factor: Vec3::ONE,
        });
        for t in &mut scene.triangles {
            t.texture_uv = t.lightmap_uv;
        }
        let lightmap = Lightmap::load(&texels, &scene, &out).unwrap();
        let stage = Stage::new(&scene, &texels).unwrap();
        // Straight down from above the centre, the plane filling the middle of the view.
        let camera = Camera::look_at(Vec3::new(0.0, 6.0, 0.0), Vec3::ZERO, -Vec3::Z, 0.9);
        let options = ViewOptions {
            width: 48,
            height: 48,
            cutaway: false,
        };
        let view = render(&stage, &lightmap, &camera, options);
        let (mut black, mut white, mut plane) = (0, 0, 0);
        for (i, s) in view.surface.iter().enumerate() {
            if *s != 4 {
                continue;
            }
            plane += 1;
            let c = view.radiance[i];
            assert!(
                c.is_finite() && c.cmple(SKY * 1.001).all(),
                "pixel {i}: {c}"
            );
            // Grey: the texture is grey, times the sky's colour.
            assert!((c / SKY - Vec3::splat(c.x / SKY.x)).abs().max_element() < 1e-3);
            black += usize::from(c.max_element() < 1e-4);
            white += usize::from((c - SKY).abs().max_element() < 1e-3 * SKY.max_element());
        }
        // A quarter of the plane is black and a quarter white (a constant albedo would give
        // ½ L everywhere), up to the columns of pixels the quarter lines cross.
        assert!(plane > 400, "{plane}");
        let quarter = plane as f64 / 4.0;
        for (what, n) in [("black", black), ("white", white)] {
            assert!(
                (n as f64 - quarter).abs() < 0.15 * quarter,
                "{what}: {n} of {plane} pixels"
            );
        }
    }

    #[test]
    fn a_cutaway_passes_through_the_unlit_side_and_a_plain_view_shades_it() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, texels, out) = baked_plane(dir.path());
        let lightmap = Lightmap::load(&texels, &scene, &out).unwrap();
        let stage = Stage::new(&scene, &texels).unwrap();
        // From below, looking straight up at the plane's unlit side.
        let camera = Camera::look_at(Vec3::new(0.0, -1.0, 0.0), Vec3::ZERO, Vec3::Z, 0.5);
        let mut options = ViewOptions {
            width: 8,
            height: 8,
            cutaway: true,
        };
        let through = render(&stage, &lightmap, &camera, options);
        assert!(through.surface.iter().all(|&s| s == 0));
        assert!(through.radiance.iter().all(|&c| c == SKY));
        options.cutaway = false;
        let shaded = render(&stage, &lightmap, &camera, options);
        assert!(shaded.surface.iter().all(|&s| s == 4));
        for c in shaded.radiance {
            assert!((c - SKY * ALBEDO).abs().max_element() < 1e-3, "{c}");
        }
    }

    #[test]
    fn lightmaps_that_do_not_fit_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, texels, out) = baked_plane(dir.path());
        let missing = dir.path().join("other.exr");
        let err = Lightmap::load(&texels, &scene, &missing).err().unwrap();
        assert!(err.to_string().contains("other.exr"), "{err}");
        let mut bigger = crate::output::exr_pages::PageImage::new(8, 8);
        bigger.set(0, 0, [1.0; 3]);
        let small = dir.path().join("small.exr");
        bigger.write_exr(&small).unwrap();
        let err = Lightmap::load(&texels, &scene, &small).err().unwrap();
        assert!(err.to_string().contains("8×8"), "{err}");
        let mut two = scene.clone();
        two.triangles.pop();
        let err = Lightmap::load(&texels, &two, &out).err().unwrap();
        assert!(err.to_string().contains("1 triangles"), "{err}");
    }

    #[test]
    fn a_gltf_camera_is_read_in_world_space() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cam.gltf");
        // A parent translated by (0, 1, 0) holding a camera at (0, 0, 5), turned 90° about
        // +Y (so it looks along −X).
        let json = r#"{
          "asset": {"version": "2.0"},
          "scene": 0,
          "scenes": [{"nodes": [0]}],
          "nodes": [
            {"translation": [0, 1, 0], "children": [1]},
            {"translation": [0, 0, 5], "rotation": [0, 0.7071068, 0, 0.7071068], "camera": 0}
          ],
          "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.1}}]
        }"#;
        std::fs::write(&path, json).unwrap();
        let camera = gltf_camera(&path).unwrap().unwrap();
        assert!((camera.eye - Vec3::new(0.0, 1.0, 5.0)).length() < 1e-5);
        assert!(
            (camera.forward - -Vec3::X).length() < 1e-5,
            "{}",
            camera.forward
        );
        assert!((camera.up - Vec3::Y).length() < 1e-5);
        assert_eq!(camera.aspect, Some(1.5));
        assert_eq!(
            camera.projection,
            Projection::Perspective {
                tan_half_fov: 0.4f32.tan()
            }
        );
        assert_eq!(gltf_camera(&dir.path().join("x.obj")).unwrap(), None);
        std::fs::write(&path, "{ not json").unwrap();
        let err = gltf_camera(&path).unwrap_err();
        assert!(err.to_string().contains("cam.gltf"), "{err}");
    }
}
