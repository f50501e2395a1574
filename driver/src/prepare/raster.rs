//! Rasterisation (steps 2–5 of [`super`]'s list; paper §2.1 assumes its texels): texel
//! centres inside a triangle, the conservative pass for partial texels, each texel's
//! record (position, normal, footprint axes), the triangle table, and the tiles written in
//! Morton order.

use std::path::Path;

use glam::{Vec2, Vec3};
use guidebake_kernels::presort::CurveOrder;
use rayon::prelude::*;

use super::facing::{Visibility, seen_sides};
use crate::scene::{Scene, Triangle};
use crate::texels::{
    FLAG_INSIDE, FLAG_PARTIAL, FLAG_VALID, PageRecord, TILE_SIZE, TexelRecord, TexelWriter,
    TileRect, TriangleRecord,
};

use super::*;

/// Rasterises `scene`'s lightmap UVs through the layout `pages` and `meshes` into `out`.
pub(super) fn rasterise(
    scene: &Scene,
    out: &Path,
    pages: &[PageRecord],
    meshes: &[MeshLayout],
    tpu: f32,
    per_mesh: bool,
    stage: &mut dyn FnMut(PrepareStage),
) -> Result<PrepareReport, PrepareError> {
    stage(PrepareStage::SeenSides {
        triangles: scene.triangles.len(),
    });
    let (visibility, facing) = seen_sides(scene).map_err(|e| PrepareError::Resolution {
        path: scene.path.clone(),
        message: format!("cannot trace the scene to orient its surfaces: {e}"),
    })?;
    let mut shell =
        shell::find_shell(scene, &visibility).map_err(|e| PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!("cannot trace the scene to look for a shell around it: {e}"),
        })?;
    let triangles = triangle_records(scene, meshes, visibility.sides());
    let mut w = TexelWriter::create(out, pages, &triangles, tpu)?;
    w.set_lighting(scene.lighting_fingerprint());
    w.set_geometry(scene.geometry_fingerprint());
    let mut report = PrepareReport {
        texels: 0,
        partial_texels: 0,
        tiles: 0,
        pages: pages.iter().map(|p| (p.width, p.height)).collect(),
        per_mesh_layout: per_mesh,
        texels_per_unit: tpu,
        meshes_without_lightmap_uvs: scene
            .meshes_without_lightmap_uvs()
            .into_iter()
            .map(str::to_owned)
            .collect(),
        uv_degenerate_triangles: 0,
        inside_texels: 0,
        flipped_triangles: triangles.iter().filter(|t| t.texels_face_back()).count() as u64,
        facing,
        unwrap: None,
        not_atlas: Vec::new(),
        missing_textures: Vec::new(),
        roles: crate::scene::RoleReport::default(),
        shell: None,
    };
    for (page_index, page) in pages.iter().enumerate() {
        stage(PrepareStage::Rasterising {
            page: page_index,
            pages: pages.len(),
        });
        let raster = PageRaster::new(&triangles, page_index as u32, *page, &mut report);
        if let Some(shell) = &mut shell {
            let (on, all) = raster.texels_of(&shell.mask);
            shell.texels += on;
            shell.atlas_texels += all;
        }
        raster.emit_tiles(scene, &triangles, &visibility, &mut w, &mut report)?;
    }
    if report.texels == 0 {
        return Err(PrepareError::NoTexels {
            path: scene.path.clone(),
        });
    }
    w.finish()?;
    report.shell = shell;
    Ok(report)
}

/// Calls `f(x, y)` for every pixel whose centre lies inside (or on) the triangle `q`.
pub(super) fn for_each_centre(q: &[Vec2; 3], size: (u32, u32), mut f: impl FnMut(u32, u32)) {
    let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let (x0, x1, y0, y1) = pixel_range(q, size);
    for y in y0..y1 {
        for x in x0..x1 {
            let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            if barycentric(q, c, area).iter().all(|&l| l >= 0.0) {
                f(x, y);
            }
        }
    }
}

/// Pixel index ranges `[x0, x1) × [y0, y1)` of the triangle's bounding box, clipped.
pub(super) fn pixel_range(q: &[Vec2; 3], size: (u32, u32)) -> (u32, u32, u32, u32) {
    let lo = q[0].min(q[1]).min(q[2]);
    let hi = q[0].max(q[1]).max(q[2]);
    let clip = |v: f32, n: u32| v.clamp(0.0, n as f32) as u32;
    (
        clip(lo.x.floor(), size.0),
        clip(hi.x.floor() + 1.0, size.0),
        clip(lo.y.floor(), size.1),
        clip(hi.y.floor() + 1.0, size.1),
    )
}

/// Barycentrics of `c` in the 2D triangle `q` whose doubled signed area is `area`.
pub(super) fn barycentric(q: &[Vec2; 3], c: Vec2, area: f32) -> [f32; 3] {
    let l0 = (q[1] - c).perp_dot(q[2] - c) / area;
    let l1 = (q[2] - c).perp_dot(q[0] - c) / area;
    [l0, l1, 1.0 - l0 - l1]
}

/// Separating-axis test: does the triangle overlap the open unit square at (x, y)?
pub(super) fn overlaps_square(q: &[Vec2; 3], x: u32, y: u32) -> bool {
    let lo = Vec2::new(x as f32, y as f32);
    let corners = [lo, lo + Vec2::X, lo + Vec2::ONE, lo + Vec2::Y];
    let (tlo, thi) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
    if thi.x <= lo.x || thi.y <= lo.y || tlo.x >= lo.x + 1.0 || tlo.y >= lo.y + 1.0 {
        return false;
    }
    for i in 0..3 {
        let e = q[(i + 1) % 3] - q[i];
        let n = e.perp();
        let tri = [q[0].dot(n), q[1].dot(n), q[2].dot(n)];
        let (tmin, tmax) = (
            tri[0].min(tri[1]).min(tri[2]),
            tri[0].max(tri[1]).max(tri[2]),
        );
        let sq = corners.map(|c| c.dot(n));
        let (smin, smax) = (
            sq[0].min(sq[1]).min(sq[2]).min(sq[3]),
            sq[0].max(sq[1]).max(sq[2]).max(sq[3]),
        );
        if smax <= tmin || smin >= tmax {
            return false;
        }
    }
    true
}

/// Closest point of the 2D triangle `q` to `c`, as clamped barycentrics.
pub(super) fn closest_barycentric(q: &[Vec2; 3], c: Vec2, area: f32) -> [f32; 3] {
    let b = barycentric(q, c, area);
    if b.iter().all(|&l| l >= 0.0) {
        return b;
    }
    let mut best = ([1.0, 0.0, 0.0], f32::INFINITY);
    for i in 0..3 {
        let (a, e) = (q[i], q[(i + 1) % 3] - q[i]);
        let t = ((c - a).dot(e) / e.length_squared().max(1e-30)).clamp(0.0, 1.0);
        let d = (a + e * t).distance_squared(c);
        if d < best.1 {
            let mut l = [0.0; 3];
            l[i] = 1.0 - t;
            l[(i + 1) % 3] = t;
            best = (l, d);
        }
    }
    best.0
}

/// A triangle's UVs in page pixel coordinates.
pub(super) fn pixel_uv(t: &Triangle, m: &MeshLayout) -> Option<[Vec2; 3]> {
    let (s, o) = (Vec2::from(m.uv_scale), Vec2::from(m.uv_offset));
    t.lightmap_uv.map(|uv| uv.map(|v| v * s + o))
}

/// The texel file's triangle table: each triangle's UVs through its mesh's layout (where the
/// mesh has texels) and the sides it is seen from (`sides`, [`Visibility::sides`]).
pub(super) fn triangle_records(
    scene: &Scene,
    meshes: &[MeshLayout],
    sides: &[u32],
) -> Vec<TriangleRecord> {
    scene
        .triangles
        .iter()
        .zip(sides)
        .enumerate()
        .map(|(i, (t, &seen))| {
            let m = &meshes[t.mesh as usize];
            let role = scene.role(i);
            let record = match pixel_uv(t, m).filter(|_| m.flags != 0 && role.has_texels()) {
                Some(q) if q.iter().all(|v| v.is_finite()) => {
                    TriangleRecord::lightmapped(m.page, q, seen)
                }
                _ => TriangleRecord::unmapped(seen),
            };
            record.with_role(role)
        })
        .collect()
}

/// Ownership grid of one page: `triangle + 1` (0 empty), high bit = partial.
pub(super) struct PageRaster {
    page: u32,
    size: PageRecord,
    owner: Vec<u32>,
}

impl PageRaster {
    /// Texels of the page owned by a triangle `mask` names, and texels in all.
    fn texels_of(&self, mask: &[bool]) -> (u64, u64) {
        self.owner
            .iter()
            .filter(|&&o| o != 0)
            .fold((0, 0), |(on, all), &o| {
                let t = ((o & !PARTIAL_BIT) - 1) as usize;
                (
                    on + u64::from(mask.get(t).copied().unwrap_or(false)),
                    all + 1,
                )
            })
    }
}

impl PageRaster {
    fn new(
        triangles: &[TriangleRecord],
        page: u32,
        size: PageRecord,
        report: &mut PrepareReport,
    ) -> Self {
        let dims = (size.width, size.height);
        let mut owner = vec![0u32; size.width as usize * size.height as usize];
        // The page's triangles in pixel space, once for both passes; UV-degenerate ones counted.
        let mut on_page: Vec<(u32, [Vec2; 3])> = Vec::new();
        for (i, t) in triangles.iter().enumerate() {
            let Some((_, q)) = t.pixel_uv().filter(|&(p, _)| p == page) else {
                continue;
            };
            let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
            if area == 0.0 || !area.is_finite() {
                report.uv_degenerate_triangles += 1;
                continue;
            }
            on_page.push((i as u32 + 1, q));
        }
        // Pass 1: texel centres covered by a triangle (the first triangle wins).
        for &(id, q) in &on_page {
            for_each_centre(&q, dims, |x, y| {
                let o = &mut owner[y as usize * size.width as usize + x as usize];
                if *o == 0 {
                    *o = id;
                }
            });
        }
        // Pass 2: texels left empty that a triangle still overlaps, marked partial.
        for &(id, q) in &on_page {
            let (x0, x1, y0, y1) = pixel_range(&q, dims);
            for y in y0..y1 {
                for x in x0..x1 {
                    let o = &mut owner[y as usize * size.width as usize + x as usize];
                    if *o == 0 && overlaps_square(&q, x, y) {
                        *o = id | PARTIAL_BIT;
                    }
                }
            }
        }
        Self { page, size, owner }
    }

    fn emit_tiles(
        &self,
        scene: &Scene,
        triangles: &[TriangleRecord],
        visibility: &Visibility,
        w: &mut TexelWriter,
        report: &mut PrepareReport,
    ) -> Result<(), PrepareError> {
        let (tw, th) = (
            self.size.width.div_ceil(TILE_SIZE),
            self.size.height.div_ceil(TILE_SIZE),
        );
        let mut order: Vec<(u64, u32, u32)> = (0..th)
            .flat_map(|ty| (0..tw).map(move |tx| (CurveOrder::Morton.key([tx, ty]), tx, ty)))
            .collect();
        order.sort_unstable();
        let mut buf = Vec::with_capacity((TILE_SIZE * TILE_SIZE) as usize);
        for (_, tx, ty) in order {
            let rect = TileRect {
                page: self.page,
                x: tx * TILE_SIZE,
                y: ty * TILE_SIZE,
                width: TILE_SIZE.min(self.size.width - tx * TILE_SIZE),
                height: TILE_SIZE.min(self.size.height - ty * TILE_SIZE),
            };
            buf.clear();
            for y in rect.y..rect.y + rect.height {
                for x in rect.x..rect.x + rect.width {
                    let o = self.owner[y as usize * self.size.width as usize + x as usize];
                    if o == 0 {
                        continue;
                    }
                    let tri = (o & !PARTIAL_BIT) - 1;
                    let partial = o & PARTIAL_BIT != 0;
                    let record = texel_record(scene, triangles, self.page, tri, x, y, partial);
                    buf.push(record);
                    report.partial_texels += u64::from(partial);
                }
            }
            buf.par_iter_mut().for_each(|t| {
                if visibility.inside_geometry(t) {
                    t.flags = (t.flags & !FLAG_VALID) | FLAG_INSIDE;
                }
            });
            report.inside_texels +=
                buf.iter().filter(|t| t.flags & FLAG_INSIDE != 0).count() as u64;
            if !buf.is_empty() {
                w.push_tile(rect, &buf)?;
                report.tiles += 1;
                report.texels += buf.len() as u64;
            }
        }
        Ok(())
    }
}

/// The record of texel (x, y) owned by triangle `tri`: its normal on the side the triangle is
/// seen from ([`TriangleRecord::texels_face_back`]).
pub(super) fn texel_record(
    scene: &Scene,
    triangles: &[TriangleRecord],
    page: u32,
    tri: u32,
    x: u32,
    y: u32,
    partial: bool,
) -> TexelRecord {
    let t = &scene.triangles[tri as usize];
    let record = &triangles[tri as usize];
    let q = record.pixel_uv().map_or([Vec2::ZERO; 3], |(_, q)| q);
    let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
    let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let l = clamp_barycentric(closest_barycentric(&q, c, area));
    let p = t.positions;
    let position = p[0] * l[0] + p[1] * l[1] + p[2] * l[2];
    let geometric = t.geometric_normal();
    let side = if record.texels_face_back() { -1.0 } else { 1.0 };
    let n = (t.normals[0] * l[0] + t.normals[1] * l[1] + t.normals[2] * l[2])
        .normalize_or(geometric)
        * side;
    // dP/dq = [p1-p0, p2-p0] · [q1-q0, q2-q0]^-1
    let (e1, e2) = (q[1] - q[0], q[2] - q[0]);
    let (f1, f2) = (p[1] - p[0], p[2] - p[0]);
    let inv = 1.0 / area;
    let dpdu = (f1 * e2.y - f2 * e1.y) * inv;
    let dpdv = (f2 * e1.x - f1 * e2.x) * inv;
    let finite_or_zero = |v: Vec3| if v.is_finite() { v } else { Vec3::ZERO };
    TexelRecord {
        position: position.to_array(),
        normal: n.to_array(),
        dpdu: finite_or_zero(dpdu).to_array(),
        dpdv: finite_or_zero(dpdv).to_array(),
        page,
        pixel: [x as u16, y as u16],
        triangle: tri,
        flags: FLAG_VALID | if partial { FLAG_PARTIAL } else { 0 },
    }
}

/// Clamps barycentrics into the triangle (rounding can leave −1e-7) and renormalizes.
pub(super) fn clamp_barycentric(l: [f32; 3]) -> [f32; 3] {
    let l = l.map(|v| v.max(0.0));
    let s = l[0] + l[1] + l[2];
    if s > 0.0 {
        l.map(|v| v / s)
    } else {
        [1.0, 0.0, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_overlap_and_closest_point() {
        let q = [
            Vec2::new(0.2, 0.2),
            Vec2::new(5.0, 0.3),
            Vec2::new(0.3, 0.4),
        ];
        assert!(overlaps_square(&q, 0, 0));
        assert!(overlaps_square(&q, 3, 0));
        let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
        // Centre (3.5, 0.5) is outside the thin sliver; its closest point lies on it.
        let l = closest_barycentric(&q, Vec2::new(3.5, 0.5), area);
        assert!(l.iter().all(|&v| v >= 0.0) && (l.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let p = q[0] * l[0] + q[1] * l[1] + q[2] * l[2];
        assert!((p.x - 3.5).abs() < 0.1, "{p}");
        // A far square does not overlap.
        assert!(!overlaps_square(&q, 3, 2));
        let tilted = [
            Vec2::new(0.0, 0.0),
            Vec2::new(4.0, 4.0),
            Vec2::new(0.0, 4.0),
        ];
        assert!(!overlaps_square(&tilted, 3, 0), "below the diagonal");
        assert!(
            !overlaps_square(&tilted, 2, 1),
            "only touching the diagonal"
        );
        assert!(overlaps_square(&tilted, 1, 2), "above the diagonal");
    }
}
