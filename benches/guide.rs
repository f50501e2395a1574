//! Criterion bench of the guide build: `guide/build/<records>` in records/s at
//! 512, 4 096 and 16 384 records, with the bake's guide parameters, beside
//! `guide/build_partitioning/<records>`, the build it replaced (kept as the test oracle
//! `guide::reference::build`). Before criterion's groups the two are timed round-robin and
//! the medians printed: the ratio to trust on a shared machine.
//!
//! Records: what a cluster's gather learns from — points of the primary sample square, 70 %
//! uniform and 30 % around three bright lobes (as a guided iteration concentrates them), each
//! with flux `L / p`: a dim ambient floor everywhere plus the lobes (deterministic PCG32).
//!
//! Run: `cargo bench --bench guide -- --warm-up-time 1 --measurement-time 3`
//! (`cargo bench --bench guide -- none` prints only the round-robin medians).

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use guidebake_kernels::guide::{self, GuideNode, GuideParams, Record};
use guidebake_kernels::testing::Pcg32;
use std::hint::black_box;

/// Record counts per build: a small cluster, 4 096 (the target size; the bake's clusters
/// learn from ~1 000–2 000 today) and a large one.
const RECORD_COUNTS: [usize; 3] = [512, 4096, 16_384];

/// The bake's guide parameters (`driver/src/bake/gather/`, defaults `--min-split 64`,
/// `--smooth 10`, `--mix 25`: the mixture's uniform share 0.25 and so the mixed ambient
/// floor 0.02).
fn bake_params() -> GuideParams {
    GuideParams {
        min_records: 64,
        alpha: 0.1,
        ambient: 0.02,
        uniform: 0.25,
        ..GuideParams::default()
    }
}

/// Three bright lobes (centre, radius, radiance) over an ambient floor of 0.2.
const LOBES: [([f32; 2], f32, f32); 3] = [
    ([0.7, 0.23], 0.04, 200.0),
    ([0.15, 0.8], 0.08, 40.0),
    ([0.52, 0.55], 0.02, 800.0),
];

fn radiance(u: [f32; 2], rng: &mut Pcg32) -> f32 {
    let lobes: f32 = LOBES
        .iter()
        .map(|&(c, r, l)| {
            let d2 = (u[0] - c[0]).powi(2) + (u[1] - c[1]).powi(2);
            l * (-d2 / (r * r)).exp()
        })
        .sum();
    0.2 * (0.5 + rng.next_f32()) + lobes
}

/// `n` records: 70 % uniform points (p = 1), 30 % in a box of twice a lobe's radius around
/// one of the lobes (density 0.3/3 over the box's area plus the uniform part).
fn records(n: usize, seed: u64) -> Vec<Record> {
    let mut rng = Pcg32::new(seed, 3);
    (0..n)
        .map(|_| {
            let u = if rng.next_f32() < 0.7 {
                [rng.next_f32(), rng.next_f32()]
            } else {
                let (c, r, _) = LOBES[rng.next_u32() as usize % LOBES.len()];
                let mut v = |c: f32| (c + r * (2.0 * rng.next_f32() - 1.0)).clamp(0.0, 0.999_999);
                [v(c[0]), v(c[1])]
            };
            let p = 0.7
                + LOBES
                    .iter()
                    .filter(|&&(c, r, _)| (u[0] - c[0]).abs() < r && (u[1] - c[1]).abs() < r)
                    .map(|&(_, r, _)| 0.1 / (4.0 * r * r))
                    .sum::<f32>();
            Record {
                u,
                flux: radiance(u, &mut rng) / p,
            }
        })
        .collect()
}

/// Rounds of the round-robin timing.
const ROUNDS: usize = 51;

/// Record sets per count: every build takes the next set, so that the branch predictor
/// cannot learn one input (a bench repeating one set of 4 096 records ran the partitioning
/// build ~6× faster per record than one of 16 384).
fn record_sets(n: usize) -> Vec<Vec<Record>> {
    let sets = (1 << 18) / n;
    (0..sets).map(|k| records(n, (n + k) as u64)).collect()
}

/// A guide build: [`guide::build`] or the partitioning build it replaced.
type BuildFn = for<'a> fn(
    &mut [Record],
    &GuideParams,
    &'a mut [GuideNode],
) -> (guide::Guide<'a>, guide::BuildStats);

/// The two builds compared: today's and the partitioning one it replaced (the test
/// oracle `guide::reference::build`, feature `testing`).
const BUILDS: [(&str, BuildFn); 2] = [
    ("build", guide::build),
    ("build_partitioning", guide::reference::build),
];

/// The builds timed round-robin over the sets ([`ROUNDS`] rounds, rotating which goes
/// first), medians of one build's time printed, and the ratio to the partitioning build.
fn interleaved(sets: &[Vec<Record>], storage: &mut [GuideNode]) {
    let params = bake_params();
    let mut work = sets[0].clone();
    let mut times = [Vec::new(), Vec::new()];
    for round in 0..ROUNDS {
        for k in (0..BUILDS.len()).map(|j| (j + round) % BUILDS.len()) {
            let t = std::time::Instant::now();
            for recs in sets {
                work.copy_from_slice(recs);
                let (g, s) = (BUILDS[k].1)(&mut work, &params, storage);
                black_box((g.nodes().len(), s));
            }
            times[k].push(t.elapsed().as_secs_f64() / sets.len() as f64);
        }
    }
    let m = times.map(|mut t| {
        t.sort_by(f64::total_cmp);
        t[t.len() / 2]
    });
    let n = sets[0].len();
    for ((name, _), t) in BUILDS.iter().zip(m) {
        eprintln!(
            "interleaved median guide/{name}/{n}: {:.2} µs, {:.1} M records/s ({:.2}x build_partitioning)",
            t * 1e6,
            n as f64 / t / 1e6,
            m[1] / t
        );
    }
}

fn bench(c: &mut Criterion) {
    let sets: Vec<Vec<Vec<Record>>> = RECORD_COUNTS.iter().map(|&n| record_sets(n)).collect();
    // The bake's storage (`GUIDE_CAPACITY`).
    let mut storage = vec![GuideNode::default(); 4096];
    for s in &sets {
        let (mut nodes, mut depth) = (0, 0);
        for recs in s {
            let (g, st) = guide::build(&mut recs.clone(), &bake_params(), &mut storage);
            assert!(!g.start_table().is_empty());
            nodes += st.nodes;
            depth = depth.max(st.depth);
        }
        eprintln!(
            "{} records: {} sets, {:.0} nodes on average, depth up to {depth}",
            s[0].len(),
            s.len(),
            f64::from(nodes) / s.len() as f64
        );
    }
    for s in &sets {
        interleaved(s, &mut storage);
    }
    let mut group = c.benchmark_group("guide");
    for s in &sets {
        let n = s[0].len();
        group.throughput(Throughput::Elements(n as u64));
        for (name, build) in BUILDS {
            let mut next = 0;
            group.bench_function(BenchmarkId::new(name, n), |b| {
                b.iter_batched_ref(
                    || {
                        next = (next + 1) % s.len();
                        s[next].clone()
                    },
                    |r| {
                        let (g, st) = build(r, &bake_params(), &mut storage);
                        black_box((g.nodes().len(), st));
                    },
                    BatchSize::SmallInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
