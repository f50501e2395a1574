//! # traverse: 8-wide packet BVH traversal, with the scalar single ray beside it
//!
//! Silvennoinen & Sloan 2019, §2.4: a texel's final-gather packet shares one origin and, once
//! the Sobol points are presorted, its eight directions are coherent; tracing the eight rays
//! together turns that coherence into speed. This module traces [`Ray8`] packets (and single
//! rays) through kernel-owned, flat BVHs that the driver fills from the tree obvhs builds, in
//! one of two layouts; every traversal takes any [`Tree`] ([`BvhRef`], [`WideRef`] or a
//! [`Layout`] holding either) and gives the same results on both.
//!
//! - **Layouts.** Binary ([`BinaryNode`]): one 64-byte cache line holds the
//!   boxes of a node's *two children* (so one node visit tests two boxes for all eight
//!   lanes), their indices and their leaf counts. Wide ([`WideNode`], collapsed from the binary
//!   tree by [`collapse`]): eight child boxes per 256-byte node, structure of arrays, so one
//!   `f32x8` slab test per axis covers a node's children for one ray. Both share the leaves:
//!   ranges of [`Tri`]s, three vertices each (not edges: the watertight test needs the
//!   vertices themselves) and the primitive id, in leaf order; the wide view also holds them
//!   as structure-of-arrays rows per leaf ([`leaf_rows`]), so one ray tests eight triangles
//!   per `f32x8` pass.
//! - **Ray/triangle test.** Woop, Benthin & Wald, *Watertight Ray/Triangle Intersection*,
//!   JCGT 2(1), 2013: shear into the ray's space (`kz` = largest direction axis, `kx`/`ky`
//!   swapped when `d[kz] < 0`), 2D edge functions `U, V, W`, recomputed in `f64` when one is
//!   exactly zero (their exact signs decide inside or outside), no backface culling. Rays
//!   through a closed mesh's shared edges and vertices never slip through.
//! - **Box test.** Slabs with `(b − o) · (1/d)`; the interval is widened by 32 ulps (pbrt-v4
//!   §6.8.2's `1 + 2γ₃` plus room for the triangle test's rounding of `t`, see `SLACK`) so
//!   that rounding never culls a box holding a hit the oracle accepts. Planes are taken near
//!   first by the direction's sign bits and a NaN plane distance (`0 · ∞`, a ray running inside
//!   a box face) leaves the interval unconstrained, so rays along faces are kept. The wide
//!   tree's walks compute the same slabs fused, `b · (1/d) − o · (1/d)` with the offsets
//!   moved an ulp outwards (`slab::slab`): as conservative, one operation fewer per plane.
//! - **Packet traversal** ([`intersect8`], [`occluded8`]): one shared stack; a child is
//!   visited when any lane's interval meets its box; in the binary tree, when both children
//!   are hit the lanes vote on which is nearer and that one is visited first; in the wide
//!   tree each live lane tests the node's eight boxes at once and the children met are visited
//!   nearest first. Triangles are tested for all eight lanes at once; when every lane of the
//!   packet has the same shear permutation (the usual case for a coherent packet) the
//!   vertices are permuted once per triangle as scalars, otherwise per lane with blends.
//! - **Single rays** ([`intersect1`], [`occluded1`]) walk the same nodes with the same box and
//!   triangle arithmetic as the packets of their layout (the binary walk is the scalar
//!   reference), and [`intersect_brute`] / [`occluded_brute`] test every triangle: the test
//!   oracle.
//! - **Sections**, as Embree keeps `bvh_node_*`, `*_intersector*` and `bvh_traverser*` apart:
//!   `node` (binary layout), `triangle` (per-ray constants, the watertight test for one and
//!   eight rays), `slab` (the slab tests' slack and the fused form's constants), `scalar` (slab
//!   test, single-ray walk), `packet` (8-lane slab test, packet walk), `wide` (wide layout,
//!   collapse, both wide walks); this file holds the public API and the oracle. Measured
//!   speeds: docs/traverse.md.
//!
//! **Results are exact, not approximate.** The scalar and 8-wide triangle tests perform the
//! same IEEE operations in the same order (no FMA contraction), so `t`, `u`, `v` agree bit for
//! bit across [`intersect_brute`], [`intersect1`] and [`intersect8`], on either layout. Equal `t` from several
//! triangles is resolved by the **tie rule**: the smallest primitive id wins. Hits are accepted
//! on `[tmin, tmax]`, both ends included (`tmax` is clamped to `f32::MAX`, so `t = ∞` is never
//! reported).
//!
//! Deviations and limits:
//! - Rays with `tmin < 0` are not traced (they never hit): the conservative box bound assumes
//!   `t ≥ 0`. See [`Ray::is_traceable`](crate::packet::Ray::is_traceable) for the full rule.
//! - The tree depth is capped at [`BVH_MAX_DEPTH`] ([`WIDE_MAX_DEPTH`] for the wide layout, which
//!   [`collapse`] always meets); [`BvhRef::new`] and [`WideRef::new`] reject deeper trees.
//! - **Hits outside their own box.** At extreme magnitudes the triangle test can report a hit
//!   that lies outside the slab interval of the box of the leaf holding the triangle (its
//!   own bounding box, or with spatial splits the box of the part clipped to the leaf):
//!   - *outside the box*: origins of 10⁻³⁶ beside triangles of size 10–100, directions of
//!     10²⁸ beside components of 10⁻⁴⁰: the shear `a[kx] − s·a[kz]` rounds the origin's
//!     offsets across the ray relative to the vertices' distance along `kz`, which no slack
//!     relative to the box distances covers; a ray passing 3·10⁻²⁶ beside an edge is
//!     rounded onto it, where a spatial split clipped the triangle into parts whose boxes
//!     the ray misses;
//!   - *before the box*: origins of 10⁻²⁶–10⁻³⁸ on triangles of 10⁻⁶: `t = T/det` is the
//!     quotient of products that underflow (the terms `U·(s_z·a_z)` of 10⁻⁵⁰ round to 0), so
//!     a hit at a true distance of 2·10⁻³⁸ comes out at `t = 0`, below the box's entry
//!     distance, and no absolute slack covers `2⁻¹⁴⁹ / det` for every `det`;
//!   - *behind the origin*, at ordinary magnitudes: a ray that starts within a few ulps of
//!     a triangle's plane, just beyond one of its edges, and leaves it: `t = T/det` is then
//!     the rounded quotient of terms far larger than itself and can come out positive for a
//!     plane crossed behind the origin. Bakes meet it: a ray from a texel in a corner, lifted
//!     off its own surface by `offset_origin`, can start that close to a neighbouring sliver
//!     (Veach's bidir scene, door frame: exact `t = −2.9·10⁻⁶`, reported `+1.15·10⁻⁶`, in
//!     125 of its bake's 4.4·10⁷ gather rays at 16 spp, 2026-11-27). pbrt-v4 rejects hits
//!     below a conservative bound on `t`'s rounding error (`deltaT`), which makes `t`'s sign
//!     exact at the price of about twenty more operations per candidate hit; not done here.
//!
//!   A traversal culls a box once its entry distance passes the closest hit found so far,
//!   so it may miss such a hit, find it (a leaf tests all its triangles), or find it in place
//!   of a closer one of its kind that brute force reports. The contract, checked by
//!   [`closest_hit_allowed`] and [`occlusion_allowed`] (the `traverse` fuzz target runs
//!   them on every ray that differs from brute force): a traversal's closest hit is the
//!   closest hit (tie rule) over *some* set of the BVH's triangles that holds every triangle
//!   of every leaf whose box the slab test lets the ray meet on `[tmin, t]`, `t` the
//!   returned hit's distance (`tmax` without a hit) — which is what culling by conservative
//!   boxes guarantees, a parent's box holding its children's; it answers occlusion `true`
//!   only for a triangle that occludes, `false` only when no triangle of a leaf the ray
//!   meets on `[tmin, tmax]` does. Where every hit lies inside its leaf's box interval
//!   (every ray at ordinary magnitudes that does not start within a few ulps of a
//!   triangle's plane) that is exactly brute force. Otherwise the layouts, and the packet
//!   and single-ray walks, may answer differently (each within the contract), so a bake's
//!   result can depend on which tree its packets walk (`tests/traverse.rs`, corner rays).
//!   (A far bound widened by 2⁻¹⁸ of the root box's extent along `kz` removes the first kind
//!   found first, but culls so much less that the packet path ran 12–46 % slower on
//!   `benches/traverse.rs`.)

use crate::packet::{Hit, Hit8, NO_HIT, Ray, Ray8};
use ::wide::{f32x8, u32x8};

mod node;
mod packet_walk;
mod scalar;
mod slab;
mod triangle;
mod wide;

use packet_walk::{Closest, Occlusion, start8, walk8};
use scalar::{box1_at, walk1};
use slab::{NEAR_DOWN, widened};
use triangle::{
    Best8, Pre, Pre1x8, Pre8, accept, closest_rows, closest1, no_hit, occludes_rows, occludes1,
    traceable, tri1,
};

use node::STACK;
pub use node::{BVH_MAX_DEPTH, BinaryNode, BvhRef, LEAF, LayoutError, Tri};
pub use wide::{INTERLEAVE_BYTES, WIDE_MAX_DEPTH, WIDTH, WideNode, WideRef};
#[cfg(any(feature = "alloc", test))]
pub use wide::{collapse, leaf_rows};

/// A validated BVH in one of the kernels' layouts: what the traversals walk.
#[derive(Clone, Copy, Debug)]
pub enum Layout<'a> {
    /// Two child boxes per node ([`BinaryNode`]).
    Binary(BvhRef<'a>),
    /// Eight child boxes per node ([`WideNode`]).
    Wide(WideRef<'a>),
}

/// The triangles of one leaf of either layout.
enum LeafTris<'a> {
    Binary(core::slice::Iter<'a, Tri>),
    Wide(wide::RowTris<'a>),
}

impl Iterator for LeafTris<'_> {
    type Item = Tri;

    fn next(&mut self) -> Option<Tri> {
        match self {
            LeafTris::Binary(tris) => tris.next().copied(),
            LeafTris::Wide(rows) => rows.next(),
        }
    }
}

impl<'a> Layout<'a> {
    /// The triangles of every leaf (a triangle in several leaves comes once per leaf).
    pub fn tris(self) -> impl Iterator<Item = Tri> + 'a {
        self.leaves().flat_map(|(_, leaf)| leaf)
    }

    /// Every leaf: its box and its triangles.
    fn leaves(self) -> impl Iterator<Item = (([f32; 3], [f32; 3]), LeafTris<'a>)> {
        let (binary, wide) = match self {
            Layout::Binary(b) => (Some(b), None),
            Layout::Wide(w) => (None, Some(w)),
        };
        let binary = binary.into_iter().flat_map(|b| {
            b.nodes.iter().flat_map(move |node| {
                (0..2).filter(move |&s| node.meta[s] != 0).map(move |s| {
                    let lo = [0, 1, 2].map(|a| node.lo[a][s]);
                    let hi = [0, 1, 2].map(|a| node.hi[a][s]);
                    (
                        (lo, hi),
                        LeafTris::Binary(b.leaf(node.child[s], node.meta[s]).iter()),
                    )
                })
            })
        });
        let wide = wide
            .into_iter()
            .flat_map(|w| w.leaves().map(|(aabb, leaf)| (aabb, LeafTris::Wide(leaf))));
        binary.chain(wide)
    }
}

/// A BVH view the traversals accept: [`BvhRef`], [`WideRef`] or a [`Layout`].
pub trait Tree {
    /// The layout to walk.
    fn layout(&self) -> Layout<'_>;
}

impl Tree for BvhRef<'_> {
    fn layout(&self) -> Layout<'_> {
        Layout::Binary(*self)
    }
}

impl Tree for WideRef<'_> {
    fn layout(&self) -> Layout<'_> {
        Layout::Wide(*self)
    }
}

impl Tree for Layout<'_> {
    fn layout(&self) -> Layout<'_> {
        *self
    }
}

/// Closest hit of one ray, testing every triangle: the oracle for the traversals.
pub fn intersect_brute(tris: &[Tri], ray: &Ray) -> Option<Hit> {
    if !traceable(ray) {
        return None;
    }
    let pre = Pre::new(ray);
    let mut best = no_hit(ray.tmax);
    for tri in tris {
        closest1(&pre, tri, &mut best);
    }
    (best.prim != NO_HIT).then_some(best)
}

/// Whether `got` is a closest-hit result the traversal contract allows for `ray` through
/// `bvh` (module docs, "Hits outside their own box"): either no hit or bit for bit the hit
/// of one of the BVH's triangles on the ray's interval, and no triangle of a leaf whose box
/// the slab test lets the ray meet on `[tmin, t]` (`t` = `got`'s distance, else `tmax`) has
/// a hit the tie rule prefers. Where every hit lies inside its leaf's box interval this
/// holds exactly for the closest hit over the BVH's triangles, brute force. The test oracle
/// for the traversals where they differ from brute force.
pub fn closest_hit_allowed(bvh: &impl Tree, ray: &Ray, got: Option<Hit>) -> bool {
    let bvh = bvh.layout();
    if !traceable(ray) {
        return got.is_none();
    }
    let pre = Pre::new(ray);
    let best = match got {
        None => no_hit(ray.tmax),
        Some(h) => {
            let bits = |h: &Hit| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim);
            let own = |tri: &Tri| {
                let mut own = no_hit(ray.tmax);
                closest1(&pre, tri, &mut own);
                bits(&own) == bits(&h)
            };
            if !bvh.tris().any(|tri| tri.prim == h.prim && own(&tri)) {
                return false;
            }
            h
        }
    };
    !leaves_met(bvh, &pre, best.t)
        .any(|tri| tri1(&pre, &tri).is_some_and(|(t, _, _)| accept(t, tri.prim, pre.tmin, &best)))
}

/// Whether `got` is an occlusion answer the traversal contract allows: `true` only when a
/// triangle of `bvh` occludes the ray, `false` only when no triangle of a leaf whose box
/// the slab test lets the ray meet on `[tmin, tmax]` does (module docs, "Hits outside their
/// own box").
pub fn occlusion_allowed(bvh: &impl Tree, ray: &Ray, got: bool) -> bool {
    let bvh = bvh.layout();
    if !traceable(ray) {
        return !got;
    }
    let pre = Pre::new(ray);
    let tmax = ray.tmax.min(f32::MAX);
    if got {
        bvh.tris().any(|tri| occludes1(&pre, &tri, tmax))
    } else {
        !leaves_met(bvh, &pre, tmax).any(|tri| occludes1(&pre, &tri, tmax))
    }
}

/// The triangles of every leaf whose box the ray's conservative slab interval on
/// `[tmin, tmax]` meets: what a traversal whose closest hit is at `tmax` must have tested
/// (a parent's box contains its children's, and the slab test is monotone in the box).
fn leaves_met<'a>(bvh: Layout<'a>, pre: &Pre, tmax: f32) -> impl Iterator<Item = Tri> + 'a {
    let pre = *pre;
    bvh.leaves()
        .filter(move |(aabb, _)| box1_at(*aabb, &pre, tmax).is_some())
        .flat_map(|(_, leaf)| leaf)
}

/// Whether any triangle blocks the ray on `[tmin, tmax]`, testing every triangle: the oracle.
pub fn occluded_brute(tris: &[Tri], ray: &Ray) -> bool {
    traceable(ray) && {
        let pre = Pre::new(ray);
        let tmax = ray.tmax.min(f32::MAX);
        tris.iter().any(|tri| occludes1(&pre, tri, tmax))
    }
}

/// Closest hit of one ray: the scalar reference traversal.
///
/// Returns `None` for a miss and for rays that are not traced (inactive, non-finite, zero
/// direction, `tmin < 0`).
pub fn intersect1(bvh: &impl Tree, ray: &Ray) -> Option<Hit> {
    if !traceable(ray) {
        return None;
    }
    let pre = Pre::new(ray);
    let mut best = no_hit(ray.tmax);
    match bvh.layout() {
        Layout::Binary(b) => walk1(&b, &pre, |leaf: &[Tri]| {
            for tri in leaf {
                closest1(&pre, tri, &mut best);
            }
            best.t
        }),
        Layout::Wide(w) => {
            let pre8 = Pre1x8::new(&pre);
            wide::walk1(&w, &pre, |rows, n| {
                closest_rows(|| pre, &pre8, rows, n, &mut best);
                best.t
            })
        }
    };
    (best.prim != NO_HIT).then_some(best)
}

/// Whether anything blocks one ray on `[tmin, tmax]`: the scalar reference, with early exit.
pub fn occluded1(bvh: &impl Tree, ray: &Ray) -> bool {
    if !traceable(ray) {
        return false;
    }
    let pre = Pre::new(ray);
    let tmax = ray.tmax.min(f32::MAX);
    match bvh.layout() {
        Layout::Binary(b) => {
            // The binary walk ends when a leaf returns −∞.
            let end = walk1(&b, &pre, |leaf: &[Tri]| {
                if leaf.iter().any(|tri| occludes1(&pre, tri, tmax)) {
                    f32::NEG_INFINITY
                } else {
                    tmax
                }
            });
            end == f32::NEG_INFINITY
        }
        Layout::Wide(w) => {
            let pre8 = Pre1x8::new(&pre);
            wide::walk1_any(&w, &pre, tmax, |rows, n| {
                occludes_rows(|| pre, &pre8, rows, n, tmax)
            })
        }
    }
}

/// Closest hits of eight rays: the packet traversal.
///
/// Lanes that are not traced (inactive, non-finite, zero direction, `tmin < 0`) and lanes that
/// miss leave their `hits` lane untouched. Returns the bit mask of lanes that hit. Each hit
/// equals [`intersect1`]'s for that lane, bit for bit, whatever the layout, wherever every
/// hit lies inside its leaf's box (module docs, "Hits outside their own box").
pub fn intersect8(bvh: &impl Tree, rays: &Ray8, hits: &mut Hit8) -> u8 {
    let Some((pre, tmax)) = start8(rays) else {
        return 0;
    };
    let mut closest = Closest {
        pre: &pre,
        best: Best8 {
            t: tmax,
            u: f32x8::ZERO,
            v: f32x8::ZERO,
            prim: u32x8::splat(NO_HIT),
        },
    };
    match bvh.layout() {
        Layout::Binary(b) => walk8(&b, &pre, tmax, &mut closest),
        Layout::Wide(w) => wide::walk8(&w, &pre, tmax, &mut closest),
    }
    let best = closest.best;
    let hit_mask = best.prim.simd_ne(u32x8::splat(NO_HIT));
    let f: f32x8 = bytemuck::cast(hit_mask);
    hits.t = f.bitselect(best.t, hits.t);
    hits.u = f.bitselect(best.u, hits.u);
    hits.v = f.bitselect(best.v, hits.v);
    hits.prim = hit_mask.bitselect(best.prim, hits.prim);
    f.to_bitmask() as u8
}

/// Which of eight rays are blocked on `[tmin, tmax]`: packet traversal with early exit (a lane
/// drops out when blocked, the walk ends when all have). Returns the bit mask of blocked lanes;
/// lanes that are not traced are never blocked. Equals [`occluded1`] lane for lane.
///
/// On the wide layout the packet walk finishes a subtree that at most two live lanes reach
/// lane by lane, as single rays (Embree's hybrid switch; docs/traverse.md, "Wide layout"). On a
/// tree larger than [`INTERLEAVE_BYTES`], a packet whose lanes do not share an origin (eight
/// unrelated shadow rays) is traced as single rays from the root, interleaved, so that the
/// lanes' cache misses overlap (docs/traverse.md, "Wide layout").
pub fn occluded8(bvh: &impl Tree, rays: &Ray8) -> u8 {
    let Some((pre, tmax)) = start8(rays) else {
        return 0;
    };
    let mut occlusion = Occlusion {
        pre: &pre,
        tmax,
        blocked: 0,
    };
    match bvh.layout() {
        Layout::Binary(b) => walk8(&b, &pre, tmax, &mut occlusion),
        Layout::Wide(w) if w.bytes() > wide::INTERLEAVE_BYTES && !pre.shared_origin() => {
            return occluded_interleaved(&w, &pre, tmax);
        }
        Layout::Wide(w) => wide::walk8(&w, &pre, tmax, &mut occlusion),
    }
    occlusion.blocked
}

/// The traced lanes of a packet through the wide layout as single rays from the root, their
/// walks interleaved ([`wide::walk_interleaved_any`]): the blocked lanes.
fn occluded_interleaved(w: &WideRef<'_>, pre: &Pre8, tmax: f32x8) -> u8 {
    wide::walk_interleaved_any(w, pre, tmax, pre.traced, |i, pre8, rows, n| {
        occludes_rows(|| pre.lane(i), pre8, rows, n, tmax.as_array()[i])
    })
}

#[cfg(test)]
mod tests {
    use super::scalar::box1;
    use super::*;
    use crate::packet::LANES;
    use crate::testing::Pcg32;
    use glam::Vec3;
    use std::vec::Vec;

    /// Test-only builder: median split on the longest axis, leaves of at most 3 triangles.
    fn build(soup: &[[Vec3; 3]]) -> (Vec<BinaryNode>, Vec<Tri>) {
        let mut items: Vec<(u32, [Vec3; 3])> = soup
            .iter()
            .enumerate()
            .map(|(i, t)| (i as u32, *t))
            .collect();
        let mut nodes = std::vec![BinaryNode::EMPTY];
        let mut tris = Vec::new();
        if items.len() <= 3 {
            fill(&mut nodes, 0, 0, &mut items, &mut tris);
            return (nodes, tris);
        }
        let mid = items.len() / 2;
        split(&mut items);
        let (l, r) = items.split_at_mut(mid);
        fill(&mut nodes, 0, 0, l, &mut tris);
        fill(&mut nodes, 0, 1, r, &mut tris);
        (nodes, tris)
    }

    fn bounds(items: &[(u32, [Vec3; 3])]) -> (Vec3, Vec3) {
        items
            .iter()
            .flat_map(|(_, t)| t.iter())
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            })
    }

    fn split(items: &mut [(u32, [Vec3; 3])]) {
        let (lo, hi) = bounds(items);
        let axis = (hi - lo).max_position();
        items.sort_by(|a, b| {
            let c = |t: &[Vec3; 3]| t[0][axis] + t[1][axis] + t[2][axis];
            c(&a.1).total_cmp(&c(&b.1))
        });
    }

    fn fill(
        nodes: &mut Vec<BinaryNode>,
        parent: usize,
        slot: usize,
        items: &mut [(u32, [Vec3; 3])],
        tris: &mut Vec<Tri>,
    ) {
        let (lo, hi) = bounds(items);
        nodes[parent].set_box(slot, lo, hi);
        if items.len() <= 3 {
            nodes[parent].child[slot] = tris.len() as u32;
            nodes[parent].meta[slot] = LEAF | items.len() as u32;
            tris.extend(items.iter().map(|(p, t)| Tri::new(*t, *p)));
            return;
        }
        let index = nodes.len();
        nodes.push(BinaryNode::EMPTY);
        nodes[parent].child[slot] = index as u32;
        nodes[parent].meta[slot] = 0;
        split(items);
        let mid = items.len() / 2;
        let (l, r) = items.split_at_mut(mid);
        fill(nodes, index, 0, l, tris);
        fill(nodes, index, 1, r, tris);
    }

    fn v3(rng: &mut Pcg32, s: f32) -> Vec3 {
        Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * s
    }

    fn soup(rng: &mut Pcg32, n: usize) -> Vec<[Vec3; 3]> {
        (0..n)
            .map(|_| {
                let c = v3(rng, 4.0);
                [c + v3(rng, 0.5), c + v3(rng, 0.5), c + v3(rng, 0.5)]
            })
            .collect()
    }

    /// A ray from edge values: axis-aligned, zero and signed-zero components, shared origins.
    fn ray(rng: &mut Pcg32, org: Vec3) -> Ray {
        let special = [0.0, -0.0, 1.0, -1.0, 1e-20, 0.5];
        let mut c = || {
            if rng.next_u32().is_multiple_of(3) {
                special[(rng.next_u32() % 6) as usize]
            } else {
                rng.next_f32() * 2.0 - 1.0
            }
        };
        let d = Vec3::new(c(), c(), c());
        let tmax = if rng.next_u32().is_multiple_of(3) {
            1.0 + 4.0 * rng.next_f32()
        } else {
            f32::INFINITY
        };
        Ray::new(org, d, 0.0, tmax)
    }

    /// The collapse of `binary` and its leaf rows.
    fn widen(binary: &BvhRef<'_>) -> (Vec<WideNode>, Vec<f32>) {
        let wide = collapse(binary);
        let rows = leaf_rows(&wide, binary.tris());
        (wide, rows)
    }

    /// The binary view of `nodes`/`tris` and the wide view of its collapse (`wide`).
    fn layouts<'a>(bvh: BvhRef<'a>, wide: &'a (Vec<WideNode>, Vec<f32>)) -> [Layout<'a>; 2] {
        [
            Layout::Binary(bvh),
            Layout::Wide(WideRef::new(&wide.0, &wide.1).expect("collapse is valid")),
        ]
    }

    #[test]
    fn packet_equals_scalar_equals_brute_force_for_1_to_8_lanes() {
        let mut rng = Pcg32::new(41, 2);
        let soup = soup(&mut rng, 150);
        let (nodes, tris) = build(&soup);
        let binary = BvhRef::new(&nodes, &tris).unwrap();
        let wide = widen(&binary);
        assert!(
            wide.0.len() * 3 < nodes.len(),
            "{} wide nodes",
            wide.0.len()
        );
        for trial in 0..300 {
            let lanes = trial % LANES + 1;
            let shared = v3(&mut rng, 4.5);
            let rays: Vec<Ray> = (0..lanes)
                .map(|_| {
                    let org = if trial % 2 == 0 {
                        shared
                    } else {
                        v3(&mut rng, 4.5)
                    };
                    ray(&mut rng, org)
                })
                .collect();
            let packet = Ray8::from_rays(&rays);
            for bvh in layouts(binary, &wide) {
                let mut hits = Hit8::NONE;
                let mask = intersect8(&bvh, &packet, &mut hits);
                let blocked = occluded8(&bvh, &packet);
                if let (Layout::Wide(w), Some((pre, tmax))) = (bvh, start8(&packet)) {
                    // The single-ray any-hit walks from the root, whatever the tree's size:
                    // lane after lane (what the hybrid switch runs from an inner node) and
                    // interleaved (a large tree's packets of unrelated lanes).
                    assert_eq!(
                        wide::occluded_alone(&w, &pre, tmax, pre.traced, 0),
                        blocked,
                        "{packet:?}"
                    );
                    assert_eq!(occluded_interleaved(&w, &pre, tmax), blocked, "{packet:?}");
                }
                for lane in 0..LANES {
                    let r = packet.lane(lane);
                    let oracle = intersect_brute(&tris, &r);
                    assert_eq!(intersect1(&bvh, &r), oracle, "{r:?}");
                    assert_eq!(hits.lane(lane), oracle, "lane {lane} of {lanes}: {r:?}");
                    assert_eq!(mask >> lane & 1 == 1, oracle.is_some());
                    assert_eq!(occluded1(&bvh, &r), occluded_brute(&tris, &r));
                    assert_eq!(blocked >> lane & 1 == 1, occluded_brute(&tris, &r));
                    if lane >= lanes {
                        assert_eq!(hits.lane(lane), None, "inactive lane written");
                    }
                }
            }
        }
    }

    /// Origins a subnormal distance beyond a box face at 0, rays along the other axes (the
    /// `traverse` fuzz target): an edge function of ~10⁻⁴⁶ rounded to 0 in `f32`
    /// let the triangle test accept a point outside the triangle that the box test had
    /// culled, so brute force found a hit (at `t = −0`) the BVH missed. Both now miss it.
    #[test]
    fn subnormal_origins_beyond_a_box_face_agree_with_brute_force() {
        let s = (-20f32).exp2();
        // An edge on x = 0 from y = −s to y = s, the triangle on the x ≤ 0 side; the median
        // split along x puts it in a leaf whose box ends at x = 0.
        let tri = |x0: f32, x1: f32| {
            [
                Vec3::new(x0 * s, -s, 0.0),
                Vec3::new(x0 * s, s, 0.0),
                Vec3::new(x1 * s, 0.0, 0.0),
            ]
        };
        let soup = [
            tri(0.0, -1.0),
            tri(4.0, 5.0),
            tri(-9.0, -8.0),
            tri(9.0, 8.0),
        ];
        let (nodes, tris) = build(&soup);
        assert_eq!(nodes[0].hi[0][0], 0.0, "the left leaf's box ends at x = 0");
        let binary = BvhRef::new(&nodes, &tris).unwrap();
        let wide = widen(&binary);
        let rays = [
            // The ray: origin (8.8e-44, −6.7e-9, 9.2e-41), direction (0, 0, 56.06).
            Ray::new(
                Vec3::new(8.8e-44, -6.7e-9, 9.2e-41),
                Vec3::new(0.0, 0.0, 56.06),
                0.0,
                f32::INFINITY,
            ),
            Ray::new(
                Vec3::new(8.8e-44, 0.0, 0.0),
                Vec3::new(0.0, 0.0, -1.0),
                0.0,
                f32::INFINITY,
            ),
            Ray::new(
                Vec3::new(f32::from_bits(1), 1e-40, -1e-41),
                Vec3::new(0.0, 0.0, 3.0),
                0.0,
                f32::INFINITY,
            ),
            // On the edge itself: a hit for all of them.
            Ray::new(
                Vec3::new(0.0, 1e-9, -1.0),
                Vec3::new(0.0, 0.0, 1.0),
                0.0,
                2.0,
            ),
        ];
        for (r, bvh) in rays
            .iter()
            .flat_map(|r| layouts(binary, &wide).map(|b| (r, b)))
        {
            let oracle = intersect_brute(&tris, r);
            assert_eq!(intersect1(&bvh, r), oracle, "{r:?}");
            assert_eq!(occluded1(&bvh, r), occluded_brute(&tris, r), "{r:?}");
            let packet = Ray8::from_rays(&[*r; LANES]);
            let mut hits = Hit8::NONE;
            intersect8(&bvh, &packet, &mut hits);
            assert_eq!(hits.lane(0), oracle, "{r:?}");
            assert_eq!(occluded8(&bvh, &packet) & 1 == 1, oracle.is_some(), "{r:?}");
        }
        assert_eq!(
            intersect_brute(&tris, &rays[0]),
            None,
            "outside the triangle"
        );
        assert_eq!(intersect_brute(&tris, &rays[3]).map(|h| h.prim), Some(0));
    }

    /// An origin 10⁻³⁶ outside a triangle's box, on the triangle's edge once the shear has
    /// rounded it (the `traverse` fuzz target): brute force hits it at `t = 0`, the
    /// box test culls it; the traversals keep to the contract ("Hits outside their own box").
    #[test]
    fn origins_rounded_onto_an_edge_by_the_shear_keep_to_the_contract() {
        let soup = [
            [
                Vec3::new(-0.078125, 0.0, 0.0),
                Vec3::new(0.015625, -48.0, 0.015625),
                Vec3::new(80.0, 0.0, 0.0),
            ],
            [
                Vec3::new(-4.0, 0.0, 0.0),
                Vec3::new(0.0, -0.078125, 0.0),
                Vec3::new(0.0, 0.0, -100.0),
            ],
        ];
        let (nodes, tris) = build(&soup);
        let binary = BvhRef::new(&nodes, &tris).unwrap();
        let wide = widen(&binary);
        let org = Vec3::new(3.762_040_7e-37, 1.504_563_9e-36, 3.761_926_3e-37);
        let r = Ray::new(org, Vec3::new(-6400.0, 3.0, -1280.0), 0.0, f32::INFINITY);
        let brute = intersect_brute(&tris, &r);
        assert_eq!(brute.map(|h| (h.t, h.prim)), Some((0.0, 0)));
        let [lo, hi] = [Vec3::min, Vec3::max].map(|f| f(f(soup[0][0], soup[0][1]), soup[0][2]));
        assert!(
            !meets(&Pre::new(&r), (lo, hi), r.tmax),
            "the hit lies outside its own box"
        );
        let others: Vec<Tri> = tris.iter().filter(|t| t.prim != 0).copied().collect();
        let boxed = intersect_brute(&others, &r);
        let allowed = [brute, boxed];
        for bvh in layouts(binary, &wide) {
            assert!(allowed.contains(&intersect1(&bvh, &r)));
            let mut hits = Hit8::NONE;
            let mask = intersect8(&bvh, &Ray8::from_rays(&[r; LANES]), &mut hits);
            assert!(allowed.contains(&(mask & 1 == 1).then(|| hits.lane(0)).flatten()));
            traversals_keep_to_the_contract(&bvh, &r);
        }
    }

    /// A triangle of the `traverse` fuzz target's grid: i16 coordinates times 2⁻²⁰.
    fn grid_triangle(k: [i16; 9]) -> [Vec3; 3] {
        let c = |i: usize| f32::from(k[i]) * (-20.0f32).exp2();
        [0, 3, 6].map(|i| Vec3::new(c(i), c(i + 1), c(i + 2)))
    }

    /// The box of `v`.
    fn aabb(v: &[Vec3; 3]) -> (Vec3, Vec3) {
        (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]))
    }

    /// A root of two leaves of one triangle each, with the given boxes.
    fn two_leaves(leaves: [(Tri, (Vec3, Vec3)); 2]) -> (Vec<BinaryNode>, Vec<Tri>) {
        let mut root = BinaryNode::EMPTY;
        for (slot, (_, (lo, hi))) in leaves.iter().enumerate() {
            root.set_box(slot, *lo, *hi);
            root.child[slot] = slot as u32;
            root.meta[slot] = LEAF | 1;
        }
        (std::vec![root], leaves.map(|(t, _)| t).to_vec())
    }

    /// Whether the ray's slab interval on `[tmin, tmax]` meets the box `(lo, hi)`.
    fn meets(pre: &Pre, (lo, hi): (Vec3, Vec3), tmax: f32) -> bool {
        let mut node = BinaryNode::EMPTY;
        node.set_box(0, lo, hi);
        box1(&node, 0, pre, tmax).is_some()
    }

    /// Both traversals' answers, which the contract must allow.
    fn traversals_keep_to_the_contract(bvh: &impl Tree, r: &Ray) {
        if let Layout::Binary(binary) = bvh.layout() {
            let (wide, rows) = widen(&binary);
            let wide = WideRef::new(&wide, &rows).unwrap();
            traversals_keep_to_the_contract(&wide, r);
        }
        assert!(closest_hit_allowed(bvh, r, intersect1(bvh, r)));
        let mut hits = Hit8::NONE;
        let mask = intersect8(bvh, &Ray8::from_rays(&[*r; LANES]), &mut hits);
        let lane = (mask & 1 == 1).then(|| hits.lane(0)).flatten();
        assert!(closest_hit_allowed(bvh, r, lane));
        assert!(occlusion_allowed(bvh, r, occluded1(bvh, r)));
        assert!(occlusion_allowed(
            bvh,
            r,
            occluded8(bvh, &Ray8::from_rays(&[*r; LANES])) & 1 == 1
        ));
    }

    /// `fuzz/corpus/traverse/contract-t-underflows-before-its-box`: an origin
    /// 2.35·10⁻³⁸ above a box face at z = 0, tracing down. The triangle test's `t = T/det`
    /// underflows to 0 (its terms are ~10⁻⁵⁰), while the box is entered at 2.35·10⁻³⁸, more
    /// than the far bound's absolute slack 2⁻¹²⁶ above `t = 0`. So once another triangle was
    /// hit at `t = 0`, the BVH culled the box of the one the tie rule prefers: the contract
    /// allows either answer.
    #[test]
    fn hits_whose_t_underflows_before_their_box_keep_to_the_contract() {
        let under = grid_triangle([0, 0, 0, 20, 0, 0, -1, 256, -25600]);
        let other = grid_triangle([
            -25600, 25855, -25600, -25345, 156, -25345, 25855, -25600, 25855,
        ]);
        let org = Vec3::new(
            f32::from_bits(0x1400_00ff),
            0.0,
            f32::from_bits(0x00ff_ff00),
        );
        let r = Ray::new(org, Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
        let tris = [Tri::new(under, 0), Tri::new(other, 1)];
        let pre = Pre::new(&r);
        let t = |i: usize| tri1(&pre, &tris[i]).map(|(t, _, _)| t.to_bits());
        assert_eq!(
            (t(0), t(1)),
            (Some(0), Some(0)),
            "both hits round to t = +0"
        );
        assert!(meets(&pre, aabb(&under), f32::INFINITY));
        assert!(
            !meets(&pre, aabb(&under), 0.0),
            "entered beyond t = 0 + 2⁻¹²⁶"
        );
        let brute = intersect_brute(&tris, &r);
        assert_eq!(
            brute.map(|h| h.prim),
            Some(0),
            "the tie rule prefers prim 0"
        );
        let (nodes, leaf_tris) = two_leaves([(tris[0], aabb(&under)), (tris[1], aabb(&other))]);
        let bvh = BvhRef::new(&nodes, &leaf_tris).unwrap();
        let found_first = intersect_brute(&tris[1..], &r);
        for allowed in [brute, found_first] {
            assert!(closest_hit_allowed(&bvh, &r, allowed), "{allowed:?}");
        }
        // Neither no hit nor a hit that is not one triangle's own.
        assert!(!closest_hit_allowed(&bvh, &r, None));
        let moved = brute.map(|h| Hit {
            u: h.v,
            v: h.u,
            ..h
        });
        assert!(!closest_hit_allowed(&bvh, &r, moved));
        traversals_keep_to_the_contract(&bvh, &r);
        let (nodes, tris) = build(&[under, other]);
        traversals_keep_to_the_contract(&BvhRef::new(&nodes, &tris).unwrap(), &r);
    }

    /// `fuzz/corpus/traverse/contract-stand-in-hit-outside-its-box`: origin and
    /// direction both (−1.5·10⁻²⁶)·(1, 1, 1), beside two triangles of 10⁻⁶ through the
    /// origin. `t = T/det` underflows for both: prim 1 lies in the plane z = 0, one direction
    /// length behind the origin (true `t` = −1), yet comes out at `t = −0`, and prim 0 at
    /// `+0`; neither hit lies in its own box's interval. Brute force reports prim 0; the BVH
    /// reached prim 1's leaf and culled prim 0's, so it reported prim 1 — an answer neither
    /// brute force over all triangles nor over the own-box ones gives (the contract before
    /// this fix), which the contract allows: a hit outside its box found in place of a
    /// closer one of its kind.
    #[test]
    fn hits_outside_their_boxes_may_stand_in_for_each_other() {
        let first = grid_triangle([-5, 0, 0, 1, 0, 0, -513, 1023, 768]);
        let second = grid_triangle([768, 768, 0, 20, 0, 0, -1, 0, 0]);
        let tiny = f32::from_bits(0x9494_9494);
        let tmax = 1e-4 * (-20.0f32).exp2();
        let r = Ray::new(Vec3::splat(tiny), Vec3::splat(tiny), 0.0, tmax);
        let tris = [Tri::new(first, 0), Tri::new(second, 1)];
        let pre = Pre::new(&r);
        let hits = tris.map(|tri| tri1(&pre, &tri).map(|(t, _, _)| t.to_bits()));
        assert_eq!(
            hits,
            [Some(0), Some(0x8000_0000)],
            "prim 0 at +0, prim 1 at −0"
        );
        assert!(!meets(&pre, aabb(&first), tmax) && !meets(&pre, aabb(&second), tmax));
        let brute = intersect_brute(&tris, &r);
        assert_eq!(brute.map(|h| h.prim), Some(0));
        let (nodes, leaf_tris) = two_leaves([(tris[0], aabb(&first)), (tris[1], aabb(&second))]);
        let bvh = BvhRef::new(&nodes, &leaf_tris).unwrap();
        let stand_in = intersect_brute(&tris[1..], &r);
        for allowed in [brute, stand_in, None] {
            assert!(closest_hit_allowed(&bvh, &r, allowed), "{allowed:?}");
        }
        assert!(occlusion_allowed(&bvh, &r, true) && occlusion_allowed(&bvh, &r, false));
        traversals_keep_to_the_contract(&bvh, &r);
    }

    /// `fuzz/corpus/traverse/contract-spatial-split-reference`: with spatial
    /// splits (obvhs's slow presets) a leaf holds a triangle's part clipped to the leaf's
    /// box, not its whole box. Origin (−1.5·10⁻²⁶)·(1, 1, 1), direction (−1.5·10⁻²⁶,
    /// 3.8·10²², −6.5·10⁻²⁷): the watertight test rounds the ray, which passes 3·10⁻²⁶
    /// beside the triangle's long edge, onto the edge's midpoint (u = v = 0.5), at x = 0,
    /// z = 0, where the split clipped the triangle into a part at x ≤ 0, z ≥ 0 and one at
    /// x ≥ 0, z ≤ 0; the ray, at x < 0 and z < 0 and moving away from both planes, meets
    /// neither part's box, though it meets the triangle's whole box. So the contract is
    /// stated on the leaves' boxes.
    #[test]
    fn hits_outside_every_clipped_reference_box_keep_to_the_contract() {
        let tri = grid_triangle([
            -25345, 25855, 25600, -25600, 25855, 25600, 25600, 25600, -25600,
        ]);
        let g = |x: f32, y: f32, z: f32| Vec3::new(x, y, z) * (-20.0f32).exp2();
        let left = (g(-25600.0, 25727.0, 0.0), g(0.0, 25855.0, 25600.0));
        let right = (g(0.0, 25600.0, -25600.0), g(25600.0, 25729.0, 129.0));
        let tiny = f32::from_bits(0x9494_9494);
        let dir = Vec3::new(tiny, 3.772_186e22, -6.48207e-27);
        let r = Ray::new(Vec3::splat(tiny), dir, 0.0, 1e-4 * (-20.0f32).exp2());
        let t = Tri::new(tri, 0);
        let pre = Pre::new(&r);
        let (_, u, v) = tri1(&pre, &t).expect("rounded onto the edge");
        assert_eq!((u, v), (0.5, 0.5));
        let brute = intersect_brute(&[t], &r);
        assert!(brute.is_some() && meets(&pre, aabb(&tri), r.tmax));
        assert!(!meets(&pre, left, r.tmax) && !meets(&pre, right, r.tmax));
        let (nodes, leaf_tris) = two_leaves([(t, left), (t, right)]);
        let bvh = BvhRef::new(&nodes, &leaf_tris).unwrap();
        assert_eq!(intersect1(&bvh, &r), None, "the BVH misses it");
        for allowed in [brute, None] {
            assert!(closest_hit_allowed(&bvh, &r, allowed), "{allowed:?}");
        }
        traversals_keep_to_the_contract(&bvh, &r);
        // With the whole box as the leaf's, missing the hit breaks the contract.
        let (nodes, leaf_tris) = two_leaves([(t, aabb(&tri)), (t, aabb(&tri))]);
        assert!(!closest_hit_allowed(
            &BvhRef::new(&nodes, &leaf_tris).unwrap(),
            &r,
            None
        ));
    }

    #[test]
    fn triangle_test_8_wide_matches_scalar_bit_for_bit() {
        // Mixed shear permutations in one packet take the per-lane blend path.
        let mut rng = Pcg32::new(5, 8);
        let mut hits = 0;
        for _ in 0..2000 {
            let t = Tri::new([v3(&mut rng, 2.0), v3(&mut rng, 2.0), v3(&mut rng, 2.0)], 3);
            let rays: [Ray; LANES] = core::array::from_fn(|_| {
                let o = v3(&mut rng, 2.0) - Vec3::splat(0.5);
                // Aim at a point of the triangle's plane, inside or just outside it.
                let (a, b) = (rng.next_f32() * 1.2 - 0.1, rng.next_f32() * 1.2 - 0.1);
                let [p0, p1, p2] = t.v.map(Vec3::from);
                Ray::new(
                    o,
                    p0 + (p1 - p0) * a + (p2 - p0) * b - o,
                    0.0,
                    f32::INFINITY,
                )
            });
            let pre = Pre8::new(&Ray8::from_rays(&rays));
            let r = pre.tri8(&t);
            for (i, ray) in rays.iter().enumerate() {
                let want = tri1(&Pre::new(ray), &t);
                let lane = r.ok.to_bitmask() >> i & 1 == 1;
                if r.any_zero.to_bitmask() >> i & 1 == 1 {
                    continue; // resolved by the scalar f64 fallback in `closest8`
                }
                assert_eq!(lane, want.is_some(), "{ray:?}");
                if let Some((tt, _, _)) = want {
                    assert_eq!((r.tt / r.det).as_array()[i].to_bits(), tt.to_bits());
                    hits += 1;
                }
            }
        }
        assert!(hits > 4000, "the test must exercise hits ({hits})");
    }

    #[test]
    fn packet_constants_equal_each_lanes_scalar_constants_bit_for_bit() {
        let mut rng = Pcg32::new(77, 3);
        let bits = |v: f32x8, i: usize| v.as_array()[i].to_bits();
        for trial in 0..2000 {
            let shared = v3(&mut rng, 4.0);
            let rays: Vec<Ray> = (0..1 + trial % LANES)
                .map(|_| {
                    let org = if trial % 3 == 0 {
                        v3(&mut rng, 4.0)
                    } else {
                        shared
                    };
                    ray(&mut rng, org)
                })
                .collect();
            let packet = Ray8::from_rays(&rays);
            let pre = Pre8::new(&packet);
            let mut perms = Vec::new();
            for (i, r) in rays.iter().enumerate() {
                if !traceable(r) {
                    assert_eq!(pre.traced >> i & 1, 0);
                    continue;
                }
                assert_eq!(pre.traced >> i & 1, 1);
                let p = Pre::new(r);
                perms.push(p.k);
                for a in 0..3 {
                    assert_eq!(bits(pre.org[a], i), p.org[a].to_bits());
                    assert_eq!(bits(pre.inv[a], i), p.inv[a].to_bits(), "{r:?}");
                    assert_eq!(bits(pre.s[a], i), p.s[a].to_bits(), "{r:?}");
                    assert_eq!(bits(pre.porg[a], i), p.org[p.k[a]].to_bits(), "{r:?}");
                    assert_eq!(pre.k[a].as_array()[i] as usize, p.k[a], "{r:?}");
                }
                assert_eq!(bits(pre.tmin, i), p.tmin.to_bits());
            }
            let all_same = perms.windows(2).all(|w| w[0] == w[1]);
            assert_eq!(pre.uniform.is_some(), all_same || perms.is_empty());
            if let (Some(k), Some(first)) = (pre.uniform, perms.first()) {
                assert_eq!(k, *first);
            }
        }
    }

    #[test]
    fn layout_errors_are_reported() {
        let mut bad = BinaryNode::EMPTY;
        assert_eq!(BvhRef::new(&[], &[]).unwrap_err(), LayoutError::NoNodes);
        bad.meta = [0, LEAF];
        assert_eq!(
            BvhRef::new(&[bad], &[]).unwrap_err(),
            LayoutError::BadChild { node: 0, slot: 0 }
        );
        bad.meta = [LEAF | 2, LEAF];
        assert_eq!(
            BvhRef::new(&[bad], &[]).unwrap_err(),
            LayoutError::BadLeaf { node: 0, slot: 0 }
        );
        // A chain deeper than BVH_MAX_DEPTH.
        let chain: Vec<BinaryNode> = (0..BVH_MAX_DEPTH as u32 + 2)
            .map(|i| BinaryNode {
                child: [i + 1, 0],
                meta: [0, LEAF],
                ..BinaryNode::EMPTY
            })
            .chain([BinaryNode::EMPTY])
            .collect();
        assert!(matches!(
            BvhRef::new(&chain, &[]),
            Err(LayoutError::TooDeep { .. })
        ));
    }
}
