//! Textured albedo at gather hits, end to end: a checker-textured floor lit by a sun bounces
//! light onto a black wall standing on it. Where the wall is far from the floor (many checker
//! periods), its bounce irradiance is the one the texture's *average* predicts; close to the
//! floor it shows the checker — texels above white squares receive several times what texels
//! above black squares do — and every texel matches the value computed square by square with
//! the exact polygon form factor (Lambert's formula). A bake that used one albedo per material
//! (as before textures were sampled) gives the same value above white and black squares.
//!
//! The floor is lit by a sun in front of the wall (not by a sky, which the wall would shade
//! near its foot): its irradiance is uniform, `E_f = E_s cos θ`, and its radiance is
//! `ρ(x) E_f / π`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use glam::{DVec3, Vec2, Vec3};
use guidebake::bake::finish::FinishOptions;
use guidebake::bake::run::{BakeJob, bake};
use guidebake::bake::settings::{BakeSettings, Transport};
use guidebake::bake::shard::Shard;
use guidebake::output::readback::read_channel;
use guidebake::scene::texture::{Image, TextureOptions, Wrap};
use guidebake::scene::{BaseColorTexture, Material, Mesh, Scene, Sky, Sun, Triangle};
use guidebake::test_support::quad;
use guidebake::texels::{
    FLAG_VALID, PageRecord, SEEN_BACK, SEEN_FRONT, TexelRecord, TexelWriter, TileRect,
    TriangleRecord,
};

/// Checker square side, metres.
const P: f64 = 0.25;
/// Floor half-width (x) and depth (y), wall half-width and height, metres.
const FLOOR_X: f32 = 8.0;
const FLOOR_Y: f32 = 8.0;
const WALL_H: f32 = 5.0;
/// Albedo of the white squares (texel 255 × factor); the black squares are 0.
const WHITE: f64 = 0.8;
/// Texel columns (x at checker square centres) and rows (heights above the floor).
const COLUMNS: u32 = 16;
const HEIGHTS: [f64; 8] = [
    P / 8.0,
    P / 4.0,
    P / 2.0,
    P,
    2.0 * P,
    4.0 * P,
    8.0 * P,
    16.0 * P,
];

fn column_x(k: u32) -> f64 {
    (f64::from(k) - f64::from(COLUMNS) / 2.0 + 0.5) * P
}

/// Whether floor square (i, j) (x ∈ [iP, (i+1)P], y ∈ [jP, (j+1)P]) is white.
fn white(i: i64, j: i64) -> bool {
    (i + j).rem_euclid(2) == 0
}

/// The sun: irradiance 1 on a plane facing it, in front of the wall (+y) and high.
fn sun_direction() -> Vec3 {
    Vec3::new(0.0, 0.1, 1.0).normalize()
}

/// A 64×64 checker of 32×32 blocks (white 255, black 0), mapped so each block is one P×P
/// square of the floor: bilinear filtering blurs only a 1/32-wide band along each edge,
/// whose effect on the integral cancels to first order.
fn checker() -> BaseColorTexture {
    let n = 64u32;
    let texels: Vec<u8> = (0..n * n)
        .flat_map(|t| {
            let (x, y) = (i64::from(t % n / 32), i64::from(t / n / 32));
            [if white(x, y) { 255 } else { 0 }; 3]
        })
        .collect();
    let image = Image::from_srgb8(
        "checker".into(),
        n,
        n,
        3,
        &texels,
        TextureOptions::default(),
    );
    BaseColorTexture {
        image: Arc::new(image.unwrap()),
        wrap: [Wrap::Repeat; 2],
        factor: Vec3::splat(WHITE as f32),
    }
}

/// The scene: mesh 0 the wall (plane y = 0, facing +y, albedo 0, with texels), mesh 1 the
/// floor (plane z = 0, facing +z, in front of the wall), textured when `textured`, else of
/// the texture's average albedo.
fn scene(textured: bool) -> Scene {
    let wall = quad(
        Vec3::new(-FLOOR_X, 0.0, 0.0),
        Vec3::Z * WALL_H,
        Vec3::X * 2.0 * FLOOR_X,
        0,
    );
    let mut floor = quad(
        Vec3::new(-FLOOR_X, 0.0, 0.0),
        Vec3::X * 2.0 * FLOOR_X,
        Vec3::Y * FLOOR_Y,
        1,
    );
    for t in &mut floor {
        t.mesh = 1;
        t.lightmap_uv = None;
        t.texture_uv = Some(t.positions.map(|p| Vec2::new(p.x, p.y) / (2.0 * P as f32)));
    }
    let texture = checker();
    let floor_material = Material {
        name: "checker".into(),
        albedo: texture.factor * texture.image.average(),
        emission: Vec3::ZERO,
        base_color_texture: textured.then_some(texture),
    };
    let black = Material {
        name: "black".into(),
        albedo: Vec3::ZERO,
        emission: Vec3::ZERO,
        base_color_texture: None,
    };
    let mesh = |name: &str, first: u32, lightmapped: bool| Mesh {
        name: name.into(),
        first_triangle: first,
        triangle_count: 2,
        has_lightmap_uvs: lightmapped,
    };
    let triangles: Vec<Triangle> = wall.into_iter().chain(floor).collect();
    Scene {
        path: PathBuf::from("<checker floor>"),
        meshes: vec![mesh("wall", 0, true), mesh("floor", 2, false)],
        triangles,
        materials: vec![black, floor_material],
        lights: Vec::new(),
        sun: Some(Sun {
            direction: sun_direction(),
            angular_radius: 0.00465,
            irradiance: Vec3::ONE,
        }),
        sky: Sky::None,
        degenerate_triangles: 0,
        roles: Vec::new(),
    }
}

/// The wall's texels: column k at x = column_x(k), row r at height HEIGHTS[r].
fn write_texels(path: &Path) {
    let page = PageRecord {
        width: COLUMNS,
        height: HEIGHTS.len() as u32,
    };
    // The wall has texels (its lightmap UVs play no part here); the floor has none. Both are
    // open space on both sides.
    let seen = SEEN_FRONT | SEEN_BACK;
    let wall = TriangleRecord::lightmapped(0, [Vec2::ZERO; 3], seen);
    let triangles = [
        wall,
        wall,
        TriangleRecord::unmapped(seen),
        TriangleRecord::unmapped(seen),
    ];
    let mut writer = TexelWriter::create(path, &[page], &triangles, 64.0).unwrap();
    let texels: Vec<TexelRecord> = (0..COLUMNS * page.height)
        .map(|i| {
            let (k, r) = (i % COLUMNS, i / COLUMNS);
            let (x, z) = (column_x(k) as f32, HEIGHTS[r as usize] as f32);
            // The wall's triangle 0 covers z / H ≥ (x + X) / 2X (test_support::quad).
            let triangle = u32::from(z / WALL_H < (x + FLOOR_X) / (2.0 * FLOOR_X));
            TexelRecord {
                position: [x, 0.0, z],
                normal: [0.0, 1.0, 0.0],
                dpdu: [1.0 / 64.0, 0.0, 0.0],
                dpdv: [0.0, 0.0, 1.0 / 64.0],
                page: 0,
                pixel: [k as u16, r as u16],
                triangle,
                flags: FLAG_VALID,
            }
        })
        .collect();
    let rect = TileRect {
        page: 0,
        x: 0,
        y: 0,
        width: COLUMNS,
        height: page.height,
    };
    writer.push_tile(rect, &texels).unwrap();
    writer.finish().unwrap();
}

/// The form factor from a point `p` with unit normal `n` to the convex polygon `v` fully in
/// front of it (Lambert: `1/2π Σ γᵢ n·(Rᵢ × Rᵢ₊₁)/|Rᵢ × Rᵢ₊₁|`).
fn form_factor(p: DVec3, n: DVec3, v: &[DVec3]) -> f64 {
    let mut sum = 0.0;
    for i in 0..v.len() {
        let (a, b) = (v[i] - p, v[(i + 1) % v.len()] - p);
        let c = a.cross(b);
        let gamma = a.angle_between(b);
        sum += gamma * n.dot(c) / c.length();
    }
    (sum / (2.0 * std::f64::consts::PI)).abs()
}

fn rectangle(x0: f64, x1: f64, y0: f64, y1: f64) -> [DVec3; 4] {
    [
        DVec3::new(x0, y0, 0.0),
        DVec3::new(x1, y0, 0.0),
        DVec3::new(x1, y1, 0.0),
        DVec3::new(x0, y1, 0.0),
    ]
}

/// Bounce irradiance at wall point (x, 0, z) from the floor of irradiance `e_floor`:
/// `(square by square, with the checker; with the texture's average)`.
fn predicted(x: f64, z: f64, e_floor: f64) -> (f64, f64) {
    let (p, n) = (DVec3::new(x, 0.0, z), DVec3::Y);
    let (fx, fy) = (f64::from(FLOOR_X), f64::from(FLOOR_Y));
    let (ni, nj) = ((fx / P).round() as i64, (fy / P).round() as i64);
    let mut white_ff = 0.0;
    for i in -ni..ni {
        for j in 0..nj {
            if white(i, j) {
                let (x0, y0) = (i as f64 * P, j as f64 * P);
                white_ff += form_factor(p, n, &rectangle(x0, x0 + P, y0, y0 + P));
            }
        }
    }
    let all_ff = form_factor(p, n, &rectangle(-fx, fx, 0.0, fy));
    (WHITE * e_floor * white_ff, WHITE / 2.0 * e_floor * all_ff)
}

fn bake_wall(dir: &Path, scene: &Scene, name: &str) -> Vec<f64> {
    let out = dir.join(format!("{name}.exr"));
    let job = BakeJob {
        texels: dir.join("wall.texels"),
        out: out.clone(),
        settings: BakeSettings {
            spp: 1024,
            iterations: 2,
            transport: Transport::Series,
            bounces: 1,
            bias_correction: false,
            ..Default::default()
        },
        threads: 2,
        shard: Shard::WHOLE,
        resume: false,
        aux: false,
        finish: FinishOptions::default(),
    };
    let report = bake(&job, scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    // The stats count the checker's texels once: 64 × 64 × 3 bytes of 8-bit sRGB.
    let bytes = if scene.materials[1].base_color_texture.is_some() {
        64 * 64 * 3
    } else {
        0
    };
    assert_eq!(report.texture_bytes, bytes);
    let values: Vec<f64> = ["R", "G", "B"]
        .iter()
        .flat_map(|c| read_channel(&out, c).unwrap())
        .map(f64::from)
        .collect();
    assert!(values.iter().all(|v| v.is_finite()), "NaN or ∞ in {name}");
    read_channel(&out, "R")
        .unwrap()
        .into_iter()
        .map(f64::from)
        .collect()
}

/// Mean and standard error of the texels of row `r` in the columns `k` that `keep` selects.
fn group(values: &[f64], r: usize, keep: impl Fn(u32) -> bool) -> (f64, f64) {
    let v: Vec<f64> = (0..COLUMNS)
        .filter(|&k| keep(k))
        .map(|k| values[r * COLUMNS as usize + k as usize])
        .collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn a_checker_floor_bounces_its_average_far_away_and_its_checker_close_by() {
    let dir = tempfile::tempdir().unwrap();
    write_texels(&dir.path().join("wall.texels"));
    let sun = sun_direction();
    let (e_floor, e_direct) = (f64::from(sun.z), f64::from(sun.y));
    let textured = bake_wall(dir.path(), &scene(true), "textured");
    let averaged = bake_wall(dir.path(), &scene(false), "averaged");
    // Column k sits over the floor squares (k − 8, 0), white for even k.
    let over_white = |k: u32| white(i64::from(k) - i64::from(COLUMNS) / 2, 0);
    for (r, &z) in HEIGHTS.iter().enumerate() {
        let (w_exact, avg) = predicted(column_x(0), z, e_floor);
        let (b_exact, _) = predicted(column_x(1), z, e_floor);
        let (w_bake, w_se) = group(&textured, r, over_white);
        let (b_bake, b_se) = group(&textured, r, |k| !over_white(k));
        let (a_bake, a_se) = group(&averaged, r, |_| true);
        let (w_bake, b_bake, a_bake) = (w_bake - e_direct, b_bake - e_direct, a_bake - e_direct);
        println!(
            "z = {z:.4}: over white {w_bake:.5} ± {w_se:.5} (exact {w_exact:.5}), over black \
             {b_bake:.5} ± {b_se:.5} (exact {b_exact:.5}), average albedo {a_bake:.5} ± \
             {a_se:.5} (predicts {avg:.5})"
        );
        // Every group matches its square-by-square value; the averaged floor the average's.
        let close = |got: f64, se: f64, want: f64| (got - want).abs() < 4.0 * se + 0.01 * want;
        assert!(close(w_bake, w_se, w_exact), "over white at z = {z}");
        assert!(close(b_bake, b_se, b_exact), "over black at z = {z}");
        assert!(close(a_bake, a_se, avg), "averaged floor at z = {z}");
        if z >= 4.0 * P {
            // Far from the floor the texture averages: both groups are the average's value.
            assert!((w_exact - avg).abs() < 0.02 * avg && (b_exact - avg).abs() < 0.02 * avg);
            assert!(
                close(w_bake, w_se, avg) && close(b_bake, b_se, avg),
                "z = {z}"
            );
        }
        if z <= P / 4.0 {
            // Close by, the checker shows: over white several times over black.
            assert!(w_exact > 3.0 * b_exact, "{w_exact} {b_exact}");
            assert!(
                w_bake > 3.0 * b_bake && w_bake - b_bake > 8.0 * (w_se + b_se),
                "z = {z}: no checker in the bounce light"
            );
        }
    }
}
