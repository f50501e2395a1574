//! # traverse: 8-wide packet BVH traversal, with the scalar single ray beside it
//!
//! Silvennoinen & Sloan 2019, §2.4: a texel's final-gather packet shares one origin and, once
//! the Sobol points are presorted, its eight directions are coherent; tracing the eight rays
//! together turns that coherence into speed. This module traces [`Ray8`] packets through a
//! kernel-owned, flat, binary BVH ([`Node`], [`Tri`]) that the driver fills from the tree obvhs
//! builds.
//!
//! - **Layout.** A [`Node`] is one 64-byte cache line holding the boxes of its *two children*
//!   (so one node visit tests two boxes for all eight lanes), their indices and their leaf
//!   counts. A [`Tri`] stores its three vertices (not edges: the watertight test needs the
//!   vertices themselves) and its primitive id, in leaf order.
//! - **Ray/triangle test.** Woop, Benthin & Wald, *Watertight Ray/Triangle Intersection*,
//!   JCGT 2(1), 2013: shear into the ray's space (`kz` = largest direction axis, `kx`/`ky`
//!   swapped when `d[kz] < 0`), 2D edge functions `U, V, W`, recomputed in `f64` when one is
//!   exactly zero (their exact signs decide inside or outside), no backface culling. Rays through a closed mesh's shared edges and
//!   vertices never slip through.
//! - **Box test.** Slabs with `(b − o) · (1/d)`; the interval is widened by 32 ulps (pbrt-v4
//!   §6.8.2's `1 + 2γ₃` plus room for the triangle test's rounding of `t`, see `SLACK`) so
//!   that rounding never culls a box holding a hit the oracle accepts. Planes are taken near
//!   first by the direction's sign bits and a NaN plane distance (`0 · ∞`, a ray running inside
//!   a box face) leaves the interval unconstrained, so rays along faces are kept.
//! - **Packet traversal** ([`intersect8`], [`occluded8`]): one shared stack; a child is
//!   visited when any lane's interval meets its box; when both children are hit the lanes
//!   vote on which is nearer and that one is visited first. Triangles are tested for all eight
//!   lanes at once; when every lane of the packet has the same shear permutation (the usual
//!   case for a coherent packet) the vertices are permuted once per triangle as scalars,
//!   otherwise per lane with blends.
//! - **Scalar reference** ([`intersect1`], [`occluded1`]) walks the same nodes with the same
//!   box and triangle arithmetic, and [`intersect_brute`] / [`occluded_brute`] test every
//!   triangle: the test oracle.
//!
//! **Results are exact, not approximate.** The scalar and 8-wide triangle tests perform the
//! same IEEE operations in the same order (no FMA contraction), so `t`, `u`, `v` agree bit for
//! bit across [`intersect_brute`], [`intersect1`] and [`intersect8`]. Equal `t` from several
//! triangles is resolved by the **tie rule**: the smallest primitive id wins. Hits are accepted
//! on `[tmin, tmax]`, both ends included (`tmax` is clamped to `f32::MAX`, so `t = ∞` is never
//! reported).
//!
//! Deviations and limits:
//! - Rays with `tmin < 0` are not traced (they never hit): the conservative box bound assumes
//!   `t ≥ 0`. See [`Ray::is_traceable`](crate::packet::Ray::is_traceable) for the full rule.
//! - The tree depth is capped at [`MAX_DEPTH`]; [`BvhRef::new`] rejects deeper trees.
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
//!     distance, and no absolute slack covers `2⁻¹⁴⁹ / det` for every `det`.
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
//!   (every ray at ordinary magnitudes, and every ray a bake traces: unit directions,
//!   origins lifted off their surface by `offset_origin`) that is exactly brute force.
//!   (A far bound widened by 2⁻¹⁸ of the root box's extent along `kz` removes the first kind
//!   found first, but culls so much less that the packet path ran 12–46 % slower on
//!   `benches/traverse.rs`.)

use crate::packet::{Hit, Hit8, LANES, NO_HIT, Ray, Ray8};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use wide::{f32x8, u32x8};

mod bvh8;
#[cfg(any(feature = "alloc", test))]
pub use bvh8::collapse;
pub use bvh8::{WIDE_MAX_DEPTH, WIDTH, WideNode, WideRef};

/// `meta` bit marking a leaf child (the low bits count its triangles).
pub const LEAF: u32 = 1 << 31;

/// Deepest tree [`BvhRef::new`] accepts (root at depth 0); bounds the traversal stack.
pub const MAX_DEPTH: usize = 128;

const STACK: usize = MAX_DEPTH + 2;

/// Slack of the conservative slab test: the box interval is widened to
/// `[tmin · (1 − 2⁻¹⁸), min(far, tmax) · (1 + 2⁻¹⁸)]`. pbrt-v4's `1 + 2γ₃` (§6.8.2, about 3 ulps)
/// covers the slab arithmetic; the triangle test's own rounding of `t` can put a hit that the
/// oracle accepts at `t = tmax` (or `tmin`) a few ulps beyond a box face, so we keep 32 ulps.
const SLACK: f32 = 1.0 / (1u32 << 18) as f32;
const FAR_UP: f32 = 1.0 + SLACK;
const NEAR_DOWN: f32 = 1.0 - SLACK;
/// Absolute slack added to the widened far bound: a relative one is nothing at `far = ±0`,
/// where a box entered at a subnormal distance (an origin of 10⁻⁴³ against a box face at 0)
/// was culled although its triangle's test rounds the hit to `t = 0` (found by the
/// `traverse` fuzz target: a closest hit at `t = −0` hid another at `t = +0` with a smaller
/// primitive id, which the tie rule prefers).
const FAR_FLOOR: f32 = f32::MIN_POSITIVE;

/// The far end of the conservative slab interval: `far · (1 + 2⁻¹⁸) + 2⁻¹²⁶`.
#[inline(always)]
fn widened(far: f32) -> f32 {
    far * FAR_UP + FAR_FLOOR
}

/// One BVH node: the boxes of its two children, one 64-byte cache line.
///
/// Child `c` is an inner node when `meta[c] == 0` (its index is `child[c]`), else a leaf of
/// `meta[c] & !LEAF` triangles starting at `child[c]`. An empty slot is a leaf of zero
/// triangles. Node 0 is the root.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C, align(64))]
pub struct Node {
    /// Box minima, `lo[axis][child]`.
    pub lo: [[f32; 2]; 3],
    /// Box maxima, `hi[axis][child]`.
    pub hi: [[f32; 2]; 3],
    /// Node index (inner child) or first triangle (leaf child).
    pub child: [u32; 2],
    /// `0` for an inner child, `LEAF | count` for a leaf.
    pub meta: [u32; 2],
}

const _: () = assert!(core::mem::size_of::<Node>() == 64);
const _: () = assert!(core::mem::align_of::<Node>() == 64);

impl Node {
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
    /// The node slice is empty (an empty tree is one [`Node::EMPTY`]).
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
    /// The tree is deeper than [`MAX_DEPTH`].
    TooDeep {
        /// First node found too deep.
        node: u32,
    },
}

/// A validated view of a flat BVH: nodes (root first) and triangles in leaf order.
#[derive(Clone, Copy, Debug)]
pub struct BvhRef<'a> {
    nodes: &'a [Node],
    tris: &'a [Tri],
}

impl<'a> BvhRef<'a> {
    /// Checks every child index, leaf range and the depth, once, so traversal can trust them.
    ///
    /// # Errors
    /// The first [`LayoutError`] found, walking depth first from the root.
    pub fn new(nodes: &'a [Node], tris: &'a [Tri]) -> Result<Self, LayoutError> {
        if nodes.is_empty() {
            return Err(LayoutError::NoNodes);
        }
        let mut stack = [(0u32, 0usize); STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (index, depth) = stack[sp];
            if depth > MAX_DEPTH {
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
    pub fn new_trusted(nodes: &'a [Node], tris: &'a [Tri]) -> Self {
        debug_assert!(Self::new(nodes, tris).is_ok(), "layout never validated");
        Self { nodes, tris }
    }

    /// The nodes, root first.
    pub fn nodes(&self) -> &'a [Node] {
        self.nodes
    }

    /// The triangles, in leaf order.
    pub fn tris(&self) -> &'a [Tri] {
        self.tris
    }

    fn leaf(&self, first: u32, meta: u32) -> &'a [Tri] {
        let first = first as usize;
        &self.tris[first..first + (meta & !LEAF) as usize]
    }
}

/// A validated BVH in one of the kernels' layouts: what the traversals walk.
#[derive(Clone, Copy, Debug)]
pub enum Layout<'a> {
    /// Two child boxes per node ([`Node`]).
    Binary(BvhRef<'a>),
    /// Eight child boxes per node ([`WideNode`]).
    Wide(WideRef<'a>),
}

impl<'a> Layout<'a> {
    /// The triangles, in leaf order.
    pub fn tris(&self) -> &'a [Tri] {
        match self {
            Layout::Binary(b) => b.tris,
            Layout::Wide(w) => w.tris(),
        }
    }

    /// Every leaf: its box and its triangles.
    fn leaves(&self) -> impl Iterator<Item = (([f32; 3], [f32; 3]), &'a [Tri])> {
        let (binary, wide) = match *self {
            Layout::Binary(b) => (Some(b), None),
            Layout::Wide(w) => (None, Some(w)),
        };
        let binary = binary.into_iter().flat_map(|b| {
            b.nodes.iter().flat_map(move |node| {
                (0..2).filter(move |&s| node.meta[s] != 0).map(move |s| {
                    let lo = [0, 1, 2].map(|a| node.lo[a][s]);
                    let hi = [0, 1, 2].map(|a| node.hi[a][s]);
                    ((lo, hi), b.leaf(node.child[s], node.meta[s]))
                })
            })
        });
        binary.chain(wide.into_iter().flat_map(|w| w.leaves()))
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

// ---------------------------------------------------------------------------------------------
// Single ray: precomputation, box and triangle tests (the reference arithmetic).

/// Per-ray constants of the box and watertight tests.
#[derive(Clone, Copy, Debug)]
struct Pre {
    org: [f32; 3],
    inv: [f32; 3],
    /// Shear permutation `[kx, ky, kz]`.
    k: [usize; 3],
    /// Shear `[d[kx]/d[kz], d[ky]/d[kz], 1/d[kz]]`.
    s: [f32; 3],
    tmin: f32,
}

impl Pre {
    fn new(ray: &Ray) -> Self {
        let d = ray.dir.to_array();
        let a = ray.dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            core::mem::swap(&mut kx, &mut ky);
        }
        Self {
            org: ray.org.to_array(),
            inv: d.map(|d| 1.0 / d),
            k: [kx, ky, kz],
            s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
            tmin: ray.tmin,
        }
    }
}

/// Entry distance of slot `slot` if the ray's `[tmin, tmax]` meets its box.
///
/// Slab planes are taken in the order of the direction's sign bits (near plane first) and a
/// plane whose distance is NaN (`0 · ∞`: the ray runs inside that plane) does not constrain the
/// interval, so rays along a box face are kept. `if t > near` keeps `near` for NaN `t`, as
/// `_mm256_max_ps(t, near)` does in [`Pre8::box8`].
fn box1(node: &Node, slot: usize, pre: &Pre, tmax: f32) -> Option<f32> {
    let lo = [0, 1, 2].map(|axis| node.lo[axis][slot]);
    let hi = [0, 1, 2].map(|axis| node.hi[axis][slot]);
    box1_at((lo, hi), pre, tmax)
}

/// [`box1`] for the box `(lo, hi)`.
fn box1_at((lo, hi): ([f32; 3], [f32; 3]), pre: &Pre, tmax: f32) -> Option<f32> {
    let mut near = pre.tmin * NEAR_DOWN;
    let mut far = tmax;
    for axis in 0..3 {
        let (lo, hi) = (lo[axis], hi[axis]);
        let (pn, pf) = if pre.inv[axis].is_sign_negative() {
            (hi, lo)
        } else {
            (lo, hi)
        };
        let tn = (pn - pre.org[axis]) * pre.inv[axis];
        let tf = (pf - pre.org[axis]) * pre.inv[axis];
        near = if tn > near { tn } else { near };
        far = if tf < far { tf } else { far };
    }
    (near <= widened(far)).then_some(near)
}

/// Edge functions in `f64`, Woop et al. 2013's fallback when one is exactly zero.
///
/// The products of two `f32`s are exact in `f64` and their difference is rounded once, so the
/// signs are exact. The `f64` values are returned as they are: rounded to `f32`, a nonzero
/// value below 2⁻¹⁵⁰ becomes ±0, and a point a subnormal distance outside an edge would pass
/// the inside test (found by the `traverse` fuzz target: origins 10⁻⁴³ beyond a box face
/// at 0 hit a triangle the box test had culled, so the BVH missed hits brute force found).
fn uvw_f64(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> [f64; 3] {
    let d = |p: f32| f64::from(p);
    [
        d(c[0]) * d(b[1]) - d(c[1]) * d(b[0]),
        d(a[0]) * d(c[1]) - d(a[1]) * d(c[0]),
        d(b[0]) * d(a[1]) - d(b[1]) * d(a[0]),
    ]
}

/// Whether edge functions of mixed signs put the point outside the triangle (zeros are on
/// an edge, inside).
#[inline(always)]
fn outside<T: PartialOrd + Default>(u: T, v: T, w: T) -> bool {
    let zero = T::default();
    (u < zero || v < zero || w < zero) && (u > zero || v > zero || w > zero)
}

/// Watertight ray/triangle test (Woop, Benthin & Wald 2013, two-sided): `(t, u, v)` of the
/// hit, before any comparison with the ray's interval. `u`, `v` weight vertices 1 and 2.
///
/// This is the reference the 8-wide [`tri8`] reproduces operation for operation.
fn tri1(pre: &Pre, tri: &Tri) -> Option<(f32, f32, f32)> {
    let [kx, ky, kz] = pre.k;
    let rel = |v: &[f32; 3]| {
        [
            v[kx] - pre.org[kx],
            v[ky] - pre.org[ky],
            v[kz] - pre.org[kz],
        ]
    };
    let (a, b, c) = (rel(&tri.v[0]), rel(&tri.v[1]), rel(&tri.v[2]));
    let shear = |p: [f32; 3]| [p[0] - pre.s[0] * p[2], p[1] - pre.s[1] * p[2]];
    let (a2, b2, c2) = (shear(a), shear(b), shear(c));
    let mut u = c2[0] * b2[1] - c2[1] * b2[0];
    let mut v = a2[0] * c2[1] - a2[1] * c2[0];
    let mut w = b2[0] * a2[1] - b2[1] * a2[0];
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // The inside test on the exact signs, then the values rounded for `t`, `u`, `v`.
        let exact = uvw_f64(a2, b2, c2);
        if outside(exact[0], exact[1], exact[2]) {
            return None;
        }
        [u, v, w] = exact.map(|e| e as f32);
    } else if outside(u, v, w) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let tt = u * (pre.s[2] * a[2]) + v * (pre.s[2] * b[2]) + w * (pre.s[2] * c[2]);
    Some((tt / det, v / det, w / det))
}

/// Closest-hit acceptance with the tie rule (equal `t`: smaller primitive id wins).
fn accept(t: f32, prim: u32, tmin: f32, best: &Hit) -> bool {
    t >= tmin && t <= best.t && (t < best.t || prim < best.prim)
}

/// Intersects `tri` and keeps the hit if [`accept`] says so.
fn closest1(pre: &Pre, tri: &Tri, best: &mut Hit) {
    if let Some((t, u, v)) = tri1(pre, tri)
        && accept(t, tri.prim, pre.tmin, best)
    {
        *best = Hit {
            t,
            u,
            v,
            prim: tri.prim,
        };
    }
}

/// The start of a closest-hit search: `t = min(tmax, f32::MAX)`, no primitive.
fn no_hit(tmax: f32) -> Hit {
    Hit {
        t: tmax.min(f32::MAX),
        u: 0.0,
        v: 0.0,
        prim: NO_HIT,
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
            if !bvh.tris().iter().any(|tri| tri.prim == h.prim && own(tri)) {
                return false;
            }
            h
        }
    };
    !leaves_met(&bvh, &pre, best.t)
        .any(|tri| tri1(&pre, tri).is_some_and(|(t, _, _)| accept(t, tri.prim, pre.tmin, &best)))
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
        bvh.tris().iter().any(|tri| occludes1(&pre, tri, tmax))
    } else {
        !leaves_met(&bvh, &pre, tmax).any(|tri| occludes1(&pre, tri, tmax))
    }
}

/// The triangles of every leaf whose box the ray's conservative slab interval on
/// `[tmin, tmax]` meets: what a traversal whose closest hit is at `tmax` must have tested
/// (a parent's box contains its children's, and the slab test is monotone in the box).
fn leaves_met<'a>(bvh: &Layout<'a>, pre: &Pre, tmax: f32) -> impl Iterator<Item = &'a Tri> {
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

fn occludes1(pre: &Pre, tri: &Tri, tmax: f32) -> bool {
    tri1(pre, tri).is_some_and(|(t, _, _)| t >= pre.tmin && t <= tmax)
}

/// [`Ray::is_traceable`] plus `tmin ≥ 0` (see the module docs).
fn traceable(ray: &Ray) -> bool {
    ray.is_traceable() && ray.tmin >= 0.0
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
    let visit = |leaf: &[Tri]| {
        for tri in leaf {
            closest1(&pre, tri, &mut best);
        }
        best.t
    };
    match bvh.layout() {
        Layout::Binary(b) => walk1(&b, &pre, visit),
        Layout::Wide(w) => bvh8::walk1(&w, &pre, visit),
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
    let visit = |leaf: &[Tri]| {
        if leaf.iter().any(|tri| occludes1(&pre, tri, tmax)) {
            f32::NEG_INFINITY
        } else {
            tmax
        }
    };
    let end = match bvh.layout() {
        Layout::Binary(b) => walk1(&b, &pre, visit),
        Layout::Wide(w) => bvh8::walk1(&w, &pre, visit),
    };
    end == f32::NEG_INFINITY
}

/// Depth-first walk of one ray through the binary tree, nearer child first. `visit` tests a
/// leaf's triangles and returns the ray's new `tmax` (−∞ stops the walk).
fn walk1<'a>(bvh: &BvhRef<'a>, pre: &Pre, mut visit: impl FnMut(&'a [Tri]) -> f32) -> f32 {
    let mut tmax = visit(&[]);
    let mut stack = [(0u32, 0u32); STACK];
    let mut sp = 1;
    while sp > 0 {
        sp -= 1;
        let (child, meta) = stack[sp];
        if meta != 0 {
            tmax = visit(bvh.leaf(child, meta));
            if tmax == f32::NEG_INFINITY {
                break;
            }
            continue;
        }
        let node = &bvh.nodes[child as usize];
        let entry = |slot: usize| (node.child[slot], node.meta[slot]);
        match (box1(node, 0, pre, tmax), box1(node, 1, pre, tmax)) {
            (Some(n0), Some(n1)) => {
                let (near, far) = if n1 < n0 { (1, 0) } else { (0, 1) };
                stack[sp] = entry(far);
                stack[sp + 1] = entry(near);
                sp += 2;
            }
            (Some(_), None) => {
                stack[sp] = entry(0);
                sp += 1;
            }
            (None, Some(_)) => {
                stack[sp] = entry(1);
                sp += 1;
            }
            (None, None) => {}
        }
    }
    tmax
}

// ---------------------------------------------------------------------------------------------
// Eight rays.

/// Per-packet constants. Lanes that are not traced carry `tmin = +∞` and harmless finite
/// values everywhere else.
struct Pre8 {
    org: [f32x8; 3],
    inv: [f32x8; 3],
    /// Permuted origin `o[kx], o[ky], o[kz]` per lane.
    porg: [f32x8; 3],
    s: [f32x8; 3],
    /// `sel[i][j]`: lanes whose `k[i] == j` (for `j` in 0..2; else 2).
    sel: [[f32x8; 2]; 3],
    /// Lanes whose direction has the sign bit set, per axis.
    neg: [f32x8; 3],
    /// The shared direction sign bits when all traced lanes have the same ones.
    octant: Option<[bool; 3]>,
    /// The shared permutation when all traced lanes have the same one.
    uniform: Option<[usize; 3]>,
    tmin: f32x8,
    /// `tmin · (1 − 2⁻¹⁸)` for the box test.
    tmin_down: f32x8,
    /// The rays, for [`Pre8::lane`].
    rays: Ray8,
    /// Bit mask of traced lanes.
    traced: u8,
}

fn mask_of(bits: u8) -> f32x8 {
    f32x8::new(core::array::from_fn(|i| {
        if bits >> i & 1 == 1 {
            f32::from_bits(u32::MAX)
        } else {
            0.0
        }
    }))
}

impl Pre8 {
    /// The packet's constants, computed 8-wide with the same IEEE operations as [`Pre::new`]
    /// per lane (so every lane's values equal its scalar [`Pre`]'s bit for bit); untraced
    /// lanes get the stub ray (origin 0, direction +x, `tmin = +∞`).
    fn new(rays: &Ray8) -> Self {
        let (zero, one) = (f32x8::ZERO, f32x8::ONE);
        let live = rays.traceable() & rays.tmin.simd_ge(zero);
        let traced = live.to_bitmask() as u8;
        let org = rays.org.map(|o| live.bitselect(o, zero));
        let d = [
            live.bitselect(rays.dir[0], one),
            live.bitselect(rays.dir[1], zero),
            live.bitselect(rays.dir[2], zero),
        ];
        let tmin = live.bitselect(rays.tmin, f32x8::splat(f32::INFINITY));
        let inv = d.map(|x| one / x);
        // Shear axes as in `Pre::new`: kz the largest |d| (ties to the lower axis), kx/ky the
        // next two cyclically, swapped when d[kz] < 0.
        let a = d.map(f32x8::abs);
        let kz0 = a[0].simd_ge(a[1]) & a[0].simd_ge(a[2]);
        let kz1 = !kz0 & a[1].simd_ge(a[2]);
        let kz2 = !(kz0 | kz1);
        let dkz = kz0.bitselect(d[0], kz1.bitselect(d[1], d[2]));
        let sw = dkz.simd_lt(zero);
        let sel = [
            [(kz2 & !sw) | (kz1 & sw), (kz0 & !sw) | (kz2 & sw)],
            [(kz1 & !sw) | (kz2 & sw), (kz2 & !sw) | (kz0 & sw)],
            [kz0, kz1],
        ];
        let pick =
            |v: &[f32x8; 3], i: usize| sel[i][0].bitselect(v[0], sel[i][1].bitselect(v[1], v[2]));
        let (dx, dy, dz) = (pick(&d, 0), pick(&d, 1), pick(&d, 2));
        let neg = inv.map(f32x8::is_sign_negative);
        // Lanes agree when a mask is all-traced or none-traced.
        let same = |m: f32x8| {
            let bits = m.to_bitmask() as u8 & traced;
            bits == 0 || bits == traced
        };
        let lead = traced.trailing_zeros().min(7);
        let bit = |m: f32x8| m.to_bitmask() >> lead & 1 == 1;
        let octant = neg.iter().all(|&m| same(m)).then(|| neg.map(bit));
        let uniform = (same(kz0) && same(kz1) && same(sw)).then(|| {
            let kz = if bit(kz0) {
                0
            } else if bit(kz1) {
                1
            } else {
                2
            };
            let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
            if bit(sw) { [ky, kx, kz] } else { [kx, ky, kz] }
        });
        Self {
            porg: [pick(&org, 0), pick(&org, 1), pick(&org, 2)],
            s: [dx / dz, dy / dz, one / dz],
            org,
            inv,
            sel: [sel[0], sel[1], sel[2]],
            neg,
            octant,
            uniform,
            tmin,
            tmin_down: tmin * f32x8::splat(NEAR_DOWN),
            rays: *rays,
            traced,
        }
    }

    /// Lane `i`'s scalar constants (for the rare per-lane paths); `i` must be traced.
    fn lane(&self, i: usize) -> Pre {
        Pre::new(&self.rays.lane(i))
    }

    /// Lanes whose interval meets slot `slot`'s box, and their entry distances: [`box1`] for
    /// eight lanes, near planes picked once per packet when all lanes share the direction
    /// signs (a coherent packet), per lane otherwise.
    #[inline(always)]
    fn box8(&self, node: &Node, slot: usize, tmax: f32x8) -> (f32x8, f32x8) {
        let lo = [0, 1, 2].map(|axis| node.lo[axis][slot]);
        let hi = [0, 1, 2].map(|axis| node.hi[axis][slot]);
        self.box8_at(lo, hi, tmax)
    }

    /// [`Pre8::box8`] for the box `lo`, `hi`.
    #[inline(always)]
    fn box8_at(&self, lo: [f32; 3], hi: [f32; 3], tmax: f32x8) -> (f32x8, f32x8) {
        let mut near = self.tmin_down;
        let mut far = tmax;
        for axis in 0..3 {
            let (lo, hi) = (lo[axis], hi[axis]);
            let (pn, pf) = match self.octant {
                Some(neg) if neg[axis] => (f32x8::splat(hi), f32x8::splat(lo)),
                Some(_) => (f32x8::splat(lo), f32x8::splat(hi)),
                None => {
                    let (lo, hi) = (f32x8::splat(lo), f32x8::splat(hi));
                    (
                        self.neg[axis].bitselect(hi, lo),
                        self.neg[axis].bitselect(lo, hi),
                    )
                }
            };
            let tn = (pn - self.org[axis]) * self.inv[axis];
            let tf = (pf - self.org[axis]) * self.inv[axis];
            // fast_max(a, b) is maxps(a, b): `b` when either is NaN, like `box1`.
            near = tn.fast_max(near);
            far = tf.fast_min(far);
        }
        (
            near.simd_le(far.mul_add(f32x8::splat(FAR_UP), f32x8::splat(FAR_FLOOR))),
            near,
        )
    }

    /// Vertex `v` relative to the origin in each lane's permuted axes.
    #[inline(always)]
    fn rel(&self, v: &[f32; 3]) -> [f32x8; 3] {
        match self.uniform {
            Some(k) => [0, 1, 2].map(|i| f32x8::splat(v[k[i]]) - self.porg[i]),
            None => {
                let c = v.map(f32x8::splat);
                [0, 1, 2].map(|i| {
                    let pick = self.sel[i][0].bitselect(c[0], self.sel[i][1].bitselect(c[1], c[2]));
                    pick - self.porg[i]
                })
            }
        }
    }

    /// [`tri1`] for eight lanes: `(t, U, V, W, det, ok)` where `ok` marks lanes with a hit
    /// computed in `f32`, and `zero` lanes that need the scalar `f64` fallback.
    #[inline(always)]
    fn tri8(&self, tri: &Tri) -> Tri8 {
        let a = self.rel(&tri.v[0]);
        let b = self.rel(&tri.v[1]);
        let c = self.rel(&tri.v[2]);
        let shear = |p: &[f32x8; 3]| [p[0] - self.s[0] * p[2], p[1] - self.s[1] * p[2]];
        let (a2, b2, c2) = (shear(&a), shear(&b), shear(&c));
        let u = c2[0] * b2[1] - c2[1] * b2[0];
        let v = a2[0] * c2[1] - a2[1] * c2[0];
        let w = b2[0] * a2[1] - b2[1] * a2[0];
        let zero = f32x8::ZERO;
        let any_zero = u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero);
        let neg = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
        let pos = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
        let det = u + v + w;
        let sz = self.s[2];
        let tt = u * (sz * a[2]) + v * (sz * b[2]) + w * (sz * c[2]);
        let ok = !(neg & pos) & det.simd_ne(zero) & !any_zero;
        Tri8 {
            tt,
            v,
            w,
            det,
            ok,
            any_zero,
        }
    }
}

/// [`Pre8::tri8`]'s result; `t = tt / det` is divided only when some lane may hit.
struct Tri8 {
    tt: f32x8,
    v: f32x8,
    w: f32x8,
    det: f32x8,
    ok: f32x8,
    any_zero: f32x8,
}

/// Closest-hit state of a packet.
struct Best8 {
    t: f32x8,
    u: f32x8,
    v: f32x8,
    prim: u32x8,
}

impl Best8 {
    fn lane(&self, i: usize) -> Hit {
        Hit {
            t: self.t.as_array()[i],
            u: self.u.as_array()[i],
            v: self.v.as_array()[i],
            prim: self.prim.as_array()[i],
        }
    }
}

#[inline(always)]
fn closest8(pre: &Pre8, tri: &Tri, best: &mut Best8) {
    let r = pre.tri8(tri);
    let live = pre.tmin.simd_le(best.t);
    if !((r.ok | r.any_zero) & live).any() {
        return;
    }
    let t = r.tt / r.det;
    let cand = r.ok & t.simd_ge(pre.tmin) & t.simd_le(best.t);
    let strict = cand & t.simd_lt(best.t);
    if strict.any() {
        let m: u32x8 = bytemuck::cast(strict);
        best.t = strict.bitselect(t, best.t);
        best.u = strict.bitselect(r.v / r.det, best.u);
        best.v = strict.bitselect(r.w / r.det, best.v);
        best.prim = m.bitselect(u32x8::splat(tri.prim), best.prim);
    }
    // Rare lanes: exact ties on t (tie rule) and zero edge functions (f64 fallback).
    let rare = ((cand & !strict) | (r.any_zero & live)).to_bitmask();
    if rare != 0 {
        closest8_rare(pre, tri, best, rare as u8);
    }
}

/// The scalar path of [`closest8`]'s rare lanes (kept out of the inlined hot loop).
#[cold]
#[inline(never)]
fn closest8_rare(pre: &Pre8, tri: &Tri, best: &mut Best8, rare: u8) {
    for i in 0..LANES {
        if rare >> i & 1 == 1 {
            let mut hit = best.lane(i);
            closest1(&pre.lane(i), tri, &mut hit);
            set_lane(best, i, &hit);
        }
    }
}

fn set_lane(best: &mut Best8, i: usize, hit: &Hit) {
    best.t.as_mut_array()[i] = hit.t;
    best.u.as_mut_array()[i] = hit.u;
    best.v.as_mut_array()[i] = hit.v;
    best.prim.as_mut_array()[i] = hit.prim;
}

/// Lanes `tri` blocks on `[tmin, tmax]`, as a bit mask.
#[inline(always)]
fn occludes8(pre: &Pre8, tri: &Tri, tmax: f32x8) -> u8 {
    let r = pre.tri8(tri);
    if !(r.ok | r.any_zero).any() {
        return 0;
    }
    let t = r.tt / r.det;
    let hit = r.ok & t.simd_ge(pre.tmin) & t.simd_le(tmax);
    let mut bits = hit.to_bitmask() as u8;
    let zero = (r.any_zero & pre.tmin.simd_le(tmax)).to_bitmask() as u8;
    if zero != 0 {
        bits |= occludes8_rare(pre, tri, tmax, zero);
    }
    bits
}

/// The scalar `f64` fallback of [`occludes8`]'s lanes with a zero edge function.
#[cold]
#[inline(never)]
fn occludes8_rare(pre: &Pre8, tri: &Tri, tmax: f32x8, zero: u8) -> u8 {
    (0..LANES).fold(0, |bits, i| {
        let blocked = zero >> i & 1 == 1 && occludes1(&pre.lane(i), tri, tmax.as_array()[i]);
        bits | u8::from(blocked) << i
    })
}

/// What a packet walk does at a leaf.
trait Visitor<'a> {
    /// Tests a leaf for the packet; returns the packet's new `tmax` (−∞ in finished lanes).
    fn leaf8(&mut self, leaf: &'a [Tri]) -> f32x8;
}

/// Closest-hit visitor.
struct Closest<'p> {
    pre: &'p Pre8,
    best: Best8,
}

impl<'a> Visitor<'a> for Closest<'_> {
    #[inline(always)]
    fn leaf8(&mut self, leaf: &'a [Tri]) -> f32x8 {
        for tri in leaf {
            closest8(self.pre, tri, &mut self.best);
        }
        self.best.t
    }
}

/// Occlusion visitor: a blocked lane's `tmax` becomes −∞.
struct Occlusion<'p> {
    pre: &'p Pre8,
    tmax: f32x8,
    blocked: u8,
}

impl<'a> Visitor<'a> for Occlusion<'_> {
    #[inline(always)]
    fn leaf8(&mut self, leaf: &'a [Tri]) -> f32x8 {
        for tri in leaf {
            let bits = occludes8(self.pre, tri, self.tmax);
            if bits != 0 {
                self.blocked |= bits;
                self.tmax = mask_of(bits).bitselect(f32x8::splat(f32::NEG_INFINITY), self.tmax);
                if self.blocked == self.pre.traced {
                    break;
                }
            }
        }
        self.tmax
    }
}

/// Depth-first walk of a packet through the binary tree: a shared stack of `(child, meta)`
/// entries with `lanes`, the bit mask of lanes whose interval met the entry's box when it was
/// pushed. When both children are met, the lanes meeting both vote with their entry
/// distances for the one visited first.
fn walk8<'a>(bvh: &BvhRef<'a>, pre: &Pre8, mut tmax: f32x8, visitor: &mut impl Visitor<'a>) {
    // Entries as `child | meta << 32` and lane masks in two plain arrays: zeroing them is a
    // short memset (a tuple array with padding cost ~10% of the walk in stores).
    let mut stack = [0u64; STACK];
    let mut lanes_of = [0u8; STACK];
    lanes_of[0] = pre.traced;
    let mut sp = 1;
    let mut alive = pre.traced;
    while sp > 0 {
        sp -= 1;
        let (child, meta, lanes) = (stack[sp] as u32, (stack[sp] >> 32) as u32, lanes_of[sp]);
        if meta != 0 {
            tmax = visitor.leaf8(bvh.leaf(child, meta));
            alive = pre.tmin.simd_le(tmax).to_bitmask() as u8;
            if alive == 0 {
                return;
            }
            continue;
        }
        if lanes & alive == 0 {
            continue;
        }
        let node = &bvh.nodes[child as usize];
        let (m0, n0) = pre.box8(node, 0, tmax);
        let (m1, n1) = pre.box8(node, 1, tmax);
        let (b0, b1) = (m0.to_bitmask() as u8, m1.to_bitmask() as u8);
        let entry = |slot: usize| u64::from(node.child[slot]) | u64::from(node.meta[slot]) << 32;
        match (b0 != 0, b1 != 0) {
            (true, true) => {
                let closer1 = (n1.simd_lt(n0) & m0 & m1).to_bitmask().count_ones();
                let (near, far) = if 2 * closer1 > (b0 & b1).count_ones() {
                    (1, 0)
                } else {
                    (0, 1)
                };
                let bits = [b0, b1];
                stack[sp] = entry(far);
                lanes_of[sp] = bits[far];
                stack[sp + 1] = entry(near);
                lanes_of[sp + 1] = bits[near];
                sp += 2;
            }
            (true, false) => {
                stack[sp] = entry(0);
                lanes_of[sp] = b0;
                sp += 1;
            }
            (false, true) => {
                stack[sp] = entry(1);
                lanes_of[sp] = b1;
                sp += 1;
            }
            (false, false) => {}
        }
    }
}

/// A packet's constants and its starting `tmax` (`min(tmax, f32::MAX)`, −∞ in lanes not
/// traced), or `None` when no lane is traced.
fn start8(rays: &Ray8) -> Option<(Pre8, f32x8)> {
    let pre = Pre8::new(rays);
    if pre.traced == 0 {
        return None;
    }
    let tmax = mask_of(pre.traced).bitselect(
        rays.tmax.fast_min(f32x8::splat(f32::MAX)),
        f32x8::splat(f32::NEG_INFINITY),
    );
    Some((pre, tmax))
}

/// Closest hits of eight rays: the packet traversal.
///
/// Lanes that are not traced (inactive, non-finite, zero direction, `tmin < 0`) and lanes that
/// miss leave their `hits` lane untouched. Returns the bit mask of lanes that hit. Each hit
/// equals [`intersect1`]'s for that lane, bit for bit, whatever the layout.
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
        Layout::Wide(w) => bvh8::walk8(&w, &pre, tmax, &mut closest),
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
        Layout::Wide(w) => bvh8::walk8(&w, &pre, tmax, &mut occlusion),
    }
    occlusion.blocked
}

// ---------------------------------------------------------------------------------------------
// Ray origins.

/// Offsets a surface point along its geometric normal so a ray leaving it does not hit its own
/// surface, by as little as the rounding allows.
///
/// Two errors decide on which side of its own plane a ray's origin ends up (after Wächter &
/// Binder, *A Fast and Robust Method for Avoiding Self-Intersection*, Ray Tracing Gems ch. 6,
/// 2019, whose per-axis scaling this keeps):
/// - **where the point is**: `p` was interpolated from the vertices and rounded, and the
///   offset origin is rounded again, so on axis `i` it is off by a few ulps of `|p_i|` —
///   the floating-point spacing, which grows with the distance from the world's origin;
/// - **where the surface is**: the watertight test ([`intersect1`]) works with the vertices
///   relative to the origin, so its distances err by a few ulps of the triangle's size seen
///   from the origin, `extent` — the largest `|v − p|` over the triangle's vertices
///   ([`triangle_extent`]), plus the hit distance for a point computed as `o + t·d`.
///
/// So axis `i` moves by `n_i · (2·|p_i| + 4·extent) · ε` (ε = [`f32::EPSILON`]): two to four
/// ulps of the coordinate plus four ulps of the triangle's size. That is 25 cm at 10⁶ along
/// the normal axis (the f32 spacing there is 6.25 cm), 2.4 mm at 10⁴, 0.5 µm on a 1 m
/// triangle at the origin and 0.7 mm on a 1.4 km one. One to two ulps of the coordinate
/// left self-hits on `tests/traverse.rs`'s random soups (2 of 4 000 points, rays leaving
/// straight up that hit their own triangle 2·10⁻⁸ ahead: the interpolated point was off by
/// about an ulp on each axis); 1.5 to 3 ulps left none in 40 000.
/// (Wächter & Binder's 256 ulps were 16 m at 10⁶. Their fixed 1.5·10⁻⁵ near the origin was
/// too little for a grazing ray on a kilometre-sized triangle, where the test's distance is
/// only known to ~10⁻⁴. Both were failures of `tests/stress.rs`.) Sideways coordinates do
/// not lift the origin: `n_i` is 0 on the axes the surface extends along.
///
/// `n` must be the side the ray leaves from (flip it for rays into the back side); it need not
/// be unit length but should be about unit scale.
pub fn offset_origin(p: Vec3, n: Vec3, extent: f32) -> Vec3 {
    const POINT_ULPS: f32 = 2.0 * f32::EPSILON;
    const EXTENT_ULPS: f32 = 4.0 * f32::EPSILON;
    let lift = |p: f32, n: f32| p + n * (POINT_ULPS * p.abs() + EXTENT_ULPS * extent);
    Vec3::new(lift(p.x, n.x), lift(p.y, n.y), lift(p.z, n.z))
}

/// The size of triangle `tri` seen from `p` for [`offset_origin`]: the largest coordinate
/// of `v − p` over its vertices (0 for a non-finite triangle).
pub fn triangle_extent(p: Vec3, tri: &[Vec3; 3]) -> f32 {
    let e = tri
        .iter()
        .fold(0.0f32, |e, &v| e.max((v - p).abs().max_element()));
    if e.is_finite() { e } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;
    use std::vec::Vec;

    /// Test-only builder: median split on the longest axis, leaves of at most 3 triangles.
    fn build(soup: &[[Vec3; 3]]) -> (Vec<Node>, Vec<Tri>) {
        let mut items: Vec<(u32, [Vec3; 3])> = soup
            .iter()
            .enumerate()
            .map(|(i, t)| (i as u32, *t))
            .collect();
        let mut nodes = std::vec![Node::EMPTY];
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
        nodes: &mut Vec<Node>,
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
        nodes.push(Node::EMPTY);
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

    /// The binary view of `nodes`/`tris` and the wide view of its collapse (`wide`).
    fn layouts<'a>(bvh: BvhRef<'a>, wide: &'a [WideNode]) -> [Layout<'a>; 2] {
        [
            Layout::Binary(bvh),
            Layout::Wide(WideRef::new(wide, bvh.tris()).expect("collapse is valid")),
        ]
    }

    #[test]
    fn packet_equals_scalar_equals_brute_force_for_1_to_8_lanes() {
        let mut rng = Pcg32::new(41, 2);
        let soup = soup(&mut rng, 150);
        let (nodes, tris) = build(&soup);
        let binary = BvhRef::new(&nodes, &tris).unwrap();
        let wide = collapse(&binary);
        assert!(wide.len() * 3 < nodes.len(), "{} wide nodes", wide.len());
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
    /// `traverse` fuzz target, issue 22): an edge function of ~10⁻⁴⁶ rounded to 0 in `f32`
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
        let wide = collapse(&binary);
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
    /// rounded it (the `traverse` fuzz target, issue 22): brute force hits it at `t = 0`, the
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
        let wide = collapse(&binary);
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
    fn two_leaves(leaves: [(Tri, (Vec3, Vec3)); 2]) -> (Vec<Node>, Vec<Tri>) {
        let mut root = Node::EMPTY;
        for (slot, (_, (lo, hi))) in leaves.iter().enumerate() {
            root.set_box(slot, *lo, *hi);
            root.child[slot] = slot as u32;
            root.meta[slot] = LEAF | 1;
        }
        (std::vec![root], leaves.map(|(t, _)| t).to_vec())
    }

    /// Whether the ray's slab interval on `[tmin, tmax]` meets the box `(lo, hi)`.
    fn meets(pre: &Pre, (lo, hi): (Vec3, Vec3), tmax: f32) -> bool {
        let mut node = Node::EMPTY;
        node.set_box(0, lo, hi);
        box1(&node, 0, pre, tmax).is_some()
    }

    /// Both traversals' answers, which the contract must allow.
    fn traversals_keep_to_the_contract(bvh: &impl Tree, r: &Ray) {
        if let Layout::Binary(binary) = bvh.layout() {
            let wide = collapse(&binary);
            let wide = WideRef::new(&wide, binary.tris()).unwrap();
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

    /// `fuzz/corpus/traverse/contract-t-underflows-before-its-box` (issue 22): an origin
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

    /// `fuzz/corpus/traverse/contract-stand-in-hit-outside-its-box` (issue 22): origin and
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

    /// `fuzz/corpus/traverse/contract-spatial-split-reference` (issue 22): with spatial
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
                    for j in 0..2 {
                        assert_eq!(bits(pre.sel[a][j], i) != 0, p.k[a] == j, "{r:?}");
                    }
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
        let mut bad = Node::EMPTY;
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
        // A chain deeper than MAX_DEPTH.
        let chain: Vec<Node> = (0..MAX_DEPTH as u32 + 2)
            .map(|i| Node {
                child: [i + 1, 0],
                meta: [0, LEAF],
                ..Node::EMPTY
            })
            .chain([Node::EMPTY])
            .collect();
        assert!(matches!(
            BvhRef::new(&chain, &[]),
            Err(LayoutError::TooDeep { .. })
        ));
    }

    #[test]
    fn offset_origin_moves_along_the_normal_at_every_scale() {
        for (p, extent) in [
            (Vec3::ZERO, 1.0),
            (Vec3::splat(0.01), 0.001),
            (Vec3::new(1.0e6, -1.0e6, 3.0), 10.0),
            (Vec3::splat(-5.0e4), 1.0e3),
        ] {
            let n = Vec3::new(0.6, -0.8, 0.0);
            let q = offset_origin(p, n, extent);
            let moved = q - p;
            assert!(
                moved.x > 0.0 && moved.y < 0.0 && moved.z == 0.0,
                "{p} -> {q}"
            );
            // Scale-aware: a few ulps of the coordinate and of the triangle's size, so the
            // move grows with both but stays tiny beside them.
            let scale = p.abs().max_element() + extent;
            assert!(moved.length() < scale * 1e-6, "{p} {extent} -> {moved}");
        }
        // At 10⁶ along the normal axis: two to four ulps (6.25 cm each).
        let q = offset_origin(Vec3::new(0.0, 0.0, 1.0e6), Vec3::Z, 1.0);
        assert!((0.125..=0.25).contains(&(q.z - 1.0e6)), "{q}");
    }

    #[test]
    fn triangle_extent_is_the_farthest_vertex_coordinate() {
        let tri = [
            Vec3::ZERO,
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, -5.0, 1.0),
        ];
        assert_eq!(triangle_extent(Vec3::new(1.0, 0.0, 0.0), &tri), 5.0);
        let bad = [Vec3::ZERO, Vec3::splat(f32::NAN), Vec3::X];
        assert_eq!(triangle_extent(Vec3::ZERO, &bad), 1.0);
        let inf = [Vec3::ZERO, Vec3::splat(f32::INFINITY), Vec3::X];
        assert_eq!(triangle_extent(Vec3::ZERO, &inf), 0.0);
    }
}
