//! # traverse::wide: eight child boxes per node, tested with one 8-lane slab test
//!
//! The wide layout of the traversal ([`WideNode`], [`WideRef`]): each node holds the boxes of
//! up to eight children as structure-of-arrays `lo[axis][child]`, `hi[axis][child]`, so a
//! single ray tests all eight with one `f32x8` slab test per axis, and a packet does so for
//! each live lane ([`boxes8`]). The leaves are the binary tree's leaves,
//! unchanged: ranges of the same leaf-ordered [`Tri`]s (Woop's watertight form), so a binary
//! view and its wide view share one triangle array. After Wald, Benthin & Boulos, *Getting
//! Rid of Packets* (2008) and Embree's BVH8 (Wald et al., *Embree*, ACM TOG 33(4), 2014).
//!
//! The wide view also holds each leaf's triangles as structure-of-arrays rows
//! ([`leaf_rows`]), so one ray tests up to eight triangles per `f32x8` pass (Embree's
//! `triangle8v` idea, with the watertight test): the single-ray walk does so at every leaf,
//! the packet walk at a leaf few lanes reach. The packet walk looking for any hit finishes a
//! subtree that at most two lanes reach lane by lane ([`occluded_alone`], Embree's hybrid
//! switch). Packets of unrelated rays on a large tree are walked as interleaved single rays
//! with prefetching ([`walk_interleaved_any`]): eight independent chains of cache misses
//! overlap.
//!
//! [`collapse`] builds a wide tree from a binary [`BvhRef`]: every wide node takes its binary
//! node's grandchildren (so a wide level spans at least two binary levels and the depth stays
//! within [`WIDE_MAX_DEPTH`]), and which binary nodes become wide nodes is the least surface
//! area cost's choice, found by dynamic programming (Ylitie, Karras & Laine 2017, with the
//! binary tree's leaves kept; [`SlotCosts`]). It replaced opening the inner child of largest
//! surface area until eight slots were filled (Embree's collapse order): 30 % fewer wide nodes
//! on the 1M city, whose gather packets went from 1.01× to 1.06–1.07× Embree's
//! (docs/traverse.md, "What each kept change bought").
//!
//! The boxes and the triangle test are the binary traversal's. The slab test is as
//! conservative as the binary traversal's: in the fused form `p·inv − o·inv` with the offsets
//! moved by an ulp for rays whose inverse direction is finite, so it may meet a box the binary
//! traversal culls but never culls one it meets, and in the binary traversal's exact form
//! `(p − o)·inv` for rays with an infinite inverse component ([`super::slab`]; every walk is
//! compiled for both, `const EXACT: bool`, and chooses once a ray or packet). The results
//! equal the binary traversal's and brute force bit for bit (wherever every hit lies inside
//! its leaf's box: `traverse`'s module docs).

#[cfg(any(feature = "alloc", test))]
mod collapse;
mod node;
mod packet_walk;
mod stack;
mod walk;

use stack::*;

#[cfg(any(feature = "alloc", test))]
pub use collapse::collapse;
pub(in crate::traverse) use node::RowTris;
#[cfg(any(feature = "alloc", test))]
pub use node::leaf_rows;
pub use node::{WideNode, WideRef};
pub(in crate::traverse) use packet_walk::{Visitor, walk8};
pub use walk::INTERLEAVE_BYTES;
pub(in crate::traverse) use walk::{occluded_alone, walk_interleaved_any, walk1, walk1_any};
#[cfg(test)]
mod tests;

/// Children per wide node.
pub const WIDTH: usize = 8;

/// Deepest wide tree [`WideRef::new`] accepts (root at depth 0). [`collapse`] halves the
/// binary depth at least, so every valid binary tree collapses within it.
pub const WIDE_MAX_DEPTH: usize = crate::traverse::BVH_MAX_DEPTH / 2;

/// Stack entries a walk needs: at most `WIDTH − 1` pending siblings per level, plus one
/// node's children.
const STACK: usize = (WIDTH - 1) * (WIDE_MAX_DEPTH + 1) + WIDTH + 1;
