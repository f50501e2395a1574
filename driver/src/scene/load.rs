//! Loading a scene from its file: the format by extension (glTF, OBJ, a TOML scene file),
//! the light flags that replace its sun and sky, what the loader noted, and the builder the
//! parsers fill (degenerate triangles dropped).

use std::path::{Path, PathBuf};

use glam::Vec3;

use super::error::read_head;
use super::*;

impl Scene {
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

    pub(super) fn load_noting(
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
}

/// Accumulates meshes and triangles while a source is read; drops degenerate triangles.
pub(super) struct SceneBuilder {
    pub(super) path: PathBuf,
    meshes: Vec<Mesh>,
    triangles: Vec<Triangle>,
    degenerate: usize,
    /// The role of the triangles pushed next ([`SceneBuilder::set_role`]).
    role: Role,
    roles: Vec<Role>,
}

impl SceneBuilder {
    pub(super) fn new(path: &Path) -> Self {
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
    pub(super) fn set_role(&mut self, role: Role) {
        self.role = role;
    }

    pub(super) fn begin_mesh(&mut self, name: String) -> u32 {
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
    pub(super) fn push(&mut self, mut t: Triangle) {
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

    pub(super) fn bad_mesh(&self, mesh: u32, message: String) -> SceneError {
        SceneError::BadMesh {
            path: self.path.clone(),
            mesh: self.meshes[mesh as usize].name.clone(),
            message,
        }
    }

    pub(super) fn finish(self, materials: Vec<Material>, lights: Vec<SceneLight>) -> Scene {
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
