//! Fixtures the tests and benches of every crate share (one home instead of copies): where the
//! third-party scenes are, the closed box rooms and quads of analytic tests, hand-made texels,
//! and the check that every texel lies on its triangle. Not part of the API.

use std::path::PathBuf;

use glam::{Vec2, Vec3};

use crate::scene::{Material, Mesh, Scene, Sky, Triangle};
use crate::texels::{FLAG_VALID, PageRecord, SEEN_FRONT, TexelFile, TexelRecord, TriangleRecord};

/// Where the tests and benches find the third-party scenes: `GUIDEBAKE_SCENES` if set, else
/// `../shared/scenes` beside the workspace (or `../../shared/scenes`, for a workspace that is a
/// git worktree one level further down). Prints a "skipping" line and returns `None` when
/// none exists, so a test on a fresh clone without `../shared` skips with a message.
pub fn shared_scenes_dir() -> Option<PathBuf> {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let candidates = std::env::var_os("GUIDEBAKE_SCENES")
        .map(PathBuf::from)
        .into_iter()
        .chain(
            [
                format!("{root}/../shared/scenes"),
                format!("{root}/../../shared/scenes"),
            ]
            .map(PathBuf::from),
        );
    let found = candidates.into_iter().find(|p| p.is_dir());
    if found.is_none() {
        println!("skipping: ../shared/scenes is absent (set GUIDEBAKE_SCENES to point at it)");
    }
    found
}

/// The six faces of the axis-aligned box from `corner` with edge `size`, each as (corner,
/// edge u, edge v) with u × v pointing into the box: the closed rooms of tests and examples.
pub fn inward_box_faces(corner: Vec3, size: f32) -> [(Vec3, Vec3, Vec3); 6] {
    let (o, x, y, z) = (corner, Vec3::X * size, Vec3::Y * size, Vec3::Z * size);
    [
        (o, x, y),
        (o + z, y, x),
        (o, y, z),
        (o + x, z, y),
        (o, z, x),
        (o + y, x, z),
    ]
}

/// The six faces of the box `lo..lo + size` as (corner, edge u, edge v) with `u × v` facing
/// out of it: closed objects standing in the scenes of tests.
pub fn outward_box_faces(lo: Vec3, size: Vec3) -> [(Vec3, Vec3, Vec3); 6] {
    let (x, y, z) = (Vec3::X * size.x, Vec3::Y * size.y, Vec3::Z * size.z);
    [
        (lo, y, x),
        (lo + z, x, y),
        (lo, z, y),
        (lo + x, y, z),
        (lo, x, z),
        (lo + y, z, x),
    ]
}

/// Two materials: 0 a grey diffuse of `albedo`, 1 a lamp of the same albedo emitting
/// `emission` (white).
pub fn grey_and_lamp(albedo: f32, emission: f32) -> Vec<Material> {
    let grey = Material {
        name: "grey".into(),
        base_color_texture: None,
        albedo: Vec3::splat(albedo),
        emission: Vec3::ZERO,
    };
    let lamp = Material {
        name: "lamp".into(),
        emission: Vec3::splat(emission),
        ..grey.clone()
    };
    vec![grey, lamp]
}

/// A quad `origin + s·u + t·v`, s, t ∈ [0,1], as two triangles of mesh 0 facing `u × v`
/// (lightmap UVs all zero: for scenes that are traced, not prepared).
pub fn quad(origin: Vec3, u: Vec3, v: Vec3, material: u32) -> [Triangle; 2] {
    let n = u.cross(v).normalize();
    let tri = |a: Vec3, b: Vec3, c: Vec3| Triangle {
        positions: [a, b, c],
        normals: [n; 3],
        lightmap_uv: Some([Vec2::ZERO; 3]),
        texture_uv: None,
        colour: None,
        mesh: 0,
        material,
    };
    [
        tri(origin, origin + u, origin + u + v),
        tri(origin, origin + u + v, origin + v),
    ]
}

/// A valid texel at pixel (x, y) of page 0 lying on the floor y = 0 at (x, 0, y), facing up,
/// one unit per pixel, triangle unknown: the texels of hand-made texel files.
pub fn floor_texel(x: u16, y: u16) -> TexelRecord {
    TexelRecord {
        position: [f32::from(x), 0.0, f32::from(y)],
        normal: [0.0, 1.0, 0.0],
        dpdu: [1.0, 0.0, 0.0],
        dpdv: [0.0, 0.0, 1.0],
        page: 0,
        pixel: [x, y],
        triangle: u32::MAX,
        flags: FLAG_VALID,
    }
}

/// Asserts every texel of `f` lies on its triangle of `scene`: within 1e-5 (relative to the
/// scene size) of its plane, with barycentrics ≥ −1e-3, and has a unit normal.
///
/// # Panics
/// When a texel does not.
pub fn assert_texels_on_triangles(scene: &Scene, f: &TexelFile) {
    let (lo, hi) = scene.bounds();
    let tol = 1e-5 * (hi - lo).max_element().max(1.0);
    for (i, x) in f.texels().iter().enumerate() {
        let t = &scene.triangles[x.triangle as usize];
        let [a, b, c] = t.positions;
        let p = Vec3::from(x.position);
        let n = (b - a).cross(c - a);
        let dist = (p - a).dot(n.normalize());
        assert!(
            dist.abs() <= tol,
            "texel {i} is {dist} off its triangle's plane"
        );
        let area2 = n.length_squared();
        let l1 = (p - a).cross(c - a).dot(n) / area2;
        let l2 = (b - a).cross(p - a).dot(n) / area2;
        let l0 = 1.0 - l1 - l2;
        assert!(
            l0 >= -1e-3 && l1 >= -1e-3 && l2 >= -1e-3,
            "texel {i} barycentrics {l0} {l1} {l2}"
        );
        assert!((Vec3::from(x.normal).length() - 1.0).abs() < 1e-3);
    }
}

/// One right triangle of legs `size` on z = 0 facing +z, of grey `albedo`, whose lightmap
/// UVs span the lower-left half of a 4×4 page (one texel is `size` / 4), seen from its front:
/// the scene, its triangle record and its page, as a texel file would lay them out.
pub fn lightmapped_triangle(
    size: f32,
    albedo: f32,
) -> (Scene, Vec<TriangleRecord>, Vec<PageRecord>) {
    let tri = Triangle {
        positions: [Vec3::ZERO, Vec3::X * size, Vec3::Y * size],
        normals: [Vec3::Z; 3],
        lightmap_uv: Some([Vec2::ZERO, Vec2::X, Vec2::Y]),
        texture_uv: None,
        colour: None,
        mesh: 0,
        material: 0,
    };
    let scene = Scene {
        path: PathBuf::from("<test>"),
        meshes: vec![Mesh {
            name: "m".into(),
            first_triangle: 0,
            triangle_count: 1,
            has_lightmap_uvs: true,
        }],
        triangles: vec![tri],
        materials: vec![Material {
            name: "m".into(),
            base_color_texture: None,
            albedo: Vec3::splat(albedo),
            emission: Vec3::ZERO,
        }],
        lights: Vec::new(),
        sun: None,
        sky: Sky::None,
        degenerate_triangles: 0,
        roles: Vec::new(),
    };
    let uv = [Vec2::ZERO, Vec2::new(4.0, 0.0), Vec2::new(0.0, 4.0)];
    let triangles = vec![TriangleRecord::lightmapped(0, uv, SEEN_FRONT)];
    let pages = vec![PageRecord {
        width: 4,
        height: 4,
    }];
    (scene, triangles, pages)
}

/// The triangle table of a hand-made texel file whose one page of `page` texels holds
/// `scene`'s own lightmap UVs (0..1 across the page), every triangle seen from `seen`
/// ([`crate::texels::SEEN_FRONT`] | [`crate::texels::SEEN_BACK`]).
pub fn triangles_on_page(scene: &Scene, page: PageRecord, seen: u32) -> Vec<TriangleRecord> {
    let size = Vec2::new(page.width as f32, page.height as f32);
    scene
        .triangles
        .iter()
        .map(|t| match t.lightmap_uv {
            Some(uv) => TriangleRecord::lightmapped(0, uv.map(|v| v * size), seen),
            None => TriangleRecord::unmapped(seen),
        })
        .collect()
}
