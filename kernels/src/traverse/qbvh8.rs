//! # traverse::qbvh8: the wide layout with quantised child boxes
//!
//! [`QuantNode`] holds a wide node's eight child boxes on a per-node grid, as Ylitie, Karras
//! & Laine, *Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs* (HPG
//! 2017, §3.1) and Embree's `QBVH8` do: per axis an `f32` origin and a power-of-two scale,
//! per child an 8-bit lower and upper grid coordinate, rounded outward so that the decoded
//! box holds the exact one. One node is two cache lines (128 bytes) where [`WideNode`] takes
//! four.
//!
//! The walks decode a node's planes to `f32x8` (one multiply-add per plane, exact: the grid
//! step times an 8-bit integer is exact, so fused or not the result rounds once) and run the
//! slab test of the `f32` layout on them; the leaves are unchanged. The decoded boxes contain
//! the exact ones, so the slab test lets a ray meet every box it met before (and a few more)
//! and the walks' results equal brute force bit for bit where every hit lies inside its
//! leaf's box (module docs of [`super`], "Hits outside their own box").

use super::LEAF;
use super::bvh8::{WIDTH, WideBoxes, WideNode};
use bytemuck::{Pod, Zeroable};
use wide::f32x8;

/// One wide node with quantised child boxes, two 64-byte cache lines.
///
/// Slot `c`'s box along `axis` decodes to `origin[axis] + q · 2^(scale[axis] − 127)` for
/// `q = lo[axis][c]` and `hi[axis][c]`; slots `0..used` are used (child and meta as in
/// [`WideNode`]), the others empty (`meta == LEAF`).
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C, align(64))]
pub struct QuantNode {
    /// Grid origin per axis: the node's box minimum.
    pub origin: [f32; 3],
    /// Biased exponent of each axis's grid step (the bits of the `f32` `2^(e − 127)`).
    pub scale: [u8; 3],
    /// Slots in use, the first `used`.
    pub used: u8,
    /// Box minima in grid steps, `lo[axis][child]`, rounded down.
    pub lo: [[u8; WIDTH]; 3],
    /// Box maxima in grid steps, `hi[axis][child]`, rounded up.
    pub hi: [[u8; WIDTH]; 3],
    /// Node index (inner child) or first triangle (leaf child).
    pub child: [u32; WIDTH],
    /// `0` for an inner child, `LEAF | count` for a leaf.
    pub meta: [u32; WIDTH],
}

const _: () = assert!(core::mem::size_of::<QuantNode>() == 128);

/// Largest grid exponent the builder uses: `255 · 2^119` is finite, so the decoding
/// multiply is exact and fused or not gives the same plane.
const MAX_EXP: i32 = 119;

impl QuantNode {
    /// The grid step of `axis`.
    #[inline(always)]
    fn step(&self, axis: usize) -> f32 {
        f32::from_bits(u32::from(self.scale[axis]) << 23)
    }

    /// The quantised form of `node`: every used slot's decoded box holds its box (for boxes
    /// within ±2¹²⁵, whose extents the grid covers).
    pub fn from_wide(node: &WideNode) -> Self {
        let used = node.meta.iter().take_while(|&&m| m != LEAF).count();
        let mut q = Self {
            origin: [0.0; 3],
            scale: [127; 3],
            used: used as u8,
            lo: [[0; WIDTH]; 3],
            hi: [[0; WIDTH]; 3],
            child: node.child,
            meta: node.meta,
        };
        for axis in 0..3 {
            let lo = node.lo[axis][..used]
                .iter()
                .copied()
                .fold(f32::INFINITY, f32::min);
            let hi = node.hi[axis][..used]
                .iter()
                .copied()
                .fold(f32::NEG_INFINITY, f32::max);
            if used == 0 {
                continue;
            }
            let (step, biased) = grid(lo, hi);
            q.origin[axis] = lo;
            q.scale[axis] = biased;
            for slot in 0..used {
                q.lo[axis][slot] = round_down(node.lo[axis][slot], lo, step);
                q.hi[axis][slot] = round_up(node.hi[axis][slot], lo, step);
            }
        }
        q
    }
}

impl QuantNode {
    /// The node with its decoded boxes as `f32` planes (measurement only: the looser boxes
    /// without the decoding).
    pub fn decoded(&self) -> WideNode {
        let (lo, hi) = self.planes();
        let mut node = WideNode::EMPTY;
        for slot in 0..self.used as usize {
            let lo = [0, 1, 2].map(|a| lo[a].to_array()[slot]);
            let hi = [0, 1, 2].map(|a| hi[a].to_array()[slot]);
            node.set_slot(slot, lo, hi, self.child[slot], self.meta[slot]);
        }
        node
    }
}

/// The plane of grid coordinate `q` (as the walks decode it).
#[inline(always)]
fn decode(q: u8, origin: f32, step: f32) -> f32 {
    // `q · step` is exact (8 bits times a power of two in range): one rounding, as fused.
    f32::from(q) * step + origin
}

/// The finest grid step (a power of two, biased exponent beside it) whose 255th plane from
/// `lo` reaches `hi`.
fn grid(lo: f32, hi: f32) -> (f32, u8) {
    let extent = hi - lo;
    let exp = if extent > 0.0 {
        ((extent.to_bits() >> 23) as i32 - 127 - 8).max(-126)
    } else {
        -126
    };
    let mut e = exp.min(MAX_EXP);
    loop {
        let step = f32::from_bits(((e + 127) as u32) << 23);
        if decode(255, lo, step) >= hi || e == MAX_EXP {
            return (step, (e + 127) as u8);
        }
        e += 1;
    }
}

/// The largest grid coordinate whose plane is at most `x`.
fn round_down(x: f32, origin: f32, step: f32) -> u8 {
    let mut q = ((x - origin) / step).clamp(0.0, 255.0) as u8;
    while q > 0 && decode(q, origin, step) > x {
        q -= 1;
    }
    while q < 255 && decode(q + 1, origin, step) <= x {
        q += 1;
    }
    q
}

/// The smallest grid coordinate whose plane is at least `x` (255 if none is).
fn round_up(x: f32, origin: f32, step: f32) -> u8 {
    let mut q = ((x - origin) / step).clamp(0.0, 255.0) as u8;
    while q < 255 && decode(q, origin, step) < x {
        q += 1;
    }
    while q > 0 && decode(q - 1, origin, step) >= x {
        q -= 1;
    }
    q
}

/// Eight grid coordinates as `f32`s (one `vpmovzxbd` and one `vcvtdq2ps` with AVX2).
#[inline(always)]
fn widen(q: &[u8; WIDTH]) -> f32x8 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use core::arch::x86_64::{_mm_loadl_epi64, _mm256_cvtepi32_ps, _mm256_cvtepu8_epi32};
        // SAFETY: AVX2 is enabled at compile time; the load reads the eight bytes of `q`
        // (`_mm_loadl_epi64` has no alignment requirement).
        let v =
            unsafe { _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(q.as_ptr().cast()))) };
        bytemuck::cast(v)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        f32x8::from_i32x8(wide::i32x8::new(q.map(i32::from)))
    }
}

impl WideBoxes for QuantNode {
    const LINES: usize = 2;

    #[inline(always)]
    fn planes(&self) -> ([f32x8; 3], [f32x8; 3]) {
        let decode = |q: &[[u8; WIDTH]; 3]| {
            [0, 1, 2].map(|a| {
                widen(&q[a]).mul_add(f32x8::splat(self.step(a)), f32x8::splat(self.origin[a]))
            })
        };
        (decode(&self.lo), decode(&self.hi))
    }

    #[inline(always)]
    fn slots(&self) -> u8 {
        (0xffu32 >> (8 - u32::from(self.used).min(8))) as u8
    }

    #[inline(always)]
    fn child(&self) -> &[u32; WIDTH] {
        &self.child
    }

    #[inline(always)]
    fn meta(&self) -> &[u32; WIDTH] {
        &self.meta
    }
}

/// The quantised form of a wide tree ([`QuantNode::from_wide`] node by node; same children,
/// same leaves).
#[cfg(any(feature = "alloc", test))]
pub fn quantise(nodes: &[WideNode]) -> alloc::vec::Vec<QuantNode> {
    extern crate alloc;
    nodes.iter().map(QuantNode::from_wide).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;

    /// Every decoded box holds its exact box, at every magnitude the soup allows, and is
    /// tight: one grid step shrinks it past the exact box.
    #[test]
    fn decoded_boxes_hold_the_exact_boxes() {
        let mut rng = Pcg32::new(3, 16);
        for trial in 0..4000 {
            let magnitude = [1e-30f32, 1e-3, 1.0, 1e6, 1e30, 4e37][trial % 6];
            let centre = (rng.next_f32() - 0.5) * magnitude;
            let size = magnitude * [1.0, 1e-3, 1e-7, 0.0][trial / 6 % 4];
            let mut node = WideNode::EMPTY;
            let used = 1 + trial % WIDTH;
            for slot in 0..used {
                let lo = [0; 3].map(|_| centre + rng.next_f32() * size);
                let hi = lo.map(|l| l + rng.next_f32() * size * 0.5);
                node.set_slot(slot, lo, hi, slot as u32, LEAF | 1);
            }
            let q = QuantNode::from_wide(&node);
            assert_eq!(q.slots().count_ones() as usize, used);
            let (lo, hi) = q.planes();
            for axis in 0..3 {
                let (dlo, dhi) = (lo[axis].to_array(), hi[axis].to_array());
                for slot in 0..used {
                    let (elo, ehi) = (node.lo[axis][slot], node.hi[axis][slot]);
                    assert!(dlo[slot] <= elo && dhi[slot] >= ehi, "{node:?} {q:?}");
                    let (o, s) = (q.origin[axis], q.step(axis));
                    let (ql, qh) = (q.lo[axis][slot], q.hi[axis][slot]);
                    assert!(ql == 255 || decode(ql + 1, o, s) > elo);
                    assert!(qh == 0 || decode(qh - 1, o, s) < ehi);
                    assert_eq!(dlo[slot].to_bits(), decode(ql, o, s).to_bits());
                    assert_eq!(dhi[slot].to_bits(), decode(qh, o, s).to_bits());
                }
            }
        }
    }
}
