//! [`collapse`]: a wide tree from a binary [`BvhRef`], each wide node chosen by the least
//! surface area cost (dynamic programming over [`SlotCosts`]; Ylitie, Karras & Laine 2017,
//! §3.1, with the binary tree's leaves kept), every wide node opening its binary node's
//! inner children so the depth stays within [`WIDE_MAX_DEPTH`].

use super::*;
#[cfg(any(feature = "alloc", test))]
use crate::traverse::BvhRef;
use crate::traverse::LEAF;

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
pub(super) struct BinSlot {
    lo: [f32; 3],
    hi: [f32; 3],
    child: u32,
    meta: u32,
}

/// Least costs per slot count, `[k − 1]` for at most `k` slots (`k = 1 ..= WIDTH`).
#[cfg(any(feature = "alloc", test))]
pub(super) type Costs = [f32; WIDTH];

/// The surface area costs of a binary tree's subtrees laid out as wide slots ([`collapse`]):
/// per inner binary node `n`, `F(n, k)`, the least sum of wide node areas (relative to the
/// root's, so the sums stay finite) that covers `n`'s subtree with at most `k` slots — `n`
/// itself as one wide node (its area plus its content's, [`SlotCosts::content`]), or `n`
/// opened and its two children's subtrees covered by `k` slots between them.
#[cfg(any(feature = "alloc", test))]
pub(super) struct SlotCosts<'b> {
    nodes: &'b [crate::traverse::BinaryNode],
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
pub(super) fn best_split(l: &[f32; WIDTH + 1], r: &[f32; WIDTH + 1], k: usize) -> (f32, usize) {
    first_least((0..=k).map(|i| (l[i] + r[k - i], i)))
}

/// The least cost of `(cost, choice)` pairs and its choice, the first where several tie
/// (+∞ and 0 for none).
#[cfg(any(feature = "alloc", test))]
pub(super) fn first_least(choices: impl Iterator<Item = (f32, usize)>) -> (f32, usize) {
    choices.fold((f32::INFINITY, 0), |b, c| if c.0 < b.0 { c } else { b })
}

/// Half the surface area of the union of `boxes` (`lo`, `hi`), in `f64` (finite for finite
/// boxes; 0 for none).
#[cfg(any(feature = "alloc", test))]
pub(super) fn half_area(boxes: impl Iterator<Item = ([f32; 3], [f32; 3])>) -> f64 {
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

#[cfg(test)]
mod tests {

    use super::*;
    use crate::packet::Ray;
    use crate::testing::Pcg32;
    use crate::traverse::Tri;
    use crate::traverse::{BinaryNode, intersect1, occluded1};
    use glam::Vec3;
    use std::vec::Vec;

    /// A binary chain as deep as [`crate::traverse::BVH_MAX_DEPTH`] allows: every node a leaf of one
    /// triangle beside the next node.
    fn chain(depth: usize) -> (Vec<BinaryNode>, Vec<Tri>) {
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
        let mut nodes: Vec<BinaryNode> = (0..depth as u32)
            .map(|i| {
                let mut n = BinaryNode::EMPTY;
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

    #[test]
    fn the_deepest_binary_chain_collapses_within_the_wide_depth() {
        let (nodes, tris) = chain(crate::traverse::BVH_MAX_DEPTH + 1);
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
    fn random_tree(rng: &mut Pcg32, leaves: usize) -> (Vec<BinaryNode>, Vec<Tri>) {
        fn grow(
            rng: &mut Pcg32,
            leaves: usize,
            nodes: &mut Vec<BinaryNode>,
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
            nodes.push(BinaryNode::EMPTY);
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
    fn layouts(nodes: &[BinaryNode], n: u32, open_children: bool) -> Vec<(usize, f64)> {
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
    fn best_wide(nodes: &[BinaryNode], n: u32) -> f64 {
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
}
