//! Scenes and ray sets of the traversal checks and benchmarks (`tests/traverse.rs`,
//! `benches/traverse.rs`): the converted scenes' triangles, a procedural city, surface points
//! and the gather and shadow packets a bake would trace from them.

use std::path::{Path, PathBuf};

use glam::Vec3;
use guidebake_kernels::mapping::{
    orthonormal_basis, sample_cosine_hemisphere, sample_cosine_hemisphere_x8,
};
use guidebake_kernels::packet::{LANES, Ray8, offset_origin, triangle_extent};
use guidebake_kernels::presort::{
    CurveOrder, presorted, quadtree_sort_by, reorder_after_rotation_into,
};
use guidebake_kernels::sobol::{
    rotate, rotate_x8, rotation, sobol_2d, sobol_2d_x8, to_unit, to_unit_x8,
};
use guidebake_kernels::testing::Pcg32;
use wide::u32x8;

/// `converted/` of the shared scenes ([`guidebake::test_support::shared_scenes_dir`]), if present.
pub fn converted_dir() -> Option<PathBuf> {
    guidebake::test_support::shared_scenes_dir()
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

/// Cosine-weighted direction around unit `n` from `u` in [0,1)²: the kernels' map
/// ([`sample_cosine_hemisphere`]) in the kernels' frame ([`orthonormal_basis`]), as the bake's
/// `to_world` does.
pub fn cosine_dir(n: Vec3, u: [f32; 2]) -> Vec3 {
    to_world(n, sample_cosine_hemisphere(u))
}

fn to_world(n: Vec3, d: Vec3) -> Vec3 {
    let (t, b) = orthonormal_basis(n);
    (t * d.x + b * d.y + n * d.z).normalize_or(n)
}

/// How a texel's 256 Sobol points are grouped into packets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GatherOrder {
    /// What the bake does: the presorted order (once per sample count), rotated per texel and
    /// wrap-reordered in O(N) ([`reorder_after_rotation_into`]).
    Presorted,
    /// The comparator's best case: the rotated points fully re-sorted per texel by the
    /// Hilbert quadtree order ([`quadtree_sort_by`]); consecutive 8s or 16s are packets.
    Resorted,
}

/// Salt of the per-packet origin jitter (any constant; the bake has its own).
const ORIGIN_SALT: u32 = 0x0416_1d00;

/// Gather packets, built exactly as `driver/src/bake/gather.rs` `gather_packets` feeds the
/// tracer: per texel (a surface point, gathering from the side facing the scene's centre),
/// the first `per_texel` Sobol points in presorted order, Cranley–Patterson rotated per texel
/// ([`rotation`], [`rotate_x8`]), wrap-reordered ([`reorder_after_rotation_into`]), mapped by
/// [`sample_cosine_hemisphere_x8`] into the texel's frame; each packet's shared origin is
/// jittered over the texel's footprint (`extent / 512`, kept on the triangle, like the bake's
/// `onto_triangle`) and offset with [`offset_origin`]. `order` = [`GatherOrder::Resorted`]
/// re-sorts the rotated points instead (the Embree `rtcIntersect16` comparator).
pub fn gather_packets_ordered(
    soup: &[[Vec3; 3]],
    texels: usize,
    per_texel: usize,
    seed: u64,
    order: GatherOrder,
) -> Vec<Ray8> {
    assert_eq!(per_texel % LANES, 0);
    let presorted_order = presorted(per_texel as u32);
    let mut rotated = vec![0u32; per_texel];
    let (lo, hi) = soup
        .iter()
        .flatten()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let (centre, footprint) = ((lo + hi) * 0.5, (hi - lo).max_element() / 512.0);
    let seed32 = seed as u32;
    let mut packets = Vec::with_capacity(texels * per_texel / LANES);
    for (id, s) in surface_points(soup, texels, seed ^ 0x5eed)
        .into_iter()
        .enumerate()
    {
        // Two-sided surfaces: gather from the side facing the scene's centre (the inside of a
        // room), as a lightmap texel would.
        let n = if s.n.dot(centre - s.p) >= 0.0 {
            s.n
        } else {
            -s.n
        };
        let (t, b) = orthonormal_basis(n);
        let rot = rotation(seed32, id as u64, 0);
        match order {
            GatherOrder::Presorted => {
                reorder_after_rotation_into(&presorted_order, rot, &mut rotated)
            }
            GatherOrder::Resorted => {
                rotated.copy_from_slice(&presorted_order);
                quadtree_sort_by(&mut rotated, CurveOrder::Hilbert, |i| {
                    rotate(sobol_2d(i), rot)
                });
            }
        }
        let tri = soup[s.prim as usize];
        for (j, chunk) in rotated.chunks_exact(LANES).enumerate() {
            let index = u32x8::new(chunk.try_into().expect("packets of 8"));
            let [sx, sy] = rotate_x8(sobol_2d_x8(index), rot);
            let [dx, dy, dz] = sample_cosine_hemisphere_x8([to_unit_x8(sx), to_unit_x8(sy)]);
            let (dx, dy, dz) = (dx.to_array(), dy.to_array(), dz.to_array());
            let dirs: [Vec3; LANES] =
                std::array::from_fn(|i| to_world(n, Vec3::new(dx[i], dy[i], dz[i])));
            let r = rotation(seed32 ^ ORIGIN_SALT, id as u64, j as u32);
            let jitter =
                t * (footprint * (to_unit(r[0]) - 0.5)) + b * (footprint * (to_unit(r[1]) - 0.5));
            let p = onto_triangle(tri, s.p + jitter).unwrap_or(s.p);
            let org = offset_origin(p, n, triangle_extent(p, &tri));
            packets.push(Ray8::from_origin(org, &dirs, 0.0, f32::INFINITY));
        }
    }
    packets
}

/// [`gather_packets_ordered`] in the bake's order ([`GatherOrder::Presorted`]).
pub fn gather_packets(soup: &[[Vec3; 3]], texels: usize, per_texel: usize, seed: u64) -> Vec<Ray8> {
    gather_packets_ordered(soup, texels, per_texel, seed, GatherOrder::Presorted)
}

/// `p` projected onto `tri`'s plane if that lands inside the triangle (a jittered origin that
/// would leave its triangle falls back to the texel's point).
fn onto_triangle(tri: [Vec3; 3], p: Vec3) -> Option<Vec3> {
    let (e1, e2) = (tri[1] - tri[0], tri[2] - tri[0]);
    let n = e1.cross(e2);
    let q = p - n * ((p - tri[0]).dot(n) / n.length_squared());
    let w = q - tri[0];
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (w1, w2) = (w.dot(e1), w.dot(e2));
    let den = d11 * d22 - d12 * d12;
    let (a, b) = ((d22 * w1 - d12 * w2) / den, (d11 * w2 - d12 * w1) / den);
    (a >= 0.0 && b >= 0.0 && a + b <= 1.0).then(|| tri[0] + e1 * a + e2 * b)
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
                let org = offset_origin(s.p, n, triangle_extent(s.p, &soup[s.prim as usize]));
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
                    offset_origin(s.p, n, triangle_extent(s.p, &soup[s.prim as usize])),
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
