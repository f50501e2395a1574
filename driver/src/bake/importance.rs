//! The lookups' importance: how much of a series pass's noise in each texel reaches the next
//! pass's relative error through the lookups that read it (docs/estimator.md, "The lookup
//! passes' budget"). A lookup pass (between the direct pass and the last) is read, never
//! shown: the next pass's gather rays read its total at their hits (paper §1 and §3's series
//! setting, `transport/series.rs`), so its texel j's error e_j reaches texel i's estimate as
//! C_ij·e_j, C_ij the share of i's gather that reads j times the albedo there. Summed over
//! the readers, weighed as the bench weighs relative error, the importance of j is
//! I_j = Σ_i C_ij² / (μ_i² + ε), and the least Σ I_j σ_j² / n_j for the samples gives texel j
//! n_j ∝ σ_j √I_j ([`super::budget::SpatialBudget::for_lookups`]).
//!
//! **Measured before the pass it budgets**, from the image of the pass before it, by
//! [`IMPORTANCE_RAYS`] cosine rays per texel that take the decisions a gather hit takes
//! (`transport::path::series_read`) and trace nothing further. A texel whose rays read the same
//! pixel twice sees that pixel's noise coherently, so C_ij² is estimated without the bias of
//! its own noise by the product of two independent halves of the rays: Σ_j A_j B_j, A and B
//! each half's mean. Each reader adds its terms to the 8×8-texel block of the pixels it read,
//! in fixed point (order-free integer sums): the importance is the same on any thread count,
//! shard split or resume.

use std::sync::atomic::{AtomicI64, Ordering};

use glam::Vec3;
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
use guidebake_kernels::packet::Ray;
use guidebake_kernels::traverse::intersect1;
use rayon::prelude::*;

use super::budget::{BLOCK, RELATIVE_EPSILON};
use super::world::{SurfaceHit, World};
use crate::texels::{FLAG_VALID, TexelFile, TexelRecord};
use crate::transport::emitters::luminance;
use crate::transport::path::series_read;
use crate::transport::rng::SampleRng;

/// Rays per texel (two halves): an eighth of a 256-spp lookup pass's gather rays, and no
/// shadow rays.
pub const IMPORTANCE_RAYS: u32 = 32;
/// The iteration number of the importance rays' random streams: past any bake's iterations.
const STREAM: u32 = (1 << 12) - 1;
/// Fixed point of the block sums: 2⁻³² of a term (each term at most 1/ε's 100).
const FIXED: f64 = 4_294_967_296.0;

/// Each page's importance per 8×8-texel block: the mean over its valid texels of I_j (in
/// units of 1/μ̄², μ̄ the mean total of the previous pass's texels).
#[derive(Debug)]
pub struct LookupImportance {
    pages: Vec<(u32, Vec<f64>)>,
}

impl LookupImportance {
    /// The mean importance of the block holding `pixel` of `page` (0 outside the pages).
    pub fn block(&self, page: u32, [x, y]: [u32; 2]) -> f64 {
        self.pages
            .get(page as usize)
            .map_or(0.0, |(columns, sums)| {
                let i = (y / BLOCK * columns + x / BLOCK) as usize;
                sums.get(i).copied().unwrap_or(0.0)
            })
    }

    /// Measures the importance of the previous pass `world` holds for the pass about to read
    /// it; `None` without a previous pass or when its texels are all black.
    pub fn measure(world: &World, texels: &TexelFile, seed: u32) -> Option<Self> {
        let previous = world.previous_pass()?;
        let (world_mean, counts) = survey(world, texels)?;
        let epsilon = RELATIVE_EPSILON;
        let blocks: Vec<(u32, Vec<AtomicI64>)> = counts
            .iter()
            .map(|(columns, n)| (*columns, n.iter().map(|_| AtomicI64::new(0)).collect()))
            .collect();
        let columns: Vec<u32> = counts.iter().map(|(c, _)| *c).collect();
        let add = |page: u32, block: u32, term: f64| {
            if let Some((_, sums)) = blocks.get(page as usize)
                && let Some(sum) = sums.get(block as usize)
            {
                sum.fetch_add((term * FIXED).round() as i64, Ordering::Relaxed);
            }
        };
        (0..texels.tiles().len()).into_par_iter().for_each(|tile| {
            let first = texels.tiles()[tile].first_texel;
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (i, t) in texels.tile_texels(tile).iter().enumerate() {
                if t.flags & FLAG_VALID == 0 {
                    continue;
                }
                let mu = f64::from(previous.total_luminance_at(t.page, t.pixel.map(u32::from)))
                    / world_mean;
                let weight = 1.0 / (mu * mu + epsilon);
                reads(world, t, first + i as u64, seed, &columns, [&mut a, &mut b]);
                for_each_product(&mut a, &mut b, |page, block, ab| {
                    add(page, block, weight * ab)
                });
            }
            texels.release_tile(tile);
        });
        let pages = blocks
            .into_iter()
            .zip(counts)
            .map(|((columns, sums), (_, counts))| {
                let means = sums
                    .into_iter()
                    .zip(counts)
                    .map(|(s, n)| (s.into_inner() as f64 / FIXED).max(0.0) / f64::from(n.max(1)))
                    .collect();
                (columns, means)
            })
            .collect();
        Some(Self { pages })
    }
}

/// Each page's block columns and valid texels per block.
type Counts = Vec<(u32, Vec<u32>)>;

/// The mean luminance of the previous pass's total over the valid texels (`None` if not
/// > 0), and how many valid texels each block holds.
fn survey(world: &World, texels: &TexelFile) -> Option<(f64, Counts)> {
    let previous = world.previous_pass()?;
    let mut counts: Counts = texels
        .pages()
        .iter()
        .map(|p| {
            let columns = p.width.div_ceil(BLOCK);
            (
                columns,
                vec![0; (columns * p.height.div_ceil(BLOCK)) as usize],
            )
        })
        .collect();
    let (mut sum, mut count) = (0.0f64, 0u64);
    for tile in 0..texels.tiles().len() {
        for t in texels.tile_texels(tile) {
            if t.flags & FLAG_VALID == 0 {
                continue;
            }
            let [x, y] = t.pixel.map(u32::from);
            sum += f64::from(previous.total_luminance_at(t.page, [x, y]));
            count += 1;
            if let Some((columns, n)) = counts.get_mut(t.page as usize)
                && let Some(n) = n.get_mut((y / BLOCK * *columns + x / BLOCK) as usize)
            {
                *n += 1;
            }
        }
        texels.release_tile(tile);
    }
    let mean = sum / count.max(1) as f64;
    (mean.is_finite() && mean > 0.0).then_some((mean, counts))
}

/// One read: a block (page, its index on the page) and the share of the texel's gather it
/// is, times the albedo.
type Read = (u32, u32, f64);

/// The lookups texel `t` (id `id`) makes along its [`IMPORTANCE_RAYS`] cosine rays, by the
/// block they read (pages of `columns` blocks a row), the even rays' into `a`, the odd ones'
/// into `b`, each a half's mean (cleared first).
fn reads(
    world: &World,
    t: &TexelRecord,
    id: u64,
    seed: u32,
    columns: &[u32],
    [a, b]: [&mut Vec<Read>; 2],
) {
    a.clear();
    b.clear();
    let Some(previous) = world.previous_pass() else {
        return;
    };
    let normal = Vec3::from(t.normal);
    let position = Vec3::from(t.position);
    let footprint = Vec3::from(t.dpdu).length() + Vec3::from(t.dpdv).length();
    let on = world.onto_triangle(t.triangle, position, 0.01 * footprint);
    let facing = world.facing_normal(t.triangle, normal);
    let origin = world.leave_surface(t.triangle, on, facing, 0.0);
    let (tangent, bitangent) = orthonormal_basis(normal);
    let half = f64::from(IMPORTANCE_RAYS / 2);
    for r in 0..IMPORTANCE_RAYS {
        let d = sample_cosine_hemisphere(SampleRng::new(seed, id, STREAM, r).pair());
        let dir = (tangent * d.x + bitangent * d.y + normal * d.z).normalize_or(normal);
        let Some(h) = intersect1(
            &world.wide_bvh(),
            &Ray::new(origin, dir, 0.0, f32::INFINITY),
        ) else {
            continue;
        };
        let Some(s) = world.surfaces().get(h.prim as usize) else {
            continue;
        };
        let hit = SurfaceHit {
            prim: h.prim,
            t: h.t,
            u: h.u,
            v: h.v,
        };
        let read = series_read(previous, &hit, s.normal.dot(dir) < 0.0);
        if !(read.reads_total || read.reads_gathered) {
            continue;
        }
        let albedo = f64::from(luminance(world.albedo_at(s, &hit)));
        let into = if r % 2 == 0 { &mut *a } else { &mut *b };
        for tap in read.taps.iter().filter(|tap| tap.weight > 0.0) {
            let Some(columns) = columns.get(tap.page as usize) else {
                continue;
            };
            let [x, y] = tap.pixel;
            let block = y / BLOCK * columns + x / BLOCK;
            into.push((tap.page, block, albedo * f64::from(tap.weight) / half));
        }
    }
}

/// Calls `f` with each block both halves read and the product of their shares (each half's
/// reads of one block summed first); sorts both.
fn for_each_product(a: &mut [Read], b: &mut [Read], mut f: impl FnMut(u32, u32, f64)) {
    let key = |r: &Read| (r.0, r.1);
    a.sort_unstable_by_key(key);
    b.sort_unstable_by_key(key);
    let sum_run = |reads: &[Read], i: &mut usize| -> f64 {
        let k = key(&reads[*i]);
        let mut s = 0.0;
        while *i < reads.len() && key(&reads[*i]) == k {
            s += reads[*i].2;
            *i += 1;
        }
        s
    };
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match key(&a[i]).cmp(&key(&b[j])) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                let (page, block) = (a[i].0, a[i].1);
                let product = sum_run(a, &mut i) * sum_run(b, &mut j);
                f(page, block, product);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_product_pairs_each_pixel_both_halves_read_once() {
        let mut a = vec![(0, 7, 0.5), (0, 9, 1.0), (0, 7, 0.25)];
        let mut b = vec![(0, 9, 2.0), (1, 7, 9.0), (0, 7, 4.0)];
        let mut got = Vec::new();
        for_each_product(&mut a, &mut b, |page, block, p| got.push((page, block, p)));
        assert_eq!(got, vec![(0, 7, 3.0), (0, 9, 2.0)]);
    }
}
