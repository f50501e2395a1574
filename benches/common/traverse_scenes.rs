//! Scenes and ray sets shared by `tests/traverse.rs` and `benches/traverse.rs` (included with
//! `#[path]`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::Vec3;
use guidebake_kernels::packet::{LANES, Ray8};
use guidebake_kernels::testing::Pcg32;
use guidebake_kernels::traverse::offset_origin;

/// `converted/` of the shared scenes ([`guidebake::scene::shared_scenes_dir`]), if present.
pub fn converted_dir() -> Option<PathBuf> {
    guidebake::scene::shared_scenes_dir()
        .map(|d| d.join("converted"))
        .filter(|d| d.is_dir())
}

/// World-space triangles of a scene file, through the driver's loader
/// ([`guidebake::scene::Scene::load`]; primitive id = index in [`Scene::triangle_positions`]).
///
/// [`Scene::triangle_positions`]: guidebake::scene::Scene::triangle_positions
pub fn load_glb(path: &Path) -> Vec<[Vec3; 3]> {
    guidebake::scene::Scene::load(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .triangle_positions()
}

/// A procedural city: a `side × side` grid of boxes of random heights on a ground plane, each
/// box face split into `split × split` quads. About `side² · (10 · split²) + 2` triangles.
pub fn city(side: usize, split: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mut rng = Pcg32::new(seed, 11);
    let extent = side as f32;
    let mut soup = vec![
        [
            Vec3::ZERO,
            Vec3::new(extent, 0.0, 0.0),
            Vec3::new(extent, 0.0, extent),
        ],
        [
            Vec3::ZERO,
            Vec3::new(extent, 0.0, extent),
            Vec3::new(0.0, 0.0, extent),
        ],
    ];
    for i in 0..side {
        for j in 0..side {
            let lo = Vec3::new(i as f32 + 0.15, 0.0, j as f32 + 0.15);
            let hi = Vec3::new(i as f32 + 0.85, 0.3 + 3.0 * rng.next_f32(), j as f32 + 0.85);
            box_faces(lo, hi, split, &mut soup);
        }
    }
    soup
}

fn box_faces(lo: Vec3, hi: Vec3, split: usize, soup: &mut Vec<[Vec3; 3]>) {
    let size = hi - lo;
    // (origin, edge u, edge v) of the five visible faces (the bottom is on the ground).
    let faces = [
        (lo, Vec3::new(size.x, 0.0, 0.0), Vec3::new(0.0, size.y, 0.0)),
        (
            Vec3::new(lo.x, lo.y, hi.z),
            Vec3::new(size.x, 0.0, 0.0),
            Vec3::new(0.0, size.y, 0.0),
        ),
        (lo, Vec3::new(0.0, 0.0, size.z), Vec3::new(0.0, size.y, 0.0)),
        (
            Vec3::new(hi.x, lo.y, lo.z),
            Vec3::new(0.0, 0.0, size.z),
            Vec3::new(0.0, size.y, 0.0),
        ),
        (
            Vec3::new(lo.x, hi.y, lo.z),
            Vec3::new(size.x, 0.0, 0.0),
            Vec3::new(0.0, 0.0, size.z),
        ),
    ];
    let n = split as f32;
    for (o, eu, ev) in faces {
        for a in 0..split {
            for b in 0..split {
                let p = |da: usize, db: usize| {
                    o + eu * ((a + da) as f32 / n) + ev * ((b + db) as f32 / n)
                };
                soup.push([p(0, 0), p(1, 0), p(1, 1)]);
                soup.push([p(0, 0), p(1, 1), p(0, 1)]);
            }
        }
    }
}

/// A surface point: position and unit geometric normal.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    pub p: Vec3,
    pub n: Vec3,
    pub prim: u32,
}

/// Area-weighted random points on the soup (the texel origins of a gather bench).
pub fn surface_points(soup: &[[Vec3; 3]], count: usize, seed: u64) -> Vec<SurfacePoint> {
    let mut rng = Pcg32::new(seed, 5);
    let mut cdf = Vec::with_capacity(soup.len());
    let mut total = 0.0f64;
    for t in soup {
        total += f64::from((t[1] - t[0]).cross(t[2] - t[0]).length());
        cdf.push(total);
    }
    (0..count)
        .map(|_| {
            let x = rng.next_f64() * total;
            let i = cdf.partition_point(|&c| c <= x).min(soup.len() - 1);
            let t = soup[i];
            let (mut a, mut b) = (rng.next_f32(), rng.next_f32());
            if a + b > 1.0 {
                (a, b) = (1.0 - a, 1.0 - b);
            }
            let p = t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b;
            let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or(Vec3::Y);
            SurfacePoint {
                p,
                n,
                prim: i as u32,
            }
        })
        .filter(|s| s.n.is_finite())
        .collect()
}

/// A branch-free orthonormal basis around unit `n` (Duff et al. 2017).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Cosine-weighted direction around `n` from `u` in [0,1)² (concentric map, then lift).
// To be replaced by `guidebake_kernels::mapping::sample_cosine_hemisphere` once it lands.
pub fn cosine_dir(n: Vec3, u: [f32; 2]) -> Vec3 {
    let (a, b) = (2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0);
    let (r, phi) = if a == 0.0 && b == 0.0 {
        (0.0, 0.0)
    } else if a.abs() > b.abs() {
        (a, std::f32::consts::FRAC_PI_4 * (b / a))
    } else {
        (
            b,
            std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a / b),
        )
    };
    let (x, y) = (r * phi.cos(), r * phi.sin());
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    let (t, bt) = basis(n);
    (t * x + bt * y + n * z).normalize()
}

/// Points of a 2D quadtree order over [0,1)² whose leaves hold fewer than 8 points: each
/// consecutive 8 is a coherent group (paper §2.4, Figure 3). `points` are sorted in place.
// To be replaced by `guidebake_kernels::presort::presorted` once it lands.
pub fn presort(points: &mut [[f32; 2]]) {
    fn key(p: [f32; 2]) -> u64 {
        let q = |x: f32| ((x * 65536.0) as u32).min(65535);
        let (x, y) = (q(p[0]), q(p[1]));
        let mut k = 0u64;
        for bit in (0..16).rev() {
            k = k << 2 | u64::from(x >> bit & 1) << 1 | u64::from(y >> bit & 1);
        }
        k
    }
    points.sort_by_key(|&p| key(p));
}

/// Gather packets: for each texel, `per_texel` cosine directions from a stratified-random
/// point set (fixed per bench, like the presorted Sobol set) rotated per texel
/// (Cranley–Patterson) and ordered after rotation so each 8 are coherent; origin offset
/// robustly from the surface.
pub fn gather_packets(soup: &[[Vec3; 3]], texels: usize, per_texel: usize, seed: u64) -> Vec<Ray8> {
    assert_eq!(per_texel % LANES, 0);
    let mut rng = Pcg32::new(seed, 17);
    let side = (per_texel as f64).sqrt().ceil() as usize;
    let rows = per_texel.div_ceil(side);
    let base: Vec<[f32; 2]> = (0..per_texel)
        .map(|i| {
            let (cx, cy) = (i % side, i / side);
            let x = (cx as f32 + rng.next_f32()) / side as f32;
            let y = (cy as f32 + rng.next_f32()) / rows as f32;
            [x.min(1.0 - f32::EPSILON), y.min(1.0 - f32::EPSILON)]
        })
        .collect();
    let centre = soup
        .iter()
        .flatten()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let centre = (centre.0 + centre.1) * 0.5;
    let mut packets = Vec::with_capacity(texels * per_texel / LANES);
    for s in surface_points(soup, texels, seed ^ 0x5eed) {
        // Two-sided surfaces: gather from the side facing the scene's centre (the inside of a
        // room), as a lightmap texel would.
        let n = if s.n.dot(centre - s.p) >= 0.0 {
            s.n
        } else {
            -s.n
        };
        let org = offset_origin(s.p, n);
        let (du, dv) = (rng.next_f32(), rng.next_f32());
        let mut pts: Vec<[f32; 2]> = base
            .iter()
            .map(|p| [wrap(p[0] + du), wrap(p[1] + dv)])
            .collect();
        presort(&mut pts);
        for group in pts.chunks_exact(LANES) {
            let dirs: [Vec3; LANES] = std::array::from_fn(|i| cosine_dir(n, group[i]));
            packets.push(Ray8::from_origin(org, &dirs, 0.0, f32::INFINITY));
        }
    }
    packets
}

fn wrap(x: f32) -> f32 {
    let y = x - x.floor();
    if y >= 1.0 { 0.0 } else { y }
}

/// Shadow packets: from surface points towards random points on a small area light at
/// `light`, `tmax` just short of the light.
pub fn shadow_packets(
    soup: &[[Vec3; 3]],
    light: Vec3,
    radius: f32,
    count: usize,
    seed: u64,
) -> Vec<Ray8> {
    let mut rng = Pcg32::new(seed, 23);
    let pts = surface_points(soup, count * LANES, seed ^ 0x51ad);
    pts.chunks_exact(LANES)
        .map(|group| {
            let mut packet = Ray8::INACTIVE;
            for (lane, s) in group.iter().enumerate() {
                let target = light
                    + Vec3::new(
                        rng.next_f32() - 0.5,
                        rng.next_f32() - 0.5,
                        rng.next_f32() - 0.5,
                    ) * radius;
                let to = target - s.p;
                let n = if s.n.dot(to) >= 0.0 { s.n } else { -s.n };
                let org = offset_origin(s.p, n);
                let dir = target - org;
                packet.set_lane(
                    lane,
                    &guidebake_kernels::packet::Ray::new(org, dir, 0.0, 0.999),
                );
            }
            packet
        })
        .collect()
}

/// Incoherent packets: eight unrelated rays from random surface points in random directions.
pub fn incoherent_packets(soup: &[[Vec3; 3]], count: usize, seed: u64) -> Vec<Ray8> {
    let mut rng = Pcg32::new(seed, 29);
    let pts = surface_points(soup, count * LANES, seed ^ 0x1dc0);
    pts.chunks_exact(LANES)
        .map(|group| {
            let mut packet = Ray8::INACTIVE;
            for (lane, s) in group.iter().enumerate() {
                let n = if rng.next_u32() & 1 == 0 { s.n } else { -s.n };
                let dir = cosine_dir(
                    n,
                    [
                        rng.next_f32().min(0.99999994),
                        rng.next_f32().min(0.99999994),
                    ],
                );
                let ray = guidebake_kernels::packet::Ray::new(
                    offset_origin(s.p, n),
                    dir,
                    0.0,
                    f32::INFINITY,
                );
                packet.set_lane(lane, &ray);
            }
            packet
        })
        .collect()
}
