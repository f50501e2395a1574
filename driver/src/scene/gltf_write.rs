//! `prepare --write-gltf`: the glTF scene written back as one binary glTF whose
//! `TEXCOORD_1` are the lightmap UVs the texels were made from, so an engine can bind the
//! baked lightmap (a lightmap is only usable with the UVs it was baked for).
//!
//! The source document is kept as it is — nodes, materials, textures, lights, extensions,
//! extras — and only mesh primitives are rewritten:
//! - Every triangle the loader kept is matched to its source triangle by its world-space
//!   positions (the loader drops degenerate triangles; they are dropped here too).
//! - A vertex is split wherever its triangles give it different lightmap UVs (xatlas cuts
//!   charts along seams); every attribute of the source vertex (normals, tangents, other UV
//!   sets, colours, joints, weights, morph targets) is copied to each of its copies.
//! - `TEXCOORD_1` is the page UV (0..1 across the page, v down as every glTF UV); the
//!   node's `extras` get `guidebake_lightmap: { page, width, height, scale, offset }`, since
//!   glTF has no field for it: the page's index and size in texels, and the transform from
//!   `TEXCOORD_1` to the page's UV, `uv · scale + offset` — `[1, 1]` and `[0, 0]`, as the UVs
//!   are written in page space already (an engine that packs lightmaps again, as Unity's
//!   `lightmapScaleOffset` does, changes these, not the UVs). The document's own `extras`
//!   get `guidebake_lightmap: { pages: [{ width, height }], texcoord: 1 }`: how many pages
//!   there are (one glb for all of them: page N is the bake's `OUT.pageN.exr`, or `OUT.exr`
//!   where there is one page; docs/engines.md).
//! - A mesh instanced by several nodes gets a copy per further node (each instance has its
//!   own place in the lightmap); a mesh instance without texels is left as it is.
//! - All buffers, and images stored as files beside the source, go into the GLB's one
//!   binary chunk, so the output stands alone; an image file that cannot be read (a level
//!   without its texture pack) keeps its URI as the source had it, and every primitive keeps
//!   its texture UVs (`TEXCOORD_0`) whatever textures are missing.
//!
//! Loading the written file gives the same triangles in the same order with these UVs, so
//! `prepare --unwrap never` of it rasterises the same texels (driver/tests/unwrap.rs).
//!
//! **A scene from an OBJ** (directly or through a TOML scene file) has no glTF document to
//! keep: [`write_glb`] writes a new one ([`write_new`]; docs/levels.md, "Write the level
//! back for the engine"): a node and a mesh per scene mesh, a primitive per run of
//! triangles of one material, vertices welded where every attribute agrees — `POSITION`,
//! `NORMAL` (the loader's, so reloading gives the same ones), `TEXCOORD_0` (the texture UVs,
//! v down as glTF has them) wherever the triangles have UVs of their own, textured or not (a
//! level whose texture pack is missing keeps the UVs the pack needs: an OBJ's one UV set,
//! which the loader keeps as the triangles' own UVs when no texture was read), `TEXCOORD_1`
//! the lightmap's page UVs; materials as `baseColorFactor` (the fallback colour where a
//! texture was missing), the base-colour image embedded as it is (PNG or JPEG) and emission (with
//! `KHR_materials_emissive_strength` above 1); a camera node where one is given
//! ([`GlbCamera`]: `guidebake demo`'s view, which `render` and `view` then both start from).
//! The sun, the sky and sphere lights of a TOML file are not written: glTF has no sky; keep
//! the scene file (or the flags) for them.
//!
//! Both write through [`super::glb`], the one glb container writer (the binary chunk, its
//! views and accessors, the file's framing), which `synth`'s city uses too.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use ::gltf::json;
use glam::{Mat4, Vec2, Vec3};

use super::glb::{self, GlbBuffer};
use super::{Scene, SceneError};

/// Why the scene could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The scene did not come from a glTF or OBJ file.
    #[error("{path}: --write-gltf needs a .gltf, .glb or .obj scene")]
    NotGltf {
        /// The scene file.
        path: PathBuf,
    },
    /// Reading the source again failed.
    #[error(transparent)]
    Source(#[from] SceneError),
    /// A primitive uses something the writer does not rewrite.
    #[error("{path}: mesh '{mesh}': {message}")]
    Unsupported {
        /// The scene file.
        path: PathBuf,
        /// The mesh.
        mesh: String,
        /// What is not supported.
        message: String,
    },
    /// Writing the output failed.
    #[error("{path}: cannot write: {message}")]
    Write {
        /// The output file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// Where every triangle's texels are: the layout `prepare` rasterised, as UVs of the page
/// (0..1 across it) — what `--write-gltf` writes as `TEXCOORD_1`. Made by `prepare`
/// ([`crate::prepare`]: `Lightmap::of_texel_file`), defined here with the writer that reads it.
#[derive(Clone, Debug, PartialEq)]
pub struct Lightmap {
    /// Page sizes in texels.
    pub pages: Vec<(u32, u32)>,
    /// Per mesh: its page.
    pub mesh_page: Vec<u32>,
    /// Per triangle: its UVs on its mesh's page, `None` where it has no texels.
    pub uv: Vec<Option<[Vec2; 3]>>,
}

/// Writes `scene` (loaded from a glTF file) with `lightmap`'s UVs as `TEXCOORD_1` to `out`
/// as a binary glTF. Nothing is left at `out` on failure.
///
/// # Errors
/// [`WriteError`] naming the file (and mesh) at fault.
pub fn write_glb(scene: &Scene, lightmap: &Lightmap, out: &Path) -> Result<(), WriteError> {
    let path = &scene.path;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("gltf" | "glb") => {}
        Some("obj") => return write_new(scene, lightmap, out),
        _ => return Err(WriteError::NotGltf { path: path.clone() }),
    }
    let (doc, buffers) = super::gltf::import(path)?;
    let mut w = Writer {
        scene,
        lightmap,
        root: doc.as_json().clone(),
        bin: GlbBuffer::default(),
    };
    w.consolidate_buffers(&buffers, path.parent().unwrap_or(Path::new(".")))?;
    w.rewrite_meshes(&doc, &buffers)?;
    set_extra(&mut w.root.extras, pages_extra(lightmap));
    w.finish(out)
}

struct Writer<'a> {
    scene: &'a Scene,
    lightmap: &'a Lightmap,
    root: json::Root,
    /// The binary chunk; its views are the document's (`root.buffer_views`), not its own.
    bin: GlbBuffer,
}

/// One source triangle the loader kept: its corners (source vertex indices, in source
/// winding) and their lightmap UVs.
type Corners = [(u32, Option<[f32; 2]>); 3];

impl Writer<'_> {
    fn unsupported(&self, mesh: u32, message: String) -> WriteError {
        WriteError::Unsupported {
            path: self.scene.path.clone(),
            mesh: self.scene.meshes[mesh as usize].name.clone(),
            message,
        }
    }

    /// Appends `bytes` to the binary chunk (4-byte aligned) as a new buffer view.
    fn push_view(&mut self, bytes: &[u8], stride: Option<usize>, target: Option<u32>) -> u32 {
        let offset = self.bin.append(bytes);
        let view = glb::view(offset, bytes.len(), stride, target);
        let view: json::buffer::View = serde_json::from_value(view).expect("a valid view");
        self.root.buffer_views.push(view);
        (self.root.buffer_views.len() - 1) as u32
    }

    /// Moves every buffer into the one binary chunk, and images stored as files beside the
    /// source into buffer views.
    fn consolidate_buffers(
        &mut self,
        buffers: &[::gltf::buffer::Data],
        base: &Path,
    ) -> Result<(), WriteError> {
        let mut starts = Vec::with_capacity(buffers.len());
        for b in buffers {
            starts.push(self.bin.append(&b.0) as u64);
        }
        for view in &mut self.root.buffer_views {
            let start = starts[view.buffer.value()];
            view.byte_offset = Some((view.byte_offset.map_or(0, |o| o.0) + start).into());
            view.buffer = json::Index::new(0);
        }
        for i in 0..self.root.images.len() {
            let Some(uri) = self.root.images[i].uri.clone() else {
                continue;
            };
            if uri.starts_with("data:") {
                continue;
            }
            let file = base.join(urlencoding::decode(&uri).map_or(uri.clone(), |u| u.into_owned()));
            // An image that cannot be read (a level without its texture pack: the loader
            // warned and baked the material's colour) keeps its URI, as the source had it,
            // and its primitives keep their texture UVs, so the pack can be added later.
            let Ok(bytes) = std::fs::read(&file) else {
                continue;
            };
            let mime = if bytes.starts_with(b"\x89PNG") {
                "image/png"
            } else {
                "image/jpeg"
            };
            let view = self.push_view(&bytes, None, None);
            let image = &mut self.root.images[i];
            image.uri = None;
            image.buffer_view = Some(json::Index::new(view));
            image.mime_type = Some(json::image::MimeType(mime.into()));
        }
        Ok(())
    }

    /// Walks the nodes as the loader does and rewrites every mesh instance's primitives.
    fn rewrite_meshes(
        &mut self,
        doc: &::gltf::Document,
        buffers: &[::gltf::buffer::Data],
    ) -> Result<(), WriteError> {
        let mut next_mesh = 0u32;
        let mut rewritten = vec![false; self.root.meshes.len()];
        for (node, world) in super::gltf::nodes_in_load_order(doc) {
            if let Some(mesh) = node.mesh() {
                let id = next_mesh;
                next_mesh += 1;
                if id as usize >= self.scene.meshes.len() {
                    return Err(self.changed(next_mesh));
                }
                if self.without_texels(id) {
                    // No lightmap place: the mesh stays as the source has it.
                    continue;
                }
                let primitives = self.mesh_corners(id, &mesh, buffers, world)?;
                let new = self.rewrite_mesh(id, &mesh, buffers, &primitives)?;
                let index = if rewritten[mesh.index()] {
                    self.root.meshes.push(new);
                    self.root.meshes.len() - 1
                } else {
                    rewritten[mesh.index()] = true;
                    self.root.meshes[mesh.index()] = new;
                    mesh.index()
                };
                let page = self.lightmap.mesh_page[id as usize];
                let node_json = &mut self.root.nodes[node.index()];
                node_json.mesh = Some(json::Index::new(index as u32));
                set_extra(&mut node_json.extras, mesh_extra(self.lightmap, page));
            }
        }
        if next_mesh as usize != self.scene.meshes.len() {
            return Err(self.changed(next_mesh));
        }
        Ok(())
    }

    /// The source no longer has the scene's mesh instances (changed since it was loaded).
    fn changed(&self, instances: u32) -> WriteError {
        WriteError::Write {
            path: self.scene.path.clone(),
            message: format!(
                "the file has {instances} or more mesh instances but the scene loaded from it {}",
                self.scene.meshes.len()
            ),
        }
    }

    /// Whether mesh instance `id` has no texels (no lightmap UVs at all).
    fn without_texels(&self, id: u32) -> bool {
        let m = &self.scene.meshes[id as usize];
        self.lightmap.uv[m.first_triangle as usize..][..m.triangle_count as usize]
            .iter()
            .all(Option::is_none)
    }

    /// Per primitive of mesh instance `id`: the kept triangles' corners, matched to the
    /// scene's triangles by world positions (as the loader computes them).
    fn mesh_corners(
        &self,
        id: u32,
        mesh: &::gltf::Mesh,
        buffers: &[::gltf::buffer::Data],
        world: Mat4,
    ) -> Result<Vec<Vec<Corners>>, WriteError> {
        let m = &self.scene.meshes[id as usize];
        let tris = &self.scene.triangles[m.first_triangle as usize..][..m.triangle_count as usize];
        let uvs = &self.lightmap.uv[m.first_triangle as usize..][..m.triangle_count as usize];
        let mirrored = glam::Mat3::from_mat4(world).determinant() < 0.0;
        let mut next = 0usize;
        let mut out = Vec::new();
        for prim in mesh.primitives() {
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.0.as_slice()));
            let positions: Vec<Vec3> = reader
                .read_positions()
                .map(|p| p.map(|p| world.transform_point3(Vec3::from(p))).collect())
                .unwrap_or_default();
            let count = positions.len() as u32;
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..count).collect(),
            };
            let mut corners = Vec::with_capacity(indices.len() / 3);
            for tri in indices.chunks_exact(3) {
                let mut v = [tri[0], tri[1], tri[2]];
                if mirrored {
                    v.swap(1, 2);
                }
                let p = v.map(|i| positions[i as usize]);
                if next < tris.len() && tris[next].positions == p {
                    let uv = uvs[next].map(|q| q.map(|v| v.to_array()));
                    let mut c = [0, 1, 2].map(|k| (v[k], uv.map(|q| q[k])));
                    if mirrored {
                        c.swap(1, 2);
                    }
                    corners.push(c);
                    next += 1;
                }
            }
            out.push(corners);
        }
        if next != tris.len() {
            return Err(self.unsupported(
                id,
                format!(
                    "{next} of its {} triangles were found again in the file",
                    tris.len()
                ),
            ));
        }
        Ok(out)
    }

    /// The mesh with its primitives rewritten: vertices split by lightmap UV, every
    /// attribute copied, `TEXCOORD_1` and 32-bit indices new.
    fn rewrite_mesh(
        &mut self,
        id: u32,
        mesh: &::gltf::Mesh,
        buffers: &[::gltf::buffer::Data],
        primitives: &[Vec<Corners>],
    ) -> Result<json::Mesh, WriteError> {
        let mut new = self.root.meshes[mesh.index()].clone();
        for ((prim, corners), prim_json) in
            mesh.primitives().zip(primitives).zip(&mut new.primitives)
        {
            let mut vertices: Vec<(u32, [f32; 2])> = Vec::new();
            let mut ids: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
            let mut indices: Vec<u32> = Vec::with_capacity(corners.len() * 3);
            for (v, uv) in corners.iter().flatten() {
                let uv = uv.unwrap_or([0.0; 2]);
                let key = (*v, uv.map(f32::to_bits));
                let next = vertices.len() as u32;
                let id = *ids.entry(key).or_insert(next);
                if id == next {
                    vertices.push((*v, uv));
                }
                indices.push(id);
            }
            let sources: Vec<u32> = vertices.iter().map(|v| v.0).collect();
            let mut attributes = std::collections::BTreeMap::new();
            for (semantic, accessor) in prim.attributes() {
                if semantic == ::gltf::Semantic::TexCoords(1) {
                    continue;
                }
                let is_position = semantic == ::gltf::Semantic::Positions;
                let a = self.remap_accessor(id, &accessor, buffers, &sources, is_position)?;
                attributes.insert(json::validation::Checked::Valid(semantic), a);
            }
            let uv_bytes: Vec<u8> = vertices
                .iter()
                .flat_map(|v| v.1)
                .flat_map(f32::to_le_bytes)
                .collect();
            let uv_view = self.push_view(&uv_bytes, None, Some(json::buffer::ARRAY_BUFFER));
            let uv = self.push_accessor(serde_json::json!({
                "bufferView": uv_view, "componentType": json::accessor::FLOAT,
                "count": vertices.len(), "type": "VEC2",
            }));
            attributes.insert(
                json::validation::Checked::Valid(json::mesh::Semantic::TexCoords(1)),
                uv,
            );
            let index_bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
            let index_view =
                self.push_view(&index_bytes, None, Some(json::buffer::ELEMENT_ARRAY_BUFFER));
            let index = self.push_accessor(serde_json::json!({
                "bufferView": index_view, "componentType": json::accessor::UNSIGNED_INT,
                "count": indices.len(), "type": "SCALAR",
            }));
            let mut targets = Vec::new();
            for target in prim.morph_targets() {
                let mut t = json::mesh::MorphTarget {
                    positions: None,
                    normals: None,
                    tangents: None,
                };
                if let Some(a) = target.positions() {
                    t.positions = Some(self.remap_accessor(id, &a, buffers, &sources, false)?);
                }
                if let Some(a) = target.normals() {
                    t.normals = Some(self.remap_accessor(id, &a, buffers, &sources, false)?);
                }
                if let Some(a) = target.tangents() {
                    t.tangents = Some(self.remap_accessor(id, &a, buffers, &sources, false)?);
                }
                targets.push(t);
            }
            prim_json.attributes = attributes;
            prim_json.indices = Some(index);
            prim_json.targets = (!targets.is_empty()).then_some(targets);
        }
        Ok(new)
    }

    fn push_accessor(&mut self, value: serde_json::Value) -> json::Index<json::Accessor> {
        let a: json::Accessor = serde_json::from_value(value).expect("a valid accessor");
        self.root.accessors.push(a);
        json::Index::new((self.root.accessors.len() - 1) as u32)
    }

    /// A new accessor holding `accessor`'s elements at `sources`, tightly packed (each
    /// element padded to 4 bytes, as vertex attributes must be).
    fn remap_accessor(
        &mut self,
        id: u32,
        accessor: &::gltf::Accessor,
        buffers: &[::gltf::buffer::Data],
        sources: &[u32],
        with_bounds: bool,
    ) -> Result<json::Index<json::Accessor>, WriteError> {
        let (Some(view), None) = (accessor.view(), accessor.sparse()) else {
            return Err(self.unsupported(
                id,
                format!(
                    "accessor {} is sparse or has no buffer view, which --write-gltf does not rewrite",
                    accessor.index()
                ),
            ));
        };
        let size = accessor.size();
        let stride = view.stride().unwrap_or(size);
        let data = &buffers[view.buffer().index()].0;
        let start = view.offset() + accessor.offset();
        let padded = size.next_multiple_of(4);
        let mut bytes = Vec::with_capacity(sources.len() * padded);
        for &s in sources {
            let at = start + s as usize * stride;
            let element = data.get(at..at + size).ok_or_else(|| {
                self.unsupported(
                    id,
                    format!("accessor {} runs past its buffer", accessor.index()),
                )
            })?;
            bytes.extend_from_slice(element);
            bytes.resize(bytes.len() + padded - size, 0);
        }
        let new_view = self.push_view(
            &bytes,
            (padded != size).then_some(padded),
            Some(json::buffer::ARRAY_BUFFER),
        );
        let mut a = self.root.accessors[accessor.index()].clone();
        a.buffer_view = Some(json::Index::new(new_view));
        a.byte_offset = None;
        a.count = sources.len().into();
        a.sparse = None;
        a.min = None;
        a.max = None;
        if with_bounds {
            let (lo, hi) = float3_bounds(&bytes, padded);
            a.min = Some(serde_json::json!(lo));
            a.max = Some(serde_json::json!(hi));
        }
        self.root.accessors.push(a);
        Ok(json::Index::new((self.root.accessors.len() - 1) as u32))
    }

    /// One buffer (the binary chunk), the JSON, written atomically.
    fn finish(mut self, out: &Path) -> Result<(), WriteError> {
        let (bin, _) = self.bin.finish();
        let buffer: json::Buffer =
            serde_json::from_value(serde_json::json!({ "byteLength": bin.len() }))
                .expect("a valid buffer");
        self.root.buffers = vec![buffer];
        let write_error = |message: String| WriteError::Write {
            path: out.to_owned(),
            message,
        };
        let json = self.root.to_vec().map_err(|e| write_error(e.to_string()))?;
        glb::write(out, json, &bin).map_err(|e| write_error(e.to_string()))
    }
}

/// Per-component min and max of packed `f32` VEC3 elements `stride` bytes apart.
fn float3_bounds(bytes: &[u8], stride: usize) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for e in bytes.chunks_exact(stride) {
        for k in 0..3 {
            let v = f32::from_le_bytes(e[4 * k..4 * k + 4].try_into().expect("4 bytes"));
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    (lo, hi)
}

/// The key of the lightmap binding in a node's and in the document's `extras`.
pub const EXTRAS_KEY: &str = "guidebake_lightmap";

/// A mesh instance's lightmap binding (module docs): its page, the page's size, and the
/// transform from `TEXCOORD_1` to the page's UV (identity: the UVs are page UVs).
fn mesh_extra(lightmap: &Lightmap, page: u32) -> serde_json::Value {
    let (width, height) = lightmap.pages[page as usize];
    serde_json::json!({
        "page": page, "width": width, "height": height,
        "scale": [1.0, 1.0], "offset": [0.0, 0.0],
    })
}

/// The document's lightmap description: the pages' sizes and the UV set they use.
fn pages_extra(lightmap: &Lightmap) -> serde_json::Value {
    let pages: Vec<_> = lightmap
        .pages
        .iter()
        .map(|&(width, height)| serde_json::json!({ "width": width, "height": height }))
        .collect();
    serde_json::json!({ "pages": pages, "texcoord": 1 })
}

/// Sets `extras.guidebake_lightmap` to `value`, keeping other extras of an object.
fn set_extra(extras: &mut json::Extras, value: serde_json::Value) {
    let mut object = extras
        .as_ref()
        .and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok())
        .filter(serde_json::Value::is_object)
        .unwrap_or_else(|| serde_json::json!({}));
    object[EXTRAS_KEY] = value;
    *extras = serde_json::value::to_raw_value(&object).ok();
}

/// A perspective camera to write into a new glb ([`write_new_with_camera`]): where it
/// stands, where it looks, which way is up, its vertical field of view (radians) and the
/// width / height it asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlbCamera {
    /// Eye position.
    pub eye: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit up vector, orthogonal to `forward`.
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub yfov: f32,
    /// Width / height.
    pub aspect: f32,
}

impl GlbCamera {
    /// The camera's node and camera objects: glTF cameras look along their local −Z with
    /// +Y up, so the node's rotation takes (X, Y, −Z) to (right, up, forward).
    fn to_json(self) -> (serde_json::Value, serde_json::Value) {
        let right = self.forward.cross(self.up).normalize();
        let up = right.cross(self.forward).normalize();
        let q = glam::Quat::from_mat3(&glam::Mat3::from_cols(right, up, -self.forward)).normalize();
        let node = serde_json::json!({
            "name": "camera",
            "camera": 0,
            "translation": self.eye.to_array(),
            "rotation": q.to_array(),
        });
        let camera = serde_json::json!({
            "type": "perspective",
            "perspective": { "yfov": self.yfov, "aspectRatio": self.aspect, "znear": 0.01 },
        });
        (node, camera)
    }
}

/// Writes `scene` (from an OBJ: no source document to keep) as a new binary glTF with
/// `lightmap`'s UVs as `TEXCOORD_1` (module docs). Nothing is left at `out` on failure.
///
/// # Errors
/// [`WriteError::Write`] naming `out` (or a texture file that can no longer be read).
pub fn write_new(scene: &Scene, lightmap: &Lightmap, out: &Path) -> Result<(), WriteError> {
    write_new_with_camera(scene, lightmap, None, out)
}

/// [`write_new`], with `camera` as the document's first camera where one is given (a scene
/// made in code, whose view `render` and `view` should share).
///
/// # Errors
/// As [`write_new`].
pub fn write_new_with_camera(
    scene: &Scene,
    lightmap: &Lightmap,
    camera: Option<GlbCamera>,
    out: &Path,
) -> Result<(), WriteError> {
    use serde_json::{Value, json};
    let write_error = |message: String| WriteError::Write {
        path: out.to_owned(),
        message,
    };
    use glb::{ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, UNSIGNED_INT};
    let mut buffer = GlbBuffer::default();
    let mut accessors: Vec<Value> = Vec::new();

    // Materials, their base-colour images embedded once each.
    let mut images: Vec<Value> = Vec::new();
    let mut image_of: HashMap<String, usize> = HashMap::new();
    let mut materials: Vec<Value> = Vec::new();
    let mut emissive_strength = false;
    for m in &scene.materials {
        let mut pbr = json!({ "metallicFactor": 0.0, "roughnessFactor": 1.0 });
        let colour = match &m.base_color_texture {
            Some(t) => {
                let source = &t.image.source;
                let index = match image_of.get(source) {
                    Some(&i) => i,
                    None => {
                        let bytes = std::fs::read(source)
                            .map_err(|e| write_error(format!("texture {source}: {e}")))?;
                        let mime = if bytes.starts_with(b"\x89PNG") {
                            "image/png"
                        } else if bytes.starts_with(&[0xFF, 0xD8]) {
                            "image/jpeg"
                        } else {
                            return Err(write_error(format!(
                                "texture {source}: neither PNG nor JPEG, which glTF needs"
                            )));
                        };
                        let view = buffer.push_view(&bytes, None, None);
                        images.push(json!({ "bufferView": view, "mimeType": mime }));
                        image_of.insert(source.clone(), images.len() - 1);
                        images.len() - 1
                    }
                };
                pbr["baseColorTexture"] = json!({ "index": index, "texCoord": 0 });
                t.factor.clamp(Vec3::ZERO, Vec3::ONE)
            }
            None => m.albedo,
        };
        pbr["baseColorFactor"] = json!([colour.x, colour.y, colour.z, 1.0]);
        let mut material = json!({ "name": m.name, "pbrMetallicRoughness": pbr });
        let e = m.emission;
        if e.max_element() > 0.0 {
            let strength = e.max_element().max(1.0);
            let f = e / strength;
            material["emissiveFactor"] = json!([f.x, f.y, f.z]);
            if strength > 1.0 {
                emissive_strength = true;
                material["extensions"] = json!({
                    "KHR_materials_emissive_strength": { "emissiveStrength": strength }
                });
            }
        }
        materials.push(material);
    }
    // One texture per image, repeating (OBJ textures tile).
    let textures: Vec<Value> = (0..images.len())
        .map(|i| json!({ "source": i, "sampler": 0 }))
        .collect();

    let mut meshes: Vec<Value> = Vec::new();
    let mut nodes: Vec<Value> = Vec::new();
    let mut cameras: Vec<Value> = Vec::new();
    for (id, mesh) in scene.meshes.iter().enumerate() {
        let first = mesh.first_triangle as usize;
        let range = first..first + mesh.triangle_count as usize;
        let with_texels = lightmap.uv[range.clone()].iter().any(Option::is_some);
        let mut primitives: Vec<Value> = Vec::new();
        let mut start = range.start;
        while start < range.end {
            let material = scene.triangles[start].material;
            let mut end = start + 1;
            while end < range.end && scene.triangles[end].material == material {
                end += 1;
            }
            let run = &scene.triangles[start..end];
            // The texture's UVs; where no texture was read, the triangles' own UVs (an OBJ's
            // one UV set, which the loader keeps as `lightmap_uv`), v turned down as the
            // loader turns a textured OBJ's.
            let texture_uv = |t: &super::Triangle| {
                t.texture_uv.or_else(|| {
                    t.lightmap_uv
                        .map(|q| q.map(|v| glam::Vec2::new(v.x, 1.0 - v.y)))
                })
            };
            let textured = run.iter().all(|t| texture_uv(t).is_some());
            // Vertices welded where every attribute written agrees (by bits).
            let mut index_of: HashMap<[u32; 12], u32> = HashMap::new();
            let (mut pos, mut nor, mut uv0, mut uv1) = (vec![], vec![], vec![], vec![]);
            let mut indices: Vec<u32> = Vec::with_capacity(3 * run.len());
            for (k, t) in run.iter().enumerate() {
                let lm = lightmap.uv[start + k];
                for c in 0..3 {
                    let p = t.positions[c];
                    let n = t.normals[c];
                    let a = texture_uv(t).map_or(glam::Vec2::ZERO, |q| q[c]);
                    let b = lm.map_or(glam::Vec2::ZERO, |q| q[c]);
                    let key = [p.x, p.y, p.z, n.x, n.y, n.z, a.x, a.y, b.x, b.y, 0.0, 0.0]
                        .map(f32::to_bits);
                    let next = index_of.len() as u32;
                    let i = *index_of.entry(key).or_insert_with(|| {
                        pos.push(p);
                        nor.push(n);
                        uv0.push(a);
                        uv1.push(b);
                        next
                    });
                    indices.push(i);
                }
            }
            let floats =
                |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
            let (lo, hi) = pos.iter().fold(
                (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(*p), hi.max(*p)),
            );
            let count = pos.len();
            let mut attribute = |bytes: Vec<u8>, kind: &str, minmax: Option<(Vec3, Vec3)>| {
                let view = buffer.push_view(&bytes, None, Some(ARRAY_BUFFER));
                let bounds = minmax.map(|(lo, hi)| (lo.to_array(), hi.to_array()));
                accessors.push(glb::accessor(view, FLOAT, count, kind, bounds));
                accessors.len() - 1
            };
            let flat3 =
                |v: &[Vec3]| floats(&v.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>());
            let flat2 =
                |v: &[glam::Vec2]| floats(&v.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>());
            let mut attributes = serde_json::Map::new();
            attributes.insert(
                "POSITION".into(),
                attribute(flat3(&pos), "VEC3", Some((lo, hi))).into(),
            );
            attributes.insert("NORMAL".into(), attribute(flat3(&nor), "VEC3", None).into());
            if textured {
                attributes.insert(
                    "TEXCOORD_0".into(),
                    attribute(flat2(&uv0), "VEC2", None).into(),
                );
            }
            if with_texels {
                attributes.insert(
                    "TEXCOORD_1".into(),
                    attribute(flat2(&uv1), "VEC2", None).into(),
                );
            }
            let bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
            let view = buffer.push_view(&bytes, None, Some(ELEMENT_ARRAY_BUFFER));
            accessors.push(glb::accessor(
                view,
                UNSIGNED_INT,
                indices.len(),
                "SCALAR",
                None,
            ));
            primitives.push(json!({
                "attributes": attributes,
                "indices": accessors.len() - 1,
                "material": material,
                "mode": 4,
            }));
            start = end;
        }
        meshes.push(json!({ "name": mesh.name, "primitives": primitives }));
        let mut node = json!({ "name": mesh.name, "mesh": id });
        let mut extras = serde_json::Map::new();
        if with_texels {
            extras.insert(
                EXTRAS_KEY.into(),
                mesh_extra(lightmap, lightmap.mesh_page[id]),
            );
        }
        // The mesh's role, where all its triangles share one but `baked` (`roles`), so the
        // glb prepares as the OBJ did.
        let first = mesh.first_triangle as usize;
        let roles: Vec<_> = (first..first + mesh.triangle_count as usize)
            .map(|t| scene.role(t))
            .collect();
        if let Some(&role) = roles.first()
            && role != super::Role::Baked
            && roles.iter().all(|&r| r == role)
        {
            extras.insert(super::roles::EXTRAS_KEY.into(), json!(role.name()));
        }
        if !extras.is_empty() {
            node["extras"] = extras.into();
        }
        nodes.push(node);
    }
    let (bin, views) = buffer.finish();
    if let Some(camera) = camera {
        let (node, camera) = camera.to_json();
        nodes.push(node);
        cameras.push(camera);
    }
    let mut root = json!({
        "asset": { "version": "2.0", "generator": "guidebake prepare --write-gltf" },
        "scene": 0,
        "scenes": [{ "nodes": (0..nodes.len()).collect::<Vec<_>>() }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{ "byteLength": bin.len() }],
    });
    if !images.is_empty() {
        root["images"] = images.into();
        root["textures"] = textures.into();
        root["samplers"] = json!([{ "wrapS": 10497, "wrapT": 10497 }]);
    }
    root["extras"] = json!({});
    root["extras"][EXTRAS_KEY] = pages_extra(lightmap);
    if !cameras.is_empty() {
        root["cameras"] = cameras.into();
    }
    if emissive_strength {
        root["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
    }
    let json = serde_json::to_vec(&root).map_err(|e| write_error(e.to_string()))?;
    glb::write(out, json, &bin).map_err(|e| write_error(e.to_string()))
}
