//! Lightmap UVs for meshes that have none, from xatlas (crate `guidebake-xatlas`, our own
//! bindings to the C++ library, built with the system compiler; docs/texels.md, "Lightmap
//! UVs when a mesh has none").
//!
//! The paper (Silvennoinen & Sloan 2019, §2.1) starts from lightmap texels and so from a
//! UV layout; production bakers generate one when an asset has none (Unity's "Generate
//! Lightmap UVs", Godot's and Blender's lightmap unwrap, Bakery's xatlas option). Here:
//!
//! 1. **Chunk.** Each mesh is cut into spatial chunks of at most [`CHUNK_TRIANGLES`]
//!    triangles ([`chunk::median_cut`] over triangle centroids); a smaller mesh is one
//!    chunk. Edges between chunks become chart seams.
//! 2. **Weld.** A chunk's triangles (a world-space triangle soup, [`Scene::triangles`]) are
//!    welded where position and normal are bit-identical, so xatlas sees the connectivity
//!    (charts follow it) and hard edges (split normals) stay seams.
//! 3. **Chart** once ([`Charted::new`]): every chunk in an xatlas atlas of its own, on
//!    every core (rayon), with xatlas's region growing and parameterisation at its default
//!    options. Only each triangle's chart and chart-local UVs are kept (28 bytes a
//!    triangle); the chunk's atlas is dropped, so xatlas's memory is bounded by the chunk
//!    size times the threads, whatever the triangle count.
//! 4. **Pack** at a texel density ([`Charted::pack`], [`super::pack`]): every chart scaled to the
//!    density as xatlas scales it, then placed by a skyline packer of our own that keeps
//!    at least [`PADDING`] empty texels between the texels of two charts (the dilation of
//!    `bake` needs a gutter); charts longer than the page are scaled down to fit one.
//!
//! The result is, per triangle, its UV in texels of the atlas; `prepare` places atlases on
//! pages. The output triangles are the input ones in the same order, which the tests
//! check. Deterministic: chunks are cut and charts numbered in a fixed order, xatlas is
//! built single-threaded, and packing is sequential: the same bytes for any thread count.

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec2;
use guidebake_xatlas::{AddMeshError, Atlas};
use rayon::prelude::*;

use crate::scene::Scene;

use super::pack::pack_charts;

pub mod chunk;

/// Empty texels the packer keeps between the texels of two charts, on every side
/// ([`super::pack`]); the tests measure it on every scene here.
pub const PADDING: u32 = 2;

/// Triangles in one xatlas atlas at most: a bigger mesh is charted in spatial chunks
/// ([`chunk::median_cut`]) of 1/2 to 1 times this. xatlas (with `vendor/README.md`'s
/// hash-map fix) peaks at about 1.2 kB a triangle while charting a game level (docs/texels.md,
/// "Unwrapping big meshes"), so a chunk stays near 20 MB per thread.
pub const CHUNK_TRIANGLES: usize = 16_384;

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
        // A mesh whose every triangle's role has no texels (a sky shell) gets no UVs.
        scene
            .meshes
            .iter()
            .map(|m| match self {
                Unwrap::Never => false,
                Unwrap::Missing => !m.has_lightmap_uvs && scene.mesh_has_texels(m),
                Unwrap::Always => m.triangle_count > 0 && scene.mesh_has_texels(m),
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
    weld_triangles(
        scene,
        m.first_triangle as usize..(m.first_triangle + m.triangle_count) as usize,
    )
}

/// Merges the vertices of the triangles `tris` (indices into [`Scene::triangles`], in this
/// order) whose position and normal are bit-identical.
#[must_use]
pub fn weld_triangles(scene: &Scene, tris: impl IntoIterator<Item = usize>) -> Welded {
    let mut ids = std::collections::HashMap::<[u32; 6], u32>::new();
    let mut w = Welded::default();
    for t in tris {
        let t = &scene.triangles[t];
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

/// No chart: a triangle xatlas skipped (or gave UVs that are not finite).
const NO_CHART: u32 = u32::MAX;

/// Meshes charted by xatlas chunk by chunk, ready to be packed at any density.
pub struct Charted {
    meshes: Vec<usize>,
    /// Per triangle of `meshes` (mesh after mesh, each in its order): its chart, or
    /// [`NO_CHART`].
    chart: Vec<u32>,
    /// Per triangle: its UVs at one texel per unit in its chart ([`guidebake_xatlas::Charts`]).
    uv: Vec<[Vec2; 3]>,
    charts: u32,
    chunks: usize,
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

/// One chunk's charts: per triangle of the chunk, its chart (numbered within the chunk)
/// and UVs.
struct ChunkCharts {
    count: u32,
    chart: Vec<u32>,
    uv: Vec<[Vec2; 3]>,
}

impl Charted {
    /// Welds and charts `meshes` of `scene` (mesh indices), chunk by chunk
    /// ([`CHUNK_TRIANGLES`]) on rayon's threads.
    ///
    /// # Errors
    /// [`UnwrapError::NonFinite`] naming a mesh with a NaN or infinite vertex (before xatlas
    /// sees it: its packer then loops without end), [`UnwrapError::Refused`] naming the mesh
    /// xatlas refuses.
    pub fn new(scene: &Scene, meshes: &[usize]) -> Result<Self, UnwrapError> {
        Self::with_chunks(scene, meshes, CHUNK_TRIANGLES)
    }

    /// [`Charted::new`] with chunks of at most `chunk_triangles` triangles (≥ 1).
    ///
    /// # Errors
    /// As [`Charted::new`].
    pub fn with_chunks(
        scene: &Scene,
        meshes: &[usize],
        chunk_triangles: usize,
    ) -> Result<Self, UnwrapError> {
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
        // Chunks: (position in `meshes`, the mesh's triangles, local indices).
        let mut work: Vec<(usize, Vec<u32>)> = Vec::new();
        for (i, &m) in meshes.iter().enumerate() {
            let mesh = &scene.meshes[m];
            let first = mesh.first_triangle as usize;
            // Its triangles that get texels (`scene::roles`), as indices within the mesh.
            let keep: Vec<u32> = (0..mesh.triangle_count)
                .filter(|&k| scene.role(first + k as usize).has_texels())
                .collect();
            if keep.is_empty() {
                continue;
            }
            if keep.len() <= chunk_triangles {
                work.push((i, keep));
                continue;
            }
            let centroids: Vec<[f32; 3]> = keep
                .iter()
                .map(|&k| {
                    let t = &scene.triangles[first + k as usize];
                    ((t.positions[0] + t.positions[1] + t.positions[2]) / 3.0).to_array()
                })
                .collect();
            for c in chunk::median_cut(&centroids, chunk_triangles) {
                work.push((i, c.into_iter().map(|j| keep[j as usize]).collect()));
            }
        }
        let results: Vec<Result<ChunkCharts, UnwrapError>> = work
            .par_iter()
            .map(|(i, tris)| chart_chunk(scene, meshes[*i], tris))
            .collect();
        let mut base = Vec::with_capacity(meshes.len() + 1);
        base.push(0usize);
        for &m in meshes {
            base.push(base.last().copied().unwrap_or(0) + scene.meshes[m].triangle_count as usize);
        }
        let total = base.last().copied().unwrap_or(0);
        let mut chart = vec![NO_CHART; total];
        let mut uv = vec![[Vec2::ZERO; 3]; total];
        let mut charts = 0u32;
        let chunks = work.len();
        for ((i, tris), r) in work.into_iter().zip(results) {
            let c = r?;
            for (k, &t) in tris.iter().enumerate() {
                let at = base[i] + t as usize;
                if c.chart[k] != NO_CHART {
                    chart[at] = charts + c.chart[k];
                    uv[at] = c.uv[k];
                }
            }
            charts += c.count;
        }
        Ok(Self {
            meshes: meshes.to_vec(),
            chart,
            uv,
            charts,
            chunks,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// Seconds spent charting and packing so far.
    #[must_use]
    pub fn seconds(&self) -> f64 {
        self.seconds
    }

    /// Charts over all meshes.
    #[must_use]
    pub fn charts(&self) -> u32 {
        self.charts
    }

    /// Chunks charted (one xatlas atlas each).
    #[must_use]
    pub fn chunks(&self) -> usize {
        self.chunks
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
        let layout = pack_charts(
            &self.uv,
            &self.chart,
            self.charts,
            texels_per_unit,
            max_chart.saturating_sub(2 * PADDING + 2).max(1),
            PADDING,
        );
        self.seconds += start.elapsed().as_secs_f64();
        let mut meshes = Vec::with_capacity(self.meshes.len());
        let mut at = 0;
        for &m in &self.meshes {
            let mesh = &scene.meshes[m];
            let first = mesh.first_triangle as usize;
            let n = mesh.triangle_count as usize;
            let mut uvs = Vec::with_capacity(n);
            let mut unmapped = 0;
            for k in 0..n {
                let mapped = self.chart[at + k] != NO_CHART;
                // xatlas skips triangles of area ≤ FLT_EPSILON (absolute, in its
                // `AddMesh`): those get no texels; any other triangle left out is an error.
                let tiny = scene.triangles[first + k].area() <= TINY_AREA;
                unmapped += usize::from(!mapped && !tiny);
                uvs.push(mapped.then(|| layout.uv[at + k]));
            }
            at += n;
            if unmapped > 0 || uvs.iter().all(Option::is_none) {
                return Err(UnwrapError::Unmapped {
                    path: scene.path.clone(),
                    mesh: mesh.name.clone(),
                    triangles: if unmapped > 0 { unmapped } else { n },
                });
            }
            meshes.push((m, uvs));
        }
        Ok(Packed {
            width: layout.width,
            height: layout.height,
            charts: self.charts,
            meshes,
        })
    }
}

/// Welds and charts one chunk (`tris`: indices into mesh `mesh`'s triangles) in an xatlas
/// atlas of its own, keeps each triangle's chart and UVs, and drops the atlas. A chart
/// with a UV that is not finite is dropped (its triangles are then unmapped).
fn chart_chunk(scene: &Scene, mesh: usize, tris: &[u32]) -> Result<ChunkCharts, UnwrapError> {
    let first = scene.meshes[mesh].first_triangle as usize;
    let w = weld_triangles(scene, tris.iter().map(|&t| first + t as usize));
    let mut atlas = Atlas::new();
    atlas
        .add_mesh(&w.positions, Some(&w.normals), &w.indices)
        .map_err(|source| UnwrapError::Refused {
            path: scene.path.clone(),
            mesh: scene.meshes[mesh].name.clone(),
            source,
        })?;
    drop(w);
    atlas.compute_charts();
    let c = atlas.charts(0).unwrap_or(guidebake_xatlas::Charts {
        count: 0,
        chart: vec![None; tris.len()],
        uv: vec![[[0.0; 2]; 3]; tris.len()],
    });
    drop(atlas);
    let mut bad = vec![false; c.count as usize];
    for (k, q) in c.chart.iter().zip(&c.uv) {
        if let Some(k) = k
            && !q.iter().flatten().all(|v| v.is_finite())
        {
            bad[*k as usize] = true;
        }
    }
    Ok(ChunkCharts {
        count: c.count,
        chart: c
            .chart
            .iter()
            .map(|k| k.filter(|&k| !bad[k as usize]).unwrap_or(NO_CHART))
            .collect(),
        uv: c.uv.iter().map(|q| q.map(Vec2::from)).collect(),
    })
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

    /// A mesh's triangles appended to `scene` as a new mesh.
    fn push_mesh(scene: &mut Scene, name: &str, tris: Vec<([Vec3; 3], [Vec3; 3])>) {
        let mesh = scene.meshes.len() as u32;
        scene.meshes.push(crate::scene::Mesh {
            name: name.into(),
            first_triangle: scene.triangles.len() as u32,
            triangle_count: tris.len() as u32,
            has_lightmap_uvs: false,
        });
        scene
            .triangles
            .extend(tris.into_iter().map(|(positions, normals)| Triangle {
                positions,
                normals,
                lightmap_uv: None,
                texture_uv: None,
                colour: None,
                mesh,
                material: 0,
            }));
    }

    /// A bumpy n×n terrain (smooth normals) and boxes whose faces are 6×6 grids of quads
    /// (flat normals): meshes big enough to be cut into chunks.
    fn world(n: usize, boxes: usize) -> Scene {
        let mut s = quad_scene();
        let h = |x: f32, y: f32| 0.4 * (x * 0.7).sin() * (y * 0.5).cos();
        let p = |x: usize, y: usize| {
            let (x, y) = (x as f32 * 0.5, y as f32 * 0.5);
            Vec3::new(x, y, h(x, y))
        };
        let nrm = |v: Vec3| {
            let dx = 0.4 * 0.7 * (v.x * 0.7).cos() * (v.y * 0.5).cos();
            let dy = -0.4 * 0.5 * (v.x * 0.7).sin() * (v.y * 0.5).sin();
            Vec3::new(-dx, -dy, 1.0).normalize()
        };
        let mut tris = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let q = [p(x, y), p(x + 1, y), p(x + 1, y + 1), p(x, y + 1)];
                for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                    tris.push((t, t.map(nrm)));
                }
            }
        }
        push_mesh(&mut s, "terrain", tris);
        let mut tris = Vec::new();
        for b in 0..boxes {
            let o = Vec3::new(2.0 * b as f32, -3.0, 0.0);
            for (c, u, v) in crate::test_support::inward_box_faces(o, 1.5) {
                let n = u.cross(v).normalize();
                for j in 0..6 {
                    for i in 0..6 {
                        let at =
                            |a: usize, b: usize| c + u * (a as f32 / 6.0) + v * (b as f32 / 6.0);
                        let q = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                        tris.push(([q[0], q[1], q[2]], [n; 3]));
                        tris.push(([q[0], q[2], q[3]], [n; 3]));
                    }
                }
            }
        }
        push_mesh(&mut s, "boxes", tris);
        s
    }

    fn packed_on(threads: usize, s: &Scene, chunk: usize, density: f32) -> (usize, Packed) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut c = Charted::with_chunks(s, &[0, 1, 2], chunk).unwrap();
            (c.chunks(), c.pack(s, density, 4096).unwrap())
        })
    }

    #[test]
    fn chunks_give_the_same_atlas_on_any_thread_count() {
        let s = world(40, 3);
        let (chunks, one) = packed_on(1, &s, 400, 6.0);
        assert!(chunks >= 10, "{chunks} chunks");
        for threads in [2, 3, 5] {
            assert_eq!(packed_on(threads, &s, 400, 6.0).1, one, "{threads} threads");
        }
        // Not the same as one chunk per mesh: the chunk seams are charts' edges.
        let (whole, p) = packed_on(2, &s, usize::MAX, 6.0);
        assert_eq!(whole, 3);
        assert!(one.charts > p.charts, "{} vs {}", one.charts, p.charts);
    }

    #[test]
    fn chunked_triangles_keep_their_order_and_shape() {
        // The boxes' faces are flat: each chart is an isometry of its triangles, scaled to
        // the density and stretched to whole texels (by less than a texel over the chart,
        // whose smallest is one triangle of 5 texels' legs here).
        let s = world(8, 4);
        let d = 20.0;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let (c, p) = pool.install(|| {
            let mut c = Charted::with_chunks(&s, &[0, 1, 2], 100).unwrap();
            let p = c.pack(&s, d, 4096).unwrap();
            (c, p)
        });
        assert!(c.chunks() >= 8, "{}", c.chunks());
        assert_eq!(p.meshes.iter().map(|m| m.0).collect::<Vec<_>>(), [0, 1, 2]);
        // Corners of one chart at one world position share one UV: a triangle whose UVs
        // were another's would tear its chart.
        let mut corner = std::collections::HashMap::<(u32, [u32; 3]), Vec2>::new();
        let mut at = 0;
        for (m, uvs) in &p.meshes {
            let mesh = &s.meshes[*m];
            assert_eq!(uvs.len(), mesh.triangle_count as usize);
            for (k, q) in uvs.iter().enumerate() {
                let t = &s.triangles[mesh.first_triangle as usize + k];
                let chart = c.chart[at];
                at += 1;
                let q = q.unwrap_or_else(|| panic!("mesh {m} triangle {k} unmapped"));
                for (v, pos) in q.iter().zip(t.positions) {
                    assert!(v.x >= 0.0 && v.y >= 0.0);
                    assert!(v.x <= p.width as f32 && v.y <= p.height as f32);
                    let key = (chart, pos.to_array().map(f32::to_bits));
                    let seen = *corner.entry(key).or_insert(*v);
                    assert!(
                        (seen - *v).length() < 1e-3,
                        "mesh {m} triangle {k}: {seen} vs {v}"
                    );
                }
                if *m != 2 {
                    continue;
                }
                for (a, b) in [(0, 1), (1, 2), (2, 0)] {
                    let world = (t.positions[a] - t.positions[b]).length() * d;
                    let ratio = (q[a] - q[b]).length() / world;
                    assert!(
                        (0.995..1.21).contains(&ratio),
                        "triangle {k} edge {a}{b}: {ratio} texels per texel of density"
                    );
                }
            }
        }
    }

    #[test]
    fn chunked_charts_keep_the_padding_between_them() {
        let s = world(24, 2);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let (c, p) = pool.install(|| {
            let mut c = Charted::with_chunks(&s, &[0, 1, 2], 300).unwrap();
            let p = c.pack(&s, 8.0, 4096).unwrap();
            (c, p)
        });
        let uvs = p.meshes.iter().flat_map(|(_, uvs)| uvs).map(|q| q.unwrap());
        crate::prepare::pack::tests::assert_charts_apart(
            c.chart.iter().copied().zip(uvs),
            PADDING,
            "chunked",
        );
        assert!(c.charts() > 10, "{} charts", c.charts());
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
