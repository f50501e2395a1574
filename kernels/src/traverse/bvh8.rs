//! # traverse::bvh8: eight child boxes per node, tested with one 8-lane slab test
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
use super::BvhRef;
use super::slab::{exact, met8, plane8, slab_of};
use super::triangle::{Pre1x8, ROWS, RowTri, TriAt, occludes_rows};
use super::{LEAF, LayoutError, NEAR_DOWN, Pre, Pre8, Tri};
use crate::packet::{LANES, mask_of, set_lanes};
use bytemuck::{Pod, Zeroable};
use core::mem::MaybeUninit;
use wide::{f32x8, u32x8};

/// Children per wide node.
pub const WIDTH: usize = 8;

/// Deepest wide tree [`WideRef::new`] accepts (root at depth 0). [`collapse`] halves the
/// binary depth at least, so every valid binary tree collapses within it.
pub const WIDE_MAX_DEPTH: usize = super::MAX_DEPTH / 2;

/// Stack entries a walk needs: at most `WIDTH − 1` pending siblings per level, plus one
/// node's children.
const STACK: usize = (WIDTH - 1) * (WIDE_MAX_DEPTH + 1) + WIDTH + 1;

/// A walk's stack of [`STACK`] entries, left uninitialised: zeroing the 3.7–7.4 KB per ray
/// was a fifth of the wide single-ray walk's time on the Veach room (libc `memset`). (Built
/// from an associated `const` holding `len: 0` beside the uninitialised array, it was copied
/// from a constant instead: the single-ray walk lost 40 %.)
struct Stack<T: Copy> {
    items: [MaybeUninit<T>; STACK],
    len: usize,
}

impl<T: Copy> Stack<T> {
    #[inline(always)]
    fn new() -> Self {
        Self {
            items: [const { MaybeUninit::uninit() }; STACK],
            len: 0,
        }
    }

    /// Pushes `v` (a walk never exceeds [`STACK`]; indexing checks it anyway).
    #[inline(always)]
    fn push(&mut self, v: T) {
        self.items[self.len].write(v);
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: `push` wrote every entry below the previous `len`, and `len` only grows
        // through `push`.
        Some(unsafe { self.items[self.len].assume_init() })
    }
}

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
    fn slot_box(&self, slot: usize) -> ([f32; 3], [f32; 3]) {
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
    nodes: &'a [WideNode],
    rows: &'a [f32],
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
    fn leaf_rows(&self, first: u32) -> &'a [f32] {
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
    pub(super) fn leaves(self) -> impl Iterator<Item = (([f32; 3], [f32; 3]), RowTris<'a>)> {
        let view = self;
        self.nodes.iter().flat_map(move |node| {
            (0..WIDTH)
                .filter(move |&s| node.meta[s] != 0 && node.meta[s] != LEAF)
                .map(move |s| (node.slot_box(s), view.leaf(node.child[s], node.meta[s])))
        })
    }
}

/// Collapses a binary tree into the wide layout, depth first; the leaves keep their triangle
/// ranges, so the result is valid with the same triangle slice.
///
/// Which binary nodes become wide nodes is chosen by the surface area heuristic, optimally
/// (Ylitie, Karras & Laine, *Efficient Incoherent Ray Traversal on GPUs Through Compressed
/// Wide BVHs*, HPG 2017, §3.1, with the leaves fixed): the leaves are the binary tree's, so
/// the cost to minimise is the sum of the wide nodes' surface areas (`SlotCosts`). Every wide
/// node opens its binary node's inner children (so a wide level spans at least two binary
/// levels and the depth stays within [`WIDE_MAX_DEPTH`]).
#[cfg(any(feature = "alloc", test))]
pub fn collapse(bvh: &BvhRef<'_>) -> alloc::vec::Vec<WideNode> {
    extern crate alloc;
    use alloc::vec::Vec;
    let costs = SlotCosts::new(bvh);
    let mut out = alloc::vec![WideNode::EMPTY];
    // (binary node, wide node built from its slots)
    let mut work = alloc::vec![(0u32, 0usize)];
    let mut slots: Vec<BinSlot> = Vec::with_capacity(WIDTH);
    while let Some((from, ours)) = work.pop() {
        slots.clear();
        costs.wide_slots(from, &mut slots);
        for (slot, s) in slots.iter().enumerate() {
            if s.meta == 0 {
                let index = out.len();
                out.push(WideNode::EMPTY);
                out[ours].set_slot(slot, s.lo, s.hi, index as u32, 0);
                work.push((s.child, index));
            } else {
                out[ours].set_slot(slot, s.lo, s.hi, s.child, s.meta);
            }
        }
    }
    out
}

/// A slot of a binary node: its box, child and meta.
#[cfg(any(feature = "alloc", test))]
#[derive(Clone, Copy)]
struct BinSlot {
    lo: [f32; 3],
    hi: [f32; 3],
    child: u32,
    meta: u32,
}

/// Least costs per slot count, `[k − 1]` for at most `k` slots (`k = 1 ..= WIDTH`).
#[cfg(any(feature = "alloc", test))]
type Costs = [f32; WIDTH];

/// The surface area costs of a binary tree's subtrees laid out as wide slots ([`collapse`]):
/// per inner binary node `n`, `F(n, k)`, the least sum of wide node areas (relative to the
/// root's, so the sums stay finite) that covers `n`'s subtree with at most `k` slots — `n`
/// itself as one wide node (its area plus its content's, [`SlotCosts::content`]), or `n`
/// opened and its two children's subtrees covered by `k` slots between them.
#[cfg(any(feature = "alloc", test))]
struct SlotCosts<'b> {
    nodes: &'b [super::Node],
    /// `F(n, ·)` by binary node index (computed children first: a child's index is larger).
    least: alloc::vec::Vec<Costs>,
}

#[cfg(any(feature = "alloc", test))]
impl<'b> SlotCosts<'b> {
    fn new(bvh: &BvhRef<'b>) -> Self {
        let nodes = bvh.nodes();
        let mut costs = Self {
            nodes,
            least: alloc::vec![[f32::INFINITY; WIDTH]; nodes.len()],
        };
        let root = costs.half_area(0);
        let scale = if root.is_finite() && root > 0.0 {
            1.0 / root
        } else {
            1.0
        };
        for n in (0..nodes.len() as u32).rev() {
            costs.least[n as usize] = costs.compute(n, scale);
        }
        costs
    }

    /// Half the surface area of node `n`'s box (its non-empty slots').
    fn half_area(&self, n: u32) -> f64 {
        half_area(
            [0, 1]
                .map(|s| self.slot(n, s))
                .into_iter()
                .filter(|s| s.meta != LEAF)
                .map(|s| (s.lo, s.hi)),
        )
    }

    fn slot(&self, n: u32, s: usize) -> BinSlot {
        let node = &self.nodes[n as usize];
        BinSlot {
            lo: [0, 1, 2].map(|a| node.lo[a][s]),
            hi: [0, 1, 2].map(|a| node.hi[a][s]),
            child: node.child[s],
            meta: node.meta[s],
        }
    }

    /// `F(s, k)` for `k = 0 ..= WIDTH` of a slot: an empty slot costs nothing in no slots,
    /// a leaf nothing in one, an inner child its [`SlotCosts::least`].
    fn of(&self, s: BinSlot) -> [f32; WIDTH + 1] {
        let mut f = [0.0; WIDTH + 1];
        if s.meta == 0 {
            f[0] = f32::INFINITY;
            f[1..].copy_from_slice(&self.least[s.child as usize]);
        } else if s.meta != LEAF {
            f[0] = f32::INFINITY;
        }
        f
    }

    /// `G(s, k)`: as [`SlotCosts::of`], but an inner child opened (two slots at least).
    fn opened(&self, s: BinSlot) -> [f32; WIDTH + 1] {
        if s.meta == 0 {
            self.splits(s.child)
        } else {
            self.of(s)
        }
    }

    /// `D(n, k)` for each `k`: the least cost of node `n` opened, its children covered by at
    /// most `k` slots between them (+∞ below two slots, which [`SlotCosts::opened`] needs).
    fn splits(&self, n: u32) -> [f32; WIDTH + 1] {
        let (l, r) = (self.of(self.slot(n, 0)), self.of(self.slot(n, 1)));
        let mut d = [f32::INFINITY; WIDTH + 1];
        for (k, d) in d.iter_mut().enumerate().skip(2) {
            *d = best_split(&l, &r, k).0;
        }
        d
    }

    /// The slots of the left child in the least split of node `n` opened into `k` slots.
    fn split(&self, n: u32, k: usize) -> usize {
        best_split(&self.of(self.slot(n, 0)), &self.of(self.slot(n, 1)), k).1
    }

    /// The least cost of a wide node's content built from node `n` (`n` and its inner
    /// children opened, at most `WIDTH` slots), and the left child's slots in it.
    fn content(&self, n: u32) -> (f32, usize) {
        let (l, r) = (self.opened(self.slot(n, 0)), self.opened(self.slot(n, 1)));
        best_split(&l, &r, WIDTH)
    }

    fn compute(&self, n: u32, scale: f64) -> Costs {
        let area = (self.half_area(n) * scale).min(1e30) as f32;
        let d = self.splits(n);
        let mut f = [area + self.content(n).0; WIDTH];
        for k in 2..=WIDTH {
            f[k - 1] = f[k - 2].min(d[k]);
        }
        f
    }

    /// The slots of the wide node built from binary node `n`, as [`SlotCosts::content`]
    /// chose them.
    fn wide_slots(&self, n: u32, out: &mut alloc::vec::Vec<BinSlot>) {
        let kl = self.content(n).1;
        self.expand_opened(self.slot(n, 0), kl, out);
        self.expand_opened(self.slot(n, 1), WIDTH - kl, out);
    }

    /// The slots covering `s` with at most `k`, an inner `s` opened.
    fn expand_opened(&self, s: BinSlot, k: usize, out: &mut alloc::vec::Vec<BinSlot>) {
        if s.meta == 0 {
            self.expand_node(s.child, k, out);
        } else if s.meta != LEAF {
            out.push(s);
        }
    }

    /// The slots covering inner node `n` opened with at most `k`.
    fn expand_node(&self, n: u32, k: usize, out: &mut alloc::vec::Vec<BinSlot>) {
        let kl = self.split(n, k);
        self.expand(self.slot(n, 0), kl, out);
        self.expand(self.slot(n, 1), k - kl, out);
    }

    /// The slots covering `s` with at most `k`, at the least cost: an inner `s` kept as one
    /// slot (a wide node of its own) or opened.
    fn expand(&self, s: BinSlot, k: usize, out: &mut alloc::vec::Vec<BinSlot>) {
        if s.meta != 0 {
            return self.expand_opened(s, k, out);
        }
        let whole = self.least[s.child as usize][0];
        let d = self.splits(s.child);
        let (cost, j) = first_least((2..=k).map(|j| (d[j], j)));
        if whole <= cost {
            out.push(s);
        } else {
            self.expand_node(s.child, j, out);
        }
    }
}

/// The least `l[i] + r[k − i]` over `i = 0 ..= k`, and its `i` ([`first_least`]).
#[cfg(any(feature = "alloc", test))]
fn best_split(l: &[f32; WIDTH + 1], r: &[f32; WIDTH + 1], k: usize) -> (f32, usize) {
    first_least((0..=k).map(|i| (l[i] + r[k - i], i)))
}

/// The least cost of `(cost, choice)` pairs and its choice, the first where several tie
/// (+∞ and 0 for none).
#[cfg(any(feature = "alloc", test))]
fn first_least(choices: impl Iterator<Item = (f32, usize)>) -> (f32, usize) {
    choices.fold((f32::INFINITY, 0), |b, c| if c.0 < b.0 { c } else { b })
}

/// Half the surface area of the union of `boxes` (`lo`, `hi`), in `f64` (finite for finite
/// boxes; 0 for none).
#[cfg(any(feature = "alloc", test))]
fn half_area(boxes: impl Iterator<Item = ([f32; 3], [f32; 3])>) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (l, h) in boxes {
        for a in 0..3 {
            lo[a] = lo[a].min(f64::from(l[a]));
            hi[a] = hi[a].max(f64::from(h[a]));
        }
    }
    let e = [0, 1, 2].map(|a| (hi[a] - lo[a]).max(0.0));
    e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
}

/// Length of the rows of `tris` triangles: [`ROWS`] values per triangle and eight of
/// padding, so the last leaf's 8-wide loads stay inside.
#[cfg(any(feature = "alloc", test))]
fn rows_len(tris: usize) -> usize {
    ROWS * tris + 8
}

/// The triangles rows of length `len` hold, if [`rows_len`] gives that length.
fn rows_tris(len: usize) -> Option<usize> {
    let values = len.checked_sub(8)?;
    values.is_multiple_of(ROWS).then_some(values / ROWS)
}

/// The triangles of one leaf, read back from its rows ([`WideRef::leaves`]).
#[derive(Clone, Debug)]
pub(super) struct RowTris<'a> {
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
                rows[ROWS * first + super::triangle::PRIM_ROW * n + i] = f32::from_bits(t.prim);
            }
        }
    }
    rows
}

// ---------------------------------------------------------------------------------------------
// Single ray.

/// One ray's box-test constants ([`super::slab`]) splatted over the eight children of a node,
/// for the slab test's fused form (`EXACT = false`) or its exact one (a ray with an infinite
/// inverse direction component, [`super::slab::exact`]).
pub(super) struct Ray1x8<const EXACT: bool> {
    inv: [f32x8; 3],
    c_near: [f32x8; 3],
    c_far: [f32x8; 3],
    /// Axes whose near plane is `hi` (direction sign bit set). A branch per axis: picking
    /// the planes by row index, as the packet walk's lanes do, made the single-ray walks
    /// 10 % slower (docs/traverse.md, "Measured and dropped").
    neg: [bool; 3],
    tmin_down: f32x8,
}

impl<const EXACT: bool> Ray1x8<EXACT> {
    pub(super) fn new(pre: &Pre) -> Self {
        debug_assert!(
            EXACT || !exact(&pre.inv),
            "an infinite inverse takes the exact form"
        );
        let axes = [0, 1, 2].map(|a| slab_of::<EXACT>(pre.org[a], pre.inv[a]).map(f32x8::splat));
        Self {
            inv: axes.map(|[inv, _, _]| inv),
            c_near: axes.map(|[_, near, _]| near),
            c_far: axes.map(|[_, _, far]| far),
            neg: pre.inv.map(f32::is_sign_negative),
            tmin_down: f32x8::splat(pre.tmin * NEAR_DOWN),
        }
    }

    /// [`Ray1x8::new`] of lane `i` of a packet (traced), from the packet's constants, which
    /// equal the lane's scalar ones bit for bit ([`super::slab8`]): no divisions.
    #[inline(always)]
    pub(super) fn lane(pre: &Pre8, i: usize) -> Self {
        debug_assert!(
            EXACT || pre.exact >> i & 1 == 0,
            "an infinite inverse: exact"
        );
        let at = |v: &f32x8| f32x8::splat(v.as_array()[i]);
        let (inv, c_near, c_far) = if EXACT {
            (&pre.inv, &pre.org, &pre.org)
        } else {
            (&pre.slab_inv, &pre.c_near, &pre.c_far)
        };
        Self {
            inv: inv.each_ref().map(at),
            c_near: c_near.each_ref().map(at),
            c_far: c_far.each_ref().map(at),
            neg: pre.neg.map(|m| m.to_bitmask() >> i & 1 == 1),
            tmin_down: at(&pre.tmin_down),
        }
    }

    /// The slab test ([`super::slab`]) of the eight slots of `node` at once, the far bound
    /// widened ([`super::slab::met8`]): the mask of slots met and their entry distances. In
    /// the exact form, [`box1`](super::scalar::box1)'s slots and distances bit for bit.
    #[inline(always)]
    fn boxes(&self, node: &WideNode, tmax: f32) -> (u8, f32x8) {
        let mut near = self.tmin_down;
        let mut far = f32x8::splat(tmax);
        for axis in 0..3 {
            let (lo, hi) = (f32x8::from(node.lo[axis]), f32x8::from(node.hi[axis]));
            let (pn, pf) = if self.neg[axis] { (hi, lo) } else { (lo, hi) };
            let tn = plane8::<EXACT>(pn, self.inv[axis], self.c_near[axis]);
            let tf = plane8::<EXACT>(pf, self.inv[axis], self.c_far[axis]);
            near = tn.fast_max(near);
            far = tf.fast_min(far);
        }
        (met8::<EXACT>(near, far).to_bitmask() as u8, near)
    }
}

/// [`walk1_with`] for the ray `pre`, in the slab test's form it needs
/// ([`super::slab::exact`]): the closest-hit walk of a single ray.
pub(super) fn walk1<'a>(
    bvh: &WideRef<'a>,
    pre: &Pre,
    visit: impl FnMut(&'a [f32], usize) -> f32,
) -> f32 {
    if exact(&pre.inv) {
        walk1_with(bvh, &Ray1x8::<true>::new(pre), visit)
    } else {
        walk1_with(bvh, &Ray1x8::<false>::new(pre), visit)
    }
}

/// [`walk1_any_with`] for the ray `pre` from the root, in the slab test's form it needs
/// ([`super::slab::exact`]): the any-hit walk of a single ray.
pub(super) fn walk1_any<'a>(
    bvh: &WideRef<'a>,
    pre: &Pre,
    tmax: f32,
    blocked: impl FnMut(&'a [f32], usize) -> bool,
) -> bool {
    if exact(&pre.inv) {
        walk1_any_with(bvh, &Ray1x8::<true>::new(pre), tmax, 0, blocked)
    } else {
        walk1_any_with(bvh, &Ray1x8::<false>::new(pre), tmax, 0, blocked)
    }
}

/// Depth-first walk of one ray, nearest child first. `visit` tests the leaf of `n` triangles
/// whose rows start at `rows[0]` and returns the ray's new `tmax` (−∞ stops the walk).
///
/// The stack ([`Stack8`]) holds each slot's child and meta with its entry distance beside
/// it, so a pop never reads the parent node again; a popped entry whose entry distance lies
/// beyond the widened `tmax` is skipped: exactly the slab test repeated with the new `tmax`.
pub(super) fn walk1_with<'a, const EXACT: bool>(
    bvh: &WideRef<'a>,
    ray: &Ray1x8<EXACT>,
    mut visit: impl FnMut(&'a [f32], usize) -> f32,
) -> f32 {
    let mut tmax = visit(&[], 0);
    let mut stack = Stack8::new();
    let mut index = 0;
    loop {
        let node = &bvh.nodes[index];
        let (bits, near) = ray.boxes(node, tmax);
        let n = bits.count_ones() as usize;
        // The nearest slot met is visited next; the others are pushed farthest first, sorted
        // as the packet walk sorts them (+4–8 % on single gather rays,
        // docs/traverse.md, "What each kept change bought").
        let mut next = match n {
            0 => None,
            1 => {
                let slot = bits.trailing_zeros() as usize;
                Some((node.child[slot], node.meta[slot]))
            }
            _ => {
                let hit = bytemuck::cast(mask_of(bits));
                let rows = [
                    u32x8::from(node.child),
                    u32x8::from(node.meta),
                    bytemuck::cast(near),
                    u32x8::ZERO,
                ];
                let (next, pushed) = stack.push_sorted(sorted_rows(near, hit, rows), n);
                // The nearest slot pushed is prefetched (every slot pushed, as before the sorting
                // network: +4–5 % on the city's single rays, −1 % in cache on the room).
                prefetch_entry(bvh, pushed.entry());
                Some((next.child, next.meta))
            }
        };
        loop {
            let (child, meta) = match next.take() {
                Some(e) => e,
                None => {
                    let Some(e) = stack.pop() else {
                        return tmax;
                    };
                    if e.dist > super::widened(tmax) {
                        continue;
                    }
                    (e.child, e.meta)
                }
            };
            if meta == 0 {
                index = child as usize;
                break;
            }
            tmax = visit(bvh.leaf_rows(child), (meta & !LEAF) as usize);
            if tmax == f32::NEG_INFINITY {
                return tmax;
            }
        }
    }
}

/// Depth-first walk of one ray for any hit (occlusion) through the subtree of the entry
/// `start` (`child | meta << 32`; 0 for the whole tree): `blocked` tests the leaf of `n`
/// triangles whose rows start at `rows[0]`; the walk ends at the first leaf that blocks.
/// The slots met are taken in storage order, without a sort and without entry distances
/// on the stack: `tmax` never shrinks, so a popped entry is always still met (Embree's
/// any-hit traversal, `traverseAnyHit`). Returns whether a leaf blocked the ray.
pub(super) fn walk1_any_with<'a, const EXACT: bool>(
    bvh: &WideRef<'a>,
    ray: &Ray1x8<EXACT>,
    tmax: f32,
    start: u64,
    mut blocked: impl FnMut(&'a [f32], usize) -> bool,
) -> bool {
    let mut stack = Stack::<u64>::new();
    // The entry visited next: `start` first.
    let mut e = start;
    loop {
        let (child, meta) = (e as u32, (e >> 32) as u32);
        if meta == 0 {
            let node = &bvh.nodes[child as usize];
            let (bits, _) = ray.boxes(node, tmax);
            if bits != 0 {
                // [`slots_any_hit`] written out: through it (a closure pushing), the lanes of
                // the room's shadow packets walked 5 % slower (docs/traverse.md,
                // "Measured and dropped").
                let entry = |slot: u32| {
                    u64::from(node.child[slot as usize]) | u64::from(node.meta[slot as usize]) << 32
                };
                let leaves = !u32x8::from(node.meta).simd_eq(u32x8::ZERO).to_bitmask() as u8;
                let mut last = None;
                for group in [bits & !leaves, bits & leaves] {
                    let mut rest = group;
                    while rest != 0 {
                        let pushed = entry(rest.trailing_zeros());
                        rest &= rest - 1;
                        if let Some(p) = last.replace(pushed) {
                            prefetch_entry(bvh, p);
                            stack.push(p);
                        }
                    }
                }
                e = last.unwrap();
                continue;
            }
        } else if blocked(bvh.leaf_rows(child), (meta & !LEAF) as usize) {
            return true;
        }
        match stack.pop() {
            Some(next) => e = next,
            None => return false,
        }
    }
}

/// The lanes `lanes` of a packet as single rays looking for any hit ([`walk1_any_with`]), one
/// after another, each from the entry `entry` (`child | meta << 32`; 0 for the root), each in
/// the slab test's form it needs as a single ray ([`Pre8::exact`]): the lanes blocked.
pub(super) fn occluded_alone(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    lanes: u8,
    entry: u64,
) -> u8 {
    set_lanes(lanes).fold(0, |blocked, i| {
        let end = if pre.exact >> i & 1 == 1 {
            lane_any::<true>(bvh, pre, tmax, i, entry)
        } else {
            lane_any::<false>(bvh, pre, tmax, i, entry)
        };
        blocked | u8::from(end) << i
    })
}

/// Lane `i` of a packet as a single ray looking for any hit from the entry `entry`, in the
/// slab test's form `EXACT`: whether it is blocked.
#[inline(always)]
fn lane_any<const EXACT: bool>(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    i: usize,
    entry: u64,
) -> bool {
    let pre1 = Pre1x8::lane(pre, i);
    let tmax = tmax.as_array()[i];
    walk1_any_with(
        bvh,
        &Ray1x8::<EXACT>::lane(pre, i),
        tmax,
        entry,
        |rows, n| occludes_rows(|| pre.lane(i), &pre1, rows, n, tmax),
    )
}

/// The slots `bits` (one or more) of `node` in the order an any-hit walk takes them: inner
/// nodes pushed first, then leaves (so a leaf is popped, and may end the walk, before another
/// subtree is opened), each group in storage order. `push` takes the entries
/// `child | meta << 32` but the last, which is returned: the one visited next.
#[inline(always)]
fn slots_any_hit(node: &WideNode, bits: u8, mut push: impl FnMut(u64)) -> u64 {
    let entry = |slot: u32| {
        u64::from(node.child[slot as usize]) | u64::from(node.meta[slot as usize]) << 32
    };
    let leaves = !u32x8::from(node.meta).simd_eq(u32x8::ZERO).to_bitmask() as u8;
    let mut last = None;
    for group in [bits & !leaves, bits & leaves] {
        let mut rest = group;
        while rest != 0 {
            let pushed = entry(rest.trailing_zeros());
            rest &= rest - 1;
            if let Some(p) = last.replace(pushed) {
                push(p);
            }
        }
    }
    last.unwrap()
}

/// Layout size ([`WideRef::bytes`]) from which [`super::occluded8`] interleaves the
/// single-ray walks of a packet whose lanes do not share an origin: 1 MiB, a core's L2 on the
/// measuring machine. Measured on two trees only (docs/traverse.md, "What falls
/// short"): on the Veach room (0.27 MB, in cache) interleaving costs 30–37 %, on the 1M-triangle
/// city (59 MB) it gains 1.9×.
pub const INTERLEAVE_BYTES: usize = 1 << 20;

/// Asks the cache for the 256 bytes of the node, or the first rows of the leaf, of the entry
/// `child | meta << 32`. The address is chosen without a branch: branching on the kind of entry
/// mispredicted a third of the time in the packet walk (docs/traverse.md, "What each kept change
/// bought").
#[inline(always)]
fn prefetch_entry(bvh: &WideRef<'_>, e: u64) {
    let (child, meta) = (e as usize & 0xffff_ffff, (e >> 32) as u32);
    let node = bvh.nodes.as_ptr().wrapping_add(child).cast::<i8>();
    let rows = bvh
        .rows
        .as_ptr()
        .wrapping_add(child.wrapping_mul(ROWS))
        .cast::<i8>();
    // `rows − node` for a leaf, 0 for an inner node.
    let leaf = (rows as isize).wrapping_sub(node as isize) & -isize::from(meta != 0);
    let p = node.wrapping_byte_offset(leaf);
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        for line in 0..4 {
            // SAFETY: a prefetch never faults and has no effect on memory; `wrapping_add`
            // keeps the address arithmetic defined.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * line)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// The lanes `lanes` of a packet as single rays looking for any hit (occlusion), walked
/// interleaved: each round advances every unfinished lane by one node or leaf and prefetches
/// what that lane visits next, so the cache misses of the independent walks overlap (a single
/// walk waits for each node in turn). Each lane's walk is [`walk1_any`]'s: the slots met in
/// storage order, leaves first. `blocked(lane, pre, rows, n)` tests a leaf for one lane;
/// the lanes it blocks are returned as a bit mask. All lanes take the exact slab test when
/// one needs it ([`Pre8::exact`]), the fused one otherwise.
pub(super) fn walk_interleaved_any(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    lanes: u8,
    blocked: impl FnMut(usize, &Pre1x8, &[f32], usize) -> bool,
) -> u8 {
    if pre.exact & lanes != 0 {
        interleaved_any::<true>(bvh, pre, tmax, lanes, blocked)
    } else {
        interleaved_any::<false>(bvh, pre, tmax, lanes, blocked)
    }
}

/// [`walk_interleaved_any`] in the slab test's form `EXACT`.
fn interleaved_any<const EXACT: bool>(
    bvh: &WideRef<'_>,
    pre: &Pre8,
    tmax: f32x8,
    lanes: u8,
    mut blocked: impl FnMut(usize, &Pre1x8, &[f32], usize) -> bool,
) -> u8 {
    let ray: [Option<(Ray1x8<EXACT>, Pre1x8)>; LANES] = core::array::from_fn(|i| {
        (lanes >> i & 1 == 1).then(|| (Ray1x8::lane(pre, i), Pre1x8::lane(pre, i)))
    });
    let tmax = tmax.to_array();
    let mut stacks: [[MaybeUninit<u64>; STACK]; LANES] =
        [const { [const { MaybeUninit::uninit() }; STACK] }; LANES];
    let mut sp = [0usize; LANES];
    // The entry each lane visits next (`child | meta << 32`): the root first.
    let mut next = [0u64; LANES];
    let mut active = lanes;
    let mut hit = 0;
    while active != 0 {
        for i in set_lanes(active) {
            let Some((r, consts)) = &ray[i] else {
                continue;
            };
            let (child, meta) = (next[i] as u32, (next[i] >> 32) as u32);
            let mut go = None;
            if meta == 0 {
                let node = &bvh.nodes[child as usize];
                let (bits, _) = r.boxes(node, tmax[i]);
                if bits != 0 {
                    go = Some(slots_any_hit(node, bits, |p| {
                        stacks[i][sp[i]].write(p);
                        sp[i] += 1;
                    }));
                }
            } else if blocked(i, consts, bvh.leaf_rows(child), (meta & !LEAF) as usize) {
                hit |= 1 << i;
                active &= !(1 << i);
                continue;
            }
            let e = go.or_else(|| {
                sp[i] = sp[i].checked_sub(1)?;
                // SAFETY: every entry below the previous `sp[i]` was written above.
                Some(unsafe { stacks[i][sp[i]].assume_init() })
            });
            let Some(e) = e else {
                active &= !(1 << i);
                continue;
            };
            prefetch_entry(bvh, e);
            next[i] = e;
        }
    }
    hit
}

// ---------------------------------------------------------------------------------------------
// Eight rays.

/// The box-test constants of a packet's lanes, read from its [`Pre8`], by lane (lane `i` at
/// index `i`), so a lane's test loads each of them with one scaled index; in the slab test's
/// form `EXACT` ([`super::slab`]), the same for every lane.
struct Lanes<const EXACT: bool> {
    /// [`super::slab::slab_of`]'s constants per axis.
    inv: [[f32; LANES]; 3],
    c_near: [[f32; LANES]; 3],
    c_far: [[f32; LANES]; 3],
    /// Byte offsets within a [`WideNode`] of the rows of each lane's near and far planes per
    /// axis, `32·row` (`lo` x, y, z rows 0–2, `hi` rows 3–5): only [`Lanes::new`] writes
    /// them, and [`Lanes::row`] relies on them being such offsets.
    near: [[u32; LANES]; 3],
    far: [[u32; LANES]; 3],
    tmin_down: [f32; LANES],
}

/// Bytes of one row of a [`WideNode`]: the eight `lo` or `hi` values of one axis.
const ROW_BYTES: u32 = 4 * WIDTH as u32;

impl<const EXACT: bool> Lanes<EXACT> {
    fn new(pre: &Pre8) -> Self {
        let offsets = |far: bool| {
            [0, 1, 2].map(|a| {
                // 1 in the lanes whose direction has the sign bit set (near plane `hi`).
                let neg = bytemuck::cast::<f32x8, u32x8>(pre.neg[a]) >> 31;
                let hi = if far { u32x8::ONE - neg } else { neg };
                (u32x8::splat(a as u32) + hi * u32x8::splat(3)) * u32x8::splat(ROW_BYTES)
            })
        };
        let (inv, c_near, c_far) = if EXACT {
            (pre.inv, pre.org, pre.org)
        } else {
            (pre.slab_inv, pre.c_near, pre.c_far)
        };
        Self {
            inv: inv.map(f32x8::to_array),
            c_near: c_near.map(f32x8::to_array),
            c_far: c_far.map(f32x8::to_array),
            near: offsets(false).map(u32x8::to_array),
            far: offsets(true).map(u32x8::to_array),
            tmin_down: pre.tmin_down.to_array(),
        }
    }

    /// The row of `node` at the byte offset `off`, one of [`Lanes::near`] or [`Lanes::far`].
    /// (Indexing the rows by row number took an `and` and a shift per plane and lane: 12 of
    /// the 70 instructions of a lane's test, docs/traverse.md, "What each kept change bought".)
    #[inline(always)]
    fn row(node: &WideNode, off: u32) -> f32x8 {
        debug_assert!(off.is_multiple_of(ROW_BYTES) && off < 6 * ROW_BYTES);
        // SAFETY: `off` is `32·row` with `row < 6` (`Lanes::new` writes no other values), so
        // the 32 bytes read lie inside the 256-byte node; `[f32; 8]` needs the alignment of
        // `f32` only, which `off` (a multiple of 4) keeps.
        f32x8::from(unsafe {
            core::ptr::from_ref(node)
                .cast::<u8>()
                .add(off as usize)
                .cast::<[f32; WIDTH]>()
                .read()
        })
    }
}

/// `u32x8::splat(1 << i)` for lane `i`, as one load.
const LANE_BIT: [[u32; WIDTH]; LANES] = {
    let mut bits = [[0; WIDTH]; LANES];
    let mut i = 0;
    while i < LANES {
        bits[i] = [1 << i; WIDTH];
        i += 1;
    }
    bits
};

/// The slab test of `node`'s eight slots for each lane of `live`, lane by lane (one `f32x8`
/// test per lane, [`Ray1x8::boxes`]' operations): per slot, the mask of lanes that meet it
/// (`u32` lanes) and the nearest of their entry distances (+∞ where none does).
#[inline(always)]
fn boxes8<const EXACT: bool>(
    node: &WideNode,
    lanes: &Lanes<EXACT>,
    live: u8,
    tmax: &[f32; LANES],
) -> (u32x8, f32x8) {
    let inf = f32x8::splat(f32::INFINITY);
    let mut met = u32x8::ZERO;
    let mut nearest = inf;
    let mut test = |i: usize| {
        let mut near = f32x8::splat(lanes.tmin_down[i]);
        let mut far = f32x8::splat(tmax[i]);
        for axis in 0..3 {
            let pn = Lanes::<EXACT>::row(node, lanes.near[axis][i]);
            let pf = Lanes::<EXACT>::row(node, lanes.far[axis][i]);
            let inv = f32x8::splat(lanes.inv[axis][i]);
            near = plane8::<EXACT>(pn, inv, f32x8::splat(lanes.c_near[axis][i])).fast_max(near);
            far = plane8::<EXACT>(pf, inv, f32x8::splat(lanes.c_far[axis][i])).fast_min(far);
        }
        let m = met8::<EXACT>(near, far);
        nearest = m.select(near, inf).fast_min(nearest);
        met |= bytemuck::cast::<f32x8, u32x8>(m) & u32x8::from(LANE_BIT[i]);
    };
    // A node that all eight lanes reach is tested without the loop over set lanes, whose exit the
    // branch predictor misses once a node (city gather 0.90–0.94× → 0.97–1.00× Embree,
    // docs/traverse.md, "What each kept change bought"; the same for six or more lanes, the dead
    // ones tested with `tmax = −∞`, was no faster).
    if live == 0xff {
        for i in 0..LANES {
            test(i);
        }
    } else {
        for i in set_lanes(live) {
            test(i & 7);
        }
    }
    (met, nearest)
}

/// What a packet walk (the binary tree's, `super::packet`, and the wide one below) does at a
/// leaf.
pub(super) trait Visitor<'a> {
    /// The live lanes at most from which the wide walk finishes the subtree of an inner
    /// node lane by lane ([`Visitor::alone`]); 0: never. (The closest-hit walk never does:
    /// Embree's hybrid switch was measured and dropped there four times, docs/traverse.md,
    /// "Measured and dropped".)
    const ALONE: u32 = 0;

    /// Walks the subtree of the wide entry `entry` (`child | meta << 32`) for each lane of
    /// `lanes` alone; returns the packet's new `tmax`.
    fn alone(&mut self, _bvh: &WideRef<'a>, _lanes: u8, _entry: u64) -> f32x8 {
        unreachable!("ALONE is 0")
    }

    /// Tests a leaf's triangles for the packet, eight lanes per test; returns the packet's
    /// new `tmax` (−∞ in finished lanes).
    fn leaf8<T: TriAt>(&mut self, leaf: impl Iterator<Item = T>) -> f32x8;

    /// Tests the wide leaf of `n` triangles whose rows start at `rows[0]` for each lane of
    /// `lanes`, eight triangles per pass; returns the packet's new `tmax`.
    fn rows1(&mut self, rows: &'a [f32], n: usize, lanes: u8) -> f32x8;
}

/// Depth-first walk of a packet: a shared stack ([`Stack8`]) of slots, each with the lanes
/// whose interval met its box when it was pushed; the children a node's live lanes meet are
/// sorted by the nearest entry distance among their lanes ([`sort8_descending`]), the
/// nearest visited next and the others pushed farthest first. A node is tested lane by lane,
/// eight slots at a time ([`boxes8`]): only the live lanes are tested, and a packet's lanes
/// drift apart deeper in the tree. (Measured against testing slot by slot, eight lanes at a
/// time, against one frustum test for a shared-origin packet, and against a frustum test
/// choosing the slots then tested eight lanes at a time: docs/traverse.md,
/// "Measured and dropped".) A popped inner node that at most [`Visitor::ALONE`] live lanes reach is
/// handed to [`Visitor::alone`] (any-hit walks only: docs/traverse.md, "Wide layout").
pub(super) fn walk8<'a, V: Visitor<'a>>(
    bvh: &WideRef<'a>,
    pre: &Pre8,
    tmax: f32x8,
    visitor: &mut V,
) {
    // A packet with a lane that needs the exact slab test takes it in every lane (lanes of a
    // packet are tested alike; the exact test keeps a subset of the fused one's boxes, and
    // both keep every box `box1` keeps).
    if pre.exact != 0 {
        walk8_with::<V, true>(bvh, pre, tmax, visitor);
    } else {
        walk8_with::<V, false>(bvh, pre, tmax, visitor);
    }
}

/// [`walk8`] in the slab test's form `EXACT`.
fn walk8_with<'a, V: Visitor<'a>, const EXACT: bool>(
    bvh: &WideRef<'a>,
    pre: &Pre8,
    mut tmax: f32x8,
    visitor: &mut V,
) {
    let lanes = Lanes::<EXACT>::new(pre);
    let mut stack = Stack8::new();
    let mut alive = pre.traced;
    let mut index = 0usize;
    let mut live = alive;
    let mut far = widened_largest(tmax, alive);
    loop {
        let node = &bvh.nodes[index];
        let (met, nearest) = boxes8(node, &lanes, live, tmax.as_array());
        // The slots met sorted farthest first without a branch: the first `n − 1` pushed,
        // the nearest visited next. (Sorted by insertion, the sort's and the pushes' branches
        // were two fifths of the walk's mispredictions on the city: callgrind's model,
        // docs/traverse.md, "What each kept change bought".)
        let hit = !met.simd_eq(u32x8::ZERO);
        let n = hit.to_bitmask().count_ones() as usize;
        let mut next = (n > 0).then(|| {
            let rows = [
                u32x8::from(node.child),
                u32x8::from(node.meta),
                bytemuck::cast(nearest),
                met,
            ];
            let (next, pushed) = stack.push_sorted(sorted_rows(nearest, hit, rows), n);
            // The nearest entry pushed is prefetched: the walk comes back to it after the
            // nearest subtree (docs/traverse.md).
            prefetch_entry(bvh, pushed.entry());
            next
        });
        loop {
            let e = match next.take() {
                Some(e) => e,
                None => {
                    let Some(e) = stack.pop() else {
                        return;
                    };
                    // Beyond every live lane's widened `tmax`: the slab tests repeated
                    // would all fail.
                    if e.dist > far {
                        continue;
                    }
                    e
                }
            };
            let (child, meta) = (e.child, e.meta);
            live = e.lanes & alive;
            if live == 0 {
                continue;
            }
            tmax = if meta != 0 {
                let n = (meta & !LEAF) as usize;
                let rows = bvh.leaf_rows(child);
                if rows_for(live, meta) {
                    visitor.rows1(rows, n, live)
                } else {
                    let leaf = &rows[..ROWS * n];
                    visitor.leaf8((0..n).map(|i| RowTri::new(leaf, n, i)))
                }
            } else if live.count_ones() <= V::ALONE {
                visitor.alone(bvh, live, e.entry())
            } else {
                index = child as usize;
                break;
            };
            alive = pre.tmin.simd_le(tmax).to_bitmask() as u8;
            if alive == 0 {
                return;
            }
            far = widened_largest(tmax, alive);
        }
    }
}

/// The slot numbers, lane by lane.
const SLOTS: u32x8 = u32x8::new([0, 1, 2, 3, 4, 5, 6, 7]);

/// The slot rows `rows` permuted so that the slots of `hit` come first, farthest first by
/// their entry distances `near`. Keys `near bits & !7 | slot` of the slots met (entry
/// distances are ≥ 0, so their bits order like the values; the order only steers the walk),
/// 0 elsewhere, sorted descending ([`sort8_descending`]): with `n` slots met, entry `n − 1`
/// is the nearest (a key 0 met, slot 0 at distance 0, sorts among the zeros and is still
/// entry `n − 1`).
#[inline(always)]
fn sorted_rows(near: f32x8, hit: u32x8, rows: [u32x8; 4]) -> [u32x8; 4] {
    let keys = (bytemuck::cast::<f32x8, u32x8>(near) & u32x8::splat(!7) | SLOTS) & hit;
    let order = sort8_descending(keys) & u32x8::splat(7);
    rows.map(|row| permute(row, order))
}

/// `v[idx[i] & 7]` in each lane `i` (`vpermd`).
#[inline(always)]
fn permute(v: u32x8, idx: u32x8) -> u32x8 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use core::arch::x86_64::{__m256i, _mm256_permutevar8x32_epi32};
        // SAFETY: AVX2 is enabled at compile time (the `cfg` above), so `vpermd` exists on
        // every CPU this code runs on.
        bytemuck::cast(unsafe {
            _mm256_permutevar8x32_epi32(bytemuck::cast::<u32x8, __m256i>(v), bytemuck::cast(idx))
        })
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let (v, idx) = (v.to_array(), idx.to_array());
        u32x8::from(idx.map(|i| v[(i & 7) as usize]))
    }
}

/// The comparators of an optimal sorting network for eight keys (19 comparators in 6
/// layers; Knuth, *TAOCP* vol. 3, §5.3.4), layer by layer.
const NETWORK_PAIRS: [&[(usize, usize)]; 6] = [
    &[(0, 2), (1, 3), (4, 6), (5, 7)],
    &[(0, 4), (1, 5), (2, 6), (3, 7)],
    &[(0, 1), (2, 3), (4, 5), (6, 7)],
    &[(2, 4), (3, 5)],
    &[(1, 4), (3, 6)],
    &[(1, 2), (3, 4), (5, 6)],
];

/// [`NETWORK_PAIRS`] as lanes: per layer, each lane's partner (itself where it has none) and
/// a mask of the lanes that are the lower of their pair.
const NETWORK: [([u32; WIDTH], [u32; WIDTH]); 6] = {
    let mut layers = [([0, 1, 2, 3, 4, 5, 6, 7], [0; WIDTH]); 6];
    let mut l = 0;
    while l < layers.len() {
        let mut p = 0;
        while p < NETWORK_PAIRS[l].len() {
            let (a, b) = NETWORK_PAIRS[l][p];
            layers[l].0[a] = b as u32;
            layers[l].0[b] = a as u32;
            layers[l].1[a] = u32::MAX;
            p += 1;
        }
        l += 1;
    }
    layers
};

/// `keys` sorted descending by [`NETWORK`], without a branch: per layer one permute, a `max`,
/// a `min` and a blend.
#[inline(always)]
fn sort8_descending(mut keys: u32x8) -> u32x8 {
    for (partner, lower) in NETWORK {
        let other = permute(keys, u32x8::from(partner));
        keys = u32x8::from(lower).select(keys.max(other), keys.min(other));
    }
    keys
}

/// An entry of [`Stack8`]: the slot's child and meta, the (nearest) entry distance into its
/// box, and the lanes that met it (packets; 0 for a single ray).
#[derive(Clone, Copy)]
struct Entry8 {
    child: u32,
    meta: u32,
    dist: f32,
    lanes: u8,
}

impl Entry8 {
    /// `child | meta << 32`.
    fn entry(self) -> u64 {
        u64::from(self.child) | u64::from(self.meta) << 32
    }
}

/// The closest-hit walks' stack as four rows (child, meta, entry distance bits, lanes met),
/// so that a node's sorted slots are pushed with four 8-wide stores
/// ([`Stack8::push_sorted`]). Left uninitialised, as [`Stack`].
struct Stack8 {
    rows: [[MaybeUninit<u32>; STACK + WIDTH]; 4],
    len: usize,
}

impl Stack8 {
    #[inline(always)]
    fn new() -> Self {
        Self {
            rows: [[const { MaybeUninit::uninit() }; STACK + WIDTH]; 4],
            len: 0,
        }
    }

    /// Writes the eight entries `rows`, sorted farthest first, at the top and pushes the
    /// first `n − 1` of them (`n ≥ 1`). Returns entry `n − 1`, the nearest (visited next),
    /// and the nearest entry pushed (entry `n − 1` again when none is).
    #[inline(always)]
    fn push_sorted(&mut self, rows: [u32x8; 4], n: usize) -> (Entry8, Entry8) {
        let at = self.len;
        // A walk never exceeds `STACK` entries; the eight-wide stores need `WIDTH` beyond.
        assert!(at <= STACK && (1..=WIDTH).contains(&n));
        for (row, v) in self.rows.iter_mut().zip(rows) {
            row[at..at + WIDTH].copy_from_slice(&v.to_array().map(MaybeUninit::new));
        }
        self.len = at + n - 1;
        // SAFETY: entries `at .. at + WIDTH` were written just above.
        unsafe { (self.get(at + n - 1), self.get(at + n.max(2) - 2)) }
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<Entry8> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: `push_sorted` wrote every entry below the previous `len`, and `len` only
        // grows through `push_sorted`.
        Some(unsafe { self.get(self.len) })
    }

    /// Entry `i`.
    ///
    /// # Safety
    /// `push_sorted` wrote entry `i`.
    #[inline(always)]
    unsafe fn get(&self, i: usize) -> Entry8 {
        // SAFETY: the caller's promise.
        let row = |k: usize| unsafe { self.rows[k][i].assume_init() };
        Entry8 {
            child: row(0),
            meta: row(1),
            dist: f32::from_bits(row(2)),
            lanes: row(3) as u8,
        }
    }
}

/// Whether the packet walk tests the leaf `meta` for the lanes `live` lane by lane, eight
/// triangles per pass on its rows: when that takes fewer passes than triangle by triangle,
/// eight lanes per test on its [`Tri`]s.
#[inline(always)]
fn rows_for(live: u8, meta: u32) -> bool {
    let n = (meta & !LEAF) as usize;
    live.count_ones() as usize * n.div_ceil(8) < n
}

/// The widened far bound of the largest `tmax` among the lanes of `alive`, without a branch:
/// a branch per lane on `alive` mispredicted wherever lanes finish at random, as shadow lanes
/// do (the room's shadow packets 1.00× → 1.21–1.23× Embree, docs/traverse.md,
/// "What each kept change bought").
#[inline(always)]
fn widened_largest(tmax: f32x8, alive: u8) -> f32 {
    let t = mask_of(alive)
        .select(tmax, f32x8::splat(f32::NEG_INFINITY))
        .to_array();
    // Without `f32::max`'s NaN handling: an alive lane's `tmax` is never NaN.
    let max = |x: f32, y: f32| if x > y { x } else { y };
    let [a, b, c, d] = [0, 1, 2, 3].map(|i| max(t[i], t[i + 4]));
    super::widened(max(max(a, c), max(b, d)))
}

#[cfg(test)]
mod tests {
    use super::super::slab::{slab, slab8};
    use super::*;
    use crate::packet::{Hit8, LANES, Ray, Ray8};
    use crate::testing::Pcg32;
    use crate::traverse::{Node, intersect1, intersect8, occluded1, occluded8};
    use glam::Vec3;
    use std::vec::Vec;

    /// A binary chain as deep as [`super::super::MAX_DEPTH`] allows: every node a leaf of one
    /// triangle beside the next node.
    fn chain(depth: usize) -> (Vec<Node>, Vec<Tri>) {
        let tris: Vec<Tri> = (0..=depth as u32)
            .map(|i| {
                let x = i as f32;
                Tri::new(
                    [
                        Vec3::new(x, 0.0, 0.0),
                        Vec3::new(x + 0.5, 0.0, 0.0),
                        Vec3::new(x, 1.0, 0.0),
                    ],
                    i,
                )
            })
            .collect();
        let mut nodes: Vec<Node> = (0..depth as u32)
            .map(|i| {
                let mut n = Node::EMPTY;
                n.set_box(
                    0,
                    Vec3::new(i as f32, 0.0, 0.0),
                    Vec3::new(i as f32 + 0.5, 1.0, 0.0),
                );
                n.child[0] = i;
                n.meta[0] = LEAF | 1;
                n.set_box(
                    1,
                    Vec3::new(i as f32 + 1.0, 0.0, 0.0),
                    Vec3::new(depth as f32 + 0.5, 1.0, 0.0),
                );
                n.child[1] = i + 1;
                n.meta[1] = 0;
                n
            })
            .collect();
        let last = depth - 1;
        nodes[last].child[1] = depth as u32;
        nodes[last].meta[1] = LEAF | 1;
        (nodes, tris)
    }

    /// The slots of `node` that [`super::super::scalar::box1_at`] keeps for `ray`, as bits.
    fn reference_bits(node: &WideNode, ray: &Ray) -> u8 {
        let pre = Pre::new(ray);
        (0..WIDTH).fold(0, |bits, k| {
            let kept = super::super::box1_at(node.slot_box(k), &pre, ray.tmax).is_some();
            bits | u8::from(kept) << k
        })
    }

    /// The wide test's slots met for `ray` in the form `EXACT`, and their entry distances: as
    /// a single ray ([`Ray1x8::boxes`]) and as lane `lane` of a packet of copies ([`boxes8`]),
    /// which must agree.
    fn wide_bits_in<const EXACT: bool>(node: &WideNode, ray: &Ray, lane: usize) -> (u8, f32x8) {
        let (single, near) = Ray1x8::<EXACT>::new(&Pre::new(ray)).boxes(node, ray.tmax);
        let pre8 = Pre8::new(&Ray8::from_rays(&[*ray; LANES]));
        let lanes = Lanes::<EXACT>::new(&pre8);
        let (met, nearest) = boxes8(node, &lanes, 1 << lane, &[ray.tmax; LANES]);
        let packet = met
            .to_array()
            .iter()
            .enumerate()
            .fold(0u8, |bits, (k, &m)| {
                bits | u8::from(m >> lane & 1 == 1) << k
            });
        assert_eq!(single, packet, "{ray:?}");
        let inf = f32x8::splat(f32::INFINITY);
        let near = mask_of(single).select(near, inf);
        assert_eq!(
            near.to_array().map(f32::to_bits),
            nearest.to_array().map(f32::to_bits)
        );
        (single, near)
    }

    /// The wide test's slots met for `ray`, in the form the walks take for it
    /// ([`super::super::slab::exact`]).
    fn fused_bits(node: &WideNode, ray: &Ray, lane: usize) -> u8 {
        if exact(&Pre::new(ray).inv) {
            wide_bits_in::<true>(node, ray, lane).0
        } else {
            wide_bits_in::<false>(node, ray, lane).0
        }
    }

    #[test]
    fn the_fused_slab_test_keeps_every_box_the_reference_keeps() {
        let mut rng = crate::testing::Pcg32::new(19, 7);
        let mut unit = || rng.next_f32();
        let (mut kept, mut extra) = (0u32, 0u32);
        for trial in 0..20_000 {
            // Origins near the world's origin, at 10⁶, and on the boxes' faces; directions
            // generic, or with a component ±0 or subnormal (infinite inverse).
            let scale = [1.0, 100.0, 1e6][trial % 3];
            let mut node = WideNode::EMPTY;
            let mut boxes = Vec::new();
            for k in 0..WIDTH {
                let c = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale;
                let h = Vec3::new(unit(), unit(), unit()) * scale * 0.3 * unit();
                node.set_slot(k, (c - h).to_array(), (c + h).to_array(), 0, 0);
                boxes.push((c - h, c + h));
            }
            // Towards a box's centre, give or take, from near the world's origin or from 10⁶.
            let (lo, hi) = boxes[trial / 2 % WIDTH];
            let face = if trial / 4 % 2 == 0 { lo } else { hi };
            let mut org = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale;
            let aim = (lo + hi) * 0.5 - org;
            let jitter = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * 0.2;
            let mut dir = aim + jitter * aim.length();
            let axis = trial / 3 % 3;
            match trial / 9 % 4 {
                0 => {}
                // In the plane of the aimed box's face, along it (`(p − o)·∞` is NaN there);
                // every other time that plane moved to 0, where `o·inv` is exact.
                1 => {
                    org[axis] = face[axis];
                    dir[axis] = if trial / 72 % 2 == 0 { 0.0 } else { -0.0 };
                    if trial / 36 % 2 == 0 {
                        let shift = Vec3::AXES[axis] * face[axis];
                        let k = trial / 2 % WIDTH;
                        node.set_slot(k, (lo - shift).to_array(), (hi - shift).to_array(), 0, 0);
                        org[axis] = 0.0;
                    }
                }
                2 => dir[axis] = f32::from_bits(1) * if trial / 72 % 2 == 0 { 1.0 } else { -1.0 },
                // On the aimed box's face or an ulp or two off it, leaving or entering.
                _ => org[axis] = f32::from_bits(face[axis].to_bits() + (trial % 3) as u32),
            }
            let tmax = [f32::INFINITY, scale * unit()][trial % 2];
            let ray = Ray::new(org, dir.normalize_or(Vec3::X), 0.0, tmax);
            let (reference, fused) = (
                reference_bits(&node, &ray),
                fused_bits(&node, &ray, trial % LANES),
            );
            assert_eq!(reference & !fused, 0, "a box culled: {ray:?} {node:?}");
            if exact(&Pre::new(&ray).inv) {
                assert_eq!(
                    reference, fused,
                    "the exact form is box1's: {ray:?} {node:?}"
                );
            }
            kept += reference.count_ones();
            extra += (fused & !reference).count_ones();
        }
        assert!(kept > 5_000, "the test must keep boxes ({kept})");
        // Conservative, not loose: the fused test meets few boxes the reference culls.
        assert!(extra * 100 < kept, "{extra} extra of {kept}");
    }

    /// The exact form ([`super::super::slab::plane8`] with `EXACT`), single ray and packet
    /// lane, is [`box1`](super::super::scalar::box1) bit for bit: the same slots met and the
    /// same entry distances, for rays with infinite inverse components (which take it) and
    /// for generic ones (which do not, but may: a packet with one such lane tests all lanes
    /// so); and `Pre8::exact` marks exactly the traced lanes that take it as single rays.
    #[test]
    fn the_exact_slab_test_is_box1_bit_for_bit() {
        let mut rng = crate::testing::Pcg32::new(41, 3);
        let mut unit = || rng.next_f32();
        let mut kept = 0u32;
        for trial in 0..20_000 {
            let scale = [1.0, 1e3, 1e6, 1e30][trial % 4];
            let mut node = WideNode::EMPTY;
            for k in 0..WIDTH - trial % 3 {
                let c = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale;
                let h = Vec3::new(unit(), unit(), unit()) * scale * 0.3 * unit();
                node.set_slot(k, (c - h).to_array(), (c + h).to_array(), 0, 0);
            }
            let (lo, hi) = node.slot_box(trial % (WIDTH - 2));
            let mut org = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale * 4.0;
            // Towards the aimed box's centre, give or take.
            let jitter = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * 0.3;
            let mut dir = ((Vec3::from(lo) + Vec3::from(hi)) * 0.5 - org) / scale;
            dir = dir.normalize_or(Vec3::X) + jitter;
            let axis = trial / 4 % 3;
            let tiny = [0.0, -0.0, f32::from_bits(1), -1e-40, 3e-39][trial / 12 % 5];
            match trial / 60 % 4 {
                0 => {}
                // Inside the aimed box's slab, the axis's component tiny or ±0.
                1 => {
                    org[axis] = lo[axis] + (hi[axis] - lo[axis]) * unit();
                    dir[axis] = tiny;
                }
                // In a face's plane, the component tiny or ±0 (`(p − o)·∞` is NaN).
                2 => {
                    org[axis] = if trial % 2 == 0 { lo[axis] } else { hi[axis] };
                    dir[axis] = tiny;
                }
                // Two components tiny: along an axis, far away.
                _ => {
                    org = Vec3::from(lo.map(|l| l * 0.5)) - Vec3::AXES[axis] * 1e38;
                    dir = Vec3::AXES[axis] + Vec3::AXES[(axis + 1) % 3] * tiny;
                }
            }
            let tmin = [0.0, scale * unit()][trial / 2 % 2];
            let tmax = [f32::INFINITY, f32::MAX, scale * 8.0 * unit()][trial % 3];
            let ray = Ray::new(org, dir, tmin, tmax);
            if !crate::traverse::triangle::traceable(&ray) {
                continue;
            }
            let pre = Pre::new(&ray);
            let (bits, near) = wide_bits_in::<true>(&node, &ray, trial % LANES);
            for k in 0..WIDTH {
                let reference = super::super::box1_at(node.slot_box(k), &pre, ray.tmax);
                assert_eq!(
                    reference.map(f32::to_bits),
                    (bits >> k & 1 == 1).then(|| near.as_array()[k].to_bits()),
                    "slot {k}: {ray:?} {node:?}"
                );
                kept += u32::from(reference.is_some());
            }
            // The packet's mark of lanes that need the exact form: this lane and no other.
            let mut rays = [Ray::new(Vec3::ZERO, Vec3::ONE, 0.0, 1.0); LANES];
            rays[trial % LANES] = ray;
            let pre8 = Pre8::new(&Ray8::from_rays(&rays));
            assert_eq!(
                pre8.exact,
                u8::from(exact(&pre.inv)) << (trial % LANES),
                "{ray:?}"
            );
        }
        assert!(kept > 5_000, "the test must keep boxes ({kept})");
    }

    /// Issue 43: along an axis of infinite inverse direction, a ray inside a box's slab meets
    /// the box at any distance along the others, as [`box1`](super::super::scalar::box1)
    /// (`(hi − o)·∞ = ∞`) does; the fused test's former stand-in `2¹⁰⁰` (slack `2⁶⁰`) culled
    /// it beyond `(hi − o)·2¹⁰⁰ + 2⁶⁰`.
    #[test]
    fn an_infinite_inverse_meets_boxes_at_any_distance() {
        let mut node = WideNode::EMPTY;
        node.set_slot(0, [0.0, -0.25, -0.25], [0.0, 0.25, 0.25], 0, LEAF | 1);
        for x in [-1e15, -1e30, -1e38, -3e38] {
            for dy in [0.0, -0.0, 3e-45, -1.5e-40] {
                let ray = Ray::new(
                    Vec3::new(x, 0.1, 0.05),
                    Vec3::new(1.0, dy, 0.0),
                    0.0,
                    f32::MAX,
                );
                assert_eq!(reference_bits(&node, &ray), 1, "{ray:?}");
                for lane in [0, 5] {
                    assert_eq!(fused_bits(&node, &ray, lane), 1, "{ray:?}");
                }
            }
        }
    }

    #[test]
    fn the_fused_slab_test_culls_the_box_an_offset_origin_leaves() {
        // A gather ray leaves a box's top face from an origin lifted by `offset_origin` (two
        // to four ulps): the box lies behind it, and both tests must cull it (a looser
        // offset slack met 2 % more slots on the 1M-triangle city).
        let mut rng = crate::testing::Pcg32::new(23, 5);
        let mut unit = || rng.next_f32();
        for trial in 0..20_000 {
            let scale = [1.0, 100.0, 1e4, 1e6][trial % 4];
            let top = (unit() + 0.01) * scale;
            let lo = [-scale, top - scale, -scale];
            let mut node = WideNode::EMPTY;
            node.set_slot(0, lo, [scale, top, scale], 0, 0);
            let p = Vec3::new(unit() - 0.5, 0.0, unit() - 0.5) * scale + Vec3::Y * top;
            let mut org = crate::packet::offset_origin(p, Vec3::Y, 0.0);
            // Unfused (no FMA), the offsets' slack is twice as wide: lift the origin twice.
            if cfg!(not(all(target_feature = "avx", target_feature = "fma"))) {
                org = crate::packet::offset_origin(org, Vec3::Y, 0.0);
            }
            let up = Vec3::new(unit() - 0.5, unit() + 0.05, unit() - 0.5).normalize();
            let ray = Ray::new(org, up, 0.0, f32::INFINITY);
            assert_eq!(reference_bits(&node, &ray), 0, "{ray:?}");
            assert_eq!(
                fused_bits(&node, &ray, trial % LANES),
                0,
                "{ray:?} {node:?}"
            );
        }
    }

    #[test]
    fn the_fused_slab_constants_are_the_same_8_wide_and_scalar() {
        let mut rng = crate::testing::Pcg32::new(31, 1);
        let special = [
            0.0,
            -0.0,
            f32::from_bits(1),
            1e-30,
            1e30,
            f32::INFINITY,
            3.0e38,
        ];
        for trial in 0..4000 {
            let pick = |rng: &mut crate::testing::Pcg32, k: usize| {
                let x = (rng.next_f32() - 0.5) * [1.0, 1e6, 1e-3][k % 3];
                if k.is_multiple_of(5) {
                    special[k / 5 % special.len()] * x.signum()
                } else {
                    x
                }
            };
            let o: [f32; LANES] = core::array::from_fn(|i| pick(&mut rng, trial + i));
            let inv: [f32; LANES] = core::array::from_fn(|i| pick(&mut rng, trial * 7 + i));
            let wide = slab8(f32x8::from(o), f32x8::from(inv)).map(f32x8::to_array);
            for i in 0..LANES {
                let scalar = slab(o[i], inv[i]);
                for c in 0..3 {
                    // Bit for bit, except NaN's sign and payload.
                    let (w, s) = (wide[c][i], scalar[c]);
                    assert!(
                        w.to_bits() == s.to_bits() || w.is_nan() && s.is_nan(),
                        "{o:?} {inv:?}"
                    );
                }
            }
        }
    }

    /// The sorting network sorts every 0–1 input (so, by the 0–1 principle, every input)
    /// and random keys with ties, as `sort` does.
    #[test]
    fn the_network_sorts_eight_keys_descending() {
        let check = |keys: [u32; WIDTH]| {
            let mut want = keys;
            want.sort_unstable_by(|a, b| b.cmp(a));
            assert_eq!(
                sort8_descending(u32x8::from(keys)).to_array(),
                want,
                "{keys:?}"
            );
        };
        for bits in 0..=255u32 {
            check(core::array::from_fn(|i| bits >> i & 1));
        }
        let mut rng = crate::testing::Pcg32::new(7, 1);
        for _ in 0..10_000 {
            let range = [4, 1 << 16, u32::MAX][rng.next_u32() as usize % 3];
            check(core::array::from_fn(|_| rng.next_u32() % range));
        }
    }

    #[test]
    fn permute_takes_each_lanes_index() {
        let v = u32x8::from([10, 11, 12, 13, 14, 15, 16, 17]);
        let idx = [7, 0, 3, 3, 9, 1, 6, 2];
        let want = idx.map(|i| 10 + (i & 7));
        assert_eq!(permute(v, u32x8::from(idx)).to_array(), want);
    }

    #[test]
    fn the_deepest_binary_chain_collapses_within_the_wide_depth() {
        let (nodes, tris) = chain(super::super::MAX_DEPTH + 1);
        let binary = BvhRef::new(&nodes, &tris).unwrap();
        let wide = collapse(&binary);
        let rows = leaf_rows(&wide, &tris);
        let view = WideRef::new(&wide, &rows).expect("valid wide layout");
        assert!(wide.len() <= WIDE_MAX_DEPTH + 1, "{} nodes", wide.len());
        for i in 0..tris.len() {
            let r = Ray::new(
                Vec3::new(i as f32 + 0.1, 0.1, 1.0),
                -Vec3::Z,
                0.0,
                f32::INFINITY,
            );
            assert_eq!(intersect1(&view, &r).map(|h| h.prim), Some(i as u32));
            assert_eq!(intersect1(&view, &r), intersect1(&binary, &r));
            assert!(occluded1(&view, &r));
        }
    }

    /// A random binary tree of `leaves` one-triangle leaves, each slot's box the union of
    /// its subtree's (as a builder's are): split at a random point, boxes at random.
    fn random_tree(rng: &mut Pcg32, leaves: usize) -> (Vec<Node>, Vec<Tri>) {
        fn grow(
            rng: &mut Pcg32,
            leaves: usize,
            nodes: &mut Vec<Node>,
            tris: &mut Vec<Tri>,
        ) -> (Vec3, Vec3, u32, u32) {
            if leaves == 1 {
                let at = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0;
                let size = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0;
                let id = tris.len() as u32;
                tris.push(Tri::new([at, at + size * Vec3::X, at + size], id));
                return (at, at + size, id, LEAF | 1);
            }
            let index = nodes.len();
            nodes.push(Node::EMPTY);
            let left = 1 + (rng.next_u32() as usize) % (leaves - 1);
            let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            for (slot, n) in [(0, left), (1, leaves - left)] {
                let (l, h, child, meta) = grow(rng, n, nodes, tris);
                nodes[index].set_box(slot, l, h);
                nodes[index].child[slot] = child;
                nodes[index].meta[slot] = meta;
                (lo, hi) = (lo.min(l), hi.max(h));
            }
            (lo, hi, index as u32, 0)
        }
        let (mut nodes, mut tris) = (Vec::new(), Vec::new());
        grow(rng, leaves, &mut nodes, &mut tris);
        (nodes, tris)
    }

    /// Every way binary node `n` can be laid out as a wide node's slots, by exhaustion: the
    /// (slots, cost) pairs of its subtree with `n` opened (and, if `open_children`, its inner
    /// children too), each inner slot kept costing its own best wide node.
    fn layouts(nodes: &[Node], n: u32, open_children: bool) -> Vec<(usize, f64)> {
        let of_slot = |s: usize| -> Vec<(usize, f64)> {
            let child = nodes[n as usize].child[s];
            if nodes[n as usize].meta[s] != 0 {
                return std::vec![(1, 0.0)];
            }
            let mut v = layouts(nodes, child, false);
            if !open_children {
                v.push((1, best_wide(nodes, child)));
            }
            v
        };
        let (l, r) = (of_slot(0), of_slot(1));
        let mut v = Vec::new();
        for &(a, ca) in &l {
            for &(b, cb) in r.iter().filter(|(b, _)| a + b <= WIDTH) {
                v.push((a + b, ca + cb));
            }
        }
        v
    }

    /// The least sum of wide node half areas of `n`'s subtree with `n` a wide node, by
    /// exhaustion.
    fn best_wide(nodes: &[Node], n: u32) -> f64 {
        let content = layouts(nodes, n, true)
            .into_iter()
            .map(|(_, c)| c)
            .fold(f64::INFINITY, f64::min);
        let node = &nodes[n as usize];
        let slot_box = |s: usize| {
            (
                [0, 1, 2].map(|a| node.lo[a][s]),
                [0, 1, 2].map(|a| node.hi[a][s]),
            )
        };
        half_area((0..2).filter(|&s| node.meta[s] != LEAF).map(slot_box)) + content
    }

    #[test]
    fn the_collapse_has_the_least_surface_area_cost() {
        let mut rng = Pcg32::new(17, 5);
        for case in 0..60 {
            let (nodes, tris) = random_tree(&mut rng, 2 + case % 23);
            let binary = BvhRef::new(&nodes, &tris).unwrap();
            let wide = collapse(&binary);
            let rows = leaf_rows(&wide, &tris);
            WideRef::new(&wide, &rows).expect("valid wide layout");
            // The wide tree's cost: its nodes' half areas (each the box of its slots, the
            // binary node it was built from).
            let cost: f64 = wide
                .iter()
                .map(|w| {
                    half_area(
                        (0..WIDTH)
                            .filter(|&s| w.meta[s] != LEAF)
                            .map(|s| w.slot_box(s)),
                    )
                })
                .sum();
            let least = best_wide(&nodes, 0);
            assert!(
                (cost - least).abs() <= 1e-5 * least,
                "case {case}: {cost} against the least {least}"
            );
        }
    }

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
