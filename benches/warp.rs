//! Criterion benches for the learned guide and hierarchical warping (issue 3).
//!
//! Group `warp` (samples/s): the scalar reference and the 8-wide warp, each on the same
//! Sobol points in two orders — `unsorted` (Sobol index order after the texel's rotation:
//! consecutive points far apart) and `presorted` (the presorted order repaired for the
//! rotation's wrap, `presort::reorder_after_rotation_into`: consecutive 8-point packets are
//! coherent, paper §2.4). The guide is a realistic learned one: a small bright disk and a dim
//! sky, learned in two iterations from 256 uniform and 512 guided records.
//! Group `guide` (records/s): `build` from those 512 records.
//!
//! Every function's output is checked against the scalar reference once before timing.
//!
//! Run: `cargo bench --bench warp -- --warm-up-time 1 --measurement-time 3`

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use guidebake_kernels::guide::{self, Guide, GuideParams, Node, Record};
use guidebake_kernels::presort::{presorted, reorder_after_rotation_into};
use guidebake_kernels::sobol::{rotate, rotation, sobol_2d, to_unit};
use guidebake_kernels::testing::{disk_and_sky, learning_records};
use guidebake_kernels::warp::{self, Warped};
use std::hint::black_box;
use wide::f32x8;

/// Gather samples per texel and texels per timed iteration.
const SAMPLES: u32 = 1024;
const TEXELS: u64 = 16;

fn records(previous: Option<&Guide<'_>>, n: usize, seed: u64) -> Vec<Record> {
    learning_records(previous, n, seed, disk_and_sky)
}

/// The learning records of the second iteration, drawn from the first guide.
fn second_iteration_records() -> Vec<Record> {
    let mut storage = vec![Node::default(); 4096];
    let mut first = records(None, 256, 1);
    let (g0, _) = guide::build(&mut first, &GuideParams::default(), &mut storage);
    records(Some(&g0), 512, 2)
}

/// The same points in Sobol order and in presorted, wrap-repaired order, texel after texel.
struct Points {
    unsorted: Vec<[f32; 2]>,
    presorted: Vec<[f32; 2]>,
}

fn points() -> Points {
    let order = presorted(SAMPLES);
    let mut repaired = vec![0u32; SAMPLES as usize];
    let (mut unsorted, mut sorted) = (Vec::new(), Vec::new());
    for texel in 0..TEXELS {
        let r = rotation(7, texel, 1);
        let unit = |i: u32| {
            let p = rotate(sobol_2d(i), r);
            [to_unit(p[0]), to_unit(p[1])]
        };
        reorder_after_rotation_into(&order, r, &mut repaired);
        unsorted.extend((0..SAMPLES).map(unit));
        sorted.extend(repaired.iter().map(|&i| unit(i)));
    }
    Points {
        unsorted,
        presorted: sorted,
    }
}

/// Structure of arrays, eight lanes per entry.
fn soa(points: &[[f32; 2]]) -> Vec<(f32x8, f32x8)> {
    points
        .chunks_exact(8)
        .map(|c| {
            (
                f32x8::new(std::array::from_fn(|l| c[l][0])),
                f32x8::new(std::array::from_fn(|l| c[l][1])),
            )
        })
        .collect()
}

fn scalar(g: &Guide<'_>, points: &[[f32; 2]], out: &mut [Warped]) {
    for (o, &u) in out.iter_mut().zip(points) {
        *o = warp::sample(g, u);
    }
}

fn x8(g: &Guide<'_>, packets: &[(f32x8, f32x8)], out: &mut [warp::Warped8]) {
    for (o, &(x, y)) in out.iter_mut().zip(packets) {
        *o = warp::sample8(g, x, y);
    }
}

/// The check before timing: every lane of the 8-wide warp equals the scalar reference.
fn check(g: &Guide<'_>, points: &[[f32; 2]]) {
    let mut s = vec![
        Warped {
            u: [0.0; 2],
            pdf: 0.0
        };
        points.len()
    ];
    scalar(g, points, &mut s);
    let packets = soa(points);
    let zero = f32x8::splat(0.0);
    let mut w = vec![
        warp::Warped8 {
            x: zero,
            y: zero,
            pdf: zero
        };
        packets.len()
    ];
    x8(g, &packets, &mut w);
    for (k, r) in s.iter().enumerate() {
        let p = &w[k / 8];
        let l = k % 8;
        let lane = [p.x.to_array()[l], p.y.to_array()[l], p.pdf.to_array()[l]];
        assert_eq!(
            lane.map(f32::to_bits),
            [r.u[0], r.u[1], r.pdf].map(f32::to_bits),
            "point {k}"
        );
        assert!(r.pdf > 0.0 && r.pdf.is_finite() && (0.0..1.0).contains(&r.u[0]));
    }
}

/// Share of packets that walk the whole tree on the uniform fast path.
fn uniform_share(g: &Guide<'_>, points: &[[f32; 2]]) -> f64 {
    let leaf = |u: [f32; 2]| {
        let s = warp::sample(g, u);
        let mut id = None;
        let mut k = 0;
        g.for_each_leaf(|l| {
            let inside = |a: f32, o: f32| (o..o + l.size).contains(&a);
            if inside(s.u[0], l.origin[0]) && inside(s.u[1], l.origin[1]) {
                id = Some(k);
            }
            k += 1;
        });
        id
    };
    let packets = points.chunks_exact(8);
    let n = packets.len();
    let same = packets
        .filter(|c| c.iter().all(|&u| leaf(u) == leaf(c[0])))
        .count();
    same as f64 / n as f64
}

/// The four warp variants timed round-robin, 31 rounds, medians printed: on a shared,
/// noisy machine the ratios of one interleaved run are steadier than criterion's sequential
/// groups (each of which can land in a different load phase).
fn interleaved(g: &Guide<'_>, pts: &Points) {
    let (su, sp) = (soa(&pts.unsorted), soa(&pts.presorted));
    let mut out = vec![
        Warped {
            u: [0.0; 2],
            pdf: 0.0
        };
        pts.unsorted.len()
    ];
    let zero = f32x8::splat(0.0);
    let mut out8 = vec![
        warp::Warped8 {
            x: zero,
            y: zero,
            pdf: zero
        };
        su.len()
    ];
    let mut times: [Vec<f64>; 4] = Default::default();
    for round in 0..31 {
        // Rotate which variant goes first, so none always meets the same phase of the round.
        for k in (0..4).map(|j| (j + round) % 4) {
            let t = std::time::Instant::now();
            for _ in 0..4 {
                match k {
                    0 => scalar(g, black_box(&pts.unsorted), &mut out),
                    1 => scalar(g, black_box(&pts.presorted), &mut out),
                    2 => x8(g, black_box(&su), &mut out8),
                    _ => x8(g, black_box(&sp), &mut out8),
                }
            }
            times[k].push(t.elapsed().as_secs_f64() / 4.0);
        }
        black_box((&out, &out8));
    }
    let names = [
        "scalar_unsorted",
        "scalar_presorted",
        "x8_unsorted",
        "x8_presorted",
    ];
    let n = pts.unsorted.len() as f64;
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let m: Vec<f64> = times.iter_mut().map(median).collect();
    for (name, t) in names.iter().zip(&m) {
        eprintln!(
            "interleaved median warp/{name}: {:.1} Msamples/s ({:.2}x scalar_unsorted)",
            n / t / 1e6,
            m[0] / t
        );
    }
}

fn bench(c: &mut Criterion) {
    let learned = second_iteration_records();
    let mut storage = vec![Node::default(); 4096];
    let mut recs = learned.clone();
    let (g, stats) = guide::build(&mut recs, &GuideParams::default(), &mut storage);
    let pts = points();
    check(&g, &pts.unsorted);
    check(&g, &pts.presorted);
    eprintln!(
        "guide: {} nodes, {} leaves, depth {}; packets in one leaf: presorted {:.0}%, unsorted {:.0}%",
        stats.nodes,
        stats.leaves,
        stats.depth,
        100.0 * uniform_share(&g, &pts.presorted[..4096]),
        100.0 * uniform_share(&g, &pts.unsorted[..4096]),
    );

    interleaved(&g, &pts);

    let mut group = c.benchmark_group("warp");
    group.throughput(Throughput::Elements(pts.unsorted.len() as u64));
    let mut out = vec![
        Warped {
            u: [0.0; 2],
            pdf: 0.0
        };
        pts.unsorted.len()
    ];
    for (name, p) in [
        ("scalar_unsorted", &pts.unsorted),
        ("scalar_presorted", &pts.presorted),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                scalar(&g, black_box(p), &mut out);
                black_box(&out);
            })
        });
    }
    let zero = f32x8::splat(0.0);
    let mut out8 = vec![
        warp::Warped8 {
            x: zero,
            y: zero,
            pdf: zero
        };
        pts.unsorted.len() / 8
    ];
    for (name, p) in [
        ("x8_unsorted", soa(&pts.unsorted)),
        ("x8_presorted", soa(&pts.presorted)),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                x8(&g, black_box(&p), &mut out8);
                black_box(&out8);
            })
        });
    }
    group.finish();

    let mut group = c.benchmark_group("guide");
    group.throughput(Throughput::Elements(learned.len() as u64));
    group.bench_function("build", |b| {
        b.iter_batched_ref(
            || learned.clone(),
            |r| {
                let (g, s) = guide::build(r, &GuideParams::default(), &mut storage);
                black_box((g.nodes().len(), s));
            },
            BatchSize::SmallInput,
        )
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
