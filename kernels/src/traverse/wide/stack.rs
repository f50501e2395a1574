//! What both wide walks push and pop: [`Stack8`], a node's slots with their entry distances
//! sorted nearest first by a sorting network ([`sort8_descending`], [`sorted_rows`]), the
//! uninitialised [`Stack`] of the interleaved walk, and [`prefetch_entry`], which asks for a
//! pushed node's cache lines before it is popped.

use crate::traverse::triangle::ROWS;
use core::mem::MaybeUninit;
use wide::{f32x8, u32x8};

use super::*;

/// A walk's stack of [`STACK`] entries, left uninitialised: zeroing the 3.7–7.4 KB per ray
/// was a fifth of the wide single-ray walk's time on the Veach room (libc `memset`). (Built
/// from an associated `const` holding `len: 0` beside the uninitialised array, it was copied
/// from a constant instead: the single-ray walk lost 40 %.)
pub(super) struct Stack<T: Copy> {
    items: [MaybeUninit<T>; STACK],
    len: usize,
}

impl<T: Copy> Stack<T> {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            items: [const { MaybeUninit::uninit() }; STACK],
            len: 0,
        }
    }

    /// Pushes `v` (a walk never exceeds [`STACK`]; indexing checks it anyway).
    #[inline(always)]
    pub(super) fn push(&mut self, v: T) {
        self.items[self.len].write(v);
        self.len += 1;
    }

    #[inline(always)]
    pub(super) fn pop(&mut self) -> Option<T> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: `push` wrote every entry below the previous `len`, and `len` only grows
        // through `push`.
        Some(unsafe { self.items[self.len].assume_init() })
    }
}

/// The slot numbers, lane by lane.
pub(super) const SLOTS: u32x8 = u32x8::new([0, 1, 2, 3, 4, 5, 6, 7]);

/// The slot rows `rows` permuted so that the slots of `hit` come first, farthest first by
/// their entry distances `near`. Keys `near bits & !7 | slot` of the slots met (entry
/// distances are ≥ 0, so their bits order like the values; the order only steers the walk),
/// 0 elsewhere, sorted descending ([`sort8_descending`]): with `n` slots met, entry `n − 1`
/// is the nearest (a key 0 met, slot 0 at distance 0, sorts among the zeros and is still
/// entry `n − 1`).
#[inline(always)]
pub(super) fn sorted_rows(near: f32x8, hit: u32x8, rows: [u32x8; 4]) -> [u32x8; 4] {
    let keys = (bytemuck::cast::<f32x8, u32x8>(near) & u32x8::splat(!7) | SLOTS) & hit;
    let order = sort8_descending(keys) & u32x8::splat(7);
    rows.map(|row| permute(row, order))
}

/// `v[idx[i] & 7]` in each lane `i` (`vpermd`).
#[inline(always)]
pub(super) fn permute(v: u32x8, idx: u32x8) -> u32x8 {
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
pub(super) const NETWORK_PAIRS: [&[(usize, usize)]; 6] = [
    &[(0, 2), (1, 3), (4, 6), (5, 7)],
    &[(0, 4), (1, 5), (2, 6), (3, 7)],
    &[(0, 1), (2, 3), (4, 5), (6, 7)],
    &[(2, 4), (3, 5)],
    &[(1, 4), (3, 6)],
    &[(1, 2), (3, 4), (5, 6)],
];

/// [`NETWORK_PAIRS`] as lanes: per layer, each lane's partner (itself where it has none) and
/// a mask of the lanes that are the lower of their pair.
pub(super) const NETWORK: [([u32; WIDTH], [u32; WIDTH]); 6] = {
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
pub(super) fn sort8_descending(mut keys: u32x8) -> u32x8 {
    for (partner, lower) in NETWORK {
        let other = permute(keys, u32x8::from(partner));
        keys = u32x8::from(lower).select(keys.max(other), keys.min(other));
    }
    keys
}

/// An entry of [`Stack8`]: the slot's child and meta, the (nearest) entry distance into its
/// box, and the lanes that met it (packets; 0 for a single ray).
#[derive(Clone, Copy)]
pub(super) struct Entry8 {
    pub(super) child: u32,
    pub(super) meta: u32,
    pub(super) dist: f32,
    pub(super) lanes: u8,
}

impl Entry8 {
    /// `child | meta << 32`.
    pub(super) fn entry(self) -> u64 {
        u64::from(self.child) | u64::from(self.meta) << 32
    }
}

/// The closest-hit walks' stack as four rows (child, meta, entry distance bits, lanes met),
/// so that a node's sorted slots are pushed with four 8-wide stores
/// ([`Stack8::push_sorted`]). Left uninitialised, as [`Stack`].
pub(super) struct Stack8 {
    rows: [[MaybeUninit<u32>; STACK + WIDTH]; 4],
    len: usize,
}

impl Stack8 {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            rows: [[const { MaybeUninit::uninit() }; STACK + WIDTH]; 4],
            len: 0,
        }
    }

    /// Writes the eight entries `rows`, sorted farthest first, at the top and pushes the
    /// first `n − 1` of them (`n ≥ 1`). Returns entry `n − 1`, the nearest (visited next),
    /// and the nearest entry pushed (entry `n − 1` again when none is).
    #[inline(always)]
    pub(super) fn push_sorted(&mut self, rows: [u32x8; 4], n: usize) -> (Entry8, Entry8) {
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
    pub(super) fn pop(&mut self) -> Option<Entry8> {
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

/// Asks the cache for the 256 bytes of the node, or the first rows of the leaf, of the entry
/// `child | meta << 32`. The address is chosen without a branch: branching on the kind of entry
/// mispredicted a third of the time in the packet walk (docs/traverse.md, "What each kept change
/// bought").
#[inline(always)]
pub(super) fn prefetch_entry(bvh: &WideRef<'_>, e: u64) {
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
