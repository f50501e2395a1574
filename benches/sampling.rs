//! Criterion benches of the sampling kernels (paper §2.4): Sobol points with their
//! Cranley–Patterson rotation, and the cosine-weighted hemisphere map, scalar against 8-wide
//! (group `sampling`, elements/s); and the per-N presort against the per-texel wrap reorder
//! (group `presort`). Each bench checks its result against the scalar reference before
//! timing.
//!
//! Run: `cargo bench --bench sampling -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use guidebake_kernels::mapping::{sample_cosine_hemisphere, sample_cosine_hemisphere_x8};
use guidebake_kernels::presort::{presort_into, presorted, reorder_after_rotation_into};
use guidebake_kernels::sobol::{
    rotate, rotate_x8, rotation, sobol_2d, sobol_2d_x8, to_unit, to_unit_x8,
};
use guidebake_kernels::testing::Pcg32;
use wide::{f32x8, u32x8};

/// Elements per iteration: a few texels' worth, small enough to stay in L1.
const COUNT: usize = 4096;

/// Rotated Sobol points of indices `first..first + COUNT` as f32, scalar.
fn sobol_scalar(first: u32, r: [u32; 2], out: &mut [[f32; 2]]) {
    for (k, o) in out.iter_mut().enumerate() {
        *o = rotate(sobol_2d(first + k as u32), r).map(to_unit);
    }
}

/// The same, eight at a time, into SoA lanes.
fn sobol_x8(first: u32, r: [u32; 2], out: &mut [[f32x8; 2]]) {
    let step = u32x8::new([0, 1, 2, 3, 4, 5, 6, 7]);
    for (k, o) in out.iter_mut().enumerate() {
        let index = u32x8::splat(first + 8 * k as u32) + step;
        let [x, y] = rotate_x8(sobol_2d_x8(index), r);
        *o = [to_unit_x8(x), to_unit_x8(y)];
    }
}

fn cosine_scalar(us: &[[f32; 2]], out: &mut [Vec3]) {
    for (u, o) in us.iter().zip(out) {
        *o = sample_cosine_hemisphere(*u);
    }
}

fn cosine_x8(us: &[[f32x8; 2]], out: &mut [[f32x8; 3]]) {
    for (u, o) in us.iter().zip(out) {
        *o = sample_cosine_hemisphere_x8(*u);
    }
}

fn lane(v: f32x8, i: usize) -> f32 {
    v.to_array()[i]
}

fn sampling(c: &mut Criterion) {
    let r = rotation(1, 77, 0);
    let first = 1 << 20;
    let mut scalar_u = vec![[0.0f32; 2]; COUNT];
    let mut wide_u = vec![[f32x8::ZERO; 2]; COUNT / 8];
    sobol_scalar(first, r, &mut scalar_u);
    sobol_x8(first, r, &mut wide_u);
    for (k, u) in scalar_u.iter().enumerate() {
        let w = wide_u[k / 8];
        assert_eq!(
            *u,
            [lane(w[0], k % 8), lane(w[1], k % 8)],
            "sobol_x8 differs at {k}"
        );
    }

    // Random inputs for the map (the Sobol ones would be just as good; these are independent).
    let mut rng = Pcg32::new(3, 5);
    let us: Vec<[f32; 2]> = (0..COUNT)
        .map(|_| [rng.next_f32(), rng.next_f32()])
        .collect();
    let us8: Vec<[f32x8; 2]> = us
        .chunks_exact(8)
        .map(|c| {
            [
                f32x8::new(std::array::from_fn(|i| c[i][0])),
                f32x8::new(std::array::from_fn(|i| c[i][1])),
            ]
        })
        .collect();
    let mut scalar_w = vec![Vec3::ZERO; COUNT];
    let mut wide_w = vec![[f32x8::ZERO; 3]; COUNT / 8];
    cosine_scalar(&us, &mut scalar_w);
    cosine_x8(&us8, &mut wide_w);
    for (k, w) in scalar_w.iter().enumerate() {
        let v = wide_w[k / 8];
        let got = Vec3::new(lane(v[0], k % 8), lane(v[1], k % 8), lane(v[2], k % 8));
        assert_eq!(
            got.to_array().map(f32::to_bits),
            w.to_array().map(f32::to_bits),
            "cosine_x8 differs at {k}"
        );
    }

    let mut group = c.benchmark_group("sampling");
    group.throughput(Throughput::Elements(COUNT as u64));
    group.bench_function("sobol_scalar", |b| {
        b.iter(|| sobol_scalar(black_box(first), black_box(r), &mut scalar_u));
    });
    group.bench_function("sobol_x8", |b| {
        b.iter(|| sobol_x8(black_box(first), black_box(r), &mut wide_u));
    });
    group.bench_function("cosine_scalar", |b| {
        b.iter(|| cosine_scalar(black_box(&us), &mut scalar_w));
    });
    group.bench_function("cosine_x8", |b| {
        b.iter(|| cosine_x8(black_box(&us8), &mut wide_w));
    });
    group.finish();
}

/// What keeping packets coherent costs: the per-N presort (once per sample count) against
/// the per-texel O(N) wrap reorder, N = 256.
fn presort(c: &mut Criterion) {
    const N: u32 = 256;
    let order = presorted(N);
    let mut out = vec![0u32; N as usize];
    let r = rotation(1, 5, 0);
    reorder_after_rotation_into(&order, r, &mut out);
    let mut check = out.clone();
    check.sort_unstable();
    assert!(
        check.iter().copied().eq(0..N),
        "the reorder is not a permutation"
    );

    let mut group = c.benchmark_group("presort");
    group.throughput(Throughput::Elements(u64::from(N)));
    group.bench_function("presort_256", |b| {
        b.iter(|| presort_into(black_box(N), &mut out))
    });
    group.bench_function("wrap_reorder_256", |b| {
        b.iter(|| reorder_after_rotation_into(black_box(&order), black_box(r), &mut out));
    });
    group.finish();
}

criterion_group!(benches, sampling, presort);
criterion_main!(benches);
