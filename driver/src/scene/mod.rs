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

mod error;
pub mod fingerprint;
pub mod glb;
mod gltf;
pub mod gltf_write;
mod lit;
mod load;
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

pub use error::{SceneError, TextPos};
pub(crate) use error::{looks_like, shown_absolute};
use load::SceneBuilder;

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
