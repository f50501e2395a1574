//! Spatial chunks of a big mesh, each charted by its own xatlas atlas (module docs of
//! [`super`]): a median cut over triangle centroids, as a BVH builder's object split
//! (Wald 2007, "On fast construction of SAH-based bounding volume hierarchies", §3 — here
//! the plain median, no SAH), halving along the widest axis of the centroids until every
//! chunk holds at most the budget: the cut the BVH's regions are made by
//! ([`crate::bvh::split_at_median`]). Edges between two chunks become chart seams.

use glam::Vec3;

/// Splits triangles `0..centroids.len()` into chunks of at most `budget` triangles
/// (`budget` ≥ 1), spatially coherent, each in ascending triangle order. The chunks come
/// in a fixed order: the same centroids give the same chunks (ties broken by index).
#[must_use]
pub fn median_cut(centroids: &[[f32; 3]], budget: usize) -> Vec<Vec<u32>> {
    let budget = budget.max(1);
    let mut ids: Vec<u32> = (0..centroids.len() as u32).collect();
    let mut chunks = Vec::with_capacity(centroids.len().div_ceil(budget) * 2);
    let mut stack = vec![(0usize, ids.len())];
    // Depth first, lower half first: chunks come in the order of a left-to-right walk.
    while let Some((lo, hi)) = stack.pop() {
        let part = &mut ids[lo..hi];
        if part.len() <= budget {
            let mut chunk = part.to_vec();
            chunk.sort_unstable();
            chunks.push(chunk);
            continue;
        }
        let mid = part.len() / 2;
        crate::bvh::split_at_median(|t| Vec3::from(centroids[t as usize]), part, mid);
        stack.push((lo + mid, hi));
        stack.push((lo, lo + mid));
    }
    chunks
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> Vec<[f32; 3]> {
        (0..n * n)
            .map(|i| [(i % n) as f32, (i / n) as f32, 0.0])
            .collect()
    }

    #[test]
    fn every_triangle_lands_in_exactly_one_chunk_within_the_budget() {
        for (n, budget) in [(1, 1), (7, 5), (32, 64), (33, 100), (10, 1000)] {
            let c = grid(n);
            let chunks = median_cut(&c, budget);
            let mut seen = vec![0u32; c.len()];
            for chunk in &chunks {
                assert!(!chunk.is_empty() && chunk.len() <= budget, "{n} {budget}");
                assert!(chunk.windows(2).all(|w| w[0] < w[1]), "ascending");
                for &t in chunk {
                    seen[t as usize] += 1;
                }
            }
            assert!(seen.iter().all(|&s| s == 1), "{n} {budget}");
            if c.len() <= budget {
                assert_eq!(chunks.len(), 1);
            } else {
                // Median halving: no chunk below half the budget.
                assert!(chunks.iter().all(|k| 2 * k.len() >= budget), "{n} {budget}");
            }
        }
    }

    #[test]
    fn chunks_are_spatially_coherent() {
        // A 64×64 grid in chunks of 1024: four 32×32 squares (each extent 31 on both axes).
        let chunks = median_cut(&grid(64), 1024);
        assert_eq!(chunks.len(), 4);
        for chunk in &chunks {
            let xs = chunk.iter().map(|&t| t % 64);
            let ys = chunk.iter().map(|&t| t / 64);
            assert_eq!(xs.clone().max().unwrap() - xs.min().unwrap(), 31);
            assert_eq!(ys.clone().max().unwrap() - ys.min().unwrap(), 31);
        }
    }

    #[test]
    fn equal_centroids_split_by_index() {
        let c = vec![[1.0, 2.0, 3.0]; 10];
        assert_eq!(
            median_cut(&c, 3),
            vec![vec![0, 1], vec![2, 3, 4], vec![5, 6], vec![7, 8, 9]]
        );
    }
}
