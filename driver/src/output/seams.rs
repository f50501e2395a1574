//! Seams: the two sides of a UV seam — one 3D edge, two charts (or two places of one chart)
//! — made to show the same light at the edge (`--seams stitch`).
//!
//! A lightmap is sampled bilinearly, so along a seam each side shows its own chart's border
//! texels and the padding dilated from them: two independent reconstructions of the light at
//! the same 3D points, and a visible jump where they differ.
//!
//! **Detection** ([`seam_samples`], run by `prepare`, which has the scene): every 3D edge
//! that two triangles share (the same two vertex positions, bit for bit) but that lies in
//! different places of the atlas is a seam edge, unless the faces meet at an angle (normals
//! with |cos| below [`PAIR_COS`]: a crease is lit differently on its two faces) or their
//! texels face opposite sides (a thin sheet's rim). Along the edge, [`SAMPLES_PER_PIXEL`]
//! points per atlas pixel are taken; each is kept as an [`EdgePoint`] — where it lies in
//! each side's chart, in pixel coordinates — and as a [`SeamPair`] of the pixels holding it
//! (nudged a third of a pixel into each triangle), for the texel-pair measure. They are kept
//! in a small file beside the texel file ([`seam_file_path`]), read when a bake or merge
//! finishes. Topology, not proximity: an earlier detector that paired border texels by
//! world distance also paired the floor on the two sides of a wall it runs under (measured in
//! docs/lightmaps.md).
//!
//! **Stitching** makes the *reconstructed value at the edge* agree, not the texels beside
//! it: at every edge point, the bilinear reconstruction from side a's written pixels at the
//! point's place in chart a must equal side b's at its place in chart b. A shader reads the
//! page's pixels as written — texels and the padding dilated from them — so a tap on a
//! padding pixel is expanded into the texels the dilation averages it from
//! ([`written_as`], the same passes as `exr_pages`' dilation); the unknowns are texels only,
//! and the padding, dilated again after the stitch, follows them. A point with a tap off the
//! page, beyond the padding (a pixel the page leaves black), or on a texel whose value is not
//! finite is left out and counted. Per colour channel, with `x̂` the values as baked,
//!
//! ```text
//! min Σ_i d_i (x_i − x̂_i)² + Σ_points λ_p (r_a(x) − r_b(x))²,
//! d_i = 1 / (1 + min(σ_i² / σ²_med, R)),      λ_p = K / Σ_i (a_pi² + b_pi²) / d_i
//! ```
//!
//! `r_a`, `r_b` the two reconstructions (linear in the texels, `a_pi` and `b_pi` their
//! coefficients, `c_p = a_p − b_p`), `σ_i` the texel's standard error (the bake's relative standard error × its
//! luminance), σ²_med the median over the unknowns and R = [`NOISE_RANGE`]: a noisy texel
//! gives way more than a certain one, by at most 1 + R (a first version weighted by
//! `1 / (σ_i² + σ̄²/4)`; on the Veach ajar room, whose fireflies make some σ huge, it gave
//! texels nearly free to move, which the edge terms then drove negative). λ_p scales each
//! point so that alone it would close its jump to 1/(1 + K), K = [`EDGE_STRENGTH`]: not
//! hard, because a texel the edge reads only at a small weight (one the padding beside a
//! chart's corner averages in) would otherwise be moved many times as far as the jump (in
//! the gradient test, K = 1000 moved such a texel 8× as far as K = 30). For the same reason
//! a texel that no edge point reads at a weight of [`MIN_TAP`] or more is held (its data
//! weight × 10⁶); on the converted scenes that lowered the stitched RMSE (docs). Only
//! texels the edge points' taps reach take part: texels further in keep their values, and
//! with them the light's gradient. Solved by preconditioned conjugate gradients (Jacobi) on the normal equations
//! ([`EdgeStitch::solve`]), in f64, in a fixed order — deterministic, run on the merged
//! results, so shards still give one bake's bytes. The same linear operator (weights from
//! the irradiance) applies to every channel, the directional ones too.
//!
//! Measured on the converted scenes (docs/lightmaps.md), the stitch closes the jumps at the
//! edge but raises the RMSE against the reference: the reference's own bilinear values at
//! the edge disagree about as much as a bake's, so they are the reconstruction's error (two
//! pixels of box dilation beside a border texel), not noise, and forcing them equal moves
//! the texels away from the light. `--seams` stays off by default.
//!
//! An earlier stitch pulled the seam *texel pairs* together as far as their jump could be
//! noise; it kept the jumps that are the light's change between the two texel centres,
//! which a shader still shows at the edge. Its figures are in docs/lightmaps.md.
//!
//! Memory: detection holds one entry per triangle edge and the seams' samples, never the
//! atlas; stitching holds the values of the pixels the edge points read (and their
//! dilation's sources).
//!
//! The measures: [`mean_relative_jump`] over texel pairs, and [`EdgeSystem::edge_jump`],
//! the same over the edge points' two reconstructions — `|l_a − l_b| / (l̄ + ε)`, `l` the
//! luminance, `l̄` the two's mean and `ε` a hundredth of the mean luminance of the pixels
//! read.

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
/// K: how far one edge point's term alone closes its jump, to 1/(1 + K).
pub const EDGE_STRENGTH: f64 = 30.0;
/// R: a texel's variance counts up to R times the median's: `d_i = 1 / (1 + min(σ_i² / σ²_med, R))`.
pub const NOISE_RANGE: f64 = 8.0;
/// Most solves of [`stitch_channels`]: each holds the texels the last took below zero.
pub const MAX_ROUNDS: usize = 8;
/// Smallest weight at which some edge point must read a texel for the stitch to move it.
pub const MIN_TAP: f64 = 0.25;
/// The factor on a held texel's data weight.
const HELD: f64 = 1e6;
/// Most conjugate-gradient iterations of a stitch.
pub const MAX_ITERATIONS: usize = 1000;
/// The solve stops when the residual is this fraction of the right-hand side's norm.
const TOLERANCE: f64 = 1e-9;
/// First bytes of a seam file.
const MAGIC: &[u8; 8] = b"GBSEAMS3";
/// `u32` words of one pair in a seam file.
const PAIR_WORDS: usize = 6;
/// `u32` words of one edge point in a seam file (page, x, y per side; f32 bits).
const POINT_WORDS: usize = 6;

/// An atlas pixel: page, x, y.
pub type Pixel = [u32; 3];

/// The pixels holding one edge point on the seam's two sides, `a < b`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SeamPair {
    /// The pixel on one side.
    pub a: Pixel,
    /// The pixel on the other side.
    pub b: Pixel,
}

/// One sample point of a seam edge: where it lies on each side, the page and the point in
/// that page's pixel coordinates (pixel `x` spans `[x, x + 1)`, its centre at `x + ½`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgePoint {
    /// Each side's page.
    pub page: [u32; 2],
    /// Each side's place on its page, in pixels.
    pub at: [[f32; 2]; 2],
}

/// What `prepare` finds of a texel file's seams.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SeamSamples {
    /// The texel pairs, sorted, each once.
    pub pairs: Vec<SeamPair>,
    /// The edge points, sorted, each once.
    pub points: Vec<EdgePoint>,
}

/// The file beside `texels` that holds its seam samples.
pub fn seam_file_path(texels: &Path) -> PathBuf {
    let mut name = texels.as_os_str().to_owned();
    name.push(".seams");
    PathBuf::from(name)
}

/// The samples of every seam edge of `scene` in the atlas of `texels` (prepared from it).
pub fn seam_samples(scene: &Scene, texels: &TexelFile) -> SeamSamples {
    type Key = ([u32; 3], [u32; 3]);
    let bits = |v: glam::Vec3| v.to_array().map(f32::to_bits);
    let mut edges: HashMap<Key, Vec<(usize, usize)>> = HashMap::new();
    for (t, tri) in scene.triangles.iter().enumerate() {
        if pixel_corners(texels, t).is_none() {
            continue;
        }
        for e in 0..3 {
            let (a, b) = (bits(tri.positions[e]), bits(tri.positions[(e + 1) % 3]));
            edges.entry((a.min(b), a.max(b))).or_default().push((t, e));
        }
    }
    let mut keys: Vec<&Key> = edges.keys().collect();
    keys.sort_unstable();
    let mut found = Vec::new();
    for key in keys {
        let sides = &edges[key];
        for (i, &(t1, e1)) in sides.iter().enumerate() {
            for &(t2, e2) in &sides[i + 1..] {
                edge_samples(scene, texels, (t1, e1), (t2, e2), &mut found);
            }
        }
    }
    // Both pixels must hold a texel, and the texels face the same side (the two faces of a
    // thin sheet share its rim but not their light).
    let normals = texel_normals(texels, &found);
    found.retain(|(p, _)| match (normals.get(&p.a), normals.get(&p.b)) {
        (Some(na), Some(nb)) => na.dot(*nb) >= PAIR_COS,
        _ => false,
    });
    let mut pairs: Vec<SeamPair> = found.iter().map(|(p, _)| *p).collect();
    pairs.sort_unstable_by_key(|p| (p.a, p.b));
    pairs.dedup();
    let point_key = |p: &EdgePoint| (p.page, p.at.map(|a| a.map(f32::to_bits)));
    let mut points: Vec<EdgePoint> = found.into_iter().map(|(_, q)| q).collect();
    points.sort_unstable_by_key(point_key);
    points.dedup_by_key(|p| point_key(p));
    SeamSamples { pairs, points }
}

/// The normal of the texel at each pixel of `found` (pixels without a texel are absent):
/// memory for the seams' pixels only, not the atlas.
fn texel_normals(
    texels: &TexelFile,
    found: &[(SeamPair, EdgePoint)],
) -> HashMap<Pixel, glam::Vec3> {
    let mut normals: HashMap<Pixel, glam::Vec3> = found
        .iter()
        .flat_map(|(p, _)| [p.a, p.b])
        .map(|p| (p, glam::Vec3::ZERO))
        .collect();
    let mut seen = std::collections::HashSet::new();
    for t in 0..texels.tiles().len() {
        for texel in texels.tile_texels(t) {
            let [x, y] = texel.pixel.map(u32::from);
            let pixel = [texel.page, x, y];
            if let Some(n) = normals.get_mut(&pixel) {
                *n = texel.normal();
                seen.insert(pixel);
            }
        }
        texels.release_tile(t);
    }
    normals.retain(|p, _| seen.contains(p));
    normals
}

/// Where triangle `t`'s lightmap lies (the texel file's triangle table): its page and its
/// corners in pixel coordinates.
fn pixel_corners(texels: &TexelFile, t: usize) -> Option<(u32, [Vec2; 3])> {
    texels.triangles().get(t)?.pixel_uv()
}

/// Adds the samples of the edge shared by edge `e1` of triangle `t1` and edge `e2` of `t2`,
/// if it is a seam.
fn edge_samples(
    scene: &Scene,
    texels: &TexelFile,
    (t1, e1): (usize, usize),
    (t2, e2): (usize, usize),
    found: &mut Vec<(SeamPair, EdgePoint)>,
) {
    let (tri1, tri2) = (&scene.triangles[t1], &scene.triangles[t2]);
    if tri1.geometric_normal().dot(tri2.geometric_normal()).abs() < PAIR_COS {
        return;
    }
    let (Some((page1, c1)), Some((page2, c2))) =
        (pixel_corners(texels, t1), pixel_corners(texels, t2))
    else {
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
        let (p1, p2) = (a1.lerp(b1, s), a2.lerp(b2, s));
        let side1 = pixel_of(texels, page1, p1, in1);
        let side2 = pixel_of(texels, page2, p2, in2);
        let (Some(s1), Some(s2)) = (side1, side2) else {
            continue;
        };
        if s1 == s2 {
            continue;
        }
        let (first, second) = if s1 < s2 {
            ((s1, page1, p1), (s2, page2, p2))
        } else {
            ((s2, page2, p2), (s1, page1, p1))
        };
        found.push((
            SeamPair {
                a: first.0,
                b: second.0,
            },
            EdgePoint {
                page: [first.1, second.1],
                at: [first.2.to_array(), second.2.to_array()],
            },
        ));
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
/// beside it ([`seam_file_path`]); returns the number of texel pairs.
///
/// # Errors
/// A message naming the file that cannot be opened or written.
pub fn prepare_seams(scene: &Scene, texels: &Path) -> Result<usize, String> {
    let file = TexelFile::open(texels).map_err(|e| e.to_string())?;
    let samples = seam_samples(scene, &file);
    let path = seam_file_path(texels);
    write_seam_file(&path, &samples)
        .map_err(|e| format!("{}: cannot write: {e}", path.display()))?;
    Ok(samples.pairs.len())
}

/// Writes `samples` to the seam file at `path` (through a temporary name).
///
/// # Errors
/// The I/O error, when the file cannot be written.
pub fn write_seam_file(path: &Path, samples: &SeamSamples) -> std::io::Result<()> {
    let (pairs, points) = (&samples.pairs, &samples.points);
    let mut bytes =
        Vec::with_capacity(24 + 4 * (pairs.len() * PAIR_WORDS + points.len() * POINT_WORDS));
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(pairs.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&(points.len() as u64).to_le_bytes());
    for p in pairs {
        for v in p.a.iter().chain(&p.b) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    for q in points {
        for side in 0..2 {
            let [x, y] = q.at[side].map(f32::to_bits);
            for v in [q.page[side], x, y] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    crate::atomic::write(path, bytes)
}

/// Reads a seam file.
///
/// # Errors
/// A message naming what is wrong when the file is missing, not a seam file, of an older
/// guidebake, or truncated.
pub fn read_seam_file(path: &Path) -> Result<SeamSamples, String> {
    let bytes = std::fs::read(path).map_err(|e| {
        format!(
            "cannot read the seam file ({e}): `guidebake prepare` writes it beside the texel file"
        )
    })?;
    if bytes.len() >= 8 && (&bytes[..8] == b"GBSEAMS1" || &bytes[..8] == b"GBSEAMS2") {
        return Err(
            "a seam file of an older guidebake (no edge points): run `guidebake prepare` again"
                .into(),
        );
    }
    if bytes.len() < 24 || &bytes[..8] != MAGIC {
        return Err("not a guidebake seam file".into());
    }
    let count = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    let (pairs, points) = (count(8), count(16));
    let words = (pairs as u128) * PAIR_WORDS as u128 + (points as u128) * POINT_WORDS as u128;
    if (bytes.len() - 24) as u128 != 4 * words {
        return Err(format!(
            "truncated: {pairs} pairs and {points} edge points declared, {} bytes",
            bytes.len()
        ));
    }
    let word =
        |i: usize| u32::from_le_bytes(bytes[24 + 4 * i..28 + 4 * i].try_into().expect("4 bytes"));
    let pixel = |at: usize| [word(at), word(at + 1), word(at + 2)];
    let pairs = pairs as usize;
    let first_point = PAIR_WORDS * pairs;
    Ok(SeamSamples {
        pairs: (0..pairs)
            .map(|p| SeamPair {
                a: pixel(PAIR_WORDS * p),
                b: pixel(PAIR_WORDS * p + 3),
            })
            .collect(),
        points: (0..points as usize)
            .map(|q| {
                let side = |at: usize| (word(at), [word(at + 1), word(at + 2)].map(f32::from_bits));
                let (pa, a) = side(first_point + POINT_WORDS * q);
                let (pb, b) = side(first_point + POINT_WORDS * q + 3);
                EdgePoint {
                    page: [pa, pb],
                    at: [a, b],
                }
            })
            .collect(),
    })
}

/// The mean relative luminance jump across `pairs` of `values` (pairs with a non-finite
/// side left out), 0 without pairs.
pub fn mean_relative_jump(values: &[[f32; 3]], pairs: &[(u32, u32)]) -> f64 {
    let lum = |i: u32| f64::from(luminance_f32(values[i as usize]));
    let finite: Vec<f64> = values
        .iter()
        .map(|v| f64::from(luminance_f32(*v)))
        .filter(|l| l.is_finite())
        .collect();
    let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
    relative_jumps(pairs.iter().map(|&(a, b)| (lum(a), lum(b))), mean)
}

/// The mean of `|a − b| / ((a + b)/2 + ε)` over the finite pairs `(a, b)`, ε a hundredth
/// of `mean`; 0 without any.
fn relative_jumps(pairs: impl Iterator<Item = (f64, f64)>, mean: f64) -> f64 {
    let eps = 1e-2 * mean.abs().max(f64::MIN_POSITIVE);
    let (sum, n) = pairs
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .fold((0.0, 0usize), |(s, n), (a, b)| {
            (s + (a - b).abs() / ((a + b) / 2.0 + eps), n + 1)
        });
    sum / n.max(1) as f64
}

/// The bilinear taps of a point at `at` (pixels) on a page, as a GPU filters: the four pixels
/// whose centres surround it and their weights (pixel coordinates may lie off the page).
fn bilinear_taps(at: [f32; 2]) -> [([i64; 2], f64); 4] {
    let [x, y] = at.map(|c| f64::from(c) - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    [
        ([x0, y0], (1.0 - fx) * (1.0 - fy)),
        ([x0 + 1, y0], fx * (1.0 - fy)),
        ([x0, y0 + 1], (1.0 - fx) * fy),
        ([x0 + 1, y0 + 1], fx * fy),
    ]
}

/// What one pixel of a page looks like to [`written_as`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Written {
    /// No texel: black, or padding if dilation reaches it.
    Empty,
    /// A texel with a finite value.
    Texel,
    /// A texel whose value is not finite (the page holds 0 there).
    NonFinite,
}

/// The page-level facts [`edge_system`] needs: a page's size and what a pixel holds.
pub trait PageFacts {
    /// Width and height of `page`, if it exists.
    fn size(&self, page: u32) -> Option<(u32, u32)>;
    /// What pixel `p` holds.
    fn written(&self, p: Pixel) -> Written;
}

/// The written value of pixel (`page`, `x`, `y`) as a combination of texels, after `passes`
/// passes of the page writer's dilation (each fills an empty pixel with the mean of its
/// 8-neighbours filled before it): the pixel itself if it holds a texel; `None` off the page
/// or where dilation does not reach (the page holds 0 there).
pub fn written_as(
    facts: &dyn PageFacts,
    page: u32,
    [x, y]: [i64; 2],
    passes: u32,
) -> Option<Vec<(Pixel, f64)>> {
    let (w, h) = facts.size(page)?;
    let on_page = |x: i64, y: i64| (0..i64::from(w)).contains(&x) && (0..i64::from(h)).contains(&y);
    // The pass that fills (x, y) (0: a texel), if it is filled within `limit` passes.
    fn level(
        facts: &dyn PageFacts,
        on_page: &dyn Fn(i64, i64) -> bool,
        page: u32,
        [x, y]: [i64; 2],
        limit: u32,
    ) -> Option<u32> {
        if !on_page(x, y) {
            return None;
        }
        if facts.written([page, x as u32, y as u32]) != Written::Empty {
            return Some(0);
        }
        if limit == 0 {
            return None;
        }
        neighbours(x, y)
            .filter_map(|q| level(facts, on_page, page, q, limit - 1))
            .min()
            .map(|l| l + 1)
    }
    fn expand(
        facts: &dyn PageFacts,
        on_page: &dyn Fn(i64, i64) -> bool,
        page: u32,
        [x, y]: [i64; 2],
        at: u32,
        weight: f64,
        out: &mut Vec<(Pixel, f64)>,
    ) {
        if at == 0 {
            out.push(([page, x as u32, y as u32], weight));
            return;
        }
        let sources: Vec<([i64; 2], u32)> = neighbours(x, y)
            .filter_map(|q| Some((q, level(facts, on_page, page, q, at - 1)?)))
            .collect();
        let share = weight / sources.len() as f64;
        for (q, l) in sources {
            expand(facts, on_page, page, q, l, share, out);
        }
    }
    let at = level(facts, &on_page, page, [x, y], passes)?;
    let mut terms = Vec::new();
    expand(facts, &on_page, page, [x, y], at, 1.0, &mut terms);
    Some(merge_terms(terms))
}

/// The 8-neighbours of (`x`, `y`), row by row.
fn neighbours(x: i64, y: i64) -> impl Iterator<Item = [i64; 2]> {
    (y - 1..=y + 1)
        .flat_map(move |ny| (x - 1..=x + 1).map(move |nx| [nx, ny]))
        .filter(move |&[nx, ny]| (nx, ny) != (x, y))
}

/// `terms` sorted by key with equal keys summed.
fn merge_terms<K: Ord + Copy>(mut terms: Vec<(K, f64)>) -> Vec<(K, f64)> {
    terms.sort_by_key(|t| t.0);
    let mut merged: Vec<(K, f64)> = Vec::with_capacity(terms.len());
    for (k, w) in terms {
        match merged.last_mut() {
            Some(last) if last.0 == k => last.1 += w,
            _ => merged.push((k, w)),
        }
    }
    merged
}

/// The pixels the reconstructions at `points` may read, and the pixels the dilation fills
/// those from (`passes` around each tap): what [`edge_system`] asks [`PageFacts`] about.
pub fn pixels_read(points: &[EdgePoint], passes: u32) -> Vec<Pixel> {
    let reach = i64::from(passes);
    let mut pixels: Vec<Pixel> = points
        .iter()
        .flat_map(|q| (0..2).map(move |side| (q.page[side], q.at[side])))
        .flat_map(|(page, at)| {
            bilinear_taps(at).into_iter().flat_map(move |([x, y], _)| {
                (y - reach..=y + reach)
                    .flat_map(move |ny| (x - reach..=x + reach).map(move |nx| (nx, ny)))
                    .filter(|&(nx, ny)| {
                        nx >= 0 && ny >= 0 && nx <= u32::MAX as i64 && ny <= u32::MAX as i64
                    })
                    .map(move |(nx, ny)| [page, nx as u32, ny as u32])
            })
        })
        .collect();
    pixels.sort_unstable();
    pixels.dedup();
    pixels
}

/// The edge points' reconstructions as linear functions of the texels they read.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeSystem {
    /// The texels read: the stitch's unknowns, sorted.
    pub pixels: Vec<Pixel>,
    /// Per edge point kept, each side's reconstruction as (unknown, weight).
    rows: Vec<[Vec<(u32, f64)>; 2]>,
    /// Edge points left out: a tap off the page, beyond the padding, or on a texel whose
    /// value is not finite.
    pub skipped: usize,
}

/// The reconstructions at `points` on pages described by `facts`, dilated `passes` pixels.
pub fn edge_system(points: &[EdgePoint], facts: &dyn PageFacts, passes: u32) -> EdgeSystem {
    let mut sides: Vec<[Vec<(Pixel, f64)>; 2]> = Vec::new();
    let mut skipped = 0;
    'points: for q in points {
        let mut row: [Vec<(Pixel, f64)>; 2] = Default::default();
        for (side, terms) in row.iter_mut().enumerate() {
            for (tap, w) in bilinear_taps(q.at[side]) {
                if w == 0.0 {
                    continue;
                }
                let Some(texels) = written_as(facts, q.page[side], tap, passes) else {
                    skipped += 1;
                    continue 'points;
                };
                if texels
                    .iter()
                    .any(|(p, _)| facts.written(*p) != Written::Texel)
                {
                    skipped += 1;
                    continue 'points;
                }
                terms.extend(texels.into_iter().map(|(p, t)| (p, w * t)));
            }
            *terms = merge_terms(std::mem::take(terms));
        }
        sides.push(row);
    }
    let mut pixels: Vec<Pixel> = sides.iter().flatten().flatten().map(|t| t.0).collect();
    pixels.sort_unstable();
    pixels.dedup();
    let index = |p: &Pixel| pixels.binary_search(p).expect("a pixel read") as u32;
    let rows = sides
        .iter()
        .map(|row| {
            row.clone()
                .map(|terms| terms.iter().map(|(p, w)| (index(p), *w)).collect())
        })
        .collect();
    EdgeSystem {
        pixels,
        rows,
        skipped,
    }
}

impl EdgeSystem {
    /// Edge points kept.
    pub fn points(&self) -> usize {
        self.rows.len()
    }

    /// The reconstruction of one side of row `r` from `values` (one per unknown).
    fn reconstruct(&self, r: usize, side: usize, values: &[[f32; 3]]) -> [f64; 3] {
        let mut sum = [0.0; 3];
        for &(i, w) in &self.rows[r][side] {
            for (s, v) in sum.iter_mut().zip(values[i as usize]) {
                *s += w * f64::from(v);
            }
        }
        sum
    }

    /// The mean relative luminance jump between the two reconstructions at the edge points
    /// from `values` (irradiance per unknown), 0 without points.
    pub fn edge_jump(&self, values: &[[f32; 3]]) -> f64 {
        let lum = |rgb: [f64; 3]| f64::from(luminance_f32(rgb.map(|c| c as f32)));
        let mean = values
            .iter()
            .map(|v| f64::from(luminance_f32(*v)))
            .sum::<f64>()
            / values.len().max(1) as f64;
        let jumps = (0..self.rows.len()).map(|r| {
            (
                lum(self.reconstruct(r, 0, values)),
                lum(self.reconstruct(r, 1, values)),
            )
        });
        relative_jumps(jumps, mean)
    }
}

/// The stitch of an [`EdgeSystem`]: the least-squares problem of the module docs, weighted
/// by the unknowns' variances, ready to solve for any channel.
pub struct EdgeStitch {
    /// d_i per unknown.
    data: Vec<f64>,
    /// Per edge point: λ_p and the coefficients of r_a − r_b, (unknown, c).
    terms: Vec<(f64, Vec<(u32, f64)>)>,
    /// The normal matrix's diagonal (the preconditioner).
    diagonal: Vec<f64>,
}

impl EdgeStitch {
    /// The stitch of `system` for unknowns whose luminance has squared standard errors
    /// `variance` (one per unknown; non-finite or negative taken as 0), those marked in
    /// `held` (missing: not held) kept at their values.
    pub fn new(system: &EdgeSystem, variance: &[f32], held: &[bool]) -> Self {
        let n = system.pixels.len();
        let v: Vec<f64> = (0..n)
            .map(|i| f64::from(variance.get(i).copied().unwrap_or(0.0)))
            .map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 })
            .collect();
        let mut positive: Vec<f64> = v.iter().copied().filter(|v| *v > 0.0).collect();
        positive.sort_unstable_by(f64::total_cmp);
        let median = positive.get(positive.len() / 2).copied().unwrap_or(0.0);
        let mut data: Vec<f64> = v
            .iter()
            .map(|v| {
                let relative = if median > 0.0 { v / median } else { 0.0 };
                1.0 / (1.0 + relative.min(NOISE_RANGE))
            })
            .collect();
        // A texel no edge point reads at a weight of MIN_TAP or more (one that the padding
        // beside a chart's corner averages in) is held: moving it would take it many times
        // as far as the jump it closes.
        let mut reach = vec![0.0f64; n];
        for (i, w) in system.rows.iter().flatten().flatten() {
            reach[*i as usize] = reach[*i as usize].max(w.abs());
        }
        for (i, (d, r)) in data.iter_mut().zip(&reach).enumerate() {
            if *r < MIN_TAP || held.get(i).copied().unwrap_or(false) {
                *d *= HELD;
            }
        }
        let terms: Vec<(f64, Vec<(u32, f64)>)> = system
            .rows
            .iter()
            .filter_map(|[a, b]| {
                let c = merge_terms(
                    a.iter()
                        .copied()
                        .chain(b.iter().map(|&(i, w)| (i, -w)))
                        .collect(),
                );
                // Each side's own spread, not the difference's: where the two sides read
                // the same texels (a seam whose sides lie side by side in the atlas) the
                // difference's coefficients nearly cancel, and a scale taken from them would
                // make the term all but hard on a tiny difference.
                let spread: f64 = a
                    .iter()
                    .chain(b)
                    .map(|&(i, w)| w * w / data[i as usize])
                    .sum();
                (spread > 0.0).then(|| (EDGE_STRENGTH / spread, c))
            })
            .collect();
        let mut diagonal = data.clone();
        for (lambda, c) in &terms {
            for &(i, c) in c {
                diagonal[i as usize] += lambda * c * c;
            }
        }
        Self {
            data,
            terms,
            diagonal,
        }
    }

    /// The normal matrix times `x`: `D x + Σ_p λ_p c_p (c_p · x)`.
    fn apply(&self, x: &[f64], out: &mut [f64]) {
        for ((o, d), x) in out.iter_mut().zip(&self.data).zip(x) {
            *o = d * x;
        }
        for (lambda, c) in &self.terms {
            let dot: f64 = c.iter().map(|&(i, c)| c * x[i as usize]).sum();
            for &(i, c) in c {
                out[i as usize] += lambda * c * dot;
            }
        }
    }

    /// The stitched values of one channel, `baked` its values as baked (one per unknown):
    /// preconditioned conjugate gradients from the baked values, at most
    /// [`MAX_ITERATIONS`], in a fixed order.
    pub fn solve(&self, baked: &[f32]) -> Vec<f32> {
        let n = self.data.len();
        let mut x: Vec<f64> = baked.iter().map(|&v| f64::from(v)).collect();
        let rhs_norm = x
            .iter()
            .zip(&self.data)
            .map(|(x, d)| (x * d) * (x * d))
            .sum::<f64>()
            .sqrt();
        let mut ax = vec![0.0; n];
        self.apply(&x, &mut ax);
        // r = D x̂ − A x̂ = −Σ λ c (c·x̂).
        let mut r: Vec<f64> = (0..n).map(|i| self.data[i] * x[i] - ax[i]).collect();
        let mut z: Vec<f64> = r.iter().zip(&self.diagonal).map(|(r, d)| r / d).collect();
        let mut p = z.clone();
        let mut rz: f64 = r.iter().zip(&z).map(|(r, z)| r * z).sum();
        let mut ap = vec![0.0; n];
        for _ in 0..MAX_ITERATIONS {
            let r_norm = r.iter().map(|r| r * r).sum::<f64>().sqrt();
            if r_norm.is_nan() || r_norm <= TOLERANCE * rhs_norm {
                break;
            }
            self.apply(&p, &mut ap);
            let pap: f64 = p.iter().zip(&ap).map(|(p, a)| p * a).sum();
            if pap.is_nan() || pap <= 0.0 {
                break;
            }
            let alpha = rz / pap;
            for i in 0..n {
                x[i] += alpha * p[i];
                r[i] -= alpha * ap[i];
                z[i] = r[i] / self.diagonal[i];
            }
            let rz_next: f64 = r.iter().zip(&z).map(|(r, z)| r * z).sum();
            let beta = rz_next / rz;
            rz = rz_next;
            for i in 0..n {
                p[i] = z[i] + beta * p[i];
            }
        }
        x.iter()
            .zip(baked)
            .map(|(&v, &b)| if v.is_finite() { v as f32 } else { b })
            .collect()
    }
}

/// Stitches `channels` (one value per unknown of `system` each; the first three are the
/// irradiance, any more are stitched with the same operator) in place, `variance` the
/// irradiance luminance's squared standard errors. Irradiance cannot be negative: a texel
/// the solve takes below zero in an irradiance channel is held at its baked value and the
/// solve repeated, at most [`MAX_ROUNDS`] times. Returns the texels so held.
pub fn stitch_channels(system: &EdgeSystem, variance: &[f32], channels: &mut [Vec<f32>]) -> usize {
    let n = system.pixels.len();
    let mut held = vec![false; n];
    let mut stitch = EdgeStitch::new(system, variance, &held);
    for _ in 0..MAX_ROUNDS {
        let mut more = false;
        for channel in channels.iter().take(3) {
            for (i, v) in stitch.solve(channel).into_iter().enumerate() {
                if v < 0.0 && !held[i] {
                    held[i] = true;
                    more = true;
                }
            }
        }
        if !more {
            break;
        }
        stitch = EdgeStitch::new(system, variance, &held);
    }
    for channel in channels.iter_mut() {
        *channel = stitch.solve(channel);
    }
    held.iter().filter(|h| **h).count()
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
        let samples = seam_samples(&scene, &texels);
        let pairs = &samples.pairs;
        // The cut: chart one's column x = 17 (u = 0.45 · 40 − ⅓) against chart two's x = 22.
        assert!(pairs.len() >= 16, "{pairs:?}");
        for p in pairs {
            let (a, b) = (p.a, p.b);
            assert_eq!((a[1], b[1]), (17, 22), "{a:?} {b:?}");
            assert!(
                a[2].abs_diff(b[2]) <= 1,
                "the same point along the edge: {a:?} {b:?}"
            );
        }
        // The edge points: on the cut, u = 0.45 and 0.55 of the page (x = 18 and 22), two
        // per pixel along its 16 pixels.
        assert_eq!(samples.points.len(), 32, "{:?}", samples.points);
        for q in &samples.points {
            assert_eq!(q.page, [0, 0]);
            assert!((q.at[0][0] - 18.0).abs() < 1e-4, "{q:?}");
            assert!((q.at[1][0] - 22.0).abs() < 1e-4, "{q:?}");
            assert!((q.at[0][1] - q.at[1][1]).abs() < 1e-4, "{q:?}");
        }
        let file = dir.path().join("floor.seams");
        write_seam_file(&file, &samples).unwrap();
        assert_eq!(read_seam_file(&file).unwrap(), samples);
        let mut bytes = std::fs::read(&file).unwrap();
        bytes.pop();
        std::fs::write(&file, &bytes).unwrap();
        assert!(read_seam_file(&file).unwrap_err().contains("truncated"));
        std::fs::write(&file, b"GBSEAMS2\x05\0\0\0\0\0\0\0").unwrap();
        assert!(read_seam_file(&file).unwrap_err().contains("prepare"));
    }

    /// Pixels with texels on one page of `width` × `height`: a [`PageFacts`] for the tests.
    struct Atlas {
        width: u32,
        height: u32,
        texels: HashMap<Pixel, f32>,
    }

    impl PageFacts for Atlas {
        fn size(&self, page: u32) -> Option<(u32, u32)> {
            (page == 0).then_some((self.width, self.height))
        }
        fn written(&self, p: Pixel) -> Written {
            match self.texels.get(&p) {
                None => Written::Empty,
                Some(v) if v.is_finite() => Written::Texel,
                Some(_) => Written::NonFinite,
            }
        }
    }

    /// Two charts of one plane, 8 × 8 texels each, meeting along the plane's line u = 1:
    /// chart a covers pixels x ∈ [2, 10) (u ∈ [0, 1]), chart b x ∈ [14, 22) (u ∈ [1, 2]),
    /// both y ∈ [2, 10) (w ∈ [0, 1]); `light(u, w)` at each texel centre. The seam's edge
    /// points: two per pixel, at x = 10 in a and x = 14 in b.
    fn two_charts(light: impl Fn(f32, f32) -> f32) -> (Atlas, Vec<EdgePoint>) {
        let mut texels = HashMap::new();
        for y in 2..10u32 {
            let w = (y as f32 - 1.5) / 8.0;
            for x in 2..10u32 {
                texels.insert([0, x, y], light((x as f32 - 1.5) / 8.0, w));
            }
            for x in 14..22u32 {
                texels.insert([0, x, y], light(1.0 + (x as f32 - 13.5) / 8.0, w));
            }
        }
        let points = (0..16)
            .map(|k| {
                let y = 2.0 + (k as f32 + 0.5) / 2.0;
                EdgePoint {
                    page: [0, 0],
                    at: [[10.0, y], [14.0, y]],
                }
            })
            .collect();
        let atlas = Atlas {
            width: 24,
            height: 12,
            texels,
        };
        (atlas, points)
    }

    /// A test stitch: the system, the values before and after, the edge jumps.
    type StitchedAtlas = (EdgeSystem, Vec<[f32; 3]>, Vec<[f32; 3]>, [f64; 2]);

    /// Stitches the texels of `atlas` along `points` with variance `variance(pixel)`; returns
    /// the system, the values before and after (per unknown), and the edge jumps.
    fn stitch_atlas(
        atlas: &Atlas,
        points: &[EdgePoint],
        variance: impl Fn(Pixel) -> f32,
    ) -> StitchedAtlas {
        let system = edge_system(points, atlas, 2);
        let before: Vec<[f32; 3]> = system.pixels.iter().map(|p| [atlas.texels[p]; 3]).collect();
        let variances: Vec<f32> = system.pixels.iter().map(|p| variance(*p)).collect();
        let mut channels = vec![before.iter().map(|v| v[0]).collect::<Vec<_>>(); 3];
        stitch_channels(&system, &variances, &mut channels);
        let after: Vec<[f32; 3]> = channels[0].iter().map(|v| [*v; 3]).collect();
        let jumps = [system.edge_jump(&before), system.edge_jump(&after)];
        (system, before, after, jumps)
    }

    #[test]
    fn padding_taps_expand_into_the_texels_the_dilation_copies() {
        // A ragged chart on a 9 × 7 page: every pixel's expansion, evaluated with the texels'
        // values, is what the page writer's dilation writes there (2 passes), and pixels the
        // dilation does not reach are None.
        let mut texels = HashMap::new();
        let mut page = crate::output::exr_pages::PageImage::new(9, 7);
        let mut seed = 7u32;
        for (x, y) in [
            (3, 2),
            (4, 2),
            (5, 2),
            (3, 3),
            (4, 3),
            (4, 4),
            (5, 4),
            (2, 3),
        ] {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = (seed >> 8) as f32 / (1u32 << 24) as f32;
            texels.insert([0, x, y], v);
            page.set(x, y, [v; 3]);
        }
        page.dilate(2);
        let atlas = Atlas {
            width: 9,
            height: 7,
            texels,
        };
        let (mut reached, mut unreached) = (0, 0);
        for y in -1..8i64 {
            for x in -1..10i64 {
                match written_as(&atlas, 0, [x, y], 2) {
                    Some(terms) => {
                        let value: f64 = terms
                            .iter()
                            .map(|(p, w)| w * f64::from(atlas.texels[p]))
                            .sum();
                        let written = page.get(x as u32, y as u32)[0];
                        assert!(
                            (value - f64::from(written)).abs() < 1e-6,
                            "({x}, {y}): {value} against {written}"
                        );
                        let total: f64 = terms.iter().map(|t| t.1).sum();
                        assert!((total - 1.0).abs() < 1e-12, "({x}, {y}): {terms:?}");
                        reached += 1;
                    }
                    None => {
                        let on_page = (0..9).contains(&x) && (0..7).contains(&y);
                        if on_page {
                            assert_eq!(page.get(x as u32, y as u32), [0.0; 3], "({x}, {y})");
                        }
                        unreached += 1;
                    }
                }
            }
        }
        assert!(reached > 30 && unreached > 20, "{reached} {unreached}");
    }

    #[test]
    fn a_linear_gradient_meets_at_the_edge_and_keeps_its_slope() {
        // The light rises 1 per unit across the seam and 0.5 along it, noise-free. Each side's
        // reconstruction at the edge is its border texels' value, half a texel (1/16) short
        // of the edge: the sides differ by 1/8 before the stitch.
        let light = |u: f32, w: f32| 1.0 + u + 0.5 * w;
        let (atlas, points) = two_charts(light);
        let (system, before, after, [raw, stitched]) = stitch_atlas(&atlas, &points, |_| 0.0);
        assert_eq!((system.points(), system.skipped), (16, 0));
        assert!((raw - 0.0625).abs() < 0.01, "raw edge jump {raw}");
        assert!(stitched < raw / 30.0, "stitched edge jump {stitched}");
        // The edge reads the true light there: each side met the other halfway, to within
        // the 1/(1 + K) the terms leave of a jump.
        let row_light = |r: usize| {
            let [a, b] = [0, 1].map(|s| system.reconstruct(r, s, &after)[0]);
            (a, b)
        };
        for (r, q) in points.iter().enumerate() {
            let (a, b) = row_light(r);
            let w = (q.at[0][1] - 2.0) / 8.0;
            let truth = f64::from(light(1.0, w));
            assert!((a - b).abs() < 1e-2 * truth, "point {r}: {a} against {b}");
            // Away from the chart's corners the edge value is exact (beside a chart's first
            // and last rows the padding averages two rows: 1/256 off there).
            if (4..12).contains(&r) {
                assert!(
                    (a - truth).abs() < 1e-3,
                    "point {r}: {a}, the light {truth}"
                );
            }
        }
        // Only the border column moves (by about the half-jump, 1/16). At the chart's two
        // corner rows the column beside it is read too, through the corners' padding, but
        // at 1/16 only, below MIN_TAP: it is held (moving it would take it 16× as far as
        // the jump it closes). Texels further in are no unknowns at all: the gradient stands.
        let mut moved = 0;
        for ((p, b), a) in system.pixels.iter().zip(&before).zip(&after) {
            let change = (a[0] - b[0]).abs();
            match p[1] {
                9 | 14 => assert!((change - 0.0625).abs() < 0.015, "{p:?}: {b:?} → {a:?}"),
                8 | 15 => {
                    assert!(p[2] == 2 || p[2] == 9, "{p:?} is read");
                    assert!(change < 1e-4, "{p:?}: {b:?} → {a:?}");
                }
                _ => panic!("{p:?} should not be read"),
            }
            moved += 1;
        }
        assert_eq!(moved, 2 * 8 + 4);
    }

    #[test]
    fn noisy_flat_light_stitches_toward_the_truth() {
        // Flat light 1 under noise of standard error 0.1 (a fixed pseudo-random draw): the
        // edge jump closes, and the texels the stitch moves end nearer the truth on average.
        let mut seed = 12_345u32;
        let mut noise = move || {
            // The sum of 4 uniforms, scaled to unit variance.
            (0..4)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
                })
                .sum::<f32>()
                * 3f32.sqrt()
        };
        let (mut atlas, points) = two_charts(|_, _| 1.0);
        let mut keys: Vec<Pixel> = atlas.texels.keys().copied().collect();
        keys.sort_unstable();
        for k in keys {
            *atlas.texels.get_mut(&k).unwrap() = 1.0 + 0.1 * noise();
        }
        let (_, before, after, [raw, stitched]) = stitch_atlas(&atlas, &points, |_| 0.01);
        let rmse = |v: &[[f32; 3]]| {
            (v.iter()
                .map(|v| (f64::from(v[0]) - 1.0).powi(2))
                .sum::<f64>()
                / v.len() as f64)
                .sqrt()
        };
        let mean = |v: &[[f32; 3]]| v.iter().map(|v| f64::from(v[0])).sum::<f64>() / v.len() as f64;
        assert!(raw > 0.05, "raw edge jump {raw}");
        assert!(stitched < raw / 30.0, "stitched edge jump {stitched}");
        let (rmse_before, rmse_after) = (rmse(&before), rmse(&after));
        assert!(
            rmse_after < 0.9 * rmse_before,
            "RMSE of the texels read {rmse_before} → {rmse_after}"
        );
        assert!((mean(&after) - mean(&before)).abs() < 0.02, "the mean");
    }

    #[test]
    fn the_noisier_side_gives_way() {
        // Flat light, side a at 1 known to ±0.01, side b at 1.2 known to ±0.3: the edge
        // meets nearer a's value. The median variance is b's, so the data weights are
        // 1 / (1 + 1e-4 / 0.09) against 1 / (1 + 1): b moves twice as far, the edge meets
        // at 1 + 0.2 / 3.
        let (atlas, points) = two_charts(|u, _| if u < 1.0 { 1.0 } else { 1.2 });
        let variance = |p: Pixel| if p[1] < 12 { 1e-4 } else { 0.09 };
        let (system, _, after, [_, stitched]) = stitch_atlas(&atlas, &points, variance);
        assert!(stitched < 0.01, "{stitched}");
        let edge = system.reconstruct(8, 0, &after)[0];
        assert!((edge - 1.0667).abs() < 0.005, "the edge at {edge}");
    }

    #[test]
    fn irradiance_stays_non_negative() {
        // Two edge points whose side a reads texels t1, t2 at ¾ + ¼ and ¼ + ¾, side b one
        // texel each, u1 = 0 and u2 = 12; a is noisier than b. To meet b, a's two
        // reconstructions must differ by much while its texels are read mixed: the free solve
        // takes t1 below zero. Held at its baked value, nothing ends negative, and the
        // second point (t2 alone can still move) closes most of its jump.
        let system = EdgeSystem {
            pixels: vec![
                [0, 0, 0],
                [0, 1, 0],
                [0, 5, 0],
                [0, 5, 1],
                [0, 9, 0],
                [0, 9, 1],
            ],
            rows: vec![
                [vec![(0, 0.75), (1, 0.25)], vec![(2, 1.0)]],
                [vec![(0, 0.25), (1, 0.75)], vec![(3, 1.0)]],
            ],
            skipped: 0,
        };
        // Two more texels, no point's, set the median variance low: a's weigh 1/9, b's ½.
        let baked = vec![1.0, 1.0, 0.0, 12.0, 5.0, 5.0];
        let variance = [1.0, 1.0, 1e-6, 1e-6, 1e-6, 1e-6];
        let free = EdgeStitch::new(&system, &variance, &[]).solve(&baked);
        assert!(free[0] < -0.5, "the free solve: {free:?}");
        let mut channels = vec![baked.clone(); 3];
        let held = stitch_channels(&system, &variance, &mut channels);
        assert_eq!(held, 1);
        let solved = &channels[0];
        assert!(solved.iter().all(|v| *v >= 0.0), "{solved:?}");
        assert!((solved[0] - 1.0).abs() < 1e-5, "t1 held: {solved:?}");
        let rgb = |v: &[f32]| v.iter().map(|v| [*v; 3]).collect::<Vec<_>>();
        let (raw, stitched) = (
            system.edge_jump(&rgb(&baked)),
            system.edge_jump(&rgb(solved)),
        );
        assert!(
            stitched < raw / 2.0,
            "edge jump {raw} → {stitched}: {solved:?}"
        );
    }

    #[test]
    fn points_off_the_padding_or_on_non_finite_texels_are_left_out() {
        let (mut atlas, mut points) = two_charts(|_, _| 1.0);
        // A point whose b side lies in the empty middle of the page, 2 pixels beyond any
        // padding; a texel that is not finite under two points' taps.
        points.push(EdgePoint {
            page: [0, 0],
            at: [[10.0, 5.0], [12.0, 11.5]],
        });
        atlas.texels.insert([0, 9, 4], f32::NAN);
        let system = edge_system(&points, &atlas, 2);
        assert_eq!(system.points() + system.skipped, 17);
        assert!(system.skipped >= 3, "{}", system.skipped);
        assert!(!system.pixels.contains(&[0, 9, 4]));
    }
}
