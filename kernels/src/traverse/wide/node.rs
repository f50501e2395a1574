//! The wide layout: [`WideNode`] (eight child boxes as structure-of-arrays, four cache
//! lines) and [`WideRef`], the validated view of a wide tree with its leaves' triangles as
//! structure-of-arrays rows ([`leaf_rows`]), which the walks ([`super::walk`],
//! [`super::packet_walk`]) read. After Embree's BVH8 (Wald et al., *Embree*, ACM TOG 33(4),
//! 2014) and its `triangle8v` leaves.

use super::*;
use crate::traverse::triangle::{ROWS, RowTri, TriAt};
use crate::traverse::{LEAF, LayoutError, Tri};
use bytemuck::{Pod, Zeroable};

/// One wide node: the boxes of up to eight children, four 64-byte cache lines.
///
/// Slot `c` is an inner child when `meta[c] == 0` (node `child[c]`), a leaf of
/// `meta[c] & !LEAF` triangles starting at `child[c]` otherwise. Used slots come first; an
/// empty slot has `meta == LEAF`, a `child` of at most the triangle count, and the inverted
/// box `lo = +∞`, `hi = −∞`, which every slab test misses. Node 0 is the root.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C, align(64))]
pub struct WideNode {
    /// Box minima, `lo[axis][child]`.
    pub lo: [[f32; WIDTH]; 3],
    /// Box maxima, `hi[axis][child]`.
    pub hi: [[f32; WIDTH]; 3],
    /// Node index (inner child) or first triangle (leaf child).
    pub child: [u32; WIDTH],
    /// `0` for an inner child, `LEAF | count` for a leaf.
    pub meta: [u32; WIDTH],
}

const _: () = assert!(core::mem::size_of::<WideNode>() == 256);

impl WideNode {
    /// A node whose slots are all empty (the root of an empty tree).
    pub const EMPTY: Self = Self {
        lo: [[f32::INFINITY; WIDTH]; 3],
        hi: [[f32::NEG_INFINITY; WIDTH]; 3],
        child: [0; WIDTH],
        meta: [LEAF; WIDTH],
    };

    /// Sets slot `slot`'s box, child and meta.
    pub fn set_slot(&mut self, slot: usize, lo: [f32; 3], hi: [f32; 3], child: u32, meta: u32) {
        for axis in 0..3 {
            self.lo[axis][slot] = lo[axis];
            self.hi[axis][slot] = hi[axis];
        }
        self.child[slot] = child;
        self.meta[slot] = meta;
    }

    /// The box of slot `slot`.
    pub(super) fn slot_box(&self, slot: usize) -> ([f32; 3], [f32; 3]) {
        (
            [0, 1, 2].map(|a| self.lo[a][slot]),
            [0, 1, 2].map(|a| self.hi[a][slot]),
        )
    }
}

/// A validated view of a wide BVH: nodes (root first) and the triangles as
/// structure-of-arrays rows per leaf ([`leaf_rows`]), which a single ray tests eight at a
/// time and a packet one at a time for its eight lanes; no other copy of the triangles.
#[derive(Clone, Copy, Debug)]
pub struct WideRef<'a> {
    pub(super) nodes: &'a [WideNode],
    pub(super) rows: &'a [f32],
}

impl<'a> WideRef<'a> {
    /// Checks every child index, leaf range (an empty slot's empty one too, which a crafted
    /// box lets a ray reach) against the triangles `rows` holds, that used slots come first,
    /// and the depth, once, so traversal can trust them.
    ///
    /// # Errors
    /// [`LayoutError::BadRows`] when `rows` is not the length [`leaf_rows`] gives; else the
    /// first [`LayoutError`] found, walking depth first from the root (slots `0..8`).
    pub fn new(nodes: &'a [WideNode], rows: &'a [f32]) -> Result<Self, LayoutError> {
        let tris = rows_tris(rows.len()).ok_or(LayoutError::BadRows)?;
        if nodes.is_empty() {
            return Err(LayoutError::NoNodes);
        }
        if nodes.len() > (u32::MAX / WIDTH as u32) as usize {
            return Err(LayoutError::BadChild { node: 0, slot: 0 });
        }
        let mut stack = [(0u32, 0usize); STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (index, depth) = stack[sp];
            if depth > WIDE_MAX_DEPTH {
                return Err(LayoutError::TooDeep { node: index });
            }
            let node = &nodes[index as usize];
            let mut ended = false;
            for slot in 0..WIDTH {
                let (child, meta) = (node.child[slot], node.meta[slot]);
                let bad_leaf = LayoutError::BadLeaf {
                    node: index,
                    slot: slot as u8,
                };
                if meta == LEAF {
                    // A crafted box can let a ray meet an empty slot: the packet walk then
                    // slices the leaf of no triangles at `child`.
                    if child as usize > tris {
                        return Err(bad_leaf);
                    }
                    ended = true;
                } else if ended {
                    return Err(bad_leaf);
                } else if meta == 0 {
                    if child <= index || child as usize >= nodes.len() {
                        return Err(LayoutError::BadChild {
                            node: index,
                            slot: slot as u8,
                        });
                    }
                    stack[sp] = (child, depth + 1);
                    sp += 1;
                } else if child as u64 + u64::from(meta & !LEAF) > tris as u64 {
                    return Err(bad_leaf);
                }
            }
        }
        Ok(Self { nodes, rows })
    }

    /// A view of a layout that already passed [`WideRef::new`] and has not changed since
    /// (see [`BvhRef::new_trusted`]; debug builds check the layout anyway).
    pub fn new_trusted(nodes: &'a [WideNode], rows: &'a [f32]) -> Self {
        debug_assert!(Self::new(nodes, rows).is_ok(), "layout never validated");
        Self { nodes, rows }
    }

    /// The nodes, root first.
    pub fn nodes(&self) -> &'a [WideNode] {
        self.nodes
    }

    /// The triangles of every leaf, read back from the rows, leaf by leaf (a triangle in
    /// several leaves comes once per leaf).
    pub fn tris(&self) -> impl Iterator<Item = Tri> + 'a {
        self.leaves().flat_map(|(_, leaf)| leaf)
    }

    /// Bytes of nodes and leaf rows (all the view holds).
    pub fn bytes(&self) -> usize {
        core::mem::size_of_val(self.nodes) + core::mem::size_of_val(self.rows)
    }

    /// The rows of the leaf starting at triangle `first`, to the end of the slice (the
    /// 8-wide loads read past a leaf's last row).
    pub(super) fn leaf_rows(&self, first: u32) -> &'a [f32] {
        // An empty slot (`meta == LEAF`, any `child`) that a crafted box lets a ray meet
        // reads no rows.
        self.rows.get(ROWS * first as usize..).unwrap_or(&[])
    }

    /// The triangles of the leaf `first`, `meta` (a used leaf slot), from its rows.
    fn leaf(&self, first: u32, meta: u32) -> RowTris<'a> {
        let n = (meta & !LEAF) as usize;
        RowTris {
            leaf: &self.leaf_rows(first)[..ROWS * n],
            n,
            i: 0,
        }
    }

    /// Every leaf slot: its box and its triangles (for the contract oracle).
    pub(in crate::traverse) fn leaves(
        self,
    ) -> impl Iterator<Item = (([f32; 3], [f32; 3]), RowTris<'a>)> {
        let view = self;
        self.nodes.iter().flat_map(move |node| {
            (0..WIDTH)
                .filter(move |&s| node.meta[s] != 0 && node.meta[s] != LEAF)
                .map(move |s| (node.slot_box(s), view.leaf(node.child[s], node.meta[s])))
        })
    }
}

/// Length of the rows of `tris` triangles: [`ROWS`] values per triangle and eight of
/// padding, so the last leaf's 8-wide loads stay inside.
#[cfg(any(feature = "alloc", test))]
pub(super) fn rows_len(tris: usize) -> usize {
    ROWS * tris + 8
}

/// The triangles rows of length `len` hold, if [`rows_len`] gives that length.
pub(super) fn rows_tris(len: usize) -> Option<usize> {
    let values = len.checked_sub(8)?;
    values.is_multiple_of(ROWS).then_some(values / ROWS)
}

/// The triangles of one leaf, read back from its rows ([`WideRef::leaves`]).
#[derive(Clone, Debug)]
pub(in crate::traverse) struct RowTris<'a> {
    leaf: &'a [f32],
    n: usize,
    i: usize,
}

impl Iterator for RowTris<'_> {
    type Item = Tri;

    fn next(&mut self) -> Option<Tri> {
        let i = self.i;
        (i < self.n).then(|| {
            self.i += 1;
            RowTri::new(self.leaf, self.n, i).tri()
        })
    }
}

/// The triangles of each leaf of `nodes` as structure-of-arrays rows, for [`WideRef::new`]:
/// the leaf of `n` triangles starting at triangle `first` holds row `r` (vertex `r / 3`, axis
/// `r % 3`; row 9 the primitive ids' bits) at `ROWS·first + r·n`, so one 8-wide load reads an
/// axis of eight of its triangles. Triangles outside every leaf keep zeros.
#[cfg(any(feature = "alloc", test))]
pub fn leaf_rows(nodes: &[WideNode], tris: &[Tri]) -> alloc::vec::Vec<f32> {
    extern crate alloc;
    let mut rows = alloc::vec![0.0; rows_len(tris.len())];
    for node in nodes {
        for slot in 0..WIDTH {
            let (first, meta) = (node.child[slot] as usize, node.meta[slot]);
            if meta == 0 || meta == LEAF {
                continue;
            }
            let n = (meta & !LEAF) as usize;
            for (i, t) in tris[first..first + n].iter().enumerate() {
                for r in 0..9 {
                    rows[ROWS * first + r * n + i] = t.v[r / 3][r % 3];
                }
                rows[ROWS * first + crate::traverse::triangle::PRIM_ROW * n + i] =
                    f32::from_bits(t.prim);
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {

    use super::*;
    use crate::packet::{Hit8, LANES, Ray, Ray8};

    use crate::traverse::{intersect1, intersect8, occluded1, occluded8};
    use glam::Vec3;
    use std::vec::Vec;

    #[test]
    fn wide_layout_errors_are_reported() {
        let tris = [Tri::new([Vec3::ZERO, Vec3::X, Vec3::Y], 0)];
        let mut one = WideNode::EMPTY;
        one.meta[0] = LEAF | 1;
        let rows = leaf_rows(&[one], &tris);
        assert_eq!(WideRef::new(&[], &rows).unwrap_err(), LayoutError::NoNodes);
        let mut bad = WideNode::EMPTY;
        bad.meta[0] = 0;
        assert_eq!(
            WideRef::new(&[bad], &rows).unwrap_err(),
            LayoutError::BadChild { node: 0, slot: 0 }
        );
        bad.meta[0] = LEAF | 2;
        assert_eq!(
            WideRef::new(&[bad], &rows).unwrap_err(),
            LayoutError::BadLeaf { node: 0, slot: 0 }
        );
        // An empty slot whose child lies past the triangles: a box that a ray meets would
        // have it sliced (with a box here; the packet walk panicked before the check).
        let mut past = WideNode::EMPTY;
        past.set_slot(0, [0.0; 3], [1.0, 1.0, 0.0], 0, LEAF | 1);
        past.set_slot(1, [0.0; 3], [1.0, 1.0, 0.0], 2, LEAF);
        assert_eq!(
            WideRef::new(&[past], &rows).unwrap_err(),
            LayoutError::BadLeaf { node: 0, slot: 1 }
        );
        past.child[1] = 1;
        let nodes = [past];
        let view = WideRef::new(&nodes, &rows).expect("an empty range at the end");
        let r = Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
        let mut hits = Hit8::NONE;
        let mask = intersect8(&view, &Ray8::from_rays(&[r; LANES]), &mut hits);
        assert_eq!((mask, hits.lane(0)), (0xff, intersect1(&view, &r)));
        assert_eq!(occluded8(&view, &Ray8::from_rays(&[r; LANES])), 0xff);
        // A used slot after an empty one.
        let mut gap = WideNode::EMPTY;
        gap.meta[3] = LEAF | 1;
        assert_eq!(
            WideRef::new(&[gap], &rows).unwrap_err(),
            LayoutError::BadLeaf { node: 0, slot: 3 }
        );
        let chain: Vec<WideNode> = (0..WIDE_MAX_DEPTH as u32 + 2)
            .map(|i| {
                let mut n = WideNode::EMPTY;
                n.child[0] = i + 1;
                n.meta[0] = 0;
                n
            })
            .chain([WideNode::EMPTY])
            .collect();
        assert!(matches!(
            WideRef::new(&chain, &rows),
            Err(LayoutError::TooDeep { .. })
        ));
        // Rows of no whole number of triangles, or shorter than the padding.
        for len in [rows.len() - 1, rows.len() + 3, 7, 0] {
            let odd = std::vec![0.0; len];
            assert_eq!(
                WideRef::new(&[one], &odd).unwrap_err(),
                LayoutError::BadRows,
                "{len}"
            );
        }
        // Rows of fewer triangles than a leaf's range.
        let short = leaf_rows(&[WideNode::EMPTY], &[]);
        assert_eq!(
            WideRef::new(&[one], &short).unwrap_err(),
            LayoutError::BadLeaf { node: 0, slot: 0 }
        );
        // The empty tree: every ray misses.
        let empty = [WideNode::EMPTY];
        let empty_rows = leaf_rows(&empty, &[]);
        let view = WideRef::new(&empty, &empty_rows).unwrap();
        let r = Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(intersect1(&view, &r), None);
        assert!(!occluded1(&view, &r));
    }
}
