//! Seams: texels on the two sides of a UV seam — one 3D edge, two charts (or two places of
//! one chart) — made to agree (`--seams stitch`).
//!
//! A lightmap is sampled bilinearly, so along a seam each side shows its own chart's border
//! texels and the padding dilated from them: two independent estimates, and a visible jump
//! where they differ.
//!
//! **Detection** ([`seam_pixel_pairs`], run by `prepare`, which has the scene): every 3D edge
//! that two triangles share (the same two vertex positions, bit for bit) but that lies in
//! different places of the atlas is a seam edge, unless the faces meet at an angle (normals
//! with |cos| below [`PAIR_COS`]: a crease is lit differently on its two faces). Along the
//! edge, [`SAMPLES_PER_PIXEL`] points per atlas pixel are mapped to each side's pixel (nudged
//! a third of a pixel into its triangle), giving the seam's **pixel pairs**. They are kept in
//! a small file beside the texel file ([`seam_file_path`]), read when a bake or merge
//! finishes. Topology, not proximity: an earlier detector that paired border texels by world
//! distance also paired the floor on the two sides of a wall it runs under (measured in
//! docs/lightmaps.md).
//!
//! **Stitching** is a least-squares fit, after the public write-ups on lightmap seams:
//! minimise `Σ_i |x_i − x̂_i|² + λ Σ_pairs |x_a − x_b|²` over the seam pixels' irradiance
//! (`x̂` the estimate as written, [`STITCH_WEIGHT`] = λ), by [`SWEEPS`] Gauss–Seidel sweeps in
//! a fixed order — a small sparse solve, deterministic, run on the merged results, so shards
//! still give one bake's bytes. Other pixels are untouched.
//!
//! Memory: detection holds one entry per triangle edge and the seams' pixel pairs (with their
//! texels' normals), never the atlas; stitching holds the seam pixels' values.
//!
//! The measure ([`mean_relative_jump`]): the mean over seam pairs of `|l_a − l_b| / (l̄ + ε)`,
//! `l` the luminance, `l̄` the pair's mean and `ε` a hundredth of the seam pixels' mean
//! luminance.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::Vec2;
use guidebake_kernels::estimator::luminance_f32;

use crate::scene::Scene;
use crate::texels::TexelFile;

/// Smallest |cos| between the faces of a seam edge.
pub const PAIR_COS: f32 = 0.9;
/// Points sampled along a seam edge per atlas pixel of its longer side.
pub const SAMPLES_PER_PIXEL: f32 = 2.0;
/// The seam term's weight λ against the data term.
pub const STITCH_WEIGHT: f32 = 8.0;
/// Gauss–Seidel sweeps of the stitch.
pub const SWEEPS: usize = 32;
/// First bytes of a seam file.
const MAGIC: &[u8; 8] = b"GBSEAMS1";

/// An atlas pixel: page, x, y.
pub type Pixel = [u32; 3];

/// The file beside `texels` that holds its seam pairs.
pub fn seam_file_path(texels: &Path) -> PathBuf {
    let mut name = texels.as_os_str().to_owned();
    name.push(".seams");
    PathBuf::from(name)
}

/// The pixel pairs of every seam edge of `scene` in the atlas of `texels` (prepared from
/// it), sorted, each pair once (`a < b`).
pub fn seam_pixel_pairs(scene: &Scene, texels: &TexelFile) -> Vec<(Pixel, Pixel)> {
    type Key = ([u32; 3], [u32; 3]);
    let bits = |v: glam::Vec3| v.to_array().map(f32::to_bits);
    let mut edges: HashMap<Key, Vec<(usize, usize)>> = HashMap::new();
    for (t, tri) in scene.triangles.iter().enumerate() {
        if tri.lightmap_uv.is_none() {
            continue;
        }
        for e in 0..3 {
            let (a, b) = (bits(tri.positions[e]), bits(tri.positions[(e + 1) % 3]));
            edges.entry((a.min(b), a.max(b))).or_default().push((t, e));
        }
    }
    let mut keys: Vec<&Key> = edges.keys().collect();
    keys.sort_unstable();
    let mut pairs = Vec::new();
    for key in keys {
        let sides = &edges[key];
        for (i, &(t1, e1)) in sides.iter().enumerate() {
            for &(t2, e2) in &sides[i + 1..] {
                edge_pairs(scene, texels, (t1, e1), (t2, e2), &mut pairs);
            }
        }
    }
    // Both pixels must hold a texel, and the texels face the same side (the two faces of a
    // thin sheet share its rim but not their light).
    let normals = texel_normals(texels, &pairs);
    pairs.retain(|(a, b)| match (normals.get(a), normals.get(b)) {
        (Some(na), Some(nb)) => na.dot(*nb) >= PAIR_COS,
        _ => false,
    });
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// The normal of the texel at each pixel of `pairs` (pixels without a texel are absent):
/// memory for the seams' pixels only, not the atlas.
fn texel_normals(texels: &TexelFile, pairs: &[(Pixel, Pixel)]) -> HashMap<Pixel, glam::Vec3> {
    let mut normals: HashMap<Pixel, glam::Vec3> = pairs
        .iter()
        .flat_map(|&(a, b)| [(a, glam::Vec3::ZERO), (b, glam::Vec3::ZERO)])
        .collect();
    let mut found = std::collections::HashSet::new();
    for t in 0..texels.tiles().len() {
        for texel in texels.tile_texels(t) {
            let [x, y] = texel.pixel.map(u32::from);
            let pixel = [texel.page, x, y];
            if let Some(n) = normals.get_mut(&pixel) {
                *n = texel.normal();
                found.insert(pixel);
            }
        }
        texels.release_tile(t);
    }
    normals.retain(|p, _| found.contains(p));
    normals
}

/// Where triangle `t`'s lightmap lies: its page and its corners in pixel coordinates.
fn pixel_corners(scene: &Scene, texels: &TexelFile, t: usize) -> Option<(u32, [Vec2; 3])> {
    let tri = &scene.triangles[t];
    let mesh = texels.meshes().get(tri.mesh as usize)?;
    let (scale, offset) = (Vec2::from(mesh.uv_scale), Vec2::from(mesh.uv_offset));
    Some((mesh.page, tri.lightmap_uv?.map(|uv| uv * scale + offset)))
}

/// Adds the pixel pairs of the edge shared by edge `e1` of triangle `t1` and edge `e2` of
/// `t2`, if it is a seam.
fn edge_pairs(
    scene: &Scene,
    texels: &TexelFile,
    (t1, e1): (usize, usize),
    (t2, e2): (usize, usize),
    pairs: &mut Vec<(Pixel, Pixel)>,
) {
    let (tri1, tri2) = (&scene.triangles[t1], &scene.triangles[t2]);
    if tri1.geometric_normal().dot(tri2.geometric_normal()).abs() < PAIR_COS {
        return;
    }
    let (Some((page1, c1)), Some((page2, c2))) = (
        pixel_corners(scene, texels, t1),
        pixel_corners(scene, texels, t2),
    ) else {
        return;
    };
    // The edge's ends on each side, in the same order (by position).
    let (a1, b1) = (c1[e1], c1[(e1 + 1) % 3]);
    let same_order = tri1.positions[e1] == tri2.positions[e2];
    let (a2, b2) = if same_order {
        (c2[e2], c2[(e2 + 1) % 3])
    } else {
        (c2[(e2 + 1) % 3], c2[e2])
    };
    let shared = page1 == page2 && a1.distance(a2) < 1e-3 && b1.distance(b2) < 1e-3;
    if shared || !(a1.is_finite() && b1.is_finite() && a2.is_finite() && b2.is_finite()) {
        return;
    }
    let inward = |c: &[Vec2; 3]| (c[0] + c[1] + c[2]) / 3.0;
    let (in1, in2) = (inward(&c1), inward(&c2));
    let length = a1.distance(b1).max(a2.distance(b2));
    let n = (length * SAMPLES_PER_PIXEL).ceil().clamp(1.0, 1e6) as usize;
    for k in 0..n {
        let s = (k as f32 + 0.5) / n as f32;
        let p1 = pixel_of(texels, page1, a1.lerp(b1, s), in1);
        let p2 = pixel_of(texels, page2, a2.lerp(b2, s), in2);
        if let (Some(p1), Some(p2)) = (p1, p2)
            && p1 != p2
        {
            pairs.push((p1.min(p2), p1.max(p2)));
        }
    }
}

/// The pixel holding point `p` of a triangle edge, nudged a third of a pixel towards the
/// triangle's centroid `inside`; `None` off the page.
fn pixel_of(texels: &TexelFile, page: u32, p: Vec2, inside: Vec2) -> Option<Pixel> {
    let size = texels.pages().get(page as usize)?;
    let q = p + (inside - p).normalize_or_zero() / 3.0;
    let (x, y) = (q.x.floor(), q.y.floor());
    let fits = x >= 0.0 && y >= 0.0 && x < size.width as f32 && y < size.height as f32;
    fits.then_some([page, x as u32, y as u32])
}

/// Finds the seams of `scene` in the texel file at `texels` (prepared from it) and writes them
/// beside it ([`seam_file_path`]); returns the number of pixel pairs.
///
/// # Errors
/// A message naming the file that cannot be opened or written.
pub fn prepare_seams(scene: &Scene, texels: &Path) -> Result<usize, String> {
    let file = TexelFile::open(texels).map_err(|e| e.to_string())?;
    let pairs = seam_pixel_pairs(scene, &file);
    let path = seam_file_path(texels);
    write_seam_file(&path, &pairs).map_err(|e| format!("{}: cannot write: {e}", path.display()))?;
    Ok(pairs.len())
}

/// Writes `pairs` to the seam file at `path` (through a temporary name).
///
/// # Errors
/// The I/O error, when the file cannot be written.
pub fn write_seam_file(path: &Path, pairs: &[(Pixel, Pixel)]) -> std::io::Result<()> {
    let mut bytes = Vec::with_capacity(16 + pairs.len() * 24);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(pairs.len() as u64).to_le_bytes());
    for (a, b) in pairs {
        for v in a.iter().chain(b) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    super::atomic::write(path, bytes)
}

/// Reads a seam file.
///
/// # Errors
/// A message naming what is wrong when the file is missing, not a seam file, or truncated.
pub fn read_seam_file(path: &Path) -> Result<Vec<(Pixel, Pixel)>, String> {
    let bytes = std::fs::read(path).map_err(|e| {
        format!(
            "cannot read the seam file ({e}): `guidebake prepare` writes it beside the texel file"
        )
    })?;
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err("not a guidebake seam file".into());
    }
    let count = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes")) as usize;
    if (bytes.len() - 16) / 24 != count || (bytes.len() - 16) % 24 != 0 {
        return Err(format!(
            "truncated: {count} pairs declared, {} bytes",
            bytes.len()
        ));
    }
    let word =
        |i: usize| u32::from_le_bytes(bytes[16 + 4 * i..20 + 4 * i].try_into().expect("4 bytes"));
    Ok((0..count)
        .map(|p| {
            let at = 6 * p;
            (
                [word(at), word(at + 1), word(at + 2)],
                [word(at + 3), word(at + 4), word(at + 5)],
            )
        })
        .collect())
}

/// The mean relative luminance jump across `pairs` of `values` (pairs with a non-finite
/// side left out), 0 without pairs.
pub fn mean_relative_jump(values: &[[f32; 3]], pairs: &[(u32, u32)]) -> f64 {
    if pairs.is_empty() {
        return 0.0;
    }
    let lum = |i: u32| f64::from(luminance_f32(values[i as usize]));
    let finite: Vec<f64> = values
        .iter()
        .map(|v| f64::from(luminance_f32(*v)))
        .filter(|l| l.is_finite())
        .collect();
    let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
    let eps = 1e-2 * mean.abs().max(f64::MIN_POSITIVE);
    let jumps: Vec<f64> = pairs
        .iter()
        .map(|&(a, b)| (lum(a), lum(b)))
        .filter(|(la, lb)| la.is_finite() && lb.is_finite())
        .map(|(la, lb)| (la - lb).abs() / ((la + lb) / 2.0 + eps))
        .collect();
    jumps.iter().sum::<f64>() / jumps.len().max(1) as f64
}

/// Stitches `values` along `pairs` (indices into `values`) in place: the least-squares fit of
/// the module docs. Non-finite values take no part.
pub fn stitch(values: &mut [[f32; 3]], pairs: &[(u32, u32)]) {
    let finite = |v: &[f32; 3]| v.iter().all(|c| c.is_finite());
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); values.len()];
    for &(a, b) in pairs {
        if finite(&values[a as usize]) && finite(&values[b as usize]) {
            neighbours[a as usize].push(b);
            neighbours[b as usize].push(a);
        }
    }
    let baked = values.to_vec();
    for _ in 0..SWEEPS {
        for i in 0..values.len() {
            if neighbours[i].is_empty() {
                continue;
            }
            let mut sum = baked[i].map(f64::from);
            for &j in &neighbours[i] {
                for (c, s) in sum.iter_mut().enumerate() {
                    *s += f64::from(STITCH_WEIGHT) * f64::from(values[j as usize][c]);
                }
            }
            let weight = 1.0 + f64::from(STITCH_WEIGHT) * neighbours[i].len() as f64;
            values[i] = sum.map(|s| (s / weight) as f32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};
    use crate::scene::{Material, Triangle};
    use glam::Vec3;

    /// A 2 × 1 floor of two quads meeting at x = 1, each its own chart (side by side in the
    /// atlas with a gap), and a wall standing on the far edge (a crease, not a seam).
    fn cut_floor() -> Scene {
        let tri = |p: [Vec3; 3], uv: [Vec2; 3]| Triangle {
            positions: p,
            normals: [Vec3::Y; 3],
            lightmap_uv: Some(uv),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        let quad = |x0: f32, u0: f32, out: &mut Vec<Triangle>| {
            let p = |s: f32, t: f32| Vec3::new(x0 + s, 0.0, 1.0 - t);
            let uv = |s: f32, t: f32| Vec2::new(u0 + s * 0.4, 0.1 + t * 0.4);
            out.push(tri(
                [p(0., 0.), p(1., 0.), p(1., 1.)],
                [uv(0., 0.), uv(1., 0.), uv(1., 1.)],
            ));
            out.push(tri(
                [p(0., 0.), p(1., 1.), p(0., 1.)],
                [uv(0., 0.), uv(1., 1.), uv(0., 1.)],
            ));
        };
        let mut triangles = Vec::new();
        quad(0.0, 0.05, &mut triangles);
        quad(1.0, 0.55, &mut triangles);
        // The wall x = 2 on the floor's far edge, facing −x, its own chart.
        let w = |y: f32, z: f32| Vec3::new(2.0, y, z);
        let wuv = |s: f32, t: f32| Vec2::new(0.05 + s * 0.4, 0.55 + t * 0.4);
        triangles.push(tri(
            [w(0., 0.), w(0., 1.), w(1., 1.)],
            [wuv(0., 0.), wuv(1., 0.), wuv(1., 1.)],
        ));
        triangles.push(tri(
            [w(0., 0.), w(1., 1.), w(1., 0.)],
            [wuv(0., 0.), wuv(1., 1.), wuv(0., 1.)],
        ));
        Scene::of_triangles("cut floor", triangles, vec![Material::default_grey()])
    }

    #[test]
    fn the_cut_is_a_seam_and_the_crease_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let scene = cut_floor();
        let path = dir.path().join("floor.texels");
        let options = PrepareOptions {
            resolution: Resolution::Size(40, 40),
            layout: Layout::Shared,
        };
        prepare(&scene, &path, options).unwrap();
        let texels = TexelFile::open(&path).unwrap();
        let pairs = seam_pixel_pairs(&scene, &texels);
        // The cut: chart one's column x = 17 (u = 0.45 · 40 − ⅓) against chart two's x = 22.
        assert!(pairs.len() >= 16, "{pairs:?}");
        for &(a, b) in &pairs {
            assert_eq!((a[1], b[1]), (17, 22), "{a:?} {b:?}");
            assert!(
                a[2].abs_diff(b[2]) <= 1,
                "the same point along the edge: {a:?} {b:?}"
            );
        }
        let file = dir.path().join("floor.seams");
        write_seam_file(&file, &pairs).unwrap();
        assert_eq!(read_seam_file(&file).unwrap(), pairs);
        std::fs::write(&file, b"GBSEAMS1\x05\0\0\0\0\0\0\0").unwrap();
        assert!(read_seam_file(&file).unwrap_err().contains("truncated"));
    }

    #[test]
    fn stitching_closes_the_jump_and_keeps_the_mean() {
        // Ten seam pairs, side a at 1.0, side b at 2.0, plus an untouched value.
        let pairs: Vec<(u32, u32)> = (0..10).map(|i| (2 * i, 2 * i + 1)).collect();
        let mut values: Vec<[f32; 3]> = (0..21)
            .map(|i| {
                if i == 20 {
                    [7.0; 3]
                } else if i % 2 == 0 {
                    [1.0; 3]
                } else {
                    [2.0; 3]
                }
            })
            .collect();
        let before = mean_relative_jump(&values, &pairs);
        let sum_before: f32 = values.iter().map(|v| v[0]).sum();
        stitch(&mut values, &pairs);
        let after = mean_relative_jump(&values, &pairs);
        let sum_after: f32 = values.iter().map(|v| v[0]).sum();
        assert!((before - 1.0 / 1.5).abs() < 0.02, "{before}");
        assert!(after < 0.1 * before, "jump {before} → {after}");
        assert!(
            (sum_after - sum_before).abs() < 1e-3 * sum_before,
            "{sum_before} → {sum_after}"
        );
        assert_eq!(values[20], [7.0; 3]);
    }
}
