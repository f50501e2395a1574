//! The ABI's BVH helper: a median-split build from a triangle soup into caller buffers, in
//! the kernels' node layout, without allocation.
//!
//! A top-down build: a range of triangles splits at the median of its centroids along their
//! bounds' longest axis (`select_nth_unstable_by` on the output triangles themselves, ties
//! broken by primitive id so the tree is a function of the input alone); ranges of at most
//! [`LEAF_MAX`] triangles become leaves. The median keeps the depth at ⌈log₂ n⌉ (≤ 32 < the
//! traversal's 128) and the node count at most `max(1, n − 1)`.
//!
//! This is for bakers without a BVH builder of their own. The driver builds with obvhs
//! (PLOC with reinsertion, `driver/src/bvh.rs`), which traces faster on real scenes; any tree
//! gives the same hits bit for bit (closest hit, smallest primitive id on ties).

use core::cmp::Ordering;

use guidebake_kernels::traverse::{BinaryNode, LEAF, Tri};

/// Most triangles in a leaf.
pub(crate) const LEAF_MAX: usize = 2;

/// Nodes the build needs for `tris` triangles.
pub(crate) fn nodes_needed(tris: usize) -> usize {
    tris.saturating_sub(1).max(1)
}

/// Builds over `out_tris` (already holding the soup, primitive id = index) into `nodes`
/// (at least [`nodes_needed`] long); reorders `out_tris` into leaf order; returns the node
/// count.
pub(crate) fn build(tris: &mut [Tri], nodes: &mut [BinaryNode]) -> usize {
    nodes[0] = BinaryNode::EMPTY;
    match tris.len() {
        0 => 1,
        1 => {
            set_leaf(&mut nodes[0], 0, tris, 0);
            1
        }
        _ => {
            let mut next = 1;
            split_into(tris, 0, nodes, 0, &mut next);
            next
        }
    }
}

/// Splits `tris` (starting at triangle `first` of the whole array) into the two slots of
/// node `index`, recursing into slots with more than [`LEAF_MAX`] triangles.
fn split_into(
    tris: &mut [Tri],
    first: usize,
    nodes: &mut [BinaryNode],
    index: usize,
    next: &mut usize,
) {
    let mid = median_split(tris);
    let (left, right) = tris.split_at_mut(mid);
    for (slot, part, start) in [(0, left, first), (1, right, first + mid)] {
        if part.len() <= LEAF_MAX {
            set_leaf(&mut nodes[index], slot, part, start);
            continue;
        }
        let child = *next;
        *next += 1;
        let (lo, hi) = bounds(part);
        let node = &mut nodes[index];
        node.set_box(slot, lo.into(), hi.into());
        node.child[slot] = child as u32;
        node.meta[slot] = 0;
        nodes[child] = BinaryNode::EMPTY;
        split_into(part, start, nodes, child, next);
    }
}

fn set_leaf(node: &mut BinaryNode, slot: usize, tris: &[Tri], start: usize) {
    let (lo, hi) = bounds(tris);
    node.set_box(slot, lo.into(), hi.into());
    node.child[slot] = start as u32;
    node.meta[slot] = LEAF | tris.len() as u32;
}

/// Vertex bounds of `tris`.
fn bounds(tris: &[Tri]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for v in tris.iter().flat_map(|t| t.v.iter()) {
        for a in 0..3 {
            lo[a] = lo[a].min(v[a]);
            hi[a] = hi[a].max(v[a]);
        }
    }
    (lo, hi)
}

/// Twice the centroid along `axis` (the factor 1/3 changes no order).
fn centroid(t: &Tri, axis: usize) -> f32 {
    t.v[0][axis] + t.v[1][axis] + t.v[2][axis]
}

/// Partitions `tris` (at least 2) around its centroid median on the centroids' longest
/// axis; returns the split index `len / 2`.
fn median_split(tris: &mut [Tri]) -> usize {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for t in tris.iter() {
        for a in 0..3 {
            let c = centroid(t, a);
            lo[a] = lo[a].min(c);
            hi[a] = hi[a].max(c);
        }
    }
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])).then(b.cmp(&a)))
        .unwrap_or(0);
    let mid = tris.len() / 2;
    tris.select_nth_unstable_by(mid, |a, b| -> Ordering {
        centroid(a, axis)
            .total_cmp(&centroid(b, axis))
            .then(a.prim.cmp(&b.prim))
    });
    mid
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use guidebake_kernels::packet::Ray;
    use guidebake_kernels::testing::Pcg32;
    use guidebake_kernels::traverse::{BvhRef, intersect_brute, intersect1};

    #[test]
    fn tree_is_valid_and_finds_the_brute_force_hits() {
        let mut rng = Pcg32::new(5, 1);
        for n in [0usize, 1, 2, 3, 4, 5, 17, 200] {
            let soup: Vec<Tri> = (0..n)
                .map(|i| {
                    let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0;
                    let mut d = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 0.5;
                    Tri::new([c, c + d(), c + d()], i as u32)
                })
                .collect();
            let mut tris = soup.clone();
            let mut nodes = vec![BinaryNode::EMPTY; nodes_needed(n)];
            let used = build(&mut tris, &mut nodes);
            assert!(used <= nodes.len(), "{n}: {used} nodes");
            let bvh = BvhRef::new(&nodes[..used], &tris).expect("valid layout");
            for _ in 0..200 {
                let o = Vec3::new(rng.next_f32(), rng.next_f32(), -1.0) * 4.0;
                let d = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 1.0);
                let ray = Ray::new(o, d, 0.0, f32::INFINITY);
                assert_eq!(intersect1(&bvh, &ray), intersect_brute(&soup, &ray), "{n}");
            }
        }
    }
}
