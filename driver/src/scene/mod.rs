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
//! - Only the diffuse albedo of a material is kept: `baseColorFactor` × the base-colour
//!   texture sampled at the hit's `TEXCOORD_n` (its `texCoord` set) × the vertex colour
//!   `COLOR_0`; OBJ `Kd` × `map_Kd` ([`texture`]). [`Material::albedo`] is the factor × the
//!   texture's average, used where the albedo does not vary. Metallic, roughness, alpha and
//!   transmission are ignored.
//! - **Assets as they come** (docs/levels.md, "What guidebake does with a level as it
//!   comes"): a texture image that is missing or cannot be decoded is not an error —
//!   downloaded levels often come without their texture packs. The material falls back to
//!   its colour factor (MTL `Kd`, glTF `baseColorFactor`) where the file gives one (a glTF
//!   factor of exactly white is glTF's default, not a colour), else to
//!   [`MISSING_TEXTURE_ALBEDO`] grey; [`Scene::load_reporting`] returns each such texture
//!   ([`MissingTexture`], naming the file and the material) for the commands to warn about and
//!   count. Structural faults of a glTF file (a malformed URI, a buffer view outside its
//!   buffer) stay errors. An OBJ material library (`mtllib`) that is missing or malformed
//!   is not an error either: the OBJ loads, the library's materials are [`Material::default_grey`], and
//!   [`LoadNotes::file_warnings`] names the library as resolved and the line naming it.
//! - **Messages** name the file and, where a parser knows it, the line and column
//!   (`level.obj:1234:7: vertex position "1.0e" is not a number`; [`TextPos`]); a path that
//!   is a directory, empty, of an unknown extension or of contents of another kind than its
//!   extension says what it is ([`SceneError::NotAScene`], [`SceneError::UnknownFormat`]).
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

/// Why a scene could not be loaded. Every variant names the file, and where a parser knows
/// it the line and column (`level.obj:1234:7: ...`, as compilers write it).
///
/// No variant's [`std::error::Error::source`] repeats what its message already says: the
/// messages carry their cause's text, and `source()` is `None` (the command line prints the
/// message and then each source as a "caused by" line).
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read (missing, unreadable).
    #[error("{path}: cannot read: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error (its text is in the message, so it is not the `source()`).
        error: std::io::Error,
    },
    /// The path is not a scene file guidebake can read: a directory, an empty file, or a
    /// file whose contents are another kind than its extension says.
    #[error("{path}: {message}")]
    NotAScene {
        /// The path.
        path: PathBuf,
        /// What it is instead, and what is accepted.
        message: String,
    },
    /// The glTF importer rejected the file (a bad GLB chunk, a failed validation, ...).
    #[error("{path}: not a loadable glTF file: {error}")]
    Gltf {
        /// The file.
        path: PathBuf,
        /// The importer's error (its text is in the message, so it is not the `source()`).
        error: ::gltf::Error,
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
    /// A text file (OBJ, glTF JSON) is malformed at a place: a number that is not one, too
    /// few components, a face index naming no element, a JSON syntax error.
    #[error("{path}:{at}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// Where.
        at: TextPos,
        /// What is wrong.
        message: String,
    },
    /// tobj rejected the OBJ for a reason the loader could not place on a line.
    #[error("{path}: not a loadable OBJ file: {error}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// tobj's error (its text is in the message, so it is not the `source()`).
        error: tobj::LoadError,
    },
    /// The TOML scene file is malformed (at `at`, where known), or a `--sun`/`--sky` value
    /// given for the scene is invalid.
    #[error("{path}{}: {message}", at.map(|a| format!(":{a}")).unwrap_or_default())]
    SceneFile {
        /// The file.
        path: PathBuf,
        /// Where in it, when the error is about one place.
        at: Option<TextPos>,
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
    #[error(
        "{path}: unknown scene format{detail}; guidebake reads .gltf, .glb, .obj and .toml scene files"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// The extension it has and, where the contents are recognised, what it looks like
        /// (e.g. ` ".fbx"` or ` ".dat" (it looks like a binary glTF (.glb): rename it)`).
        detail: String,
    },
    /// After dropping degenerate triangles nothing is left.
    #[error("{path}: the scene has no triangles ({degenerate} degenerate triangles dropped)")]
    Empty {
        /// The file.
        path: PathBuf,
        /// How many degenerate triangles were dropped.
        degenerate: usize,
    },
    /// A texture image (OBJ `map_Kd`) is missing or cannot be decoded: the OBJ loader notes
    /// it as a [`MissingTexture`] and goes on (module docs), so [`Scene::load`] does not
    /// return it.
    #[error("{path}: texture {image}: {message}")]
    Texture {
        /// The scene (or MTL) file naming it.
        path: PathBuf,
        /// The image file as named.
        image: String,
        /// What is wrong.
        message: String,
    },
    /// Nothing lights the scene: no sun, no sky, no punctual light, no emissive triangle.
    #[error(
        "{path}: nothing lights this scene (no lights, no emissive materials, no sky); add a sun and a sky on the command line, the same on prepare, bake and render, e.g. `--sun 0.3,1,0.2:3 --sky 0.5,0.6,0.8` (--sun X,Y,Z[:IRRADIANCE], towards the sun, +Y up; --sky R,G,B or an equirect .exr), or [sun] and [sky] in a TOML scene file (docs/levels.md)"
    )]
    Unlit {
        /// The scene file.
        path: PathBuf,
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

/// A place in a text file: a line and, where the parser knows it, a column, both counted
/// from 1 (the column in characters). Displays as `LINE` or `LINE:COLUMN`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextPos {
    /// The line, from 1.
    pub line: usize,
    /// The column, from 1, in characters.
    pub column: Option<usize>,
}

impl TextPos {
    /// The place of byte `offset` of `text` (clamped to its length).
    #[must_use]
    pub fn of_offset(text: &str, offset: usize) -> Self {
        let mut offset = offset.min(text.len());
        while !text.is_char_boundary(offset) {
            offset -= 1;
        }
        let before = &text[..offset];
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        Self {
            line: before.matches('\n').count() + 1,
            column: Some(before[line_start..].chars().count() + 1),
        }
    }
}

impl std::fmt::Display for TextPos {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.column {
            Some(c) => write!(f, "{}:{c}", self.line),
            None => write!(f, "{}", self.line),
        }
    }
}

/// What a file's first bytes say it is, for a message about a file whose contents are
/// another kind than its extension; `None` for text nothing here recognises.
pub(crate) fn looks_like(bytes: &[u8]) -> Option<&'static str> {
    const MAGIC: [(&[u8], &str); 9] = [
        (b"glTF", "a binary glTF (.glb)"),
        (&[0x76, 0x2f, 0x31, 0x01], "an OpenEXR image"),
        (b"GBTEXELS", "a guidebake texel file (.texels)"),
        (b"\x89PNG", "a PNG image"),
        (&[0xff, 0xd8, 0xff], "a JPEG image"),
        (b"PK\x03\x04", "a zip archive"),
        (&[0x1f, 0x8b], "a gzip file"),
        (b"Kaydara FBX Binary", "a binary FBX file"),
        (b"#?RADIANCE", "a Radiance HDR image"),
    ];
    if let Some((_, kind)) = MAGIC.iter().find(|(m, _)| bytes.starts_with(m)) {
        return Some(kind);
    }
    let head = &bytes[..bytes.len().min(4096)];
    let text = String::from_utf8_lossy(head);
    let text = text.trim_start_matches('\u{feff}').trim_start();
    if text.starts_with('{') {
        return Some("glTF JSON (.gltf)");
    }
    let words = |w: &str| text.lines().any(|l| l.split_whitespace().next() == Some(w));
    if words("v") && (words("f") || words("vt") || words("vn")) {
        return Some("a Wavefront OBJ file");
    }
    if head.contains(&0) {
        return Some("binary data");
    }
    None
}

/// The first 4 KiB of a file, if it can be read.
fn read_head(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(4096).read_to_end(&mut head))
        .ok()?;
    Some(head)
}

/// The absolute form of `path` for a message (the path as given where that fails).
pub(crate) fn shown_absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_owned())
}

/// A Lambertian material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the source file (may be empty).
    pub name: String,
    /// Diffuse albedo, linear RGB in [0, 1]: the base colour factor × the average of the
    /// base-colour texture (the albedo everywhere when there is no texture; where a
    /// triangle has no texture UVs; and for whatever wants one colour per material).
    pub albedo: Vec3,
    /// Emitted radiance, linear RGB (front face only).
    pub emission: Vec3,
    /// The base-colour texture, sampled at hits ([`texture::HitAlbedo`]).
    pub base_color_texture: Option<BaseColorTexture>,
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
            base_color_texture: None,
        }
    }
}

/// The albedo of a textured material whose texture could not be read and whose file gives
/// no colour factor (module docs).
pub const MISSING_TEXTURE_ALBEDO: f32 = 0.5;

/// A texture that could not be read; its material fell back to a colour (module docs).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MissingTexture {
    /// The material that names it (`""` for a glTF image no material uses).
    pub material: String,
    /// The image as the file names it (path or URI, or `images[i]`).
    pub file: String,
    /// Why it could not be read.
    pub message: String,
    /// The albedo the material uses instead, linear RGB.
    pub fallback: [f32; 3],
}

/// What [`Scene::load_reporting`] noticed and went on with.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LoadNotes {
    /// Textures that could not be read, in file order.
    pub missing_textures: Vec<MissingTexture>,
    /// Other things the loader went on past, each a whole warning naming its file and line:
    /// an OBJ material library that cannot be read (its materials load as the default
    /// grey), OBJ vertex positions that are not finite (the triangles using them are
    /// dropped and counted).
    pub file_warnings: Vec<String>,
    /// Every file the scene was read from: the scene file, a scene file's geometry, OBJ
    /// material libraries and textures, glTF buffers and images named by a relative URI.
    /// The commands refuse to write over any of them (`cmd::files`).
    pub files_read: Vec<PathBuf>,
}

impl LoadNotes {
    /// The [`LoadNotes::file_warnings`], then one warning line per missing texture, naming
    /// the scene file, the image and the material, for the commands to print.
    #[must_use]
    pub fn warnings(&self, scene: &Path) -> Vec<String> {
        let files = self.file_warnings.iter().cloned();
        let textures = self.missing_textures.iter().map(|m| {
            let used = if m.material.is_empty() {
                "used by no material".to_owned()
            } else {
                format!(
                    "material '{}' uses its colour {:.3},{:.3},{:.3} instead",
                    m.material, m.fallback[0], m.fallback[1], m.fallback[2]
                )
            };
            format!(
                "{}: texture {} cannot be read ({}); {used}",
                scene.display(),
                m.file,
                m.message
            )
        });
        files.chain(textures).collect()
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
    /// The UVs its material's base-colour texture is sampled at (glTF `TEXCOORD_n` of the
    /// texture's `texCoord` set; OBJ's one UV set), or `None` without a texture.
    pub texture_uv: Option<[Vec2; 3]>,
    /// Vertex colours (glTF `COLOR_0`, linear RGB), multiplied into the albedo, if any.
    pub colour: Option<[Vec3; 3]>,
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
    /// Each triangle's [`Role`] ([`roles`]), in [`Scene::triangles`] order; empty when every
    /// triangle is [`Role::Baked`].
    pub roles: Vec<Role>,
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
            roles: Vec::new(),
        }
    }

    /// Loads a scene from `.gltf`, `.glb`, `.obj` or a `.toml` scene file, its textures
    /// capped at the default size ([`TextureOptions::default`]).
    ///
    /// # Errors
    /// A [`SceneError`] naming the file and what is wrong; [`SceneError::Empty`] when no
    /// triangle survives.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        Self::load_with(path, TextureOptions::default())
    }

    /// [`Scene::load`] with the textures kept as `textures` says.
    ///
    /// # Errors
    /// As [`Scene::load`].
    pub fn load_with(path: &Path, textures: TextureOptions) -> Result<Scene, SceneError> {
        Self::load_reporting(path, textures).map(|(scene, _)| scene)
    }

    /// [`Scene::load_with`], also returning what the loader went on with: the textures that
    /// could not be read (module docs), for the commands to warn about and count.
    ///
    /// # Errors
    /// As [`Scene::load`].
    pub fn load_reporting(
        path: &Path,
        textures: TextureOptions,
    ) -> Result<(Scene, LoadNotes), SceneError> {
        let mut notes = LoadNotes::default();
        let scene = Self::load_noting(path, textures, &mut notes)?;
        Ok((scene, notes))
    }

    fn load_noting(
        path: &Path,
        textures: TextureOptions,
        notes: &mut LoadNotes,
    ) -> Result<Scene, SceneError> {
        notes.files_read.push(path.to_owned());
        const ACCEPTED: &str = "guidebake reads .gltf, .glb, .obj and .toml scene files";
        let not_a_scene = |message: String| SceneError::NotAScene {
            path: path.to_owned(),
            message,
        };
        if path.is_dir() {
            return Err(not_a_scene(format!(
                "is a directory, not a scene file; {ACCEPTED}"
            )));
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("gltf" | "glb" | "obj" | "toml")) {
            let named = match path.extension() {
                Some(e) => format!(" \".{}\"", e.to_string_lossy()),
                None => " (the file name has no extension)".to_owned(),
            };
            let seen = read_head(path)
                .as_deref()
                .and_then(looks_like)
                .map(|kind| format!(" (it looks like {kind}; rename it to match)"))
                .unwrap_or_default();
            return Err(SceneError::UnknownFormat {
                path: path.to_owned(),
                detail: format!("{named}{seen}"),
            });
        }
        match std::fs::metadata(path) {
            Ok(m) if m.len() == 0 => {
                return Err(not_a_scene(format!("is empty (0 bytes); {ACCEPTED}")));
            }
            Ok(_) => {}
            Err(error) => {
                return Err(SceneError::Io {
                    path: path.to_owned(),
                    error,
                });
            }
        }
        let scene = match ext.as_deref() {
            Some("gltf" | "glb") => gltf::load(path, textures, notes)?,
            Some("obj") => obj::load(path, textures, notes)?,
            _ => SceneFile::load_noting(path, textures, notes)?,
        };
        if scene.triangles.is_empty() {
            return Err(SceneError::Empty {
                path: path.to_owned(),
                degenerate: scene.degenerate_triangles,
            });
        }
        Ok(scene)
    }

    /// Whether anything lights the scene: a sun, a sky that is not black, a punctual light,
    /// or an emissive material on some triangle.
    #[must_use]
    pub fn is_lit(&self) -> bool {
        let emitters = {
            let mut used = vec![false; self.materials.len()];
            for t in &self.triangles {
                used[t.material as usize] = true;
            }
            self.materials
                .iter()
                .zip(&used)
                .any(|(m, &u)| u && m.emission.max_element() > 0.0)
        };
        self.lit_from_outside() || !self.lights.is_empty() || emitters
    }

    /// Whether a sun or a sky that is not black lights the scene: the light from outside that
    /// a shell around a level keeps out (`prepare::shell`).
    #[must_use]
    pub fn lit_from_outside(&self) -> bool {
        let sky = match &self.sky {
            Sky::None => false,
            Sky::Constant(c) => c.max_element() > 0.0,
            Sky::Equirect { pixels, .. } => pixels.iter().any(|p| p.max_element() > 0.0),
        };
        let sun = self
            .sun
            .as_ref()
            .is_some_and(|s| s.irradiance.max_element() > 0.0);
        sky || sun
    }

    /// A fingerprint of everything that lights the scene — punctual and sphere lights, the
    /// sun, the sky (an equirect map by its pixels) and the materials' emission — never 0.
    /// `prepare` stores it in the texel file (it decides the seen sides under these lights,
    /// `facing`), so a bake under other lights is told (docs/levels.md).
    #[must_use]
    pub fn lighting_fingerprint(&self) -> u64 {
        let mut h = Fnv::default();
        for light in &self.lights {
            match light {
                SceneLight::Directional {
                    direction,
                    irradiance,
                } => h.tag(1).vec(*direction).vec(*irradiance),
                SceneLight::Point {
                    position,
                    intensity,
                } => h.tag(2).vec(*position).vec(*intensity),
                SceneLight::Spot {
                    position,
                    direction,
                    intensity,
                    inner_cone,
                    outer_cone,
                } => h
                    .tag(3)
                    .vec(*position)
                    .vec(*direction)
                    .vec(*intensity)
                    .f(*inner_cone)
                    .f(*outer_cone),
                SceneLight::Sphere {
                    center,
                    radius,
                    radiance,
                } => h.tag(4).vec(*center).f(*radius).vec(*radiance),
            };
        }
        if let Some(sun) = &self.sun {
            h.tag(5)
                .vec(sun.direction)
                .f(sun.angular_radius)
                .vec(sun.irradiance);
        }
        match &self.sky {
            Sky::None => h.tag(6),
            Sky::Constant(c) => h.tag(7).vec(*c),
            Sky::Equirect {
                width,
                height,
                pixels,
                ..
            } => {
                h.tag(8).tag(u64::from(*width)).tag(u64::from(*height));
                for p in pixels {
                    h.vec(*p);
                }
                &mut h
            }
        };
        for m in &self.materials {
            h.tag(9).vec(m.emission);
        }
        h.0.max(1)
    }

    /// [`Scene::is_lit`] as a check for the commands that light a scene (`prepare`, whose
    /// facing analysis needs the lights, and `bake`).
    ///
    /// # Errors
    /// [`SceneError::Unlit`], which says how to add a sun and a sky from the command line.
    pub fn check_lit(&self) -> Result<(), SceneError> {
        if self.is_lit() {
            Ok(())
        } else {
            Err(SceneError::Unlit {
                path: self.path.clone(),
            })
        }
    }

    /// The flat triangle soup, world space, in [`Scene::triangles`] order (the order BVH
    /// primitive ids refer to).
    #[must_use]
    pub fn triangle_positions(&self) -> Vec<[Vec3; 3]> {
        self.triangles.iter().map(|t| t.positions).collect()
    }

    /// The [`Role`] of triangle `triangle` ([`Role::Baked`] past the end of [`Scene::roles`]).
    #[must_use]
    pub fn role(&self, triangle: usize) -> Role {
        self.roles.get(triangle).copied().unwrap_or_default()
    }

    /// Gives every triangle a rule names the rule's role, the rules in order (the last that
    /// names a triangle wins, over what the file said); returns the rules that named none.
    pub fn apply_roles(&mut self, rules: &[RoleRule]) -> Vec<String> {
        if rules.is_empty() {
            return Vec::new();
        }
        self.roles.resize(self.triangles.len(), Role::Baked);
        let mut matched = vec![false; rules.len()];
        // Per (mesh, material) pair, the rule that wins: names are matched once a pair.
        let mut last: Option<((u32, u32), Option<usize>)> = None;
        for (t, role) in self.triangles.iter().zip(&mut self.roles) {
            let pair = (t.mesh, t.material);
            let winner = match last {
                Some((p, w)) if p == pair => w,
                _ => {
                    let mesh = &self.meshes[t.mesh as usize].name;
                    let material = &self.materials[t.material as usize].name;
                    let mut w = None;
                    for (k, r) in rules.iter().enumerate() {
                        if r.matches(mesh, material) {
                            matched[k] = true;
                            w = Some(k);
                        }
                    }
                    last = Some((pair, w));
                    w
                }
            };
            if let Some(w) = winner {
                *role = rules[w].role;
            }
        }
        if self.roles.iter().all(|&r| r == Role::Baked) {
            self.roles.clear();
        }
        rules
            .iter()
            .zip(matched)
            .filter(|(_, m)| !m)
            .map(|(r, _)| r.to_string())
            .collect()
    }

    /// What [`Scene::roles`] holds, by role, with `unmatched` rules (those
    /// [`Scene::apply_roles`] returned).
    #[must_use]
    pub fn role_report(&self, unmatched: Vec<String>) -> RoleReport {
        let roles: Vec<Role> = (0..self.triangles.len()).map(|t| self.role(t)).collect();
        RoleReport::of(
            &roles,
            &self.triangles,
            &self.meshes,
            &self.materials,
            unmatched,
        )
    }

    /// The triangles rays meet ([`Role::traced`]), as BVH primitive ids; `None` when all are.
    #[must_use]
    pub fn traced_triangles(&self) -> Option<Vec<u32>> {
        ids_where(self.triangles.len(), |t| self.role(t).traced())
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

    /// How triangle `triangle` is coloured ([`texture::HitAlbedo`]: constant, or varying
    /// with a texture and vertex colours).
    ///
    /// # Panics
    /// If `triangle` is out of range.
    #[must_use]
    pub fn hit_albedo(&self, triangle: usize) -> texture::HitAlbedo {
        texture::HitAlbedo::of(&self.triangles[triangle], self.triangle_material(triangle))
    }

    /// Bytes of texture texels the scene keeps in memory (each image once).
    #[must_use]
    pub fn texture_bytes(&self) -> usize {
        texture::texture_bytes(&self.materials)
    }

    /// Names of meshes that lack lightmap UVs (reported by `prepare`).
    #[must_use]
    pub fn meshes_without_lightmap_uvs(&self) -> Vec<&str> {
        self.meshes
            .iter()
            .filter(|m| !m.has_lightmap_uvs && self.mesh_has_texels(m))
            .map(|m| m.name.as_str())
            .collect()
    }

    /// Whether a triangle of `mesh` has a role with texels ([`Role::has_texels`]).
    #[must_use]
    pub fn mesh_has_texels(&self, mesh: &Mesh) -> bool {
        let first = mesh.first_triangle as usize;
        (first..first + mesh.triangle_count as usize).any(|t| self.role(t).has_texels())
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

/// The indices below `n` where `keep` holds; `None` when it holds for all.
#[must_use]
pub fn ids_where(n: usize, keep: impl Fn(usize) -> bool) -> Option<Vec<u32>> {
    let ids: Vec<u32> = (0..n).filter(|&t| keep(t)).map(|t| t as u32).collect();
    (ids.len() < n).then_some(ids)
}

/// Accumulates meshes and triangles while a source is read; drops degenerate triangles.
struct SceneBuilder {
    path: PathBuf,
    meshes: Vec<Mesh>,
    triangles: Vec<Triangle>,
    degenerate: usize,
    /// The role of the triangles pushed next ([`SceneBuilder::set_role`]).
    role: Role,
    roles: Vec<Role>,
}

impl SceneBuilder {
    fn new(path: &Path) -> Self {
        Self {
            path: path.to_owned(),
            meshes: Vec::new(),
            triangles: Vec::new(),
            degenerate: 0,
            role: Role::Baked,
            roles: Vec::new(),
        }
    }

    /// The role the file gives the triangles pushed next.
    fn set_role(&mut self, role: Role) {
        self.role = role;
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
        if let Some(uv) = t.texture_uv
            && !uv.iter().all(|v| v.is_finite())
        {
            t.texture_uv = None;
        }
        if let Some(c) = t.colour
            && !c.iter().all(|v| v.is_finite())
        {
            t.colour = None;
        }
        let mesh = &mut self.meshes[t.mesh as usize];
        mesh.triangle_count += 1;
        if t.lightmap_uv.is_none() {
            mesh.has_lightmap_uvs = false;
        }
        self.triangles.push(t);
        self.roles.push(self.role);
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
            roles: if self.roles.iter().all(|&r| r == Role::Baked) {
                Vec::new()
            } else {
                self.roles
            },
        }
    }
}

pub mod fingerprint;
mod gltf;
pub mod gltf_write;
mod obj;
pub mod roles;
mod scene_file;
pub mod texture;

pub use roles::{Role, RoleReport, RoleRule};
pub use scene_file::{
    DEFAULT_SUN_IRRADIANCE, LightOverrides, SUN_RADIUS_DEG, SceneFile, SkySpec, SphereSpec,
    SunSpec, load_equirect, parse_sky, parse_sun,
};
pub use texture::{BaseColorTexture, TextureOptions};

/// [`crate::hash::fnv1a64`] built word by word (little-endian bytes), for
/// [`Scene::lighting_fingerprint`].
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Self(crate::hash::FNV1A64_EMPTY)
    }
}

impl Fnv {
    fn tag(&mut self, word: u64) -> &mut Self {
        self.0 = crate::hash::fnv1a64_more(self.0, &word.to_le_bytes());
        self
    }

    fn f(&mut self, x: f32) -> &mut Self {
        self.tag(u64::from(x.to_bits()))
    }

    fn vec(&mut self, v: Vec3) -> &mut Self {
        self.f(v.x).f(v.y).f(v.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The command line prints an error and then each `source()` as "caused by": an error
    /// whose message already holds its cause's text must not return it as its source too.
    #[test]
    fn no_scene_error_says_its_cause_twice() {
        use std::error::Error as _;
        let path = PathBuf::from("level.obj");
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        for e in [
            SceneError::Io {
                path: path.clone(),
                error: io(),
            },
            SceneError::Gltf {
                path: path.clone(),
                error: ::gltf::Error::Io(io()),
            },
            SceneError::Obj {
                path: path.clone(),
                error: tobj::LoadError::ReadError,
            },
        ] {
            let cause = match &e {
                SceneError::Io { error, .. } => error.to_string(),
                SceneError::Gltf { error, .. } => error.to_string(),
                SceneError::Obj { error, .. } => error.to_string(),
                _ => unreachable!(),
            };
            assert!(e.to_string().contains(&cause), "{e}");
            assert!(e.source().is_none(), "{e} also has a source");
        }
    }

    #[test]
    fn text_positions_count_lines_and_characters_from_one() {
        let text = "a = 1\nb = \"é\" x\n";
        let at = |offset| TextPos::of_offset(text, offset).to_string();
        assert_eq!(at(0), "1:1");
        assert_eq!(at(6), "2:1");
        // After the two-byte é: column 8 in characters, not 9 in bytes.
        assert_eq!(at(text.find(" x").unwrap()), "2:8");
        assert_eq!(at(usize::MAX), "3:1");
    }

    #[test]
    fn degenerate_triangles_are_dropped_and_counted() {
        let mut b = SceneBuilder::new(Path::new("x"));
        let id = b.begin_mesh("m".into());
        let t = |p: [Vec3; 3]| Triangle {
            positions: p,
            normals: [Vec3::ZERO; 3],
            lightmap_uv: None,
            texture_uv: None,
            colour: None,
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
