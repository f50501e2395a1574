//! Criterion benches for the sampling kernels (to be written).
use criterion::{Criterion, criterion_group, criterion_main};
fn sampling(_c: &mut Criterion) {}
criterion_group!(benches, sampling);
criterion_main!(benches);
