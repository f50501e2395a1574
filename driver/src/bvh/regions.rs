//! # bvh::regions: a big world's tree built region by region, in bounded scratch
//!
//! obvhs's build holds, beside its output, about 250 bytes per triangle of scratch (its copy
//! of the triangles, PLOC's node and Morton buffers, the binary tree before collapsing) and we
//! held the flattened binary tree beside the wide one: on 10⁷ triangles that is gigabytes more
//! than the tree that remains. So a soup of more than [`REGION_TRIANGLES`] triangles is cut,
//! by its triangles' centroids, at the median of the longest axis, again and again, into
//! regions of at most that many; each region's tree is built with the chosen preset as a whole
//! soup's would be, flattened, collapsed to wide nodes and leaf rows, and kept in its own
//! exactly sized array while its scratch is freed for the next region. The cuts are the top
//! level: a binary tree whose leaves are the regions, collapsed like any other, whose leaf
//! slots then point at the regions' roots. Last, the regions' nodes and rows are copied into
//! the final arrays, each region's freed as soon as it is copied.
//!
//! Peak memory beyond the finished tree: one region's build (≤ 64 MiB at
//! [`REGION_TRIANGLES`]), the index permutation (4 bytes per triangle) and the top level (a
//! node per region). Any valid tree finds the same closest hits (the kernels' tie rule), so
//! the bake's output does not depend on the regions.
//!
//! Deterministic: the cuts are sequential (`select_nth_unstable` ordered by centroid then
//! index), each region's triangles are handed to obvhs in index order.

use std::ops::Range;

use std::marker::PhantomData;

use bytemuck::Pod;
use glam::Vec3;
use guidebake_kernels::traverse::{
    BinaryNode, BvhRef, LEAF, Tri, WIDTH, WideNode, collapse, leaf_rows,
};
use memmap2::MmapMut;

use super::{BvhError, HugeSlice, Preset, obvhs_flattened};

/// Most triangles a region holds. obvhs's scratch of ~250 bytes per triangle plus the
/// region's own binary tree and wide arrays (~150 bytes per triangle) stay under 64 MiB.
pub(super) const REGION_TRIANGLES: usize = 1 << 17;

/// A region's finished tree: its wide nodes (child indices and leaf firsts local to it), its
/// leaf rows without the final padding, its triangles' count, and, when the binary tree is
/// kept, its binary nodes and triangles.
struct Region {
    wide: Spill<WideNode>,
    rows: Spill<f32>,
    tris: usize,
    binary: Option<(Vec<BinaryNode>, Vec<Tri>)>,
}

/// What [`super::Bvh`] holds: wide nodes, leaf rows and, if asked for, the binary tree.
pub(super) struct Built {
    pub(super) wide: HugeSlice<WideNode>,
    pub(super) rows: HugeSlice<f32>,
    pub(super) binary: Option<(HugeSlice<BinaryNode>, HugeSlice<Tri>)>,
}

/// Builds the tree over the triangles of `soup` that `ids` names (all for `None`) in regions
/// of at most `region` triangles (more than `region` triangles expected, `region` ≥ 16).
pub(super) fn build(
    soup: &[[Vec3; 3]],
    ids: Option<&[u32]>,
    preset: Preset,
    region: usize,
    keep_binary: bool,
) -> Result<Built, BvhError> {
    let mut ids: Vec<u32> = ids.map_or_else(|| (0..soup.len() as u32).collect(), <[u32]>::to_vec);
    let (top, ranges) = cut(soup, &mut ids, region);
    let mut regions = Vec::with_capacity(ranges.len());
    for range in &ranges {
        let ids = &mut ids[range.clone()];
        ids.sort_unstable();
        regions.push(build_region(soup, ids, preset, keep_binary)?);
    }
    drop(ids);
    // The top level: its leaves are the regions (leaf `r` of one "triangle" at `r`).
    let stand_ins: Vec<Tri> = (0..ranges.len() as u32)
        .map(|r| Tri::new([Vec3::ZERO; 3], r))
        .collect();
    let top_ref = BvhRef::new(&top, &stand_ins).map_err(BvhError::Layout)?;
    let top_wide = collapse(&top_ref);
    // Where each region's wide nodes, binary nodes and triangles start in the final arrays.
    let mut wide_at = Vec::with_capacity(regions.len());
    let mut node_at = Vec::with_capacity(regions.len());
    let mut tri_at = Vec::with_capacity(regions.len());
    let (mut w, mut n, mut t) = (top_wide.len(), top.len(), 0);
    for r in &regions {
        wide_at.push(w as u32);
        node_at.push(n as u32);
        tri_at.push(t as u32);
        w += r.wide.len();
        n += r.binary.as_ref().map_or(0, |(nodes, _)| nodes.len());
        t += r.tris;
    }
    let (wide_len, nodes_len, tris_len) = (w, n, t);
    let binary = keep_binary.then(|| graft_binary(&top, &mut regions, &node_at, &tri_at));
    let wide = HugeSlice::filled(wide_len, |out| {
        for (node, top) in out.iter_mut().zip(&top_wide) {
            *node = *top;
            for slot in 0..WIDTH {
                if node.meta[slot] != 0 && node.meta[slot] != LEAF {
                    // The collapse keeps the binary tree's leaves: one region each.
                    assert_eq!(node.meta[slot], LEAF | 1, "a region per top leaf");
                    node.child[slot] = wide_at[node.child[slot] as usize];
                    node.meta[slot] = 0;
                }
            }
        }
        for (r, region) in regions.iter_mut().enumerate() {
            let at = wide_at[r] as usize;
            let wide = std::mem::take(&mut region.wide);
            for (node, from) in out[at..at + wide.len()].iter_mut().zip(wide.as_slice()) {
                *node = *from;
                for slot in 0..WIDTH {
                    match node.meta[slot] {
                        0 => node.child[slot] += wide_at[r],
                        LEAF => {}
                        _ => node.child[slot] += tri_at[r],
                    }
                }
            }
        }
    });
    drop(top_wide);
    let rows = HugeSlice::filled(rows_len(tris_len), |out| {
        for (r, region) in regions.iter_mut().enumerate() {
            let at = ROWS * tri_at[r] as usize;
            let rows = std::mem::take(&mut region.rows);
            out[at..at + rows.len()].copy_from_slice(rows.as_slice());
        }
    });
    debug_assert!(binary.as_ref().is_none_or(|(n, _)| n.len() == nodes_len));
    Ok(Built { wide, rows, binary })
}

/// Floats per triangle in the leaf rows and the padding after the last ([`leaf_rows`]).
const ROWS: usize = 10;
const ROWS_PAD: usize = 8;

fn rows_len(tris: usize) -> usize {
    ROWS * tris + ROWS_PAD
}

/// One region's tree over the triangles `ids` names (sorted), kept in exactly sized arrays.
fn build_region(
    soup: &[[Vec3; 3]],
    ids: &[u32],
    preset: Preset,
    keep_binary: bool,
) -> Result<Region, BvhError> {
    let (nodes, tris) = obvhs_flattened(soup, Some(ids), preset);
    let tree = BvhRef::new(&nodes, &tris).map_err(BvhError::Layout)?;
    let wide = collapse(&tree);
    let mut rows = leaf_rows(&wide, &tris);
    debug_assert_eq!(rows.len(), rows_len(tris.len()));
    rows.truncate(ROWS * tris.len());
    let count = tris.len();
    let binary = keep_binary.then_some((nodes, tris));
    Ok(Region {
        wide: Spill::new(&wide),
        rows: Spill::new(&rows),
        tris: count,
        binary,
    })
}

/// The binary tree: the top level's nodes, then each region's, its leaf slots pointing at the
/// regions' roots.
fn graft_binary(
    top: &[BinaryNode],
    regions: &mut [Region],
    node_at: &[u32],
    tri_at: &[u32],
) -> (HugeSlice<BinaryNode>, HugeSlice<Tri>) {
    let mut nodes = top.to_vec();
    for node in &mut nodes {
        for slot in 0..2 {
            if node.meta[slot] == LEAF | 1 {
                node.child[slot] = node_at[node.child[slot] as usize];
                node.meta[slot] = 0;
            }
        }
    }
    let mut tris = Vec::new();
    for (r, region) in regions.iter_mut().enumerate() {
        let (region_nodes, region_tris) = region.binary.take().expect("kept");
        for mut node in region_nodes {
            for slot in 0..2 {
                match node.meta[slot] {
                    0 => node.child[slot] += node_at[r],
                    LEAF => {}
                    _ => node.child[slot] += tri_at[r],
                }
            }
            nodes.push(node);
        }
        tris.extend(region_tris);
    }
    (HugeSlice::new(nodes), HugeSlice::new(tris))
}

/// Cuts `ids` (a permutation of `soup`'s indices) into regions of at most `region`
/// triangles: the top level's binary nodes (a leaf slot `LEAF | 1` at region `r`, its box the
/// region's triangles' bounds) and each region's range of `ids`.
fn cut(soup: &[[Vec3; 3]], ids: &mut [u32], region: usize) -> (Vec<BinaryNode>, Vec<Range<usize>>) {
    let centroid = |i: u32| {
        let t = &soup[i as usize];
        (t[0] + t[1] + t[2]) / 3.0
    };
    let mut nodes = vec![BinaryNode::EMPTY];
    let mut ranges = Vec::new();
    // (range of ids, our node, slot)
    let mut pending = vec![(0..ids.len(), 0usize, usize::MAX)];
    while let Some((range, parent, slot)) = pending.pop() {
        let (lo, hi) = bounds(soup, &ids[range.clone()]);
        if range.len() <= region {
            ranges.push(range);
            let node = &mut nodes[parent];
            node.set_box(slot, lo, hi);
            node.child[slot] = (ranges.len() - 1) as u32;
            node.meta[slot] = LEAF | 1;
            continue;
        }
        let ours = if slot == usize::MAX {
            0
        } else {
            nodes.push(BinaryNode::EMPTY);
            let index = nodes.len() - 1;
            let node = &mut nodes[parent];
            node.set_box(slot, lo, hi);
            node.child[slot] = index as u32;
            node.meta[slot] = 0;
            index
        };
        let mid = range.start + range.len() / 2;
        split_at_median(centroid, &mut ids[range.clone()], mid - range.start);
        // Right pushed first: the left half is cut (and numbered) first.
        pending.push((mid..range.end, ours, 1));
        pending.push((range.start..mid, ours, 0));
    }
    (nodes, ranges)
}

/// Orders `ids` so the first `k` have the smallest centroids along the longest axis of their
/// centroids' bounds (ties by index): the median cut of the regions, and of the spatial chunks
/// `prepare` charts a big mesh in (`prepare::unwrap::chunk`). `centroid(i)` is triangle `i`'s.
pub(crate) fn split_at_median(centroid: impl Fn(u32) -> Vec3, ids: &mut [u32], k: usize) {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for &i in ids.iter() {
        let c = centroid(i);
        lo = lo.min(c);
        hi = hi.max(c);
    }
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    ids.select_nth_unstable_by(k, |&a, &b| {
        centroid(a)[axis]
            .total_cmp(&centroid(b)[axis])
            .then(a.cmp(&b))
    });
}

/// The bounds of the triangles `ids` names.
fn bounds(soup: &[[Vec3; 3]], ids: &[u32]) -> (Vec3, Vec3) {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for &i in ids {
        for v in &soup[i as usize] {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    (lo, hi)
}

/// A region's finished array, kept until the final arrays take it: exactly sized anonymous
/// memory of small pages (a huge page per region's array would round each up to 2 MiB), given
/// back to the system when dropped (a heap block of this size might stay in the allocator's
/// arena, resident, beside the final arrays).
struct Spill<T: Pod> {
    map: Option<MmapMut>,
    /// The values where no map could be made.
    heap: Vec<T>,
    len: usize,
    _values: PhantomData<T>,
}

impl<T: Pod> Default for Spill<T> {
    fn default() -> Self {
        Self {
            map: None,
            heap: Vec::new(),
            len: 0,
            _values: PhantomData,
        }
    }
}

impl<T: Pod> Spill<T> {
    fn new(values: &[T]) -> Self {
        let bytes = std::mem::size_of_val(values);
        let map = (bytes > 0)
            .then(|| memmap2::MmapOptions::new().len(bytes).map_anon().ok())
            .flatten();
        match map {
            Some(mut map) => {
                map.copy_from_slice(bytemuck::cast_slice(values));
                Self {
                    map: Some(map),
                    len: values.len(),
                    ..Self::default()
                }
            }
            None => Self {
                heap: values.to_vec(),
                len: values.len(),
                ..Self::default()
            },
        }
    }

    fn len(&self) -> usize {
        self.len
    }

    fn as_slice(&self) -> &[T] {
        // A map starts on a page: aligned for any `T` of alignment up to a page.
        self.map.as_deref().map_or(&self.heap, bytemuck::cast_slice)
    }
}
