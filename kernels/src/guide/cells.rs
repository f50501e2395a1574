//! The quadtree cells of the guide's records and the in-place radix sort that orders them
//! for [`super::build`].
//!
//! A record's **cell** at depth [`MAX_DEPTH`] is `⌊u · 2¹⁶⌋` per axis, exact in f32 (a power
//! of two scale of `u ∈ [0,1)`), and its quadrant at every depth `d < MAX_DEPTH` is bit
//! `15 − d` of each axis — the same answer as the comparison `u < origin + size/2` against
//! the node's (exact, dyadic) midpoint. Sorted by the Morton order of these cells, the
//! records of every quadtree node are one contiguous range and its four children's ranges
//! follow each other in the quadrant order of [`super::GuideNode`] (x low bit, y high bit).
//!
//! [`sort`] is an MSD radix sort on windows of up to four levels (256 buckets), so a record
//! moves once per four levels instead of being partitioned twice per level: a counting sort
//! through scratch memory (the caller's node storage, free before the tree is written), or
//! without room for it an in-place American flag sort. It recurses only into cells that the
//! split rule may split (at least [`super::GuideParams::min_records`] records, above the
//! depth cap): the order inside a cell that never splits does not matter. Nothing
//! allocates; a window spans at least two levels, so the recursion is at most eight
//! windows deep (~5 KB of stack each).

use super::{MAX_DEPTH, Record};

/// A record's cell at depth [`MAX_DEPTH`], per axis. The caller guarantees `u ∈ [0,1)²`.
#[inline(always)]
pub(super) fn cell(r: &Record) -> [u32; 2] {
    const SCALE: f32 = (1u32 << MAX_DEPTH) as f32;
    [(r.u[0] * SCALE) as u32, (r.u[1] * SCALE) as u32]
}

/// The quadrant (`right + 2·upper`) a record takes in its node of depth `depth`
/// (`depth < MAX_DEPTH`).
#[inline(always)]
pub(super) fn quadrant(r: &Record, depth: u32) -> usize {
    let s = MAX_DEPTH - 1 - depth;
    let c = cell(r);
    ((c[0] >> s) & 1 | ((c[1] >> s) & 1) << 1) as usize
}

/// The Morton key of a cell (y bits odd, x bits even: the quadrant order at every level).
#[inline(always)]
fn morton(c: [u32; 2]) -> u32 {
    let spread = |v: u32| {
        let v = (v | v << 8) & 0x00ff_00ff;
        let v = (v | v << 4) & 0x0f0f_0f0f;
        let v = (v | v << 2) & 0x3333_3333;
        (v | v << 1) & 0x5555_5555
    };
    spread(c[0]) | spread(c[1]) << 1
}

/// The bits of a 4-bit value spread to the even bits of a byte (a window's Morton digit).
const SPREAD: [u8; 16] = {
    let mut t = [0u8; 16];
    let mut v = 0;
    while v < 16 {
        t[v] = (v & 1 | (v & 2) << 1 | (v & 4) << 2 | (v & 8) << 3) as u8;
        v += 1;
    }
    t
};

/// Ranges up to this length are insertion-sorted by their full keys.
const SMALL: usize = 64;

/// Levels of a radix window for a range of `len` (> [`SMALL`]) records: about one bucket
/// per four records, two to four levels (16 to 256 buckets).
fn window(len: usize) -> u32 {
    match len {
        0..256 => 2,
        256..1024 => 3,
        _ => 4,
    }
}

/// Sorts `records`, all in one cell of depth `depth`, into the Morton order of their cells
/// as deep as the split rule can need: down to `max_depth`, and into a cell only if it holds
/// at least two and at least `min_records` records. `scratch` and `digits` (any contents)
/// are where a window's records are scattered and their bucket noted when both are as long
/// as `records`; shorter (the caller had no room), the window permutes them in place,
/// several times slower.
pub(super) fn sort(
    records: &mut [Record],
    scratch: &mut [Record],
    digits: &mut [u8],
    depth: u32,
    max_depth: u32,
    min_records: u32,
) {
    let len = records.len();
    if len < 2 || (len as u64) < u64::from(min_records) || depth >= max_depth {
        return;
    }
    if len <= SMALL {
        insertion_sort(records);
        return;
    }
    let levels = window(len).min(max_depth - depth);
    let shift = MAX_DEPTH - depth - levels;
    let mask = (1u32 << levels) - 1;
    let digit = |r: &Record| {
        let [x, y] = cell(r).map(|c| usize::from(SPREAD[((c >> shift) & mask) as usize]));
        x | y << 1
    };
    let buckets = 1usize << (2 * levels);
    let room = scratch.len() >= len && digits.len() >= len;
    // Each stream's bucket counts, turned into its first slot in each bucket.
    let mut next = if room {
        histogram(records, &mut digits[..len], &digit)
    } else {
        histogram(records, &mut [], &digit)
    };
    let mut start = [0u32; 257];
    for b in 0..buckets {
        let mut at = start[b];
        for next in next.iter_mut() {
            (next[b], at) = (at, at + next[b]);
        }
        start[b + 1] = at;
    }
    if room {
        scatter(records, &mut scratch[..len], &digits[..len], next);
    } else {
        permute(records, start, buckets, digit);
    }
    for b in 0..buckets {
        let range = start[b] as usize..start[b + 1] as usize;
        let scratch = scratch.get_mut(range.clone()).unwrap_or_default();
        let digits = digits.get_mut(range.clone()).unwrap_or_default();
        let next = depth + levels;
        sort(
            &mut records[range],
            scratch,
            digits,
            next,
            max_depth,
            min_records,
        );
    }
}

/// The counting sort's passes read the records as [`STREAMS`] consecutive parts,
/// interleaved: a run of records in one bucket is then four short chains of counter
/// updates (each a store the next load waits for), not one long one.
const STREAMS: usize = 4;

/// The parts of `len` items for [`STREAMS`]: three of `len / 4` and the rest, as ranges.
fn streams(len: usize) -> [core::ops::Range<usize>; STREAMS] {
    let q = len / STREAMS;
    [0..q, q..2 * q, 2 * q..3 * q, 3 * q..len]
}

/// Each stream's bucket counts; each record's bucket is noted in `digits` when it is as
/// long as `records`.
fn histogram(
    records: &[Record],
    digits: &mut [u8],
    digit: &impl Fn(&Record) -> usize,
) -> [[u32; 256]; STREAMS] {
    let mut counts = [[0u32; 256]; STREAMS];
    let parts = streams(records.len());
    let q = parts[0].len();
    let note = digits.len() == records.len();
    let mut count = |s: usize, i: usize, counts: &mut [[u32; 256]; STREAMS]| {
        let d = digit(&records[i]);
        counts[s][d] += 1;
        if note {
            digits[i] = d as u8;
        }
    };
    for i in 0..q {
        for (s, part) in parts.iter().enumerate() {
            count(s, part.start + i, &mut counts);
        }
    }
    for i in parts[STREAMS - 1].start + q..records.len() {
        count(STREAMS - 1, i, &mut counts);
    }
    counts
}

/// Counting sort through `out`: each record is written to its stream's next slot of its
/// bucket there (a stable order), then copied back.
fn scatter(
    records: &mut [Record],
    out: &mut [Record],
    digits: &[u8],
    mut next: [[u32; 256]; STREAMS],
) {
    let parts = streams(records.len());
    let q = parts[0].len();
    let mut put = |s: usize, i: usize| {
        let d = usize::from(digits[i]);
        out[next[s][d] as usize] = records[i];
        next[s][d] += 1;
    };
    for i in 0..q {
        for (s, part) in parts.iter().enumerate() {
            put(s, part.start + i);
        }
    }
    for i in parts[STREAMS - 1].start + q..records.len() {
        put(STREAMS - 1, i);
    }
    records.copy_from_slice(out);
}

/// American flag sort in place: the first unplaced record of each bucket is swapped to
/// where it belongs until a record of that bucket comes back (a chain of dependent loads
/// per record: the fallback when there is no scratch).
fn permute(
    records: &mut [Record],
    start: [u32; 257],
    buckets: usize,
    digit: impl Fn(&Record) -> usize,
) {
    let mut next = start;
    for b in 0..buckets {
        while next[b] < start[b + 1] {
            let mut r = records[next[b] as usize];
            let mut d = digit(&r);
            while d != b {
                core::mem::swap(&mut r, &mut records[next[d] as usize]);
                next[d] += 1;
                d = digit(&r);
            }
            records[next[b] as usize] = r;
            next[b] += 1;
        }
    }
}

/// Sorts a short range by the full Morton keys of its cells.
fn insertion_sort(records: &mut [Record]) {
    let mut keys = [0u32; SMALL];
    for i in 0..records.len() {
        let (r, k) = (records[i], morton(cell(&records[i])));
        let mut j = i;
        while j > 0 && keys[j - 1] > k {
            keys[j] = keys[j - 1];
            records[j] = records[j - 1];
            j -= 1;
        }
        keys[j] = k;
        records[j] = r;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;

    fn key(r: &Record) -> u32 {
        morton(cell(r))
    }

    #[test]
    fn morton_interleaves_x_low_y_high() {
        for v in 0..16u32 {
            assert_eq!(u32::from(SPREAD[v as usize]), morton([v, 0]));
        }
        assert_eq!(morton([0b11, 0]), 0b0101);
        assert_eq!(morton([0, 0b11]), 0b1010);
        assert_eq!(morton([0xffff, 0xffff]), u32::MAX);
        let r = Record {
            u: [0.75, 0.25],
            flux: 1.0,
        };
        // Right and lower at depth 0; in [0.5, 1) × [0, 0.5) both lie on the midpoints.
        assert_eq!(quadrant(&r, 0), 1);
        assert_eq!(quadrant(&r, 1), 3);
    }

    #[test]
    fn quadrant_matches_the_midpoint_comparison() {
        let mut rng = Pcg32::new(5, 1);
        let below_one = f32::from_bits(1.0f32.to_bits() - 1);
        for k in 0..20_000 {
            let d = k % MAX_DEPTH;
            // Points on, just below and just above dyadic midpoints, and random ones.
            let scale = (1u32 << (d + 1)) as f32;
            let m = (2 * (rng.next_u32() % (1 << d)) + 1) as f32 / scale;
            let pick = |rng: &mut Pcg32, m: f32| match rng.next_u32() % 4 {
                0 => m,
                1 => f32::from_bits(m.to_bits() - 1),
                2 => f32::from_bits(m.to_bits() + 1).min(below_one),
                _ => rng.next_f32(),
            };
            let u = [pick(&mut rng, m), pick(&mut rng, m)];
            let r = Record { u, flux: 1.0 };
            // The node of depth d holding u, and its midpoint.
            let size = 1.0 / (1u32 << d) as f32;
            let o = u.map(|v| (v / size).floor() * size);
            let mid = o.map(|o| o + size * 0.5);
            let want = usize::from(u[0] >= mid[0]) + 2 * usize::from(u[1] >= mid[1]);
            assert_eq!(quadrant(&r, d), want, "{u:?} depth {d}");
        }
    }

    fn sorted_to(records: &[Record], depth: u32) -> bool {
        let prefix = |r: &Record| key(r).checked_shr(2 * (MAX_DEPTH - depth)).unwrap_or(0);
        records.windows(2).all(|w| prefix(&w[0]) <= prefix(&w[1]))
    }

    /// `r` is a permutation of the records numbered `before` (their fluxes), sorted in
    /// every cell the split rule may split, one level below the cell.
    fn check_sorted(r: &[Record], before: &[u32], max_depth: u32, min_records: u32) {
        let n = r.len();
        let mut after: alloc::vec::Vec<u32> = r.iter().map(|r| r.flux as u32).collect();
        after.sort_unstable();
        assert_eq!(before, after.as_slice());
        if min_records <= 1 {
            assert!(sorted_to(r, max_depth), "{n} {max_depth}");
        }
        let check = |lo: usize, hi: usize, d: u32| {
            if d < max_depth && hi - lo >= (min_records as usize).max(2) {
                assert!(sorted_to(&r[lo..hi], d + 1), "{n}: cell at depth {d}");
            }
        };
        let prefix = |r: &Record, d: u32| key(r).checked_shr(2 * (MAX_DEPTH - d)).unwrap_or(0);
        for d in 0..max_depth {
            let mut lo = 0;
            for hi in 1..=n {
                if hi == n || prefix(&r[hi], d) != prefix(&r[lo], d) {
                    check(lo, hi, d);
                    lo = hi;
                }
            }
        }
    }

    #[test]
    fn sort_orders_every_splittable_cell() {
        let mut rng = Pcg32::new(11, 2);
        for (n, max_depth, min_records) in [
            (0, 10, 4),
            (1, 10, 4),
            (31, 16, 1),
            (33, 16, 1),
            (64, 16, 1),
            (65, 16, 1),
            (300, 16, 1),
            (500, 10, 4),
            (5000, 16, 4),
            (5000, 3, 4),
            (5000, 10, 64),
        ] {
            let mut r: alloc::vec::Vec<Record> = (0..n)
                .map(|k| {
                    let u = if k % 3 == 0 {
                        [0.3 + 1e-4 * rng.next_f32(), 0.6 + 1e-4 * rng.next_f32()]
                    } else {
                        [rng.next_f32(), rng.next_f32()]
                    };
                    Record { u, flux: k as f32 }
                })
                .collect();
            let mut before: alloc::vec::Vec<u32> = r.iter().map(|r| r.flux as u32).collect();
            before.sort_unstable();
            // Both ways: scattered through scratch, and permuted in place.
            let mut scratch = r.clone();
            let mut digits = alloc::vec![0u8; n];
            let mut in_place = r.clone();
            sort(&mut r, &mut scratch, &mut digits, 0, max_depth, min_records);
            sort(&mut in_place, &mut [], &mut [], 0, max_depth, min_records);
            for r in [&r, &in_place] {
                check_sorted(r, &before, max_depth, min_records);
            }
        }
    }
}
