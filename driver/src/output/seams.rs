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
//! Each pair also keeps, per side, the pixel one step further into its triangle
//! ([`SeamPair`]): where the light's slope across the seam is measured.
//!
//! **Stitching** is a least-squares fit in which a pair is pulled together only as far as
//! its jump can be noise: minimise `Σ_i |x_i − x̂_i|² + Σ_pairs w_ab |x_a − x_b|²` over the
//! seam pixels' irradiance, `x̂` the estimate as written, with
//! `w_ab = min(Λ, s² / (2 τ²))`. Here `s² = σ_a² + σ_b²` is the noise of the pair's
//! difference (`σ` a texel's standard error: the bake's relative standard error × its
//! luminance) and `τ²` the squared difference the true irradiance has between the two texel
//! centres, estimated two ways and the larger kept: from the light's slope,
//! `τ = g · |P_a − P_b|` (`P` the centres' world positions, `g` the steeper of the two sides'
//! slopes between the seam texel and its inward neighbour, noise taken out:
//! `g² = max(0, (x̂ − x̂_in)² − σ² − σ_in²) / |P − P_in|²`), and from the jumps themselves,
//! `τ² = mean(δ² − s²)` over the pair and the [`POOL`] pairs on either side of it along the
//! seam (`δ` a pair's luminance jump; what the jumps exceed their noise by is the light's).
//! For one pair the jump shrinks by `1 + 2 w`: below the cap to `τ² / (τ² + s²)` of itself
//! (the Gaussian posterior mean of the true difference), and by `1 + 2Λ` = 17, Λ =
//! [`STITCH_STRENGTH`], where the jumps are all noise (τ = 0: as the unweighted stitch).
//! The unweighted stitch (`w = 8` for every pair) raised the RMSE against the reference on
//! the Veach bidir room 2.5×, a slope-only τ 1.8× (307 of its 481 pairs have no inward
//! texel to measure a slope with), and weighting the data term by 1/σ² as well made it
//! worse still (a texel that missed the lamp, with its small σ, would pin its brighter
//! partner); this one lowers it (docs/lightmaps.md). Solved by [`SWEEPS`] Gauss–Seidel
//! sweeps in a fixed order — a small sparse solve, deterministic, run on the merged
//! results, so shards still give one bake's bytes. Other pixels are untouched.
//!
//! Memory: detection holds one entry per triangle edge and the seams' pixel pairs (with their
//! texels' normals), never the atlas; stitching holds the seam pixels' values.
//!
//! The measure ([`mean_relative_jump`]): the mean over seam pairs of `|l_a − l_b| / (l̄ + ε)`,
//! `l` the luminance, `l̄` the pair's mean and `ε` a hundredth of the seam pixels' mean
//! luminance.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use guidebake_kernels::estimator::luminance_f32;

use crate::scene::Scene;
use crate::texels::TexelFile;

/// Smallest |cos| between the faces of a seam edge.
pub const PAIR_COS: f32 = 0.9;
/// Points sampled along a seam edge per atlas pixel of its longer side.
pub const SAMPLES_PER_PIXEL: f32 = 2.0;
/// Λ: the seam term's weight where the light is flat across the seam.
pub const STITCH_STRENGTH: f64 = 8.0;
/// Pairs on either side of a pair (in the seam file's order, along the seam) whose jumps
/// are pooled to judge whether the light jumps there.
pub const POOL: usize = 3;
/// Gauss–Seidel sweeps of the stitch.
pub const SWEEPS: usize = 32;
/// First bytes of a seam file.
const MAGIC: &[u8; 8] = b"GBSEAMS2";
/// `u32` words of one pair in a seam file.
const PAIR_WORDS: usize = 12;
/// An absent inward pixel in a seam file.
const NONE: u32 = u32::MAX;

/// An atlas pixel: page, x, y.
pub type Pixel = [u32; 3];

/// One pixel pair of a seam: pixels `a < b` on its two sides, and per side (`a`, then `b`)
/// the pixel one step further into that side's triangle, if it holds a texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SeamPair {
    /// The pixel on one side.
    pub a: Pixel,
    /// The pixel on the other side.
    pub b: Pixel,
    /// Each side's inward neighbour.
    pub inward: [Option<Pixel>; 2],
}

/// A [`SeamPair`] as indices into the values being stitched.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StitchPair {
    /// Index of side a's pixel.
    pub a: u32,
    /// Index of side b's pixel.
    pub b: u32,
    /// Indices of the sides' inward neighbours.
    pub inward: [Option<u32>; 2],
}

/// The file beside `texels` that holds its seam pairs.
pub fn seam_file_path(texels: &Path) -> PathBuf {
    let mut name = texels.as_os_str().to_owned();
    name.push(".seams");
    PathBuf::from(name)
}

/// The pixel pairs of every seam edge of `scene` in the atlas of `texels` (prepared from
/// it), sorted, each pair of pixels once (`a < b`).
pub fn seam_pixel_pairs(scene: &Scene, texels: &TexelFile) -> Vec<SeamPair> {
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
    pairs.retain(|p| match (normals.get(&p.a), normals.get(&p.b)) {
        (Some(na), Some(nb)) => na.dot(*nb) >= PAIR_COS,
        _ => false,
    });
    // An inward pixel without a texel (or facing elsewhere) measures nothing.
    for p in &mut pairs {
        for (side, own) in [p.a, p.b].into_iter().enumerate() {
            let keep = p.inward[side].is_some_and(|i| {
                normals
                    .get(&i)
                    .is_some_and(|n| n.dot(normals[&own]) >= PAIR_COS)
            });
            if !keep {
                p.inward[side] = None;
            }
        }
    }
    let key = |p: &SeamPair| (p.a, p.b, p.inward.map(|i| i.unwrap_or([NONE; 3])));
    pairs.sort_unstable_by_key(key);
    pairs.dedup_by_key(|p| (p.a, p.b));
    pairs
}

/// The normal of the texel at each pixel of `pairs` (pixels without a texel are absent):
/// memory for the seams' pixels only, not the atlas.
fn texel_normals(texels: &TexelFile, pairs: &[SeamPair]) -> HashMap<Pixel, glam::Vec3> {
    let mut normals: HashMap<Pixel, glam::Vec3> = pairs
        .iter()
        .flat_map(|p| [Some(p.a), Some(p.b), p.inward[0], p.inward[1]])
        .flatten()
        .map(|p| (p, glam::Vec3::ZERO))
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
    pairs: &mut Vec<SeamPair>,
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
        let side1 = side_of(texels, page1, (a1, b1), a1.lerp(b1, s), in1);
        let side2 = side_of(texels, page2, (a2, b2), a2.lerp(b2, s), in2);
        if let (Some(s1), Some(s2)) = (side1, side2)
            && s1.0 != s2.0
        {
            let (first, second) = if s1.0 < s2.0 { (s1, s2) } else { (s2, s1) };
            pairs.push(SeamPair {
                a: first.0,
                b: second.0,
                inward: [first.1, second.1],
            });
        }
    }
}

/// One side of a seam at point `p` of its edge `(a, b)` (pixel coordinates on `page`, the
/// triangle's centroid at `inside`): the pixel holding `p` nudged inwards ([`pixel_of`]) and
/// the pixel one step further in along the edge's inward normal.
fn side_of(
    texels: &TexelFile,
    page: u32,
    (a, b): (Vec2, Vec2),
    p: Vec2,
    inside: Vec2,
) -> Option<(Pixel, Option<Pixel>)> {
    let pixel = pixel_of(texels, page, p, inside)?;
    let centre = Vec2::new(pixel[1] as f32 + 0.5, pixel[2] as f32 + 0.5);
    let along = (b - a).normalize_or_zero();
    let mut normal = along.perp();
    if normal.dot(inside - a) < 0.0 {
        normal = -normal;
    }
    let step = centre + normal;
    let size = texels.pages().get(page as usize)?;
    let fits =
        step.x >= 0.0 && step.y >= 0.0 && step.x < size.width as f32 && step.y < size.height as f32;
    let inward = [page, step.x.floor() as u32, step.y.floor() as u32];
    Some((pixel, (fits && inward != pixel).then_some(inward)))
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
pub fn write_seam_file(path: &Path, pairs: &[SeamPair]) -> std::io::Result<()> {
    let mut bytes = Vec::with_capacity(16 + pairs.len() * 4 * PAIR_WORDS);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(pairs.len() as u64).to_le_bytes());
    for p in pairs {
        let inward = p.inward.map(|i| i.unwrap_or([NONE; 3]));
        for v in p.a.iter().chain(&p.b).chain(inward.as_flattened()) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    super::atomic::write(path, bytes)
}

/// Reads a seam file.
///
/// # Errors
/// A message naming what is wrong when the file is missing, not a seam file, or truncated.
pub fn read_seam_file(path: &Path) -> Result<Vec<SeamPair>, String> {
    let bytes = std::fs::read(path).map_err(|e| {
        format!(
            "cannot read the seam file ({e}): `guidebake prepare` writes it beside the texel file"
        )
    })?;
    if bytes.len() >= 8 && &bytes[..8] == b"GBSEAMS1" {
        return Err(
            "a seam file of an older guidebake (no inward pixels): run `guidebake prepare` again"
                .into(),
        );
    }
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err("not a guidebake seam file".into());
    }
    let count = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes")) as usize;
    let pair_bytes = 4 * PAIR_WORDS;
    if (bytes.len() - 16) / pair_bytes != count || (bytes.len() - 16) % pair_bytes != 0 {
        return Err(format!(
            "truncated: {count} pairs declared, {} bytes",
            bytes.len()
        ));
    }
    let word =
        |i: usize| u32::from_le_bytes(bytes[16 + 4 * i..20 + 4 * i].try_into().expect("4 bytes"));
    let pixel = |at: usize| [word(at), word(at + 1), word(at + 2)];
    Ok((0..count)
        .map(|p| {
            let at = PAIR_WORDS * p;
            let inward = |at: usize| Some(pixel(at)).filter(|i| *i != [NONE; 3]);
            SeamPair {
                a: pixel(at),
                b: pixel(at + 3),
                inward: [inward(at + 6), inward(at + 9)],
            }
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

/// The values a seam is stitched from, by index: irradiance, the squared standard error of
/// its luminance, and the texel's world position.
pub struct SeamValues<'a> {
    /// Irradiance (NaN where no texel was baked).
    pub rgb: &'a mut [[f32; 3]],
    /// Squared standard errors of the luminance.
    pub variance: &'a [f32],
    /// Texel centres in world space.
    pub position: &'a [Vec3],
}

/// Stitches `values` along `pairs` in place: the least-squares fit of the module docs.
/// Non-finite values take no part.
pub fn stitch(values: SeamValues<'_>, pairs: &[StitchPair]) {
    let links = seam_weights(&values, pairs);
    let rgb = values.rgb;
    let baked = rgb.to_vec();
    for _ in 0..SWEEPS {
        for i in 0..rgb.len() {
            if links[i].is_empty() {
                continue;
            }
            let mut sum = baked[i].map(f64::from);
            let mut weight = 1.0;
            for &(j, w) in &links[i] {
                for (c, s) in sum.iter_mut().enumerate() {
                    *s += w * f64::from(rgb[j as usize][c]);
                }
                weight += w;
            }
            rgb[i] = sum.map(|s| (s / weight) as f32);
        }
    }
}

/// Each value's seam partners and the weights `w_ab` of the module docs.
fn seam_weights(values: &SeamValues<'_>, pairs: &[StitchPair]) -> Vec<Vec<(u32, f64)>> {
    let rgb = &*values.rgb;
    let finite = |i: usize| rgb[i].iter().all(|c| c.is_finite());
    let lum = |i: usize| f64::from(luminance_f32(rgb[i]));
    let variance = |i: usize| {
        let v = f64::from(values.variance.get(i).copied().unwrap_or(0.0));
        if v.is_finite() { v.max(0.0) } else { 0.0 }
    };
    let position = |i: usize| values.position.get(i).copied().unwrap_or(Vec3::NAN);
    // The noise-free slope between a seam texel and its inward neighbour, per unit of world
    // distance (0 when there is no neighbour to measure it with).
    let slope = |own: usize, inner: Option<u32>| -> f64 {
        let Some(inner) = inner.map(|i| i as usize) else {
            return 0.0;
        };
        let d = f64::from(position(own).distance(position(inner)));
        if !(finite(inner) && d > 0.0 && d.is_finite()) {
            return 0.0;
        }
        let step = lum(own) - lum(inner);
        (step * step - variance(own) - variance(inner))
            .max(0.0)
            .sqrt()
            / d
    };
    // Per pair: the slope's τ², the excess of its squared jump over its noise, its noise.
    let stats: Vec<Option<(f64, f64, f64)>> = pairs
        .iter()
        .map(|p| {
            let (a, b) = (p.a as usize, p.b as usize);
            if !(finite(a) && finite(b)) {
                return None;
            }
            let g = slope(a, p.inward[0]).max(slope(b, p.inward[1]));
            let apart = f64::from(position(a).distance(position(b)));
            let across = if apart.is_finite() { g * apart } else { 0.0 };
            let noise = variance(a) + variance(b);
            let jump = lum(a) - lum(b);
            Some((across * across, jump * jump - noise, noise))
        })
        .collect();
    let mut links: Vec<Vec<(u32, f64)>> = vec![Vec::new(); rgb.len()];
    for (i, p) in pairs.iter().enumerate() {
        let Some((across2, _, noise)) = stats[i] else {
            continue;
        };
        // The jumps' excess over the noise, pooled over the pairs beside this one along
        // the seam (the seam file's order): one pair's own jump says little.
        let window = &stats[i.saturating_sub(POOL)..(i + POOL + 1).min(stats.len())];
        let (sum, n) = window
            .iter()
            .flatten()
            .fold((0.0, 0u32), |(s, n), &(_, excess, _)| (s + excess, n + 1));
        let tau2 = across2.max(sum / f64::from(n.max(1)));
        let w = if tau2 > 0.0 {
            (noise / (2.0 * tau2)).min(STITCH_STRENGTH)
        } else {
            STITCH_STRENGTH
        };
        links[p.a as usize].push((p.b, w));
        links[p.b as usize].push((p.a, w));
    }
    links
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
        for p in &pairs {
            let (a, b) = (p.a, p.b);
            assert_eq!((a[1], b[1]), (17, 22), "{a:?} {b:?}");
            assert!(
                a[2].abs_diff(b[2]) <= 1,
                "the same point along the edge: {a:?} {b:?}"
            );
            // The inward neighbours: one column further into each chart.
            assert_eq!(p.inward[0].map(|i| i[1]), Some(16), "{p:?}");
            assert_eq!(p.inward[1].map(|i| i[1]), Some(23), "{p:?}");
        }
        let file = dir.path().join("floor.seams");
        write_seam_file(&file, &pairs).unwrap();
        assert_eq!(read_seam_file(&file).unwrap(), pairs);
        std::fs::write(&file, b"GBSEAMS2\x05\0\0\0\0\0\0\0").unwrap();
        assert!(read_seam_file(&file).unwrap_err().contains("truncated"));
        std::fs::write(&file, b"GBSEAMS1\x05\0\0\0\0\0\0\0").unwrap();
        assert!(read_seam_file(&file).unwrap_err().contains("prepare"));
    }

    /// Pairs `(2i, 2i + 1)` of `n` values with inward neighbours `2n + 2i` and `2n + 2i + 1`.
    fn pairs_with_neighbours(n: u32) -> Vec<StitchPair> {
        (0..n)
            .map(|i| StitchPair {
                a: 2 * i,
                b: 2 * i + 1,
                inward: [Some(2 * n + 2 * i), Some(2 * n + 2 * i + 1)],
            })
            .collect()
    }

    /// World positions for [`pairs_with_neighbours`]: the texels of pair i at x = −0.5 and
    /// 0.5 (z = i), their inward neighbours at −1.5 and 1.5.
    fn positions(n: u32) -> Vec<Vec3> {
        let at = |i: u32, x: f32| Vec3::new(x, 0.0, i as f32);
        let pairs = (0..n).flat_map(|i| [at(i, -0.5), at(i, 0.5)]);
        let inward = (0..n).flat_map(|i| [at(i, -1.5), at(i, 1.5)]);
        pairs.chain(inward).collect()
    }

    #[test]
    fn stitching_closes_a_noisy_jump_and_keeps_the_mean() {
        // Ten seam pairs across flat light: side a at 1.0, side b at 2.0, their inward
        // neighbours equal to them, every value with standard error 1 (the jump is within
        // the noise); and an untouched value.
        let pairs = pairs_with_neighbours(10);
        let side = |i: usize| {
            if i.is_multiple_of(2) {
                [1.0; 3]
            } else {
                [2.0; 3]
            }
        };
        let mut rgb: Vec<[f32; 3]> = (0..40).map(side).collect();
        rgb.push([7.0; 3]);
        let variance = vec![1.0; rgb.len()];
        let mut position = positions(10);
        position.push(Vec3::ZERO);
        let jump_pairs: Vec<(u32, u32)> = pairs.iter().map(|p| (p.a, p.b)).collect();
        let before = mean_relative_jump(&rgb, &jump_pairs);
        let sum_before: f32 = rgb[..20].iter().map(|v| v[0]).sum();
        let values = SeamValues {
            rgb: &mut rgb,
            variance: &variance,
            position: &position,
        };
        stitch(values, &pairs);
        let after = mean_relative_jump(&rgb, &jump_pairs);
        let sum_after: f32 = rgb[..20].iter().map(|v| v[0]).sum();
        assert!((before - 1.0 / 1.5).abs() < 0.02, "{before}");
        assert!(after < 0.1 * before, "jump {before} → {after}");
        assert!(
            (sum_after - sum_before).abs() < 1e-3 * sum_before,
            "{sum_before} → {sum_after}"
        );
        assert_eq!(rgb[40], [7.0; 3]);
        assert_eq!(rgb[20..40], (20..40).map(side).collect::<Vec<_>>()[..]);
    }

    #[test]
    fn a_steep_gradient_across_the_seam_is_left_alone() {
        // The irradiance climbs 1 per unit across the edge: a's inward neighbour at 0, a at 1,
        // b at 2, b's inward neighbour at 3, each known to ±0.01. The jump is the light's.
        let pairs = pairs_with_neighbours(4);
        let mut rgb = Vec::new();
        for _ in 0..4 {
            rgb.extend([[1.0f32; 3], [2.0; 3]]);
        }
        for _ in 0..4 {
            rgb.extend([[0.0f32; 3], [3.0; 3]]);
        }
        let variance = vec![1e-4; rgb.len()];
        let position = positions(4);
        let baked = rgb.clone();
        let values = SeamValues {
            rgb: &mut rgb,
            variance: &variance,
            position: &position,
        };
        stitch(values, &pairs);
        for (v, b) in rgb.iter().zip(&baked) {
            assert!((v[0] - b[0]).abs() < 0.01, "{v:?} moved from {b:?}");
        }
        // Without the neighbours the jump itself, 100 standard errors, says it is the light's.
        let flat: Vec<StitchPair> = pairs
            .iter()
            .map(|p| StitchPair {
                inward: [None; 2],
                ..*p
            })
            .collect();
        let mut kept = baked.clone();
        let values = SeamValues {
            rgb: &mut kept,
            variance: &variance,
            position: &position,
        };
        stitch(values, &flat);
        assert!((kept[0][0] - kept[1][0] + 1.0).abs() < 0.01, "{kept:?}");
        // The same values known to ±1 only: the jump is noise and closes.
        let noisy = vec![1.0; baked.len()];
        let mut forced = baked.clone();
        let values = SeamValues {
            rgb: &mut forced,
            variance: &noisy,
            position: &position,
        };
        stitch(values, &flat);
        assert!((forced[0][0] - forced[1][0]).abs() < 0.1, "{forced:?}");
    }
}
