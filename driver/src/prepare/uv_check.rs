//! Whether a mesh's own UV set is a lightmap atlas: inside [0, 1], with area, not
//! overlapping itself on a coarse raster ([`uv_set_problem`], [`NotAtlas`]); a set that is
//! not counts as missing under `--unwrap missing` (docs/levels.md, "UV sets that are not
//! lightmap atlases").

use glam::Vec2;
use rayon::prelude::*;

use crate::scene::{Scene, Triangle};

use super::*;

/// A mesh whose own UV set is not a lightmap atlas ([`uv_set_problem`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NotAtlas {
    /// The mesh.
    pub mesh: String,
    /// Why, e.g. "leaves [0, 1] (u -32.25..97.5, v -177..111.75)".
    pub reason: String,
    /// Whether it was unwrapped (under `--unwrap missing`; `never` keeps it as it is).
    pub unwrapped: bool,
}

/// Edge of the coarse raster [`uv_set_problem`] tests a UV set for overlaps on.
pub const ATLAS_TEST_SIZE: u32 = 256;

/// A UV set overlaps itself when more than this share of the raster cells it covers are
/// covered twice or more.
pub const SELF_OVERLAP_SHARE: f64 = 0.01;

/// How far outside [0, 1] an atlas's UVs may stray (rounding of exporters).
pub(super) const UV_RANGE_SLACK: f32 = 1e-3;

/// How far inside a triangle, in cells, a cell centre must lie to count for it: a centre on
/// the edge two triangles share counts for neither.
pub(super) const INSIDE_MARGIN: f32 = 1e-3;

/// Why the UV set of the triangles `triangles` (one mesh's, all with UVs) is not a lightmap
/// atlas, or `None` when it is one: its UVs leave [0, 1] (by more than rounding), it has no
/// area, or it overlaps itself (module docs). Cost: the triangles' bounding boxes on an
/// [`ATLAS_TEST_SIZE`]² raster (64 KiB).
#[must_use]
pub fn uv_set_problem(triangles: &[Triangle]) -> Option<String> {
    let uvs = || triangles.iter().filter_map(|t| t.lightmap_uv);
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    let mut area = 0.0f64;
    for uv in uvs() {
        for v in uv {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        area += f64::from(uv_area(&uv).abs());
    }
    if lo.min_element() < -UV_RANGE_SLACK || hi.max_element() > 1.0 + UV_RANGE_SLACK {
        return Some(format!(
            "leaves [0, 1] (u {}..{}, v {}..{})",
            lo.x, hi.x, lo.y, hi.y
        ));
    }
    if area.is_nan() || area <= 0.0 {
        return Some("has no area".into());
    }
    const N: u32 = ATLAS_TEST_SIZE;
    let mut count = vec![0u8; (N * N) as usize];
    for uv in uvs() {
        let q = uv.map(|v| v * N as f32);
        let orientation = (q[1] - q[0]).perp_dot(q[2] - q[0]);
        if orientation == 0.0 || !orientation.is_finite() {
            continue;
        }
        let sign = orientation.signum();
        // Per edge: the inward unit normal's distance function.
        let edges = [0, 1, 2].map(|i| {
            let (a, b) = (q[i], q[(i + 1) % 3]);
            let len = (b - a).length();
            (a, (b - a) * (sign / len))
        });
        let (x0, x1, y0, y1) = pixel_range(&q, (N, N));
        for y in y0..y1 {
            for x in x0..x1 {
                let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                if edges
                    .iter()
                    .all(|(a, e)| e.perp_dot(c - *a) > INSIDE_MARGIN)
                {
                    let n = &mut count[(y * N + x) as usize];
                    *n = n.saturating_add(1);
                }
            }
        }
    }
    let covered = count.iter().filter(|&&n| n > 0).count();
    let twice = count.iter().filter(|&&n| n > 1).count();
    if covered > 0 && twice as f64 > SELF_OVERLAP_SHARE * covered as f64 {
        return Some(format!(
            "overlaps itself ({:.1} % of the area it covers is covered twice or more)",
            100.0 * twice as f64 / covered as f64
        ));
    }
    None
}

/// The meshes of `scene` whose UV set is not a lightmap atlas; under [`Unwrap::Missing`]
/// they are added to `selected` (the meshes to unwrap).
pub(super) fn not_atlas_meshes(
    scene: &Scene,
    unwrap: Unwrap,
    selected: &mut [bool],
) -> Vec<NotAtlas> {
    if unwrap == Unwrap::Always {
        return Vec::new();
    }
    let problems: Vec<Option<String>> = scene
        .meshes
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            if selected[i] || !m.has_lightmap_uvs || m.triangle_count == 0 {
                return None;
            }
            let first = m.first_triangle as usize;
            uv_set_problem(&scene.triangles[first..first + m.triangle_count as usize])
        })
        .collect();
    let mut out = Vec::new();
    for (i, problem) in problems.into_iter().enumerate() {
        if let Some(reason) = problem {
            let unwrapped = unwrap == Unwrap::Missing;
            selected[i] |= unwrapped;
            out.push(NotAtlas {
                mesh: scene.meshes[i].name.clone(),
                reason,
                unwrapped,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Triangles with these lightmap UVs (positions on a plane, irrelevant here).
    fn with_uvs(uvs: &[[Vec2; 3]]) -> Vec<Triangle> {
        uvs.iter()
            .map(|&uv| Triangle {
                positions: uv.map(|v| v.extend(0.0)),
                normals: [Vec3::Z; 3],
                lightmap_uv: Some(uv),
                texture_uv: None,
                colour: None,
                mesh: 0,
                material: 0,
            })
            .collect()
    }

    /// An n×n grid of quads over `cell(i, j)`'s UV square, two triangles each, split along
    /// the diagonal (which runs through raster cell centres).
    fn grid(n: u32, cell: impl Fn(u32, u32) -> (Vec2, f32)) -> Vec<[Vec2; 3]> {
        let mut out = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (o, s) = cell(i, j);
                let [a, b, c, d] = [o, o + Vec2::X * s, o + Vec2::ONE * s, o + Vec2::Y * s];
                out.push([a, b, c]);
                out.push([a, c, d]);
            }
        }
        out
    }

    #[test]
    fn a_uv_set_is_an_atlas_unless_it_leaves_the_unit_square_overlaps_itself_or_has_no_area() {
        let step = 1.0 / 16.0;
        let atlas = grid(16, |i, j| (Vec2::new(i as f32, j as f32) * step, step));
        assert_eq!(uv_set_problem(&with_uvs(&atlas)), None);
        // Wound the other way (a mirrored chart) it is still one.
        let mirrored: Vec<_> = atlas.iter().map(|&[a, b, c]| [a, c, b]).collect();
        assert_eq!(uv_set_problem(&with_uvs(&mirrored)), None);
        // One quad's worth of overlap in 256 quads (< 1 %) is tolerated.
        let mut nearly = atlas.clone();
        nearly.extend_from_slice(&atlas[..2]);
        assert_eq!(uv_set_problem(&with_uvs(&nearly)), None);
        // Every quad on the whole square: a tiling texture set squeezed into [0, 1].
        let tiled = grid(16, |_, _| (Vec2::ZERO, 1.0));
        let problem = uv_set_problem(&with_uvs(&tiled)).unwrap();
        assert!(problem.starts_with("overlaps itself (100.0 %"), "{problem}");
        // Half the quads twice: 50 %.
        let mut doubled = grid(16, |i, j| (Vec2::new(i as f32, j as f32) * step, step));
        doubled.extend(grid(16, |i, j| {
            (Vec2::new((i / 2) as f32 * 2.0, j as f32) * step, step)
        }));
        let problem = uv_set_problem(&with_uvs(&doubled)).unwrap();
        assert!(
            problem.contains("(100.0 %") || problem.contains("overlaps itself"),
            "{problem}"
        );
        // Texture coordinates tiling outside [0, 1].
        let outside = grid(4, |i, j| (Vec2::new(i as f32 - 2.0, j as f32 * 3.0), 1.0));
        let problem = uv_set_problem(&with_uvs(&outside)).unwrap();
        assert_eq!(problem, "leaves [0, 1] (u -2..2, v 0..10)");
        // Within rounding of [0, 1] is inside.
        let edge = [[
            Vec2::new(-1e-4, 0.0),
            Vec2::new(1.0001, 0.0),
            Vec2::new(0.0, 1.0),
        ]];
        assert_eq!(uv_set_problem(&with_uvs(&edge)), None);
        let flat = [[Vec2::splat(0.5); 3]];
        assert_eq!(uv_set_problem(&with_uvs(&flat)).unwrap(), "has no area");
    }
}
