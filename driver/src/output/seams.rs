//! Seams: texels on the two sides of a UV seam (one 3D edge, two charts — or two places of
//! one chart) made to agree (`--seams stitch`).
//!
//! A lightmap is sampled bilinearly, so along a seam each side shows its own chart's border
//! texels and the padding dilated from them: two independent estimates, and a visible jump
//! where they differ. Detection uses what the texel file holds, world positions and normals,
//! so it needs no UV topology and works for any atlas: a **seam pair** is two *border* texels
//! (a texel with an uncovered 4-neighbour in the atlas) that lie within
//! [`PAIR_DISTANCE`] texel spacings of each other in world space, on the same tangent plane
//! (within [`PAIR_PLANE`] spacings) and side (normals within [`PAIR_COS`]), but are not atlas
//! neighbours (another page, or more
//! than [`ATLAS_NEIGHBOUR`] pixels apart). Faces meeting at an angle, the two sides of a thin
//! wall and texels of one chart are never paired.
//!
//! Stitching is a least-squares fit, after the public write-ups on lightmap seams: minimise
//! `Σ_i |x_i − x̂_i|² + λ Σ_pairs |x_a − x_b|²` over the seam texels' irradiance (`x̂` the
//! baked value, [`STITCH_WEIGHT`] = λ), solved by [`SWEEPS`] Gauss–Seidel sweeps in texel
//! order — a small sparse solve, deterministic, and run on the merged results, so shards
//! still give one bake's bytes. Interior texels are untouched.
//!
//! Memory: one bit per atlas pixel while the border is found, then the border texels only
//! (a chart's perimeter, not its area).
//!
//! The measure ([`mean_relative_jump`]): the mean over seam pairs of `|l_a − l_b| / (l̄ + ε)`,
//! `l` the luminance, `l̄` the pair's mean and `ε` a hundredth of the border's mean luminance.

use std::collections::HashMap;

use glam::Vec3;
use guidebake_kernels::estimator::luminance_f32;

use crate::texels::{TexelFile, TexelRecord};

/// Largest world distance of a seam pair, in texel spacings (centres on the two sides of an
/// edge lie about one spacing apart; diagonal neighbours up to √2).
pub const PAIR_DISTANCE: f32 = 1.5;
/// Smallest cosine between the normals of a seam pair.
pub const PAIR_COS: f32 = 0.99;
/// Largest distance of a pair's texels from each other's tangent plane, in texel spacings.
pub const PAIR_PLANE: f32 = 0.05;
/// Pixels (Chebyshev) within which two texels of a page count as atlas neighbours.
pub const ATLAS_NEIGHBOUR: u32 = 2;
/// The seam term's weight λ against the data term.
pub const STITCH_WEIGHT: f32 = 8.0;
/// Gauss–Seidel sweeps of the stitch.
pub const SWEEPS: usize = 32;

/// One border texel, where it is in the atlas and in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BorderTexel {
    /// Global texel id (index in the texel file).
    pub id: u64,
    /// Atlas page.
    pub page: u32,
    /// Pixel on the page.
    pub pixel: [u16; 2],
    /// World position.
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// World size of a texel step (the larger footprint axis).
    pub spacing: f32,
}

/// The border texels of `texels` (an uncovered 4-neighbour in the atlas), in file order.
pub fn border_texels(texels: &TexelFile) -> Vec<BorderTexel> {
    let pages = texels.pages();
    let mut covered: Vec<Vec<u64>> = pages
        .iter()
        .map(|p| vec![0u64; (p.width as usize * p.height as usize).div_ceil(64)])
        .collect();
    let bit = |page: u32, x: u32, y: u32| -> (usize, usize) {
        let i = y as usize * pages[page as usize].width as usize + x as usize;
        (i / 64, i % 64)
    };
    let each_texel = |f: &mut dyn FnMut(u64, &TexelRecord)| {
        for (t, tile) in texels.tiles().iter().enumerate() {
            for (i, texel) in texels.tile_texels(t).iter().enumerate() {
                f(tile.first_texel + i as u64, texel);
            }
            texels.release_tile(t);
        }
    };
    each_texel(&mut |_, texel| {
        let [x, y] = texel.pixel.map(u32::from);
        let (word, b) = bit(texel.page, x, y);
        covered[texel.page as usize][word] |= 1 << b;
    });
    let mut border = Vec::new();
    each_texel(&mut |id, texel| {
        let size = pages[texel.page as usize];
        let [x, y] = texel.pixel.map(i64::from);
        let open = [(-1, 0), (1, 0), (0, -1), (0, 1)].iter().any(|(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            if nx < 0 || ny < 0 || nx >= i64::from(size.width) || ny >= i64::from(size.height) {
                return true;
            }
            let (word, b) = bit(texel.page, nx as u32, ny as u32);
            covered[texel.page as usize][word] & (1 << b) == 0
        });
        if open {
            border.push(BorderTexel {
                id,
                page: texel.page,
                pixel: texel.pixel,
                position: texel.position(),
                normal: texel.normal(),
                spacing: spacing(texel),
            });
        }
    });
    border
}

/// World size of one texel step: the longer footprint axis.
fn spacing(texel: &TexelRecord) -> f32 {
    Vec3::from(texel.dpdu)
        .length()
        .max(Vec3::from(texel.dpdv).length())
}

/// The seam pairs among `border` (indices into it, `a < b`, sorted).
pub fn seam_pairs(border: &[BorderTexel]) -> Vec<(u32, u32)> {
    let mut spacings: Vec<f32> = border
        .iter()
        .map(|t| t.spacing)
        .filter(|s| s.is_finite() && *s > 0.0)
        .collect();
    if spacings.is_empty() {
        return Vec::new();
    }
    spacings.sort_by(f32::total_cmp);
    let cell = spacings[spacings.len() / 2] * PAIR_DISTANCE;
    let key = |p: Vec3| (p / cell).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<u32>> = HashMap::new();
    for (i, t) in border.iter().enumerate() {
        if t.position.is_finite() {
            grid.entry(key(t.position)).or_default().push(i as u32);
        }
    }
    let mut pairs = Vec::new();
    for (i, a) in border.iter().enumerate() {
        if !a.position.is_finite() || a.spacing.is_nan() || a.spacing <= 0.0 {
            continue;
        }
        let reach = a.spacing.max(cell / PAIR_DISTANCE) * PAIR_DISTANCE;
        let cells = (reach / cell).ceil() as i32;
        let centre = key(a.position);
        for dz in -cells..=cells {
            for dy in -cells..=cells {
                for dx in -cells..=cells {
                    let Some(found) = grid.get(&(centre + glam::IVec3::new(dx, dy, dz))) else {
                        continue;
                    };
                    for &j in found.iter().filter(|&&j| j as usize > i) {
                        if is_seam_pair(a, &border[j as usize]) {
                            pairs.push((i as u32, j));
                        }
                    }
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

fn is_seam_pair(a: &BorderTexel, b: &BorderTexel) -> bool {
    let spacing = a.spacing.max(b.spacing);
    let d = b.position - a.position;
    let atlas_neighbours = a.page == b.page
        && a.pixel[0].abs_diff(b.pixel[0]) as u32 <= ATLAS_NEIGHBOUR
        && a.pixel[1].abs_diff(b.pixel[1]) as u32 <= ATLAS_NEIGHBOUR;
    !atlas_neighbours
        && d.length() <= PAIR_DISTANCE * spacing
        && a.normal.dot(b.normal) >= PAIR_COS
        && a.normal.dot(d).abs() <= PAIR_PLANE * spacing
        && b.normal.dot(d).abs() <= PAIR_PLANE * spacing
}

/// The mean relative luminance jump across `pairs` of `values` (indexed as the border), 0
/// without pairs.
pub fn mean_relative_jump(values: &[[f32; 3]], pairs: &[(u32, u32)]) -> f64 {
    if pairs.is_empty() {
        return 0.0;
    }
    let lum = |i: u32| f64::from(luminance_f32(values[i as usize]));
    let mean = values
        .iter()
        .map(|v| f64::from(luminance_f32(*v)))
        .sum::<f64>()
        / values.len() as f64;
    let eps = 1e-2 * mean.abs().max(f64::MIN_POSITIVE);
    pairs
        .iter()
        .map(|&(a, b)| {
            let (la, lb) = (lum(a), lum(b));
            (la - lb).abs() / ((la + lb) / 2.0 + eps)
        })
        .sum::<f64>()
        / pairs.len() as f64
}

/// Stitches `values` (indexed as the border) along `pairs` in place: the least-squares fit of
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

    fn texel(id: u64, page: u32, pixel: [u16; 2], position: Vec3, normal: Vec3) -> BorderTexel {
        BorderTexel {
            id,
            page,
            pixel,
            position,
            normal,
            spacing: 0.1,
        }
    }

    /// A flat floor cut into two charts along x = 1: chart A's last column and chart B's
    /// first lie 0.1 apart in the world and 40 pixels apart in the atlas. A wall (normal +x)
    /// stands on the same edge, and a thin wall's far side (normal −y, 2 cm above) too.
    fn cut_floor() -> Vec<BorderTexel> {
        let mut border = Vec::new();
        for k in 0..10u16 {
            let z = f32::from(k) * 0.1 + 0.05;
            let id = border.len() as u64;
            border.push(texel(id, 0, [9, k], Vec3::new(0.95, 0.0, z), Vec3::Y));
            border.push(texel(id + 1, 0, [50, k], Vec3::new(1.05, 0.0, z), Vec3::Y));
            border.push(texel(id + 2, 0, [70, k], Vec3::new(1.0, 0.05, z), Vec3::X));
            border.push(texel(id + 3, 1, [3, k], Vec3::new(1.0, 0.02, z), -Vec3::Y));
        }
        border
    }

    #[test]
    fn seam_pairs_join_the_two_charts_of_a_flat_cut_only() {
        let border = cut_floor();
        let pairs = seam_pairs(&border);
        assert!(!pairs.is_empty());
        for &(a, b) in &pairs {
            let (a, b) = (&border[a as usize], &border[b as usize]);
            assert_eq!((a.normal, b.normal), (Vec3::Y, Vec3::Y), "{a:?} {b:?}");
            assert!((a.position.x < 1.0) != (b.position.x < 1.0), "{a:?} {b:?}");
        }
        // Each texel of the cut pairs with the one across and its two diagonal neighbours.
        assert_eq!(pairs.len(), 10 + 2 * 9);
    }

    #[test]
    fn stitching_closes_the_jump_and_keeps_the_mean() {
        let border = cut_floor();
        let pairs = seam_pairs(&border);
        let mut values: Vec<[f32; 3]> = border
            .iter()
            .map(|t| {
                if t.position.x < 1.0 {
                    [1.0; 3]
                } else {
                    [2.0; 3]
                }
            })
            .collect();
        let before = mean_relative_jump(&values, &pairs);
        let mean_before: f32 = values.iter().map(|v| v[0]).sum();
        stitch(&mut values, &pairs);
        let after = mean_relative_jump(&values, &pairs);
        let mean_after: f32 = values.iter().map(|v| v[0]).sum();
        assert!((before - 2.0 / 3.0).abs() < 0.01, "{before}");
        assert!(after < 0.1 * before, "jump {before} → {after}");
        assert!(
            (mean_after - mean_before).abs() < 1e-2 * mean_before,
            "{mean_before} → {mean_after}"
        );
        // The wall and the thin wall's far side are untouched.
        for (t, v) in border.iter().zip(&values) {
            if t.normal != Vec3::Y {
                assert!(v == &[1.0; 3] || v == &[2.0; 3], "{t:?} {v:?}");
            }
        }
    }
}
