//! Criterion bench for texel clustering (paper §2.1): group `cluster`, function `build`,
//! texels/s, on three inputs a baker meets — a 32×32 tile of a wavy floor (mostly one
//! normal), a tile wrapped around a cylinder (normals sweep 360°), and the six faces of a box
//! (creases). Each input is clustered once and checked before timing.
//!
//! `cargo bench --bench cluster -- --warm-up-time 1 --measurement-time 3`
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use guidebake_kernels::cluster::{ClusterParams, ClusterRange, build_clusters};
use guidebake_kernels::testing::Pcg32;
use std::f32::consts::PI;
use std::hint::black_box;

type Texels = (Vec<[f32; 3]>, Vec<[f32; 3]>);

fn wavy_floor(res: usize) -> Texels {
    let mut rng = Pcg32::new(1, 1);
    let (mut p, mut n) = (Vec::new(), Vec::new());
    for i in 0..res {
        for j in 0..res {
            let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
            p.push([x, y, 0.05 * (x * 3.0).sin() + 0.01 * rng.next_f32()]);
            n.push([-0.15 * (x * 3.0).cos(), 0.0, 1.0]);
        }
    }
    (p, n)
}

fn cylinder(around: usize, up: usize) -> Texels {
    let (mut p, mut n) = (Vec::new(), Vec::new());
    for a in 0..around {
        let phi = 2.0 * PI * (a as f32 + 0.5) / around as f32;
        for h in 0..up {
            p.push([phi.cos(), phi.sin(), 2.0 * h as f32 / up as f32]);
            n.push([phi.cos(), phi.sin(), 0.0]);
        }
    }
    (p, n)
}

fn cube(res: usize) -> Texels {
    let (mut p, mut n) = (Vec::new(), Vec::new());
    for face in 0..6 {
        let (axis, sign) = (face / 2, if face % 2 == 0 { 1.0f32 } else { -1.0 });
        for i in 0..res {
            for j in 0..res {
                let mut pos = [0.0f32; 3];
                pos[axis] = sign.max(0.0);
                pos[(axis + 1) % 3] = (i as f32 + 0.5) / res as f32;
                pos[(axis + 2) % 3] = (j as f32 + 0.5) / res as f32;
                let mut nor = [0.0f32; 3];
                nor[axis] = sign;
                p.push(pos);
                n.push(nor);
            }
        }
    }
    (p, n)
}

/// Clusters once and checks the result: a permutation, ranges tiling it, ≤ 64 texels each.
fn check(p: &[[f32; 3]], n: &[[f32; 3]]) -> usize {
    let mut perm = vec![0u32; p.len()];
    let mut ranges = vec![ClusterRange::default(); p.len()];
    let count = build_clusters(p, n, &ClusterParams::default(), &mut perm, &mut ranges)
        .expect("bench input is valid");
    let mut seen = vec![false; p.len()];
    perm.iter().for_each(|&i| seen[i as usize] = true);
    assert!(seen.iter().all(|&s| s), "not a permutation");
    let mut next = 0;
    for r in &ranges[..count] {
        assert_eq!(r.start, next);
        assert!(r.len() <= 64 && !r.is_empty());
        next = r.end;
    }
    assert_eq!(next as usize, p.len());
    count
}

fn cluster(c: &mut Criterion) {
    let inputs = [
        ("floor_32x32", wavy_floor(32)),
        ("cylinder_64x16", cylinder(64, 16)),
        ("box_6x13x13", cube(13)),
    ];
    let mut group = c.benchmark_group("cluster");
    for (name, (p, n)) in &inputs {
        let clusters = check(p, n);
        eprintln!(
            "cluster/build/{name}: {} texels → {clusters} clusters",
            p.len()
        );
        let mut perm = vec![0u32; p.len()];
        let mut ranges = vec![ClusterRange::default(); p.len()];
        let params = ClusterParams::default();
        group.throughput(Throughput::Elements(p.len() as u64));
        group.bench_with_input(BenchmarkId::new("build", name), &(), |b, _| {
            b.iter(|| {
                build_clusters(black_box(p), black_box(n), &params, &mut perm, &mut ranges).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, cluster);
criterion_main!(benches);
