//! The guide build by per-level partitioning, kept as the test oracle of [`super::build`] and for the
//! `guide` bench's same-run comparison (feature `testing`; not part of the product): the same
//! breadth-first split rule, but each split partitions its node's records in place, first by
//! x and then each half by y (three passes per split, one data-dependent branch per record
//! and pass). [`super::build`] instead sorts the records once by their Morton cells and finds
//! a node's children as sorted ranges; both give the same tree (see the tests in `guide`).

use super::{BuildStats, Guide, GuideNode, GuideParams, Record};

/// [`super::build`] with the partitioning split (the build before today's).
pub fn build<'a>(
    records: &mut [Record],
    params: &GuideParams,
    storage: &'a mut [GuideNode],
) -> (Guide<'a>, BuildStats) {
    super::build_with(records, params, storage, &mut [], |_, _, _, _| {}, split)
}

/// Splits node `i` into four children at `first`, partitioning its records by quadrant;
/// each child's `mass` is its share of `total_flux`.
fn split(records: &mut [Record], nodes: &mut [GuideNode], i: usize, first: usize, total_flux: f64) {
    let n = nodes[i];
    let ([ox, oy], size) = (n.origin, n.size);
    let h = size * 0.5;
    let (mx, my) = (ox + h, oy + h);
    let range = &mut records[n.first as usize..(n.first + n.count) as usize];
    let nx = partition(range, |r| r.u[0] < mx);
    let (left, right) = range.split_at_mut(nx);
    let nly = partition(left, |r| r.u[1] < my);
    let nry = partition(right, |r| r.u[1] < my);
    let counts = [nly, nry, left.len() - nly, right.len() - nry];
    let starts = [0, nx, nly, nx + nry];
    for q in 0..4 {
        let start = n.first as usize + starts[q];
        let recs = &records[start..start + counts[q]];
        let flux: f64 = recs.iter().map(|r| f64::from(r.flux)).sum();
        nodes[first + q] = super::child(&n, q, start, counts[q], flux / total_flux);
    }
    nodes[i].child = first as u16;
}

/// Moves the records satisfying `pred` to the front; returns their number.
fn partition(records: &mut [Record], pred: impl Fn(&Record) -> bool) -> usize {
    let mut k = 0;
    for i in 0..records.len() {
        if pred(&records[i]) {
            records.swap(k, i);
            k += 1;
        }
    }
    k
}
