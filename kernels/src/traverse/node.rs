//! # traverse::node: the binary layout
//!
//! A [`BinaryNode`] is one 64-byte cache line holding the boxes of its *two children* (so one node
//! visit tests two boxes for all eight lanes of a packet), their indices and their leaf
//! counts. A [`Tri`] stores its three vertices (not edges: the watertight test needs the
//! vertices themselves) and its primitive id, in leaf order. [`BvhRef`] is a validated view.
//! The wide layout, collapsed from this one, is in [`super::wide`].

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// `meta` bit marking a leaf child (the low bits count its triangles).
pub const LEAF: u32 = 1 << 31;

/// Deepest tree [`BvhRef::new`] accepts (root at depth 0); bounds the traversal stack.
pub const BVH_MAX_DEPTH: usize = 128;

pub(super) const STACK: usize = BVH_MAX_DEPTH + 2;

/// One BVH node: the boxes of its two children, one 64-byte cache line.
///
/// Child `c` is an inner node when `meta[c] == 0` (its index is `child[c]`), else a leaf of
/// `meta[c] & !LEAF` triangles starting at `child[c]`. An empty slot is a leaf of zero
/// triangles. Node 0 is the root.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C, align(64))]
pub struct BinaryNode {
    /// Box minima, `lo[axis][child]`.
    pub lo: [[f32; 2]; 3],
    /// Box maxima, `hi[axis][child]`.
    pub hi: [[f32; 2]; 3],
    /// Node index (inner child) or first triangle (leaf child).
    pub child: [u32; 2],
    /// `0` for an inner child, `LEAF | count` for a leaf.
    pub meta: [u32; 2],
}

const _: () = assert!(core::mem::size_of::<BinaryNode>() == 64);
const _: () = assert!(core::mem::align_of::<BinaryNode>() == 64);

impl BinaryNode {
    /// A node whose two slots are empty leaves (the root of an empty tree).
    pub const EMPTY: Self = Self {
        lo: [[0.0; 2]; 3],
        hi: [[0.0; 2]; 3],
        child: [0; 2],
        meta: [LEAF; 2],
    };

    /// Sets slot `slot`'s box.
    pub fn set_box(&mut self, slot: usize, lo: Vec3, hi: Vec3) {
        for axis in 0..3 {
            self.lo[axis][slot] = lo[axis];
            self.hi[axis][slot] = hi[axis];
        }
    }
}

/// One triangle: its vertices and its primitive id, 48 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C, align(16))]
pub struct Tri {
    /// Vertices `v[vertex][axis]`.
    pub v: [[f32; 3]; 3],
    /// Primitive id reported in hits.
    pub prim: u32,
    /// Padding (zero).
    pub pad: [u32; 2],
}

const _: () = assert!(core::mem::size_of::<Tri>() == 48);

impl Tri {
    /// A triangle with primitive id `prim`.
    pub fn new(v: [Vec3; 3], prim: u32) -> Self {
        Self {
            v: v.map(|p| p.to_array()),
            prim,
            pad: [0; 2],
        }
    }
}

/// Why [`BvhRef::new`] rejected a node/triangle layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayoutError {
    /// The node slice is empty (an empty tree is one [`BinaryNode::EMPTY`]).
    NoNodes,
    /// An inner child does not point forward to an existing node.
    BadChild {
        /// Node holding the slot.
        node: u32,
        /// Slot (0 or 1).
        slot: u8,
    },
    /// A leaf's triangle range runs past the triangle slice.
    BadLeaf {
        /// Node holding the slot.
        node: u32,
        /// Slot (0 or 1).
        slot: u8,
    },
    /// A wide view's leaf rows are not the length [`super::leaf_rows`] gives for any number
    /// of triangles.
    BadRows,
    /// The tree is deeper than [`BVH_MAX_DEPTH`].
    TooDeep {
        /// First node found too deep.
        node: u32,
    },
}

/// A validated view of a flat BVH: nodes (root first) and triangles in leaf order.
#[derive(Clone, Copy, Debug)]
pub struct BvhRef<'a> {
    pub(super) nodes: &'a [BinaryNode],
    pub(super) tris: &'a [Tri],
}

impl<'a> BvhRef<'a> {
    /// Checks every child index, leaf range and the depth, once, so traversal can trust them.
    ///
    /// # Errors
    /// The first [`LayoutError`] found, walking depth first from the root.
    pub fn new(nodes: &'a [BinaryNode], tris: &'a [Tri]) -> Result<Self, LayoutError> {
        if nodes.is_empty() {
            return Err(LayoutError::NoNodes);
        }
        let mut stack = [(0u32, 0usize); STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (index, depth) = stack[sp];
            if depth > BVH_MAX_DEPTH {
                return Err(LayoutError::TooDeep { node: index });
            }
            let node = &nodes[index as usize];
            for slot in 0..2 {
                let (child, meta) = (node.child[slot], node.meta[slot]);
                if meta == 0 {
                    if child <= index || child as usize >= nodes.len() {
                        return Err(LayoutError::BadChild {
                            node: index,
                            slot: slot as u8,
                        });
                    }
                    stack[sp] = (child, depth + 1);
                    sp += 1;
                } else {
                    let end = child as u64 + u64::from(meta & !LEAF);
                    if end > tris.len() as u64 {
                        return Err(LayoutError::BadLeaf {
                            node: index,
                            slot: slot as u8,
                        });
                    }
                }
            }
        }
        Ok(Self { nodes, tris })
    }

    /// A view of a layout that already passed [`BvhRef::new`] and has not changed since,
    /// without walking it again. The walk is linear in the nodes, and a bake that asked for a
    /// view per texel and per shadow query spent 17 % of its time in it. Safe to misuse in
    /// the memory sense: traversal indexes with bounds checks, so a layout that would fail
    /// `new` makes it panic (or, for a cycle, not finish), never read out of bounds; debug
    /// builds check the layout anyway.
    pub fn new_trusted(nodes: &'a [BinaryNode], tris: &'a [Tri]) -> Self {
        debug_assert!(Self::new(nodes, tris).is_ok(), "layout never validated");
        Self { nodes, tris }
    }

    /// The nodes, root first.
    pub fn nodes(&self) -> &'a [BinaryNode] {
        self.nodes
    }

    /// The triangles, in leaf order.
    pub fn tris(&self) -> &'a [Tri] {
        self.tris
    }

    pub(super) fn leaf(&self, first: u32, meta: u32) -> &'a [Tri] {
        let first = first as usize;
        &self.tris[first..first + (meta & !LEAF) as usize]
    }
}
