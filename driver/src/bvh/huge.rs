//! # bvh::huge: the BVH's arrays on transparent huge pages
//!
//! A big world's traversal reads nodes and leaves scattered over tens of megabytes: with 4 KiB
//! pages nearly every node visit misses the TLB, and in a virtual machine each miss is a
//! two-level page walk. Embree allocates its BVH with `madvise(MADV_HUGEPAGE)` for this
//! reason (`os_malloc`); so do we. On Linux systems whose transparent huge pages are set to
//! `madvise` (the common default) only memory so advised gets 2 MiB pages.
//!
//! Measured on the 1M-triangle city (docs/traverse.md, "What each kept change bought"): gather
//! packets 7 % and shadow rays 16 % faster with huge pages.

use std::fmt;
use std::marker::PhantomData;
use std::ops::Deref;

use bytemuck::Pod;
use memmap2::MmapMut;

/// A huge page: the alignment and the size below which an array stays on the heap.
const HUGE: usize = 2 << 20;

/// An immutable array in anonymous memory advised for huge pages (arrays of at least
/// [`HUGE`] bytes, where the system allows it), else on the heap.
pub(super) struct HugeSlice<T: Pod> {
    store: Store<T>,
}

enum Store<T: Pod> {
    Heap(Vec<T>),
    /// `len` values at byte `offset` of `map` (a multiple of [`HUGE`] from the map's
    /// page-aligned start, so the values start on a huge page).
    Mapped {
        map: MmapMut,
        offset: usize,
        len: usize,
        _values: PhantomData<T>,
    },
}

impl<T: Pod> HugeSlice<T> {
    /// `values` moved to huge pages when they are big enough and the system lets us map and
    /// advise memory; otherwise kept as they are (the advice is only a hint: any failure
    /// leaves the heap copy, which traces the same).
    pub(super) fn new(values: Vec<T>) -> Self {
        let bytes = std::mem::size_of_val(values.as_slice());
        if bytes < HUGE {
            return Self::heap(values);
        }
        match Self::mapped(&values, bytes) {
            Some(store) => Self { store },
            None => Self::heap(values),
        }
    }

    /// `len` values written by `fill` (given them zeroed) straight where they stay: on huge
    /// pages when big enough, so the array is never held twice.
    pub(super) fn filled(len: usize, fill: impl FnOnce(&mut [T])) -> Self {
        let bytes = len * std::mem::size_of::<T>();
        if bytes >= HUGE
            && let Some(mut map) = Self::map(bytes)
        {
            let offset = Self::offset(&map);
            fill(bytemuck::cast_slice_mut(&mut map[offset..offset + bytes]));
            return Self {
                store: Store::Mapped {
                    map,
                    offset,
                    len,
                    _values: PhantomData,
                },
            };
        }
        let mut values = vec![T::zeroed(); len];
        fill(&mut values);
        Self::heap(values)
    }

    /// An anonymous (zeroed) map of `bytes` and a huge page more, advised for huge pages from
    /// its first huge page boundary ([`HugeSlice::offset`]) on.
    fn map(bytes: usize) -> Option<MmapMut> {
        let map = memmap2::MmapOptions::new()
            .len(bytes.checked_add(HUGE)?)
            .map_anon()
            .ok()?;
        #[cfg(target_os = "linux")]
        {
            // Advised before the first write, so the pages are faulted in huge.
            let _ = map.advise_range(memmap2::Advice::HugePage, Self::offset(&map), bytes);
        }
        Some(map)
    }

    /// Where in `map` its first huge page starts.
    fn offset(map: &MmapMut) -> usize {
        (map.as_ptr() as usize).next_multiple_of(HUGE) - map.as_ptr() as usize
    }

    fn heap(values: Vec<T>) -> Self {
        Self {
            store: Store::Heap(values),
        }
    }

    fn mapped(values: &[T], bytes: usize) -> Option<Store<T>> {
        let mut map = Self::map(bytes)?;
        let offset = Self::offset(&map);
        map[offset..offset + bytes].copy_from_slice(bytemuck::cast_slice(values));
        Some(Store::Mapped {
            map,
            offset,
            len: values.len(),
            _values: PhantomData,
        })
    }

    /// Whether the values live in mapped memory advised for huge pages.
    pub(super) fn is_mapped(&self) -> bool {
        matches!(self.store, Store::Mapped { .. })
    }
}

impl<T: Pod> Deref for HugeSlice<T> {
    type Target = [T];

    fn deref(&self) -> &[T] {
        match &self.store {
            Store::Heap(v) => v,
            Store::Mapped {
                map, offset, len, ..
            } => {
                // The map is page-aligned and `offset` a multiple of 2 MiB: aligned for any
                // `T` of alignment up to a page.
                bytemuck::cast_slice(&map[*offset..*offset + len * std::mem::size_of::<T>()])
            }
        }
    }
}

impl<T: Pod> Clone for HugeSlice<T> {
    fn clone(&self) -> Self {
        Self::new(self.to_vec())
    }
}

impl<T: Pod> fmt::Debug for HugeSlice<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HugeSlice")
            .field("len", &self.len())
            .field("mapped", &self.is_mapped())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_arrays_stay_on_the_heap_and_big_ones_are_mapped_unchanged() {
        let small: Vec<u32> = (0..1000).collect();
        let s = HugeSlice::new(small.clone());
        assert!(!s.is_mapped());
        assert_eq!(&*s, &small[..]);
        let big: Vec<[f32; 16]> = (0..40_000).map(|i| [i as f32; 16]).collect();
        let b = HugeSlice::new(big.clone());
        assert!(
            b.is_mapped(),
            "2.6 MB of anonymous memory could not be mapped"
        );
        assert_eq!(&*b, &big[..]);
        assert_eq!(b.as_ptr() as usize % HUGE, 0, "starts on a huge page");
        let c = b.clone();
        assert_eq!(&*c, &big[..]);
        assert!(format!("{c:?}").contains("40000"));
    }
}
