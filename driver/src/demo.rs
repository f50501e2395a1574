//! The bundled default scene of `guidebake demo`: a room lit only through a door ajar.
//!
//! After Veach's "door ajar" scene (Veach 1997, Figure 10.9; Bitterli's `veach-ajar`), the
//! case that shows what ray guiding is for: a closed room whose only opening is the gap of a
//! door left ajar, under a bright sky and a low sun. From most texels only a sliver of
//! directions reaches the sky, so a cosine-weighted gather wastes nearly every ray, while a
//! guide learned from the first iteration (paper §2.2) aims the rest through the gap.
//!
//! The scene is generated in code, with its own lightmap charts: every planar face is one
//! rectangular chart of its world size, shelf-packed into the unit square with a gap of
//! [`CHART_GAP`] metres, so `prepare` at [`DEMO_TEXELS_PER_METRE`] leaves at least two empty
//! texels between charts. This is the scene's authored UV set, as an artist's would be, in
//! metres on the unit square; `prepare` keeps it as a shared atlas and packs nothing.

use std::path::PathBuf;

use glam::{Vec2, Vec3};

use crate::render::Camera;
use crate::scene::{Material, Mesh, Scene, Sky, Sun, Triangle};

/// Lightmap density the charts are laid out for (texels per metre).
pub const DEMO_TEXELS_PER_METRE: f32 = 24.0;
/// Gap between charts, in metres of the layout (2 texels at the demo density, plus a margin).
pub const CHART_GAP: f32 = 0.1;

/// Room interior: x ∈ [0, W], y ∈ [0, H] (up), z ∈ [0, D].
const W: f32 = 4.0;
const H: f32 = 2.6;
const D: f32 = 4.0;
/// The doorway in the wall z = D: x ∈ [DOOR_X0, DOOR_X1], y ∈ [0, DOOR_H].
const DOOR_X0: f32 = 1.6;
const DOOR_X1: f32 = 2.5;
const DOOR_H: f32 = 2.1;
/// How far the door stands open, radians (swung outwards about its hinge at x = DOOR_X0).
const DOOR_OPEN: f32 = 0.2;
const DOOR_THICKNESS: f32 = 0.04;

/// A planar rectangle `origin + s·u + t·v`, s, t ∈ [0, 1], facing `u × v`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Face {
    pub(crate) origin: Vec3,
    pub(crate) u: Vec3,
    pub(crate) v: Vec3,
    pub(crate) material: u32,
}

/// The demo scene: materials, geometry with lightmap UVs, sky and sun.
pub fn ajar_room() -> Scene {
    let materials = vec![
        material("walls", Vec3::splat(0.7)),
        material("floor", Vec3::new(0.55, 0.45, 0.35)),
        material("door", Vec3::new(0.5, 0.35, 0.25)),
        material("table", Vec3::new(0.6, 0.15, 0.12)),
    ];
    let groups = [
        ("room", room_faces()),
        ("door", box_faces(door_corner(), door_axes(), 2, true)),
        (
            "table",
            box_faces(Vec3::new(2.6, 0.0, 1.0), table_axes(), 3, false),
        ),
    ];
    let mut scene = scene_of_faces(&groups, materials);
    scene.path = PathBuf::from("<demo: room with a door ajar>");
    scene.sky = Sky::Constant(Vec3::new(0.6, 0.75, 1.0));
    scene.sun = Some(Sun {
        direction: Vec3::new(0.25, 0.35, 1.0).normalize(),
        angular_radius: 0.00465,
        irradiance: Vec3::new(6.0, 5.6, 5.0),
    });
    scene
}

/// A scene of named groups of planar faces (one mesh each), every face one chart packed by
/// [`pack_charts`]; no lights, black sky. The demo's room, and test rooms elsewhere.
pub(crate) fn scene_of_faces(groups: &[(&str, Vec<Face>)], materials: Vec<Material>) -> Scene {
    let all: Vec<Face> = groups.iter().flat_map(|(_, f)| f.iter().copied()).collect();
    let charts = pack_charts(&all);
    let (mut meshes, mut triangles) = (Vec::new(), Vec::new());
    let mut chart = charts.iter();
    for (mesh_index, (name, faces)) in groups.iter().enumerate() {
        let first = triangles.len() as u32;
        for face in faces {
            let uv = *chart.next().expect("one chart per face");
            triangles.extend(face_triangles(face, uv, mesh_index as u32));
        }
        meshes.push(Mesh {
            name: (*name).to_owned(),
            first_triangle: first,
            triangle_count: triangles.len() as u32 - first,
            has_lightmap_uvs: true,
        });
    }
    Scene {
        path: PathBuf::from("<faces>"),
        meshes,
        triangles,
        materials,
        lights: Vec::new(),
        sun: None,
        sky: Sky::None,
        degenerate_triangles: 0,
        roles: Vec::new(),
    }
}

/// The demo's view: from the corner of the room opposite the door, at eye height, looking at
/// the door ajar (70° vertical field of view, the image's `aspect` = width / height).
pub fn demo_camera(aspect: f32) -> Camera {
    let eye = Vec3::new(0.35, 1.6, 0.35);
    let target = Vec3::new((DOOR_X0 + DOOR_X1) / 2.0 + 0.4, 0.9, D);
    Camera {
        aspect: Some(aspect),
        ..Camera::look_at(eye, target, Vec3::Y, 70f32.to_radians())
    }
}

fn material(name: &str, albedo: Vec3) -> Material {
    Material {
        name: name.to_owned(),
        base_color_texture: None,
        albedo,
        emission: Vec3::ZERO,
    }
}

/// The room's inner faces, all facing inwards; the wall z = D is three faces around the
/// doorway.
fn room_faces() -> Vec<Face> {
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    let face = |origin, u, v, material| Face {
        origin,
        u,
        v,
        material,
    };
    vec![
        face(Vec3::ZERO, z * D, x * W, 1),                   // floor, +y
        face(Vec3::new(0.0, H, 0.0), x * W, z * D, 0),       // ceiling, −y
        face(Vec3::ZERO, y * H, z * D, 0),                   // x = 0, +x
        face(Vec3::new(W, 0.0, 0.0), z * D, y * H, 0),       // x = W, −x
        face(Vec3::ZERO, x * W, y * H, 0),                   // z = 0, +z
        face(Vec3::new(0.0, 0.0, D), y * H, x * DOOR_X0, 0), // z = D left of the door, −z
        face(Vec3::new(DOOR_X1, 0.0, D), y * H, x * (W - DOOR_X1), 0), // right of the door
        face(
            Vec3::new(DOOR_X0, DOOR_H, D),
            y * (H - DOOR_H),
            x * (DOOR_X1 - DOOR_X0),
            0,
        ), // lintel
    ]
}

/// The door: hinged at (DOOR_X0, ·, D), swung outwards (towards +z) by `DOOR_OPEN`.
fn door_corner() -> Vec3 {
    Vec3::new(DOOR_X0, 0.0, D)
}

fn door_axes() -> [Vec3; 3] {
    let (s, c) = DOOR_OPEN.sin_cos();
    let width = DOOR_X1 - DOOR_X0 - 0.02;
    let along = Vec3::new(c, 0.0, s) * width;
    let across = Vec3::new(-s, 0.0, c) * DOOR_THICKNESS;
    [along, Vec3::Y * DOOR_H, across]
}

fn table_axes() -> [Vec3; 3] {
    [Vec3::X * 0.8, Vec3::Y * 0.75, Vec3::Z * 0.9]
}

/// The faces of the box `corner + a·e0 + b·e1 + c·e2` (right-handed axes), facing outwards;
/// the bottom face is left out when the box stands on the floor.
fn box_faces(corner: Vec3, [e0, e1, e2]: [Vec3; 3], material: u32, with_bottom: bool) -> Vec<Face> {
    let face = |origin, u, v| Face {
        origin,
        u,
        v,
        material,
    };
    let mut faces = vec![
        face(corner, e1, e0),      // −e2 side
        face(corner + e2, e0, e1), // +e2 side
        face(corner, e2, e1),      // −e0 side
        face(corner + e0, e1, e2), // +e0 side
        face(corner + e1, e2, e0), // top
    ];
    if with_bottom {
        faces.push(face(corner, e0, e2));
    }
    faces
}

/// Shelf-packs one chart per face (world-size rectangles with a `CHART_GAP` border) into
/// the unit square; returns each face's UV rectangle as (min corner, size).
fn pack_charts(faces: &[Face]) -> Vec<[Vec2; 2]> {
    let sizes: Vec<Vec2> = faces
        .iter()
        .map(|f| Vec2::new(f.u.length(), f.v.length()))
        .collect();
    let area: f32 = sizes
        .iter()
        .map(|s| (s.x + CHART_GAP) * (s.y + CHART_GAP))
        .sum();
    let mut order: Vec<usize> = (0..faces.len()).collect();
    order.sort_by(|&a, &b| sizes[b].y.total_cmp(&sizes[a].y));
    // Grow the square until the shelves fit.
    let mut side = area.sqrt();
    loop {
        if let Some(placed) = shelves(&sizes, &order, side) {
            return placed
                .into_iter()
                .map(|[min, size]| [min / side, size / side])
                .collect();
        }
        side *= 1.05;
    }
}

fn shelves(sizes: &[Vec2], order: &[usize], side: f32) -> Option<Vec<[Vec2; 2]>> {
    let mut placed = vec![[Vec2::ZERO; 2]; sizes.len()];
    let (mut x, mut y, mut shelf_height) = (CHART_GAP, CHART_GAP, 0.0f32);
    for &i in order {
        let s = sizes[i];
        if x + s.x + CHART_GAP > side {
            (x, y, shelf_height) = (CHART_GAP, y + shelf_height + CHART_GAP, 0.0);
        }
        if x + s.x + CHART_GAP > side || y + s.y + CHART_GAP > side {
            return None;
        }
        placed[i] = [Vec2::new(x, y), s];
        x += s.x + CHART_GAP;
        shelf_height = shelf_height.max(s.y);
    }
    Some(placed)
}

/// The face as two triangles with flat normals and its chart's lightmap UVs.
fn face_triangles(face: &Face, [uv_min, uv_size]: [Vec2; 2], mesh: u32) -> [Triangle; 2] {
    let p = |s: f32, t: f32| face.origin + face.u * s + face.v * t;
    let uv = |s: f32, t: f32| uv_min + uv_size * Vec2::new(s, t);
    let n = face.u.cross(face.v).normalize();
    let tri = |a: (f32, f32), b: (f32, f32), c: (f32, f32)| Triangle {
        positions: [p(a.0, a.1), p(b.0, b.1), p(c.0, c.1)],
        normals: [n; 3],
        lightmap_uv: Some([uv(a.0, a.1), uv(b.0, b.1), uv(c.0, c.1)]),
        texture_uv: None,
        colour: None,
        mesh,
        material: face.material,
    };
    [
        tri((0.0, 0.0), (1.0, 0.0), (1.0, 1.0)),
        tri((0.0, 0.0), (1.0, 1.0), (0.0, 1.0)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_room_faces_inwards_and_is_closed_but_for_the_door_gap() {
        let scene = ajar_room();
        let centre = Vec3::new(W / 2.0, H / 2.0, D / 2.0);
        let room = &scene.meshes[0];
        for t in &scene.triangles[room.first_triangle as usize..][..room.triangle_count as usize] {
            let to_centre = centre - t.positions[0];
            assert!(
                t.geometric_normal().dot(to_centre) > 0.0,
                "room faces point inwards"
            );
            assert!((t.geometric_normal() - t.normals[0]).length() < 1e-6);
        }
        let room_area: f32 = scene.triangles[..room.triangle_count as usize]
            .iter()
            .map(Triangle::area)
            .sum();
        let closed = 2.0 * (W * D + W * H + D * H);
        let doorway = (DOOR_X1 - DOOR_X0) * DOOR_H;
        assert!((room_area - (closed - doorway)).abs() < 1e-3);
    }

    #[test]
    fn charts_lie_in_the_unit_square_without_overlapping() {
        let scene = ajar_room();
        let gap_uv = CHART_GAP / 2.0 / 100.0; // charts are at least this far apart
        let rects: Vec<(Vec2, Vec2)> = scene
            .triangles
            .chunks(2)
            .map(|quad| {
                let uvs = quad.iter().flat_map(|t| t.lightmap_uv.unwrap());
                let lo = uvs.clone().fold(Vec2::splat(f32::INFINITY), Vec2::min);
                let hi = uvs.fold(Vec2::splat(f32::NEG_INFINITY), Vec2::max);
                (lo, hi)
            })
            .collect();
        for (i, &(lo, hi)) in rects.iter().enumerate() {
            assert!(
                lo.cmpge(Vec2::ZERO).all() && hi.cmple(Vec2::ONE).all(),
                "chart {i} in [0,1]²"
            );
            for &(lo2, hi2) in &rects[i + 1..] {
                let apart = hi.x + gap_uv <= lo2.x
                    || hi2.x + gap_uv <= lo.x
                    || hi.y + gap_uv <= lo2.y
                    || hi2.y + gap_uv <= lo.y;
                assert!(apart, "charts overlap: {lo:?}..{hi:?} and {lo2:?}..{hi2:?}");
            }
        }
    }

    #[test]
    fn the_door_leaves_a_narrow_gap_towards_the_sun() {
        let scene = ajar_room();
        let door = &scene.meshes[1];
        // The door's free edge (largest x) against the frame corner (DOOR_X1, ·, D).
        let edge = scene.triangles[door.first_triangle as usize..][..door.triangle_count as usize]
            .iter()
            .flat_map(|t| t.positions)
            .max_by(|a, b| a.x.total_cmp(&b.x))
            .unwrap();
        let gap = Vec2::new(DOOR_X1 - edge.x, edge.z - D).length();
        assert!(
            (0.1..0.3).contains(&gap),
            "a door ajar, not open nor shut: gap {gap} m"
        );
        let sun = scene.sun.as_ref().unwrap();
        assert!(
            sun.direction.z > 0.0 && sun.direction.x > 0.0,
            "the sun lies beyond the gap"
        );
    }
}
