//! Bindings of our own to xatlas (Jonathan Young, MIT): the lightmap UV unwrapper Godot,
//! Unity's newer pipeline and the converted scenes here use. `vendor/README.md` says where
//! the C++ source comes from and why the crates.io package's bindings are not used.
//!
//! One [`Atlas`] takes meshes ([`Atlas::add_mesh`]), charts and parameterises them once
//! ([`Atlas::compute_charts`]) and packs them ([`Atlas::pack`]), as often as wanted with
//! other densities, or hands out the charts unpacked ([`Atlas::charts`]) for a packer of
//! the caller's. Built single-threaded: the same input gives the same output; separate
//! atlases may be used on separate threads at once.

use std::ffi::c_void;

unsafe extern "C" {
    fn gb_xatlas_create() -> *mut c_void;
    fn gb_xatlas_destroy(atlas: *mut c_void);
    fn gb_xatlas_add_mesh(
        atlas: *mut c_void,
        positions: *const f32,
        normals: *const f32,
        vertex_count: u32,
        indices: *const u32,
        index_count: u32,
    ) -> i32;
    fn gb_xatlas_compute_charts(atlas: *mut c_void);
    fn gb_xatlas_chart_uvs(
        atlas: *const c_void,
        mesh: u32,
        face_count: u32,
        face_chart: *mut u32,
        face_uv: *mut f32,
    ) -> u32;
    fn gb_xatlas_pack_charts(
        atlas: *mut c_void,
        texels_per_unit: f32,
        padding: u32,
        max_chart_size: u32,
    );
    fn gb_xatlas_summary(atlas: *const c_void, out: *mut u32);
    fn gb_xatlas_mesh_counts(atlas: *const c_void, mesh: u32, out: *mut u32);
    fn gb_xatlas_mesh_copy(
        atlas: *const c_void,
        mesh: u32,
        uv: *mut f32,
        xref: *mut u32,
        atlas_index: *mut i32,
        indices: *mut u32,
    );
}

/// Why xatlas refused a mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum AddMeshError {
    /// An index is not below the vertex count.
    #[error("an index is out of range")]
    IndexOutOfRange,
    /// The index count is not a multiple of 3.
    #[error("the index count is not a multiple of 3")]
    InvalidIndexCount,
    /// The arrays' lengths disagree, or a count does not fit in 32 bits.
    #[error("the position and normal arrays differ in length, or a count exceeds 2^32")]
    BadLengths,
}

/// Packing options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackOptions {
    /// Texels along one world unit.
    pub texels_per_unit: f32,
    /// Texels of padding xatlas dilates every chart by before placing it.
    pub padding: u32,
    /// Charts longer than this (texels) are scaled down to it.
    pub max_chart_size: u32,
}

/// One input mesh's output: vertices split where charts are cut.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputMesh {
    /// Per output vertex: UV in atlas texels (0..width, 0..height).
    pub uv: Vec<[f32; 2]>,
    /// Per output vertex: the input vertex it came from.
    pub xref: Vec<u32>,
    /// Per output vertex: the sub-atlas, −1 when xatlas left it out of every atlas.
    pub atlas_index: Vec<i32>,
    /// Output triangles (the input triangles, in input order).
    pub indices: Vec<u32>,
    /// Charts of this mesh.
    pub chart_count: u32,
}

/// A packed atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct Packed {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Sub-atlases (1 with the resizable single atlas packed here).
    pub atlas_count: u32,
    /// Charts over all meshes.
    pub chart_count: u32,
    /// One per [`Atlas::add_mesh`] call, in call order.
    pub meshes: Vec<OutputMesh>,
}

/// One input mesh's charts before packing ([`Atlas::charts`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Charts {
    /// Charts of the mesh.
    pub count: u32,
    /// Per input triangle: its chart (`0..count`), or `None` for a triangle in no chart
    /// (xatlas ignores triangles of area ≤ `FLT_EPSILON`).
    pub chart: Vec<Option<u32>>,
    /// Per input triangle: its three corners' UVs at one texel per world unit, in its chart's
    /// least-area bounding box (minimum corner at the origin) and scaled as xatlas's packer
    /// scales a chart (surface area over parametric area) before its size limit; zeros for a
    /// triangle in no chart. Not checked for being finite.
    pub uv: Vec<[[f32; 2]; 3]>,
}

/// An xatlas atlas (owns the C++ object).
#[derive(Debug)]
pub struct Atlas {
    handle: *mut c_void,
    /// Triangles per mesh added.
    triangles: Vec<u32>,
    charted: bool,
}

impl Default for Atlas {
    fn default() -> Self {
        Self::new()
    }
}

impl Atlas {
    /// An empty atlas.
    #[must_use]
    pub fn new() -> Self {
        // SAFETY: xatlas::Create allocates and returns a fresh atlas.
        Self {
            handle: unsafe { gb_xatlas_create() },
            triangles: Vec::new(),
            charted: false,
        }
    }

    /// Adds an indexed triangle mesh (xatlas copies the data).
    ///
    /// # Errors
    /// [`AddMeshError`] when xatlas refuses it or the slices disagree.
    pub fn add_mesh(
        &mut self,
        positions: &[[f32; 3]],
        normals: Option<&[[f32; 3]]>,
        indices: &[u32],
    ) -> Result<(), AddMeshError> {
        let n = u32::try_from(positions.len()).map_err(|_| AddMeshError::BadLengths)?;
        let ni = u32::try_from(indices.len()).map_err(|_| AddMeshError::BadLengths)?;
        if normals.is_some_and(|nm| nm.len() != positions.len()) {
            return Err(AddMeshError::BadLengths);
        }
        let normals = normals.map_or(std::ptr::null(), |nm| nm.as_ptr().cast::<f32>());
        // SAFETY: the pointers are valid for the counts given (checked above); xatlas copies.
        let e = unsafe {
            gb_xatlas_add_mesh(
                self.handle,
                positions.as_ptr().cast(),
                normals,
                n,
                indices.as_ptr(),
                ni,
            )
        };
        match e {
            0 => {
                self.triangles.push(ni / 3);
                self.charted = false;
                Ok(())
            }
            1 => Err(AddMeshError::IndexOutOfRange),
            _ => Err(AddMeshError::InvalidIndexCount),
        }
    }

    /// Charts and parameterises every mesh added (xatlas `ComputeCharts` and
    /// `ParameterizeCharts` with their default options).
    pub fn compute_charts(&mut self) {
        // SAFETY: a valid handle.
        unsafe { gb_xatlas_compute_charts(self.handle) }
        self.charted = !self.triangles.is_empty();
    }

    /// The charts of mesh `mesh` (in [`Atlas::add_mesh`] order) before packing, or `None`
    /// before [`Atlas::compute_charts`] or for a mesh not added.
    #[must_use]
    pub fn charts(&self, mesh: u32) -> Option<Charts> {
        let &n = self.triangles.get(mesh as usize)?;
        if !self.charted {
            return None;
        }
        let mut chart = vec![u32::MAX; n as usize];
        let mut uv = vec![[[0.0f32; 2]; 3]; n as usize];
        // SAFETY: a valid handle, charted; `mesh` was added with `n` triangles, and the
        // vectors hold `n` and `6 n` values, which is what gb_xatlas_chart_uvs writes.
        let count = unsafe {
            gb_xatlas_chart_uvs(
                self.handle,
                mesh,
                n,
                chart.as_mut_ptr(),
                uv.as_mut_ptr().cast(),
            )
        };
        Some(Charts {
            count,
            chart: chart
                .into_iter()
                .map(|c| (c < count).then_some(c))
                .collect(),
            uv,
        })
    }

    /// Packs the charts into one atlas as large as needed and returns the output meshes.
    #[must_use]
    pub fn pack(&mut self, options: PackOptions) -> Packed {
        let mut s = [0u32; 5];
        // SAFETY: a valid handle; `s` holds the 5 values gb_xatlas_summary writes.
        unsafe {
            gb_xatlas_pack_charts(
                self.handle,
                options.texels_per_unit,
                options.padding,
                options.max_chart_size,
            );
            gb_xatlas_summary(self.handle, s.as_mut_ptr());
        }
        let meshes = (0..s[4]).map(|m| self.output_mesh(m)).collect();
        Packed {
            width: s[0],
            height: s[1],
            atlas_count: s[2],
            chart_count: s[3],
            meshes,
        }
    }

    fn output_mesh(&self, mesh: u32) -> OutputMesh {
        let mut c = [0u32; 3];
        // SAFETY: `mesh` < meshCount (from the summary); the vectors have the sizes the
        // counts give, which is what gb_xatlas_mesh_copy writes.
        unsafe { gb_xatlas_mesh_counts(self.handle, mesh, c.as_mut_ptr()) };
        let (nv, ni) = (c[0] as usize, c[1] as usize);
        let mut out = OutputMesh {
            uv: vec![[0.0; 2]; nv],
            xref: vec![0; nv],
            atlas_index: vec![0; nv],
            indices: vec![0; ni],
            chart_count: c[2],
        };
        unsafe {
            gb_xatlas_mesh_copy(
                self.handle,
                mesh,
                out.uv.as_mut_ptr().cast(),
                out.xref.as_mut_ptr(),
                out.atlas_index.as_mut_ptr(),
                out.indices.as_mut_ptr(),
            );
        }
        out
    }
}

impl Drop for Atlas {
    fn drop(&mut self) {
        // SAFETY: the handle came from gb_xatlas_create and is destroyed once.
        unsafe { gb_xatlas_destroy(self.handle) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube with vertices shared between faces.
    fn cube() -> (Vec<[f32; 3]>, Vec<u32>) {
        let p = (0..8)
            .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
            .collect();
        #[rustfmt::skip]
        let idx = vec![
            0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
            2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5,
        ];
        (p, idx)
    }

    #[test]
    fn a_cube_unwraps_into_charts_inside_the_atlas() {
        let (p, idx) = cube();
        let mut a = Atlas::new();
        a.add_mesh(&p, None, &idx).unwrap();
        a.compute_charts();
        let opts = PackOptions {
            texels_per_unit: 16.0,
            padding: 2,
            max_chart_size: 4096,
        };
        let packed = a.pack(opts);
        assert_eq!(packed.meshes.len(), 1);
        let m = &packed.meshes[0];
        assert_eq!(m.indices.len(), idx.len());
        assert!(packed.chart_count >= 1 && m.chart_count == packed.chart_count);
        // Every output vertex comes from an input vertex at the same place, inside the atlas.
        for (uv, &x) in m.uv.iter().zip(&m.xref) {
            assert!((x as usize) < p.len());
            assert!(uv[0] >= 0.0 && uv[0] <= packed.width as f32, "{uv:?}");
            assert!(uv[1] >= 0.0 && uv[1] <= packed.height as f32, "{uv:?}");
        }
        for (t, (o, i)) in m.indices.iter().zip(&idx).enumerate() {
            assert_eq!(m.xref[*o as usize], *i, "corner {t}");
        }
        // Six unit faces at 16 texels per unit cover at least 6·16² texels.
        assert!(packed.width * packed.height >= 6 * 16 * 16);
        // Same input, same output.
        let mut b = Atlas::new();
        b.add_mesh(&p, None, &idx).unwrap();
        b.compute_charts();
        assert_eq!(b.pack(opts), packed);
    }

    #[test]
    fn charts_before_packing_cover_every_face_at_one_texel_per_unit() {
        let (p, idx) = cube();
        let mut a = Atlas::new();
        assert_eq!(a.charts(0), None);
        a.add_mesh(&p, None, &idx).unwrap();
        assert_eq!(a.charts(0), None, "not charted yet");
        a.compute_charts();
        assert_eq!(a.charts(1), None);
        let c = a.charts(0).unwrap();
        assert!(c.count >= 1);
        assert_eq!(c.chart.len(), 12);
        assert!(c.chart.iter().all(|k| k.is_some_and(|k| k < c.count)));
        // Each chart starts at the origin; the cube's six unit faces keep area 6 at one
        // texel per unit.
        let mut area = 0.0;
        for (k, uv) in c.uv.iter().enumerate() {
            let [a, b, d] = uv.map(|t| [f64::from(t[0]), f64::from(t[1])]);
            area += ((b[0] - a[0]) * (d[1] - a[1]) - (d[0] - a[0]) * (b[1] - a[1])).abs() / 2.0;
            assert!(
                uv.iter().flatten().all(|v| v.is_finite() && *v >= -1e-4),
                "{k}: {uv:?}"
            );
        }
        assert!((area - 6.0).abs() < 0.1, "{area}");
        for chart in 0..c.count {
            let lo = (0..12)
                .filter(|&t| c.chart[t] == Some(chart))
                .flat_map(|t| c.uv[t])
                .fold([f32::INFINITY; 2], |m, v| [m[0].min(v[0]), m[1].min(v[1])]);
            assert!(
                lo[0].abs() < 1e-4 && lo[1].abs() < 1e-4,
                "chart {chart}: {lo:?}"
            );
        }
    }

    #[test]
    fn bad_meshes_are_refused() {
        let (p, _) = cube();
        let mut a = Atlas::new();
        assert_eq!(
            a.add_mesh(&p, None, &[0, 1, 9]),
            Err(AddMeshError::IndexOutOfRange)
        );
        assert_eq!(
            a.add_mesh(&p, None, &[0, 1]),
            Err(AddMeshError::InvalidIndexCount)
        );
        let short = [[0.0; 3]; 2];
        assert_eq!(
            a.add_mesh(&p, Some(&short), &[0, 1, 2]),
            Err(AddMeshError::BadLengths)
        );
    }
}
