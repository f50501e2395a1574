//! Lightmap UVs for meshes that have none, from xatlas (crate `guidebake-xatlas`, our own
//! bindings to the C++ library, built with the system compiler; docs/texels.md, "Lightmap
//! UVs when a mesh has none").
//!
//! The paper (Silvennoinen & Sloan 2019, §2.1) starts from lightmap texels and so from a
//! UV layout; production bakers generate one when an asset has none (Unity's "Generate
//! Lightmap UVs", Godot's and Blender's lightmap unwrap, Bakery's xatlas option). Here:
//!
//! 1. **Weld.** A mesh is a world-space triangle soup ([`Scene::triangles`]); vertices whose
//!    position and normal are bit-identical are merged, so xatlas sees the mesh's
//!    connectivity (charts follow it) and hard edges (split normals) stay seams.
//! 2. **Chart** once ([`Charted::new`]): xatlas's region growing and parameterisation with
//!    its default options.
//! 3. **Pack** at a texel density ([`Charted::pack`]): xatlas scales every chart to the
//!    density, dilates it by [`PADDING`] texels and places it, so rasterised charts keep
//!    texels apart (the dilation of `bake` needs a gutter); charts longer than the page are
//!    scaled down to fit one.
//!
//! The result is, per triangle, its UV in texels of the atlas; `prepare` places atlases on
//! pages. The output triangles are the input ones in the same order (xatlas keeps them),
//! which the tests check. Deterministic: xatlas is built single-threaded and its packer's
//! random placement uses a fixed seed.

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec2;
use guidebake_xatlas::{AddMeshError, Atlas, PackOptions};

use crate::scene::Scene;

/// Texels xatlas dilates each chart by before placing it. The tests measure at least this
/// many empty texels between the texels of two charts on every scene here; xatlas's code
/// (2019) does not promise it on every side (docs/texels.md, "Not done / limits").
pub const PADDING: u32 = 2;

/// Triangles of at most this world area (xatlas skips those of area ≤ `FLT_EPSILON`,
/// computed its own way: twice that, for rounding) get no lightmap UVs and no texels.
pub const TINY_AREA: f32 = 2.0 * f32::EPSILON;

/// Which meshes get lightmap UVs from the unwrapper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Unwrap {
    /// None: meshes without `TEXCOORD_1` get no texels.
    Never,
    /// Meshes without `TEXCOORD_1`.
    #[default]
    Missing,
    /// All meshes (their `TEXCOORD_1` is ignored).
    Always,
}

impl Unwrap {
    /// Per mesh of `scene`: does it get UVs from the unwrapper?
    #[must_use]
    pub fn meshes(self, scene: &Scene) -> Vec<bool> {
        scene
            .meshes
            .iter()
            .map(|m| match self {
                Unwrap::Never => false,
                Unwrap::Missing => !m.has_lightmap_uvs,
                Unwrap::Always => m.triangle_count > 0,
            })
            .collect()
    }
}

/// Why a mesh could not be unwrapped. Every variant names the file and the mesh.
#[derive(Debug, thiserror::Error)]
pub enum UnwrapError {
    /// xatlas refused the mesh.
    #[error("{path}: mesh '{mesh}': xatlas cannot unwrap it: {source}")]
    Refused {
        /// The scene file.
        path: PathBuf,
        /// The mesh.
        mesh: String,
        /// xatlas's reason.
        source: AddMeshError,
    },
    /// A vertex of the mesh is not finite (NaN or ±∞): xatlas's packer would rasterise its
    /// chart without end.
    #[error(
        "{path}: mesh '{mesh}': triangle {triangle} has a vertex that is not finite: {position:?}"
    )]
    NonFinite {
        /// The scene file.
        path: PathBuf,
        /// The mesh.
        mesh: String,
        /// The triangle, as an index into the scene's triangles.
        triangle: usize,
        /// The vertex.
        position: [f32; 3],
    },
    /// xatlas left triangles out of every chart, or gave UVs that are not finite.
    #[error(
        "{path}: mesh '{mesh}': xatlas left {triangles} of its triangles without lightmap UVs \
         (degenerate or non-manifold geometry); give the mesh TEXCOORD_1 or fix its geometry"
    )]
    Unmapped {
        /// The scene file.
        path: PathBuf,
        /// The mesh.
        mesh: String,
        /// Triangles without UVs.
        triangles: usize,
    },
}

/// One mesh as xatlas takes it: welded vertices and their triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Welded {
    /// Vertex positions, world space.
    pub positions: Vec<[f32; 3]>,
    /// Vertex normals.
    pub normals: Vec<[f32; 3]>,
    /// Three per triangle, in [`Scene::triangles`] order.
    pub indices: Vec<u32>,
}

/// Merges the vertices of `mesh`'s triangles whose position and normal are bit-identical.
#[must_use]
pub fn weld(scene: &Scene, mesh: usize) -> Welded {
    let m = &scene.meshes[mesh];
    let tris = &scene.triangles[m.first_triangle as usize..][..m.triangle_count as usize];
    let mut ids = std::collections::HashMap::<[u32; 6], u32>::new();
    let mut w = Welded::default();
    for t in tris {
        for (p, n) in t.positions.iter().zip(&t.normals) {
            let key = [p.x, p.y, p.z, n.x, n.y, n.z].map(f32::to_bits);
            let next = w.positions.len() as u32;
            let id = *ids.entry(key).or_insert(next);
            if id == next {
                w.positions.push(p.to_array());
                w.normals.push(n.to_array());
            }
            w.indices.push(id);
        }
    }
    w
}

/// Meshes charted by xatlas, ready to be packed at any density.
pub struct Charted {
    atlas: Atlas,
    meshes: Vec<usize>,
    seconds: f64,
}

/// A packed atlas: per mesh, per triangle, UVs in texels of the atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct Packed {
    /// Atlas width in texels.
    pub width: u32,
    /// Atlas height in texels.
    pub height: u32,
    /// Charts in the atlas.
    pub charts: u32,
    /// `(mesh index, per triangle of the mesh its three UVs)`; `None` for the tiny
    /// triangles xatlas skips ([`TINY_AREA`]).
    pub meshes: Vec<(usize, Vec<Option<[Vec2; 3]>>)>,
}

impl Charted {
    /// Welds and charts `meshes` of `scene` (mesh indices) into one atlas.
    ///
    /// # Errors
    /// [`UnwrapError::NonFinite`] naming a mesh with a NaN or infinite vertex (before xatlas
    /// sees it: its packer then loops without end), [`UnwrapError::Refused`] naming the mesh
    /// xatlas refuses.
    pub fn new(scene: &Scene, meshes: &[usize]) -> Result<Self, UnwrapError> {
        let start = Instant::now();
        for &m in meshes {
            let mesh = &scene.meshes[m];
            let first = mesh.first_triangle as usize;
            let tris = &scene.triangles[first..][..mesh.triangle_count as usize];
            let bad = tris.iter().enumerate().find_map(|(k, t)| {
                let p = t.positions.iter().find(|p| !p.is_finite())?;
                Some((first + k, p.to_array()))
            });
            if let Some((triangle, position)) = bad {
                return Err(UnwrapError::NonFinite {
                    path: scene.path.clone(),
                    mesh: mesh.name.clone(),
                    triangle,
                    position,
                });
            }
        }
        let mut atlas = Atlas::new();
        for &m in meshes {
            let w = weld(scene, m);
            atlas
                .add_mesh(&w.positions, Some(&w.normals), &w.indices)
                .map_err(|source| UnwrapError::Refused {
                    path: scene.path.clone(),
                    mesh: scene.meshes[m].name.clone(),
                    source,
                })?;
        }
        atlas.compute_charts();
        Ok(Self {
            atlas,
            meshes: meshes.to_vec(),
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// Seconds spent in xatlas so far (charting and every packing).
    #[must_use]
    pub fn seconds(&self) -> f64 {
        self.seconds
    }

    /// Packs the charts at `texels_per_unit` into one atlas; charts longer than
    /// `max_chart` texels are scaled down to it.
    ///
    /// # Errors
    /// [`UnwrapError::Unmapped`] naming a mesh some of whose triangles xatlas left out of
    /// every chart or gave non-finite UVs.
    pub fn pack(
        &mut self,
        scene: &Scene,
        texels_per_unit: f32,
        max_chart: u32,
    ) -> Result<Packed, UnwrapError> {
        let start = Instant::now();
        let out = self.atlas.pack(PackOptions {
            texels_per_unit,
            padding: PADDING,
            max_chart_size: max_chart.saturating_sub(2 * PADDING + 2).max(1),
        });
        self.seconds += start.elapsed().as_secs_f64();
        let mut meshes = Vec::with_capacity(self.meshes.len());
        for (&m, om) in self.meshes.iter().zip(&out.meshes) {
            let first = scene.meshes[m].first_triangle as usize;
            let mut uvs = Vec::with_capacity(om.indices.len() / 3);
            let mut unmapped = 0;
            for (k, tri) in om.indices.chunks_exact(3).enumerate() {
                let mapped = tri.iter().all(|&v| {
                    let uv = om.uv[v as usize];
                    om.atlas_index[v as usize] >= 0 && uv.iter().all(|c| c.is_finite())
                });
                // xatlas skips triangles of area ≤ FLT_EPSILON (absolute, in its
                // `AddMesh`): those get no texels; any other triangle left out is an error.
                let tiny = scene
                    .triangles
                    .get(first + k)
                    .is_some_and(|t| t.area() <= TINY_AREA);
                unmapped += usize::from(!mapped && !tiny);
                uvs.push(mapped.then(|| [0, 1, 2].map(|c| Vec2::from(om.uv[tri[c] as usize]))));
            }
            let expected = scene.meshes[m].triangle_count as usize;
            let none = uvs.iter().all(Option::is_none);
            if unmapped > 0 || uvs.len() != expected || none {
                return Err(UnwrapError::Unmapped {
                    path: scene.path.clone(),
                    mesh: scene.meshes[m].name.clone(),
                    triangles: if none {
                        expected
                    } else {
                        unmapped.max(expected.abs_diff(uvs.len()))
                    },
                });
            }
            meshes.push((m, uvs));
        }
        Ok(Packed {
            width: out.width,
            height: out.height,
            charts: out.chart_count,
            meshes,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Material, Triangle};
    use glam::Vec3;

    fn quad_scene() -> Scene {
        let t = |p: [Vec3; 3]| Triangle {
            positions: p,
            normals: [Vec3::Z; 3],
            lightmap_uv: None,
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y);
        Scene::of_triangles(
            "quad",
            vec![t([a, b, c]), t([a, c, d])],
            vec![Material::default_grey()],
        )
    }

    #[test]
    fn welding_shares_identical_vertices_only() {
        let mut s = quad_scene();
        let w = weld(&s, 0);
        assert_eq!(w.positions.len(), 4);
        assert_eq!(w.indices, [0, 1, 2, 0, 2, 3]);
        // A different normal at a shared position is a seam.
        s.triangles[1].normals[0] = Vec3::X;
        assert_eq!(weld(&s, 0).positions.len(), 5);
    }

    /// `fuzz/corpus/prepare/degenerate-non-manifold-nan`: a NaN vertex reached xatlas, whose
    /// packer then rasterised the chart without end (`raster::drawTriangle`).
    #[test]
    fn non_finite_vertices_are_an_error_naming_the_mesh_before_xatlas_sees_them() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut s = quad_scene();
            s.triangles[1].positions[2].y = bad;
            let Err(e) = Charted::new(&s, &[0]) else {
                panic!("a vertex at {bad} was charted")
            };
            assert!(
                matches!(e, UnwrapError::NonFinite { triangle: 1, .. }),
                "{e}"
            );
            let message = e.to_string();
            assert!(
                message.contains("<quad>") && message.contains("mesh 'quad'"),
                "{message}"
            );
        }
    }

    #[test]
    fn a_quad_is_one_chart_at_the_requested_density() {
        let s = quad_scene();
        let mut c = Charted::new(&s, &[0]).unwrap();
        let p = c.pack(&s, 32.0, 4096).unwrap();
        assert_eq!(p.charts, 1);
        assert_eq!(p.meshes.len(), 1);
        assert_eq!(p.meshes[0].1.len(), 2);
        // A 1×1 quad at 32 texels per unit spans about 32 texels (plus padding).
        let uvs: Vec<Vec2> = p.meshes[0].1.iter().flatten().flatten().copied().collect();
        let lo = uvs.iter().fold(Vec2::INFINITY, |a, &b| a.min(b));
        let hi = uvs.iter().fold(Vec2::NEG_INFINITY, |a, &b| a.max(b));
        let extent = hi - lo;
        assert!(
            (extent.x - 32.0).abs() <= 2.0 && (extent.y - 32.0).abs() <= 2.0,
            "{extent}"
        );
        assert!(hi.x <= p.width as f32 && hi.y <= p.height as f32);
    }
}
