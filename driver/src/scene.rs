//! `scene`: the world a bake lights — world-space triangles with their lightmap UVs and
//! Lambertian materials, punctual lights, a sun and a sky.
//!
//! Sources: glTF 2.0 (`.gltf`, `.glb`, with `KHR_lights_punctual` and
//! `KHR_materials_emissive_strength`), Wavefront OBJ + MTL (`.obj`), and a small TOML scene
//! file (`.toml`, see [`SceneFile`]) that names one of those and adds the sky and the sun.
//! docs/ARCHITECTURE.md, "The bake, as data flows", and docs/bake.md.
//!
//! What the paper (Silvennoinen & Sloan 2019) assumes and we keep: diffuse (Lambertian,
//! two-sided) surfaces whose lightmap texels receive irradiance. Deviations and choices:
//! - Only the diffuse albedo of a material is kept: `baseColorFactor` × the average of the
//!   base-colour texture (texels converted sRGB → linear before averaging). Metallic,
//!   roughness and transmission are ignored.
//! - Emission is `emissiveFactor` × `KHR_materials_emissive_strength` (radiance, front face).
//! - All geometry is flattened into one triangle soup in world space (node transforms
//!   applied; normals by the inverse transpose; a mirroring transform swaps two vertices so
//!   the winding — and with it the geometric normal — stays outward).
//! - A triangle whose area is zero or whose positions are not finite is **dropped and
//!   counted** ([`Scene::degenerate_triangles`]).
//! - Lightmap UVs are glTF `TEXCOORD_1`. OBJ has one UV set only: it is taken as the lightmap
//!   UV set (OBJ exporters that lay out lightmaps write them there).
//! - A "mesh" here is one glTF mesh instanced by one node (all its primitives), or one OBJ
//!   model; it carries the name used in messages (e.g. a mesh without lightmap UVs).

use std::path::{Path, PathBuf};

use glam::{Mat3, Mat4, Vec2, Vec3};

/// Why a scene could not be loaded. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The glTF importer rejected the file (bad JSON, a missing buffer or image, a bad GLB
    /// chunk, a buffer shorter than declared, ...).
    #[error("{path}: not a loadable glTF file: {source}")]
    Gltf {
        /// The file.
        path: PathBuf,
        /// The importer's error.
        source: gltf::Error,
    },
    /// One of a glTF file's buffers or images could not be loaded: a data URI that is not
    /// base64, a relative URI whose percent-escapes do not decode to UTF-8, a file that
    /// cannot be read, a buffer shorter than its `byteLength`, an image that does not decode.
    #[error("{path}: {item}: {message}")]
    GltfResource {
        /// The glTF file.
        path: PathBuf,
        /// Which one, e.g. `buffers[0]` or `images[2]`.
        item: String,
        /// What is wrong.
        message: String,
    },
    /// An OBJ face or line names an element the file does not have.
    #[error("{path}: line {line}: {message}")]
    ObjIndex {
        /// The file.
        path: PathBuf,
        /// The line, from 1.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// tobj rejected the OBJ or its MTL.
    #[error("{path}: not a loadable OBJ file: {source}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// tobj's error.
        source: tobj::LoadError,
    },
    /// The TOML scene file is malformed.
    #[error("{path}: bad scene file: {message}")]
    SceneFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A mesh's data is inconsistent (index out of range, attribute count mismatch, ...).
    #[error("{path}: mesh '{mesh}': {message}")]
    BadMesh {
        /// The file.
        path: PathBuf,
        /// The mesh name.
        mesh: String,
        /// What is wrong.
        message: String,
    },
    /// The file extension is none we read.
    #[error("{path}: unknown scene format (expected .gltf, .glb, .obj or .toml)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// After dropping degenerate triangles nothing is left.
    #[error("{path}: the scene has no triangles ({degenerate} degenerate triangles dropped)")]
    Empty {
        /// The file.
        path: PathBuf,
        /// How many degenerate triangles were dropped.
        degenerate: usize,
    },
    /// The equirectangular sky image could not be read.
    #[error("{path}: cannot read sky image: {message}")]
    Sky {
        /// The EXR file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A Lambertian material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the source file (may be empty).
    pub name: String,
    /// Diffuse albedo, linear RGB in [0, 1].
    pub albedo: Vec3,
    /// Emitted radiance, linear RGB (front face only).
    pub emission: Vec3,
}

impl Material {
    /// The material used by primitives that have none: albedo 0.8 grey, no emission (the
    /// glTF default material is white; 0.8 keeps bounce counts finite).
    #[must_use]
    pub fn default_grey() -> Self {
        Self {
            name: "default".into(),
            albedo: Vec3::splat(0.8),
            emission: Vec3::ZERO,
        }
    }
}

/// A light as the scene file declares it (glTF `KHR_lights_punctual`, or a TOML sphere), in
/// world space; the bake samples it as a [`crate::transport::lights::AnalyticLight`].
#[derive(Clone, Debug, PartialEq)]
pub enum SceneLight {
    /// Infinitely far light travelling along `direction`.
    Directional {
        /// Unit direction the light travels in (the node's −Z).
        direction: Vec3,
        /// Irradiance on a plane facing the light, RGB (colour × intensity, lux).
        irradiance: Vec3,
    },
    /// A point light.
    Point {
        /// World position.
        position: Vec3,
        /// Radiant intensity RGB (colour × intensity, candela ~ W/sr).
        intensity: Vec3,
    },
    /// A spot light.
    Spot {
        /// World position.
        position: Vec3,
        /// Unit direction of the cone axis (the node's −Z).
        direction: Vec3,
        /// Radiant intensity RGB on the axis.
        intensity: Vec3,
        /// Angle (radians) inside which the intensity is full.
        inner_cone: f32,
        /// Angle (radians) outside which the intensity is zero.
        outer_cone: f32,
    },
    /// A sphere of uniform radiance (scene files only: glTF has no area lights of this kind).
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius, > 0.
        radius: f32,
        /// Radiance of its surface, RGB.
        radiance: Vec3,
    },
}

/// The sun: a directional light with a finite angular radius.
#[derive(Clone, Debug, PartialEq)]
pub struct Sun {
    /// Unit direction **towards** the sun.
    pub direction: Vec3,
    /// Angular radius in radians (the real sun: 0.00465).
    pub angular_radius: f32,
    /// Irradiance on a plane facing the sun, linear RGB.
    pub irradiance: Vec3,
}

/// Radiance arriving from infinitely far away where no geometry is hit.
#[derive(Clone, Debug, PartialEq)]
pub enum Sky {
    /// No sky: black.
    None,
    /// The same radiance from every direction.
    Constant(Vec3),
    /// An equirectangular (latitude-longitude) environment map, +Y up, loaded whole.
    Equirect {
        /// The EXR file it came from.
        path: PathBuf,
        /// Width in pixels (longitude).
        width: u32,
        /// Height in pixels (latitude, row 0 is the zenith).
        height: u32,
        /// Row-major linear RGB radiance.
        pixels: Vec<Vec3>,
    },
}

/// One mesh instance: a contiguous run of [`Scene::triangles`].
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Name (node name, else mesh name, else `mesh#i`).
    pub name: String,
    /// Index of its first triangle in [`Scene::triangles`].
    pub first_triangle: u32,
    /// Number of triangles kept (degenerate ones dropped).
    pub triangle_count: u32,
    /// Whether every triangle of the mesh has lightmap UVs.
    pub has_lightmap_uvs: bool,
}

/// One world-space triangle with everything the bake needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// Vertex positions, world space.
    pub positions: [Vec3; 3],
    /// Unit vertex normals, world space (the geometric normal where the source has none).
    pub normals: [Vec3; 3],
    /// Lightmap UVs (glTF `TEXCOORD_1`), or `None` when the mesh has none.
    pub lightmap_uv: Option<[Vec2; 3]>,
    /// Index into [`Scene::meshes`].
    pub mesh: u32,
    /// Index into [`Scene::materials`].
    pub material: u32,
}

impl Triangle {
    /// Unit geometric normal (right-handed winding), or zero for a degenerate triangle.
    #[must_use]
    pub fn geometric_normal(&self) -> Vec3 {
        let [a, b, c] = self.positions;
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// World-space area.
    #[must_use]
    pub fn area(&self) -> f32 {
        let [a, b, c] = self.positions;
        0.5 * (b - a).cross(c - a).length()
    }
}

/// A loaded scene. See the module docs for what is kept and dropped.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file it was loaded from.
    pub path: PathBuf,
    /// Mesh instances in file order; their triangles are contiguous.
    pub meshes: Vec<Mesh>,
    /// All triangles, world space.
    pub triangles: Vec<Triangle>,
    /// Materials; the last one may be [`Material::default_grey`].
    pub materials: Vec<Material>,
    /// Punctual lights.
    pub lights: Vec<SceneLight>,
    /// Sun, if any (from a scene file or the command line).
    pub sun: Option<Sun>,
    /// Sky radiance.
    pub sky: Sky,
    /// Triangles dropped because their area was zero or a position was not finite.
    pub degenerate_triangles: usize,
}

/// The six faces of the axis-aligned box from `corner` with edge `size`, each as (corner,
/// edge u, edge v) with u × v pointing into the box: the closed rooms of tests and examples.
pub fn inward_box_faces(corner: Vec3, size: f32) -> [(Vec3, Vec3, Vec3); 6] {
    let (o, x, y, z) = (corner, Vec3::X * size, Vec3::Y * size, Vec3::Z * size);
    [
        (o, x, y),
        (o + z, y, x),
        (o, y, z),
        (o + x, z, y),
        (o, z, x),
        (o + y, x, z),
    ]
}

impl Scene {
    /// A scene made in code: `triangles` as one mesh named `name` (with lightmap UVs where
    /// the triangles have them), `materials`, no lights, no sun, a black sky. Callers set
    /// the other fields.
    pub fn of_triangles(name: &str, triangles: Vec<Triangle>, materials: Vec<Material>) -> Scene {
        Scene {
            path: PathBuf::from(format!("<{name}>")),
            meshes: vec![Mesh {
                name: name.into(),
                first_triangle: 0,
                triangle_count: triangles.len() as u32,
                has_lightmap_uvs: triangles.iter().all(|t| t.lightmap_uv.is_some()),
            }],
            triangles,
            materials,
            lights: Vec::new(),
            sun: None,
            sky: Sky::None,
            degenerate_triangles: 0,
        }
    }

    /// Loads a scene from `.gltf`, `.glb`, `.obj` or a `.toml` scene file.
    ///
    /// # Errors
    /// A [`SceneError`] naming the file and what is wrong; [`SceneError::Empty`] when no
    /// triangle survives.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let scene = match ext.as_deref() {
            Some("gltf" | "glb") => gltf_source::load(path)?,
            Some("obj") => obj_source::load(path)?,
            Some("toml") => SceneFile::load(path)?,
            _ => {
                return Err(SceneError::UnknownFormat {
                    path: path.to_owned(),
                });
            }
        };
        if scene.triangles.is_empty() {
            return Err(SceneError::Empty {
                path: path.to_owned(),
                degenerate: scene.degenerate_triangles,
            });
        }
        Ok(scene)
    }

    /// The flat triangle soup, world space, in [`Scene::triangles`] order (the order BVH
    /// primitive ids refer to).
    #[must_use]
    pub fn triangle_positions(&self) -> Vec<[Vec3; 3]> {
        self.triangles.iter().map(|t| t.positions).collect()
    }

    /// The mesh a triangle belongs to.
    ///
    /// # Panics
    /// If `triangle` is out of range.
    #[must_use]
    pub fn triangle_mesh(&self, triangle: usize) -> &Mesh {
        &self.meshes[self.triangles[triangle].mesh as usize]
    }

    /// The material of a triangle.
    ///
    /// # Panics
    /// If `triangle` is out of range.
    #[must_use]
    pub fn triangle_material(&self, triangle: usize) -> &Material {
        &self.materials[self.triangles[triangle].material as usize]
    }

    /// Names of meshes that lack lightmap UVs (reported by `prepare`).
    #[must_use]
    pub fn meshes_without_lightmap_uvs(&self) -> Vec<&str> {
        self.meshes
            .iter()
            .filter(|m| !m.has_lightmap_uvs)
            .map(|m| m.name.as_str())
            .collect()
    }

    /// World-space bounds of all triangles, `(min, max)`.
    #[must_use]
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in self.triangles.iter().flat_map(|t| t.positions) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (lo, hi)
    }
}

/// Accumulates meshes and triangles while a source is read; drops degenerate triangles.
struct SceneBuilder {
    path: PathBuf,
    meshes: Vec<Mesh>,
    triangles: Vec<Triangle>,
    degenerate: usize,
}

impl SceneBuilder {
    fn new(path: &Path) -> Self {
        Self {
            path: path.to_owned(),
            meshes: Vec::new(),
            triangles: Vec::new(),
            degenerate: 0,
        }
    }

    fn begin_mesh(&mut self, name: String) -> u32 {
        let first = self.triangles.len() as u32;
        self.meshes.push(Mesh {
            name,
            first_triangle: first,
            triangle_count: 0,
            has_lightmap_uvs: true,
        });
        (self.meshes.len() - 1) as u32
    }

    /// Adds a triangle unless it is degenerate; `normals` may be zero (then the geometric
    /// normal is used).
    fn push(&mut self, mut t: Triangle) {
        let finite = t.positions.iter().all(|p| p.is_finite());
        let n = t.geometric_normal();
        if !finite || n == Vec3::ZERO || t.area() <= 0.0 {
            self.degenerate += 1;
            return;
        }
        for vn in &mut t.normals {
            let u = vn.normalize_or_zero();
            *vn = if u == Vec3::ZERO || !u.is_finite() {
                n
            } else {
                u
            };
        }
        if let Some(uv) = t.lightmap_uv
            && !uv.iter().all(|v| v.is_finite())
        {
            t.lightmap_uv = None;
        }
        let mesh = &mut self.meshes[t.mesh as usize];
        mesh.triangle_count += 1;
        if t.lightmap_uv.is_none() {
            mesh.has_lightmap_uvs = false;
        }
        self.triangles.push(t);
    }

    fn bad_mesh(&self, mesh: u32, message: String) -> SceneError {
        SceneError::BadMesh {
            path: self.path.clone(),
            mesh: self.meshes[mesh as usize].name.clone(),
            message,
        }
    }

    fn finish(self, materials: Vec<Material>, lights: Vec<SceneLight>) -> Scene {
        Scene {
            path: self.path,
            meshes: self.meshes,
            triangles: self.triangles,
            materials,
            lights,
            sun: None,
            sky: Sky::None,
            degenerate_triangles: self.degenerate,
        }
    }
}

/// sRGB 8-bit transfer function → linear.
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Average linear RGB of an 8-bit sRGB image given as interleaved channels.
fn average_srgb8(pixels: &[u8], channels: usize) -> Option<Vec3> {
    if channels < 3 || pixels.len() < channels {
        return None;
    }
    let mut sum = glam::DVec3::ZERO;
    let mut n = 0u64;
    for px in pixels.chunks_exact(channels) {
        let lin = |i: usize| f64::from(srgb_to_linear(f32::from(px[i]) / 255.0));
        sum += glam::DVec3::new(lin(0), lin(1), lin(2));
        n += 1;
    }
    Some((sum / n as f64).as_vec3())
}

mod gltf_source {
    //! glTF 2.0 through the `gltf` crate.
    use super::*;

    pub(super) fn load(path: &Path) -> Result<Scene, SceneError> {
        let (doc, buffers, images) = import(path)?;
        let materials = read_materials(&doc, &images);
        let default_material = materials.len() as u32;
        let mut materials = materials;
        materials.push(Material::default_grey());

        let mut b = SceneBuilder::new(path);
        let mut lights = Vec::new();
        let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
            Some(s) => s.nodes().collect(),
            None => Vec::new(),
        };
        let mut stack: Vec<(gltf::Node, Mat4)> = roots
            .into_iter()
            .rev()
            .map(|n| (n, Mat4::IDENTITY))
            .collect();
        while let Some((node, parent)) = stack.pop() {
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            if let Some(mesh) = node.mesh() {
                read_mesh(&mut b, &node, &mesh, &buffers, world, default_material)?;
            }
            if let Some(light) = node.light() {
                lights.push(read_light(&light, world));
            }
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push((child, world));
            }
        }
        Ok(b.finish(materials, lights))
    }

    /// `gltf::import` with checks of ours where the crate panics instead of erring (each
    /// found by the `scene` fuzz target): the GLB header's length ([`check_glb_length`]),
    /// before the crate's validation that every `POSITION` names an existing accessor
    /// (gltf-json 1.4.1 indexes it unchecked in `mesh.rs`, `primitive_validate_hook`;
    /// [`check_position_accessors`]) and that every image has a source
    /// ([`check_image_sources`]), and every buffer's and image's URI ([`check_uri`]) and
    /// image's buffer view ([`check_view`]). Buffers and images are loaded one by one, so an
    /// error names the one at fault.
    fn import(
        path: &Path,
    ) -> Result<
        (
            gltf::Document,
            Vec<gltf::buffer::Data>,
            Vec<gltf::image::Data>,
        ),
        SceneError,
    > {
        let whole = |source| SceneError::Gltf {
            path: path.to_owned(),
            source,
        };
        let bytes = std::fs::read(path).map_err(|e| whole(gltf::Error::Io(e)))?;
        check_glb_length(&bytes).map_err(whole)?;
        let gltf::Gltf { document, mut blob } =
            gltf::Gltf::from_slice_without_validation(&bytes).map_err(whole)?;
        let json = document.into_json();
        check_position_accessors(&json).map_err(whole)?;
        check_image_sources(&json).map_err(whole)?;
        let doc = gltf::Document::from_json(json).map_err(whole)?;
        let base = path.parent().unwrap_or_else(|| Path::new("./"));
        let resource = |item: String, message: String| SceneError::GltfResource {
            path: path.to_owned(),
            item,
            message,
        };

        let mut buffers = Vec::with_capacity(doc.buffers().len());
        for buffer in doc.buffers() {
            let item = format!("buffers[{}]", buffer.index());
            let source = buffer.source();
            if let gltf::buffer::Source::Uri(uri) = source {
                check_uri(uri).map_err(|m| resource(item.clone(), m))?;
            }
            let data = gltf::buffer::Data::from_source_and_blob(source, Some(base), &mut blob)
                .map_err(|e| resource(item.clone(), describe(&e)))?;
            if data.len() < buffer.length() {
                let message = format!(
                    "{} bytes, fewer than its byteLength of {}",
                    data.len(),
                    buffer.length()
                );
                return Err(resource(item, message));
            }
            buffers.push(data);
        }
        let mut images = Vec::with_capacity(doc.images().len());
        for image in doc.images() {
            let item = format!("images[{}]", image.index());
            let source = image.source();
            match &source {
                gltf::image::Source::Uri { uri, .. } => {
                    check_uri(uri).map_err(|m| resource(item.clone(), m))?;
                }
                gltf::image::Source::View { view, .. } => {
                    check_view(view, &buffers).map_err(|m| resource(item.clone(), m))?;
                }
            }
            let data = gltf::image::Data::from_source(source, Some(base), &buffers)
                .map_err(|e| resource(item, describe(&e)))?;
            images.push(data);
        }
        Ok((doc, buffers, images))
    }

    /// A URI the importer can resolve without panicking: gltf 1.4.1 (`import.rs`,
    /// `Scheme::parse`) takes a URI without a `:` as a relative path and unwraps its
    /// percent-decoding as UTF-8, so `%AC` panicked (found by the `scene` fuzz target, on a
    /// buffer URI `data+application/octet-stream;base64,…%AC…`). `urlencoding` is the crate
    /// the importer decodes with, so this check refuses exactly what it would panic on.
    fn check_uri(uri: &str) -> Result<(), String> {
        if uri.contains(':') || urlencoding::decode(uri).is_ok() {
            return Ok(());
        }
        const SHOWN: usize = 48;
        let shown: String = uri.chars().take(SHOWN).collect();
        let more = if uri.chars().nth(SHOWN).is_some() {
            "…"
        } else {
            ""
        };
        Err(format!(
            "uri \"{shown}{more}\" is a relative path (no scheme) whose percent-escapes \
             decode to bytes that are not UTF-8"
        ))
    }

    /// An image's buffer view lies inside its buffer: gltf 1.4.1 slices the buffer with the
    /// view's range unchecked (`import.rs`, `image::Data::from_source`) and gltf-json does not
    /// validate it (found while fixing [`check_uri`]).
    fn check_view(view: &gltf::buffer::View, buffers: &[gltf::buffer::Data]) -> Result<(), String> {
        let buffer = view.buffer().index();
        let len = buffers[buffer].len();
        let (offset, length) = (view.offset(), view.length());
        if offset.checked_add(length).is_some_and(|end| end <= len) {
            return Ok(());
        }
        Err(format!(
            "bufferViews[{}] (byteOffset {offset}, byteLength {length}) runs past the end of \
             buffers[{buffer}] ({len} bytes)",
            view.index()
        ))
    }

    /// The importer's error for one buffer or image, said in the loader's words.
    fn describe(e: &gltf::Error) -> String {
        match e {
            gltf::Error::Base64(e) => format!("its data URI is not valid base64: {e}"),
            gltf::Error::Io(e) => format!("cannot read the file its uri names: {e}"),
            gltf::Error::UnsupportedScheme => {
                "unsupported uri scheme (data:, file: or a relative path)".to_owned()
            }
            other => other.to_string(),
        }
    }

    /// A GLB header's total length covers at least the header: gltf 1.4.1 subtracts the
    /// header's 12 bytes from it unchecked (`binary.rs`), which panics on overflow in a debug
    /// build and wraps to a 4 GiB read in a release one (found by the `scene` fuzz target).
    fn check_glb_length(bytes: &[u8]) -> gltf::Result<()> {
        const HEADER: usize = 12;
        match bytes.get(8..HEADER) {
            Some(length) if bytes.starts_with(b"glTF") => {
                let length = u32::from_le_bytes(length.try_into().expect("4 bytes"));
                if (length as usize) < HEADER {
                    return Err(gltf::Error::Binary(gltf::binary::Error::Length {
                        length,
                        length_read: bytes.len(),
                    }));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// Every image has a source the importer can take: a `uri`, or a `bufferView` with a
    /// `mimeType` (the spec's rule). gltf 1.4.1's `Image::source` unwraps both, unvalidated
    /// (`image.rs`; found by the `scene` fuzz target once images were loaded one by one).
    fn check_image_sources(json: &gltf::json::Root) -> gltf::Result<()> {
        use gltf::json::{Path as JsonPath, validation::Error};
        let errors: Vec<_> = json
            .images
            .iter()
            .enumerate()
            .filter_map(|(i, image)| {
                let missing = match (&image.buffer_view, &image.mime_type, &image.uri) {
                    (Some(_), None, _) => "mimeType",
                    (None, _, None) => "uri",
                    _ => return None,
                };
                let at = JsonPath::new().field("images").index(i).field(missing);
                Some((at, Error::Missing))
            })
            .collect();
        if errors.is_empty() {
            Ok(())
        } else {
            Err(gltf::Error::Validation(errors))
        }
    }

    /// Every primitive's `POSITION` names an accessor that exists.
    fn check_position_accessors(json: &gltf::json::Root) -> gltf::Result<()> {
        use gltf::json::validation::Error;
        use gltf::json::{Path as JsonPath, mesh::Semantic, validation::Checked};
        let mut errors = Vec::new();
        for (m, mesh) in json.meshes.iter().enumerate() {
            for (p, prim) in mesh.primitives.iter().enumerate() {
                let position = prim.attributes.get(&Checked::Valid(Semantic::Positions));
                if position.is_some_and(|a| a.value() >= json.accessors.len()) {
                    let at = JsonPath::new()
                        .field("meshes")
                        .index(m)
                        .field("primitives")
                        .index(p)
                        .field("attributes")
                        .key("POSITION");
                    errors.push((at, Error::IndexOutOfBounds));
                }
            }
        }
        if errors.is_empty() {
            Ok(())
        } else {
            Err(gltf::Error::Validation(errors))
        }
    }

    fn read_materials(doc: &gltf::Document, images: &[gltf::image::Data]) -> Vec<Material> {
        doc.materials()
            .enumerate()
            .map(|(i, m)| {
                let pbr = m.pbr_metallic_roughness();
                let f = pbr.base_color_factor();
                let mut albedo = Vec3::new(f[0], f[1], f[2]);
                if let Some(info) = pbr.base_color_texture() {
                    let img = &images[info.texture().source().index()];
                    if let Some(avg) = average_image(img) {
                        albedo *= avg;
                    }
                }
                // An emissive texture is averaged like the base colour: emitters are sampled
                // as lights of uniform radiance (transport::emitters).
                let mut e = Vec3::from(m.emissive_factor());
                if let Some(info) = m.emissive_texture() {
                    let img = &images[info.texture().source().index()];
                    if let Some(avg) = average_image(img) {
                        e *= avg;
                    }
                }
                let strength = m.emissive_strength().unwrap_or(1.0);
                Material {
                    name: m
                        .name()
                        .map_or_else(|| format!("material#{i}"), str::to_owned),
                    albedo: albedo.clamp(Vec3::ZERO, Vec3::ONE),
                    emission: (e * strength).max(Vec3::ZERO),
                }
            })
            .collect()
    }

    /// Linear average of a base-colour image (8-bit sRGB; 16-bit and float images are taken
    /// as linear already, which is what the glTF importers produce for them).
    fn average_image(img: &gltf::image::Data) -> Option<Vec3> {
        use gltf::image::Format;
        match img.format {
            Format::R8G8B8 => average_srgb8(&img.pixels, 3),
            Format::R8G8B8A8 => average_srgb8(&img.pixels, 4),
            Format::R8 | Format::R8G8 => {
                let ch = if img.format == Format::R8 { 1 } else { 2 };
                let grey: Vec<u8> = img
                    .pixels
                    .chunks_exact(ch)
                    .flat_map(|p| [p[0], p[0], p[0]])
                    .collect();
                average_srgb8(&grey, 3)
            }
            _ => None,
        }
    }

    /// The `gltf` crate's readers assert an accessor's layout (a VEC4 `TEXCOORD_1` panics,
    /// found by issue 8's scene fuzz target): check what the glTF spec allows first.
    fn check_accessors(
        b: &SceneBuilder,
        id: u32,
        prim: &gltf::Primitive,
    ) -> Result<(), SceneError> {
        use gltf::Semantic;
        use gltf::accessor::{DataType as T, Dimensions as D};
        let fits = |a: &gltf::Accessor, dims: D, types: &[T]| {
            a.dimensions() == dims && types.contains(&a.data_type())
        };
        let describe = |what: String, a: &gltf::Accessor| {
            format!(
                "{what} accessor {} is {:?} of {:?}, which the glTF spec does not allow",
                a.index(),
                a.dimensions(),
                a.data_type()
            )
        };
        let attributes = prim.attributes().map(|(semantic, a)| {
            let allowed = match semantic {
                Semantic::Positions | Semantic::Normals => fits(&a, D::Vec3, &[T::F32]),
                Semantic::TexCoords(_) => fits(&a, D::Vec2, &[T::F32, T::U8, T::U16]),
                _ => true,
            };
            (format!("{semantic:?}"), a, allowed)
        });
        let indices = prim.indices().map(|a| {
            let allowed = fits(&a, D::Scalar, &[T::U8, T::U16, T::U32]);
            ("indices".to_owned(), a, allowed)
        });
        for (what, a, allowed) in attributes.chain(indices) {
            if !allowed {
                return Err(b.bad_mesh(id, describe(what, &a)));
            }
            // The readers compute `count - 1` unchecked (gltf 1.4.1, `accessor/util.rs`; a
            // subtraction overflow found by the `scene` fuzz target): the spec's minimum is 1.
            if a.count() == 0 || a.sparse().is_some_and(|s| s.count() == 0) {
                let message = format!(
                    "{what} accessor {} has a count of 0 (the glTF spec's minimum is 1)",
                    a.index()
                );
                return Err(b.bad_mesh(id, message));
            }
        }
        Ok(())
    }

    fn read_light(light: &gltf::khr_lights_punctual::Light, world: Mat4) -> SceneLight {
        use gltf::khr_lights_punctual::Kind;
        let colour = Vec3::from(light.color()) * light.intensity();
        let position = world.transform_point3(Vec3::ZERO);
        let direction = world.transform_vector3(-Vec3::Z).normalize_or(-Vec3::Z);
        match light.kind() {
            Kind::Directional => SceneLight::Directional {
                direction,
                irradiance: colour,
            },
            Kind::Point => SceneLight::Point {
                position,
                intensity: colour,
            },
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => SceneLight::Spot {
                position,
                direction,
                intensity: colour,
                inner_cone: inner_cone_angle,
                outer_cone: outer_cone_angle,
            },
        }
    }

    fn read_mesh(
        b: &mut SceneBuilder,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        buffers: &[gltf::buffer::Data],
        world: Mat4,
        default_material: u32,
    ) -> Result<(), SceneError> {
        let name = node
            .name()
            .or(mesh.name())
            .map_or_else(|| format!("mesh#{}", mesh.index()), str::to_owned);
        let id = b.begin_mesh(name);
        let normal_m = Mat3::from_mat4(world).inverse().transpose();
        let mirrored = Mat3::from_mat4(world).determinant() < 0.0;
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                return Err(b.bad_mesh(
                    id,
                    format!(
                        "primitive mode {:?} (only triangles are supported)",
                        prim.mode()
                    ),
                ));
            }
            check_accessors(b, id, &prim)?;
            let reader = prim.reader(|buf| buffers.get(buf.index()).map(|d| d.0.as_slice()));
            let Some(positions) = reader.read_positions() else {
                return Err(b.bad_mesh(id, "primitive without POSITION".into()));
            };
            let positions: Vec<Vec3> = positions
                .map(|p| world.transform_point3(Vec3::from(p)))
                .collect();
            let normals: Option<Vec<Vec3>> = reader
                .read_normals()
                .map(|n| n.map(|n| normal_m * Vec3::from(n)).collect());
            let uvs: Option<Vec<Vec2>> = reader
                .read_tex_coords(1)
                .map(|t| t.into_f32().map(Vec2::from).collect());
            let count = positions.len();
            check_len(b, id, "NORMAL", normals.as_ref().map(Vec::len), count)?;
            check_len(b, id, "TEXCOORD_1", uvs.as_ref().map(Vec::len), count)?;
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..count as u32).collect(),
            };
            if !indices.len().is_multiple_of(3) {
                return Err(b.bad_mesh(
                    id,
                    format!("{} indices is not a multiple of 3", indices.len()),
                ));
            }
            if let Some((k, &bad)) = indices
                .iter()
                .enumerate()
                .find(|&(_, &i)| i as usize >= count)
            {
                return Err(b.bad_mesh(id, format!("index {bad} at position {k} is out of range (the primitive has {count} vertices)")));
            }
            let material = prim
                .material()
                .index()
                .map_or(default_material, |m| m as u32);
            for tri in indices.chunks_exact(3) {
                let mut v = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
                if mirrored {
                    v.swap(1, 2);
                }
                b.push(Triangle {
                    positions: v.map(|i| positions[i]),
                    normals: normals
                        .as_ref()
                        .map_or([Vec3::ZERO; 3], |n| v.map(|i| n[i])),
                    lightmap_uv: uvs.as_ref().map(|u| v.map(|i| u[i])),
                    mesh: id,
                    material,
                });
            }
        }
        Ok(())
    }

    fn check_len(
        b: &SceneBuilder,
        id: u32,
        what: &str,
        len: Option<usize>,
        count: usize,
    ) -> Result<(), SceneError> {
        match len {
            Some(n) if n != count => Err(b.bad_mesh(
                id,
                format!("{what} has {n} entries but POSITION has {count}"),
            )),
            _ => Ok(()),
        }
    }
}

mod obj_source {
    //! Wavefront OBJ + MTL through `tobj`.
    use super::*;

    pub(super) fn load(path: &Path) -> Result<Scene, SceneError> {
        let opts = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        };
        check_element_indices(path)?;
        let (models, mtl) = tobj::load_obj(path, &opts).map_err(|source| SceneError::Obj {
            path: path.to_owned(),
            source,
        })?;
        // A missing or broken MTL is an error: the albedo would silently be wrong otherwise.
        let mtl = mtl.map_err(|source| SceneError::Obj {
            path: path.to_owned(),
            source,
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let mut materials: Vec<Material> = mtl.iter().map(|m| read_material(m, dir)).collect();
        let default_material = materials.len() as u32;
        materials.push(Material::default_grey());

        let mut b = SceneBuilder::new(path);
        for (k, model) in models.iter().enumerate() {
            let name = if model.name.is_empty() {
                format!("mesh#{k}")
            } else {
                model.name.clone()
            };
            let id = b.begin_mesh(name);
            read_model(&mut b, id, &model.mesh, default_material)?;
        }
        Ok(b.finish(materials, Vec::new()))
    }

    /// Every index of a face (`f`) or line (`l`) names an element of the file: tobj 4.0.5
    /// resolves a relative index before the first element (`f 1/-5` with one `vt`), or a
    /// huge one, to a huge `usize` and computes `vt * 2 + 1` and `vn * 3 + 2` unchecked
    /// (`add_vertex`; an overflow found by the `scene` fuzz target). Indices are resolved as
    /// tobj does (relative ones against the elements so far; 0 and −count+… resolving to −1
    /// mean "none"), and only kinds the file has are checked, as tobj only reads those.
    fn check_element_indices(path: &Path) -> Result<(), SceneError> {
        let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
            path: path.to_owned(),
            source,
        })?;
        let text = String::from_utf8_lossy(&bytes);
        const KINDS: [(&str, &str); 3] = [
            ("v", "vertex"),
            ("vt", "texture coordinate"),
            ("vn", "normal"),
        ];
        let kind = |word: Option<&str>| KINDS.iter().position(|k| Some(k.0) == word);
        let mut total = [0isize; 3];
        for line in text.lines() {
            if let Some(k) = kind(line.split_whitespace().next()) {
                total[k] += 1;
            }
        }
        let mut seen = [0isize; 3];
        for (n, line) in text.lines().enumerate() {
            let mut words = line.split_whitespace();
            let first = words.next();
            if let Some(k) = kind(first) {
                seen[k] += 1;
                continue;
            }
            if !matches!(first, Some("f" | "l")) {
                continue;
            }
            for (k, field) in words.flat_map(|w| w.split('/').take(3).enumerate()) {
                let Ok(x) = field.parse::<isize>() else {
                    continue; // tobj refuses the face itself
                };
                let resolved = if x < 0 {
                    seen[k].saturating_add(x)
                } else {
                    x - 1
                };
                if total[k] > 0 && (resolved < -1 || resolved >= total[k]) {
                    return Err(SceneError::ObjIndex {
                        path: path.to_owned(),
                        line: n + 1,
                        message: format!(
                            "{} index {x} names no {} (the file has {}, {} before this line)",
                            KINDS[k].1, KINDS[k].1, total[k], seen[k]
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    fn read_material(m: &tobj::Material, dir: &Path) -> Material {
        let kd = m.diffuse.map_or(Vec3::splat(0.8), Vec3::from);
        let tex = m
            .diffuse_texture
            .as_ref()
            .and_then(|t| image::open(dir.join(t)).ok())
            .and_then(|img| average_srgb8(img.to_rgb8().as_raw(), 3));
        // tobj parses `Ke` into `emissive`; older files spell it as an unknown parameter.
        let ke = m
            .emissive
            .map(Vec3::from)
            .or_else(|| m.unknown_param.get("Ke").and_then(|s| parse_vec3(s)))
            .unwrap_or(Vec3::ZERO);
        Material {
            name: m.name.clone(),
            albedo: (kd * tex.unwrap_or(Vec3::ONE)).clamp(Vec3::ZERO, Vec3::ONE),
            emission: ke.max(Vec3::ZERO),
        }
    }

    fn parse_vec3(s: &str) -> Option<Vec3> {
        let v: Vec<f32> = s
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .ok()?;
        match v.as_slice() {
            [x] => Some(Vec3::splat(*x)),
            [x, y, z] => Some(Vec3::new(*x, *y, *z)),
            _ => None,
        }
    }

    fn read_model(
        b: &mut SceneBuilder,
        id: u32,
        mesh: &tobj::Mesh,
        default_material: u32,
    ) -> Result<(), SceneError> {
        let count = mesh.positions.len() / 3;
        let at3 = |v: &[f32], i: usize| Vec3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
        let has_n = mesh.normals.len() == mesh.positions.len();
        let has_uv = mesh.texcoords.len() / 2 == count && count > 0;
        if let Some(&bad) = mesh.indices.iter().find(|&&i| i as usize >= count) {
            return Err(b.bad_mesh(
                id,
                format!("index {bad} is out of range ({count} vertices)"),
            ));
        }
        let material = mesh.material_id.map_or(default_material, |m| m as u32);
        for tri in mesh.indices.chunks_exact(3) {
            let v = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
            b.push(Triangle {
                positions: v.map(|i| at3(&mesh.positions, i)),
                normals: if has_n {
                    v.map(|i| at3(&mesh.normals, i))
                } else {
                    [Vec3::ZERO; 3]
                },
                lightmap_uv: has_uv.then(|| {
                    v.map(|i| Vec2::new(mesh.texcoords[2 * i], mesh.texcoords[2 * i + 1]))
                }),
                mesh: id,
                material,
            });
        }
        Ok(())
    }
}

/// The TOML scene file: geometry plus sky and sun.
///
/// ```toml
/// geometry = "city.glb"          # relative to this file; .gltf, .glb or .obj
/// [sky]
/// constant = [0.5, 0.6, 0.8]     # radiance, or:
/// # equirect = "sky.exr"         # latitude-longitude EXR, +Y up
/// [sun]
/// direction = [0.3, 1.0, 0.2]    # towards the sun, need not be unit
/// angular_radius_deg = 0.267
/// irradiance = [4.0, 3.8, 3.5]
/// [[sphere_light]]               # any number of sphere lights
/// center = [0.0, 2.0, 0.0]
/// radius = 0.1
/// radiance = [50.0, 50.0, 50.0]
/// ```
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Path of the geometry, relative to the scene file.
    pub geometry: PathBuf,
    /// Sky, if any.
    pub sky: Option<SkySpec>,
    /// Sun, if any.
    pub sun: Option<SunSpec>,
    /// Sphere lights.
    #[serde(default)]
    pub sphere_light: Vec<SphereSpec>,
}

/// `[[sphere_light]]` of a [`SceneFile`].
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    /// Centre.
    pub center: [f32; 3],
    /// Radius, > 0.
    pub radius: f32,
    /// Radiance, linear RGB.
    pub radiance: [f32; 3],
}

impl SphereSpec {
    /// Validates and converts.
    ///
    /// # Errors
    /// A message when the centre is not finite, the radius not positive and finite, or the
    /// radiance negative or not finite.
    pub fn to_light(&self) -> Result<SceneLight, String> {
        let center = Vec3::from(self.center);
        let radiance = Vec3::from(self.radiance);
        if !center.is_finite() {
            return Err(format!("sphere_light center {center} must be finite"));
        }
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return Err(format!(
                "sphere_light radius {} must be positive and finite",
                self.radius
            ));
        }
        if !radiance.is_finite() || radiance.min_element() < 0.0 {
            return Err(format!(
                "sphere_light radiance {radiance} must be finite and non-negative"
            ));
        }
        Ok(SceneLight::Sphere {
            center,
            radius: self.radius,
            radiance,
        })
    }
}

/// `[sky]` of a [`SceneFile`]: exactly one of the two fields.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkySpec {
    /// Constant radiance.
    pub constant: Option<[f32; 3]>,
    /// Equirectangular EXR path, relative to the scene file.
    pub equirect: Option<PathBuf>,
}

/// `[sun]` of a [`SceneFile`].
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunSpec {
    /// Direction towards the sun.
    pub direction: [f32; 3],
    /// Angular radius in degrees.
    pub angular_radius_deg: f32,
    /// Irradiance, linear RGB.
    pub irradiance: [f32; 3],
}

impl SunSpec {
    /// Validates and converts.
    ///
    /// # Errors
    /// A message when the direction is zero or not finite, the radius is outside
    /// [0°, 90°), or the irradiance is negative or not finite.
    pub fn to_sun(&self) -> Result<Sun, String> {
        let d = Vec3::from(self.direction);
        let direction = d
            .try_normalize()
            .ok_or("sun direction must be finite and non-zero")?;
        let r = self.angular_radius_deg;
        if !(0.0..90.0).contains(&r) {
            return Err(format!("sun angular_radius_deg {r} is outside [0, 90)"));
        }
        let irr = Vec3::from(self.irradiance);
        if !irr.is_finite() || irr.min_element() < 0.0 {
            return Err(format!(
                "sun irradiance {irr} must be finite and non-negative"
            ));
        }
        Ok(Sun {
            direction,
            angular_radius: r.to_radians(),
            irradiance: irr,
        })
    }
}

impl SceneFile {
    /// Loads a TOML scene file and the geometry it names.
    ///
    /// # Errors
    /// [`SceneError::SceneFile`] for a malformed file, otherwise whatever loading the
    /// geometry or the sky returns.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let bad = |message: String| SceneError::SceneFile {
            path: path.to_owned(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_owned(),
            source,
        })?;
        let file: SceneFile = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let geometry = dir.join(&file.geometry);
        if geometry
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        {
            return Err(bad(
                "geometry must be .gltf, .glb or .obj, not another scene file".into(),
            ));
        }
        let mut scene = Scene::load(&geometry)?;
        if let Some(sun) = &file.sun {
            scene.sun = Some(sun.to_sun().map_err(bad)?);
        }
        for sphere in &file.sphere_light {
            scene.lights.push(sphere.to_light().map_err(bad)?);
        }
        scene.sky = match &file.sky {
            None => Sky::None,
            Some(SkySpec {
                constant: Some(c),
                equirect: None,
            }) => {
                let c = Vec3::from(*c);
                if !c.is_finite() || c.min_element() < 0.0 {
                    return Err(bad(format!(
                        "sky constant {c} must be finite and non-negative"
                    )));
                }
                Sky::Constant(c)
            }
            Some(SkySpec {
                constant: None,
                equirect: Some(p),
            }) => load_equirect(&dir.join(p))?,
            Some(_) => {
                return Err(bad(
                    "[sky] needs exactly one of `constant` or `equirect`".into()
                ));
            }
        };
        Ok(scene)
    }
}

/// Reads the first RGBA layer of an EXR as an equirectangular sky.
///
/// # Errors
/// [`SceneError::Sky`] when the file cannot be read or holds a non-finite or negative value.
pub fn load_equirect(path: &Path) -> Result<Sky, SceneError> {
    use exr::prelude::*;
    let err = |message: String| SceneError::Sky {
        path: path.to_owned(),
        message,
    };
    let image = read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![Vec3::ZERO; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<Vec3>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = Vec3::new(r, g, b);
        },
    )
    .map_err(|e| err(e.to_string()))?;
    let size = image.layer_data.size;
    let (_, pixels) = image.layer_data.channel_data.pixels;
    if let Some(i) = pixels
        .iter()
        .position(|p| !p.is_finite() || p.min_element() < 0.0)
    {
        return Err(err(format!(
            "pixel ({}, {}) is {} (must be finite, >= 0)",
            i % size.0,
            i / size.0,
            pixels[i]
        )));
    }
    Ok(Sky::Equirect {
        path: path.to_owned(),
        width: size.0 as u32,
        height: size.1 as u32,
        pixels,
    })
}

/// Sky and sun on the command line (`#[command(flatten)]` into a subcommand's arguments);
/// they override the scene file's.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct LightArgs {
    /// Constant sky radiance `R,G,B`.
    #[arg(long, value_parser = parse_rgb, conflicts_with = "sky_exr")]
    pub sky_constant: Option<Vec3>,
    /// Equirectangular sky EXR (latitude-longitude, +Y up).
    #[arg(long)]
    pub sky_exr: Option<PathBuf>,
    /// Direction towards the sun `X,Y,Z`.
    #[arg(long, value_parser = parse_rgb, requires = "sun_irradiance")]
    pub sun_direction: Option<Vec3>,
    /// Sun irradiance `R,G,B` on a plane facing it.
    #[arg(long, value_parser = parse_rgb, requires = "sun_direction")]
    pub sun_irradiance: Option<Vec3>,
    /// Sun angular radius in degrees.
    #[arg(long, default_value_t = 0.267)]
    pub sun_radius_deg: f32,
}

/// Parses `A,B,C` into a vector.
///
/// # Errors
/// A message unless there are exactly three finite numbers.
pub fn parse_rgb(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|c| c.trim().parse::<f32>().map_err(|e| format!("'{s}': {e}")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok(Vec3::new(*a, *b, *c)),
        _ => Err(format!("'{s}' is not three finite numbers A,B,C")),
    }
}

impl LightArgs {
    /// Applies the overrides to `scene`.
    ///
    /// # Errors
    /// [`SceneError::SceneFile`] (naming the scene) for an invalid sun or sky value,
    /// [`SceneError::Sky`] when the EXR cannot be read.
    pub fn apply(&self, scene: &mut Scene) -> Result<(), SceneError> {
        let bad = |message: String| SceneError::SceneFile {
            path: scene.path.clone(),
            message: format!("command line: {message}"),
        };
        if let (Some(d), Some(irr)) = (self.sun_direction, self.sun_irradiance) {
            let spec = SunSpec {
                direction: d.to_array(),
                angular_radius_deg: self.sun_radius_deg,
                irradiance: irr.to_array(),
            };
            scene.sun = Some(spec.to_sun().map_err(bad)?);
        }
        if let Some(c) = self.sky_constant {
            if c.min_element() < 0.0 {
                return Err(bad(format!("sky constant {c} must be non-negative")));
            }
            scene.sky = Sky::Constant(c);
        }
        if let Some(p) = &self.sky_exr {
            scene.sky = load_equirect(p)?;
        }
        Ok(())
    }
}

/// Where the tests and benches find the third-party scenes: `GUIDEBAKE_SCENES` if set, else
/// `../shared/scenes` beside the workspace (or `../../shared/scenes`, for a workspace that is a
/// git worktree one level further down). Prints a "skipping" line and returns `None` when
/// none exists, so a test on a fresh clone without `../shared` skips with a message.
#[doc(hidden)]
pub fn shared_scenes_dir() -> Option<PathBuf> {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let candidates = std::env::var_os("GUIDEBAKE_SCENES")
        .map(PathBuf::from)
        .into_iter()
        .chain(
            [
                format!("{root}/../shared/scenes"),
                format!("{root}/../../shared/scenes"),
            ]
            .map(PathBuf::from),
        );
    let found = candidates.into_iter().find(|p| p.is_dir());
    if found.is_none() {
        println!("skipping: ../shared/scenes is absent (set GUIDEBAKE_SCENES to point at it)");
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenes_dir() -> Option<PathBuf> {
        shared_scenes_dir()
    }

    #[test]
    fn veach_ajar_loads_all_triangles_with_lightmap_uvs() {
        let Some(dir) = scenes_dir() else { return };
        let s = Scene::load(&dir.join("converted/bitterli_veach_ajar_no_teapots.glb")).unwrap();
        assert_eq!(s.triangles.len() + s.degenerate_triangles, 4546);
        assert!(s.meshes_without_lightmap_uvs().is_empty());
        assert!(
            s.triangles
                .iter()
                .all(|t| t.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-5))
        );
        // Two emissive meshes with radiance 1000 (scenes/README.md).
        let emissive: Vec<_> = s
            .materials
            .iter()
            .filter(|m| m.emission != Vec3::ZERO)
            .collect();
        assert!(!emissive.is_empty());
        assert!(
            emissive
                .iter()
                .all(|m| (m.emission.max_element() - 1000.0).abs() < 1e-2)
        );
        assert_eq!(s.triangle_positions().len(), s.triangles.len());
    }

    #[test]
    fn bitterli_cornell_box_matches_its_sidecar() {
        let Some(dir) = scenes_dir() else { return };
        let s = Scene::load(&dir.join("converted/bitterli_cornell_box.glb")).unwrap();
        assert_eq!(s.triangles.len(), 36);
        let names: Vec<_> = s.meshes.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["Light", "LeftWall", "RightWall", "Mesh"]);
        let light = s.triangle_material(0);
        assert!(
            (light.emission - Vec3::new(17.0, 12.0, 4.0))
                .abs()
                .max_element()
                < 1e-3
        );
        assert!(
            (s.triangle_material(2).albedo - Vec3::new(0.63, 0.065, 0.05))
                .abs()
                .max_element()
                < 1e-6
        );
        let (lo, hi) = s.bounds();
        assert!(lo.cmpge(Vec3::splat(-1.01)).all() && hi.cmple(Vec3::splat(2.01)).all());
    }

    #[test]
    fn vinc3r_node_transforms_and_missing_lightmap_uvs() {
        let Some(dir) = scenes_dir() else { return };
        let p = dir
            .join("vinc3r_cornellbox/BJS-2.80-Eevee-gltf/assets/cornellBox-2.80-Eevee-gltf.gltf");
        let s = Scene::load(&p).unwrap();
        assert_eq!(s.triangles.len() + s.degenerate_triangles, 4410);
        let with_uv = s
            .triangles
            .iter()
            .filter(|t| t.lightmap_uv.is_some())
            .count();
        // 8 primitives with TEXCOORD_1 hold 4052 triangles (scenes/README.md).
        assert!(
            with_uv <= 4052 && with_uv + s.degenerate_triangles >= 4052,
            "{with_uv}"
        );
        assert!(s.meshes_without_lightmap_uvs().contains(&"lamp.000"));
        // Bounds [-2,0,-2]..[2,3,2] (scenes/README.md) after node transforms.
        let (lo, hi) = s.bounds();
        assert!(
            (lo - Vec3::new(-2.0, 0.0, -2.0)).abs().max_element() < 0.05,
            "{lo}"
        );
        assert!(
            (hi - Vec3::new(2.0, 3.0, 2.0)).abs().max_element() < 0.05,
            "{hi}"
        );
        // lamp.000 is emissive (1,1,1); the checker texture multiplies the block's albedo.
        let lamp = s.meshes.iter().find(|m| m.name == "lamp.000").unwrap();
        assert_eq!(
            s.triangle_material(lamp.first_triangle as usize).emission,
            Vec3::ONE
        );
    }

    #[test]
    fn command_line_lights_override_and_validate() {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            lights: LightArgs,
        }
        let mut b = SceneBuilder::new(Path::new("x.glb"));
        b.begin_mesh("m".into());
        let mut scene = b.finish(vec![], vec![]);
        let cli = Cli::try_parse_from([
            "t",
            "--sun-direction",
            "0,0,3",
            "--sun-irradiance",
            "1,2,3",
            "--sky-constant",
            "0.5,0.5,0.5",
        ])
        .unwrap();
        cli.lights.apply(&mut scene).unwrap();
        assert_eq!(scene.sun.as_ref().unwrap().direction, Vec3::Z);
        assert_eq!(scene.sky, Sky::Constant(Vec3::splat(0.5)));
        assert!(
            Cli::try_parse_from(["t", "--sun-direction", "0,0,1"]).is_err(),
            "irradiance is required"
        );
        assert!(Cli::try_parse_from(["t", "--sky-constant", "1,nan,1"]).is_err());
        let cli =
            Cli::try_parse_from(["t", "--sun-direction", "0,0,0", "--sun-irradiance", "1,1,1"])
                .unwrap();
        let e = cli.lights.apply(&mut scene).unwrap_err();
        assert!(
            e.to_string()
                .contains("x.glb: bad scene file: command line: sun direction"),
            "{e}"
        );
    }

    /// A glTF of one buffer (4 bytes long) and one image with these URIs, loaded.
    fn load_gltf_with_uris(buffer_uri: &str, image_uri: &str) -> (PathBuf, SceneError) {
        load_gltf_with(buffer_uri, 4, image_uri)
    }

    fn load_gltf_with(buffer_uri: &str, length: usize, image_uri: &str) -> (PathBuf, SceneError) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("uris.gltf");
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "buffers": [{ "byteLength": length, "uri": buffer_uri }],
            "images": [{ "uri": image_uri }],
        });
        std::fs::write(&path, json.to_string()).unwrap();
        let e = Scene::load(&path).expect_err("a bad URI is an error");
        (path, e)
    }

    #[test]
    fn uris_whose_percent_escapes_are_not_utf8_are_errors_naming_the_buffer() {
        // The `scene` fuzz target's input (fuzz/corpus/scene/gltf-import-non-utf8-data-uri):
        // "data+…" has no ':', so the importer reads it as a relative path and unwrapped its
        // percent-decoding, which `%AC` makes invalid UTF-8.
        let uri = "data+application/octet-stream;base64,AAAA%ACAP%wAA";
        let (path, e) = load_gltf_with_uris(uri, "ok.png");
        let message = e.to_string();
        assert!(
            matches!(&e, SceneError::GltfResource { item, .. } if item == "buffers[0]"),
            "{message}"
        );
        assert!(message.contains(&*path.to_string_lossy()), "{message}");
        assert!(
            message.contains("not UTF-8") && message.contains("%AC"),
            "{message}"
        );

        // The same URI on an image (the importer parses image URIs the same way).
        let data = "data:application/octet-stream;base64,AAAAAA==";
        let (_, e) = load_gltf_with_uris(data, "tex%FF.png");
        assert!(
            matches!(&e, SceneError::GltfResource { item, .. } if item == "images[0]"),
            "{e}"
        );
        // Escapes that decode to UTF-8 are a path like any other: a missing file.
        let (_, e) = load_gltf_with_uris("b%C3%A4r.bin", "ok.png");
        assert!(e.to_string().contains("buffers[0]: cannot read"), "{e}");
    }

    #[test]
    fn data_uris_that_are_not_base64_are_errors_naming_the_buffer() {
        let (path, e) = load_gltf_with_uris("data:application/octet-stream;base64,AA%AC", "x.png");
        let message = e.to_string();
        assert!(
            message.starts_with(&format!(
                "{}: buffers[0]: its data URI is not valid base64",
                path.display()
            )),
            "{message}"
        );
        // 3 bytes, padded to 4 by the importer: short of 8.
        let (_, e) = load_gltf_with("data:application/octet-stream;base64,AAAA", 8, "x.png");
        assert!(
            e.to_string()
                .contains("buffers[0]: 4 bytes, fewer than its byteLength of 8"),
            "{e}"
        );
    }

    #[test]
    fn an_image_whose_buffer_view_runs_past_its_buffer_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("view.gltf");
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "buffers": [{ "byteLength": 4, "uri": "data:application/octet-stream;base64,AAAAAA==" }],
            "bufferViews": [{ "buffer": 0, "byteOffset": 2, "byteLength": 100 }],
            "images": [{ "bufferView": 0, "mimeType": "image/png" }],
        });
        std::fs::write(&path, json.to_string()).unwrap();
        let e = Scene::load(&path).expect_err("a view past its buffer is an error");
        assert_eq!(
            e.to_string(),
            format!(
                "{}: images[0]: bufferViews[0] (byteOffset 2, byteLength 100) runs past the end \
                 of buffers[0] (4 bytes)",
                path.display()
            )
        );
    }

    #[test]
    fn images_without_a_source_are_errors_naming_the_image() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("image.gltf");
        for (image, missing) in [
            (serde_json::json!({ "name": "no source" }), "images[0].uri"),
            (serde_json::json!({ "bufferView": 0 }), "images[0].mimeType"),
        ] {
            let json = serde_json::json!({
                "asset": { "version": "2.0" },
                "buffers": [{ "byteLength": 4, "uri": "data:application/octet-stream;base64,AAAAAA==" }],
                "bufferViews": [{ "buffer": 0, "byteLength": 4 }],
                "images": [image],
            });
            std::fs::write(&path, json.to_string()).unwrap();
            let e = Scene::load(&path).expect_err("an image without a source is an error");
            let message = e.to_string();
            assert!(matches!(e, SceneError::Gltf { .. }), "{message}");
            assert!(
                message.contains(&*path.to_string_lossy()) && message.contains(missing),
                "{message}"
            );
        }
    }

    #[test]
    fn accessors_of_count_zero_are_errors_naming_the_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.gltf");
        let zeros = "A".repeat(64); // 48 zero bytes
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "scene": 0, "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
            "meshes": [{ "name": "tri", "primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1 }] }],
            "accessors": [
                { "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 0] },
                { "bufferView": 1, "componentType": 5125, "count": 0, "type": "SCALAR" },
            ],
            "bufferViews": [
                { "buffer": 0, "byteLength": 36 },
                { "buffer": 0, "byteOffset": 36, "byteLength": 12 },
            ],
            "buffers": [{ "byteLength": 48, "uri": format!("data:application/octet-stream;base64,{zeros}") }],
        });
        std::fs::write(&path, json.to_string()).unwrap();
        let e = Scene::load(&path).expect_err("an accessor of count 0 is an error");
        assert_eq!(
            e.to_string(),
            format!(
                "{}: mesh 'tri': indices accessor 1 has a count of 0 (the glTF spec's minimum is 1)",
                path.display()
            )
        );
    }

    #[test]
    fn obj_indices_naming_no_element_are_errors_naming_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.obj");
        let head = "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\n";
        for (face, message) in [
            // Relative, before the first texture coordinate: overflowed in tobj.
            (
                "f 1/-3 2/1 3/1",
                "line 6: texture coordinate index -3 names no texture coordinate (the file has 1, 1 before this line)",
            ),
            (
                "f 1//1 2//1 3//9223372036854775807",
                "line 6: normal index 9223372036854775807 names no normal (the file has 1, 1 before this line)",
            ),
            (
                "f 1 2 4",
                "line 6: vertex index 4 names no vertex (the file has 3, 3 before this line)",
            ),
        ] {
            std::fs::write(&path, format!("{head}{face}\n")).unwrap();
            let e = Scene::load(&path).expect_err("an index naming no element is an error");
            assert_eq!(e.to_string(), format!("{}: {message}", path.display()));
        }
        // 0 and a relative index to just before the first element mean "none", as in tobj.
        std::fs::write(&path, format!("{head}f 1/0/-1 2/-2/1 3/1/1\n")).unwrap();
        assert_eq!(Scene::load(&path).unwrap().triangles.len(), 1);
    }

    #[test]
    fn degenerate_triangles_are_dropped_and_counted() {
        let mut b = SceneBuilder::new(Path::new("x"));
        let id = b.begin_mesh("m".into());
        let t = |p: [Vec3; 3]| Triangle {
            positions: p,
            normals: [Vec3::ZERO; 3],
            lightmap_uv: None,
            mesh: id,
            material: 0,
        };
        b.push(t([Vec3::ZERO, Vec3::X, Vec3::Y]));
        b.push(t([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]));
        b.push(t([Vec3::ZERO, Vec3::X, Vec3::NAN]));
        let s = b.finish(vec![], vec![]);
        assert_eq!(s.triangles.len(), 1);
        assert_eq!(s.degenerate_triangles, 2);
        assert_eq!(s.triangles[0].normals, [Vec3::Z; 3]);
        assert!(!s.meshes[0].has_lightmap_uvs);
    }
}
