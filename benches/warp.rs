//! Criterion benches for the learned guide and hierarchical warping.
//!
//! Group `warp` (samples/s): the scalar reference and the 8-wide warp, each on the same
//! Sobol points in two orders — `unsorted` (Sobol index order after the texel's rotation:
//! consecutive points far apart) and `presorted` (the presorted order repaired for the
//! rotation's wrap, `presort::reorder_after_rotation_into`: consecutive 8-point packets are
//! coherent, paper §2.4) — the packets `driver/src/bake/gather/iteration.rs` (`gather_packets`) feeds
//! `warp::sample8`. Both at the bake's default 64 samples per texel and iteration and at 1024
//! (benchmark ids `warp/<function>/<samples>`). The guide is a realistic learned one: a small
//! bright disk and a dim sky, learned in two iterations from 256 uniform and 512 guided
//! records.
//! The guide build has its own bench, `benches/guide.rs` (`guide/build/<records>`).
//!
//! Every function's output is checked against the scalar reference before timing.
//!
//! **No pass replays the points of the pass before.** Each warp cycles through [`SETS`]
//! distinct point sets (set `s` covers the texels after set `s − 1`'s), copying the next
//! one into its working buffer, untimed, before each timed pass — so the points are hot in
//! the cache, as in the bake, which warps a texel's packets right after generating them, and
//! are new to the branch predictor, as in the bake, which never warps the same points twice.
//! Replaying one set trains the predictor on the descents' loop exits: the scalar warp then
//! speeds up pass after pass to ~2.5× its speed on new points, the 8-wide warp to ~1.3×
//! (docs/guide.md, "Benchmark"; `WARP_SETS=1` reproduces it).
//!
//! Before the criterion groups the bench prints how coherent the packets are and times the
//! four warps round-robin (medians; the ratios to trust on a shared machine). Both loops
//! time the same pass (`Pass`), so their figures agree up to the machine's noise.
//!
//! Run: `cargo bench --bench warp -- --warm-up-time 1 --measurement-time 3`
//! (`cargo bench --bench warp -- none` prints the round-robin medians only;
//! `WARP_SETS=<n>` cycles through n point sets instead of [`SETS`]).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use guidebake_kernels::guide::{self, Guide, GuideNode, GuideParams, Record};
use guidebake_kernels::presort::{presorted, reorder_after_rotation_into};
use guidebake_kernels::sobol::{rotate, rotation, sobol_2d, to_unit};
use guidebake_kernels::testing::{disk_and_sky, learning_records};
use guidebake_kernels::warp::{self, Warped};
use std::hint::black_box;
use std::time::{Duration, Instant};
use wide::f32x8;

/// Points per timed iteration: texels × gather samples per texel.
const POINTS: u32 = 16_384;
/// Gather samples per texel and iteration: an iteration of the bake's default 256 spp (64 of
/// them over 4 iterations, when the figure was taken; 64, 64 and 128 over today's 3) and a
/// high count, where presorted packets are more coherent.
const SAMPLE_COUNTS: [u32; 2] = [64, 1024];
/// Distinct point sets each warp cycles through, one per timed pass: enough that the branch
/// predictor cannot learn them (on the 2-core EPYC the scalar warp is as slow on 8 sets as
/// on 64, and 2.5× faster on one replayed set).
const SETS: u32 = 16;

/// [`SETS`], or `WARP_SETS` from the environment.
fn sets() -> u32 {
    std::env::var("WARP_SETS")
        .ok()
        .and_then(|v| v.parse().ok())
        .map_or(SETS, |n: u32| n.max(1))
}

fn records(previous: Option<&Guide<'_>>, n: usize, seed: u64) -> Vec<Record> {
    learning_records(previous, n, seed, disk_and_sky)
}

/// The learning records of the second iteration, drawn from the first guide.
fn second_iteration_records() -> Vec<Record> {
    let mut storage = vec![GuideNode::default(); 4096];
    let mut first = records(None, 256, 1);
    let (g0, _) = guide::build(&mut first, &GuideParams::default(), &mut storage);
    records(Some(&g0), 512, 2)
}

/// The same points in Sobol order and in presorted, wrap-repaired order, texel after texel.
struct Points {
    unsorted: Vec<[f32; 2]>,
    presorted: Vec<[f32; 2]>,
}

/// Point set `set`: `samples` points per texel for the `POINTS / samples` texels after those
/// of set `set − 1`, each rotated as the bake rotates iteration 1 of a texel
/// (`gather_packets`: `rotation(seed, texel, k)`).
fn points(samples: u32, set: u32) -> Points {
    let order = presorted(samples);
    let mut repaired = vec![0u32; samples as usize];
    let (mut unsorted, mut sorted) = (Vec::new(), Vec::new());
    let texels = u64::from(POINTS / samples);
    for texel in u64::from(set) * texels..u64::from(set + 1) * texels {
        let r = rotation(7, texel, 1);
        let unit = |i: u32| {
            let p = rotate(sobol_2d(i), r);
            [to_unit(p[0]), to_unit(p[1])]
        };
        reorder_after_rotation_into(&order, r, &mut repaired);
        unsorted.extend((0..samples).map(unit));
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

/// How coherent the packets are on the guide, averaged over packets.
struct PacketPaths {
    /// Share of packets whose eight lanes end in one leaf (the whole uniform fast path).
    one_leaf: f64,
    /// Depth of the deepest node all eight lanes share.
    parting_depth: f64,
    /// Depth of the lanes' leaves.
    leaf_depth: f64,
}

/// The path of `u` through the guide's nodes (root first), by the thresholds the warp uses.
fn path(g: &Guide<'_>, u: [f32; 2]) -> Vec<usize> {
    let nodes = g.nodes();
    let mut i = 0;
    let mut p = vec![0];
    while let Some(c) = nodes[i].first_child() {
        let t = nodes[i].thresholds();
        let right = u[0] >= t[0];
        let upper = u[1] >= t[1 + usize::from(right)];
        i = c + usize::from(right) + 2 * usize::from(upper);
        p.push(i);
    }
    p
}

fn packet_paths(g: &Guide<'_>, points: &[[f32; 2]]) -> PacketPaths {
    let (mut one, mut part, mut leaf, mut n) = (0usize, 0usize, 0usize, 0usize);
    for c in points.chunks_exact(8) {
        let paths: Vec<Vec<usize>> = c.iter().map(|&u| path(g, u)).collect();
        let shared = (0..)
            .take_while(|&d| {
                paths
                    .iter()
                    .all(|p| p.get(d).is_some_and(|&k| k == paths[0][d]))
            })
            .count();
        one += usize::from(paths.iter().all(|p| p == &paths[0]));
        part += shared - 1;
        leaf += paths.iter().map(|p| p.len() - 1).sum::<usize>();
        n += 1;
    }
    PacketPaths {
        one_leaf: one as f64 / n as f64,
        parting_depth: part as f64 / n as f64,
        leaf_depth: leaf as f64 / (8 * n) as f64,
    }
}

/// Rounds of the round-robin timing.
const ROUNDS: usize = 101;

/// One timed pass of a warp: copies the next point set of its pool into its working buffer
/// (untimed) and returns the time of the warp over it. The round-robin loop and criterion
/// both time this.
type Pass<'a> = Box<dyn FnMut() -> Duration + 'a>;

/// A pass of `warp` over the sets of `pool` in turn.
fn pass<'a, T: Copy, O: Copy + 'a>(
    pool: &'a [Vec<T>],
    out: O,
    outs: usize,
    mut warp: impl FnMut(&[T], &mut [O]) + 'a,
) -> Pass<'a> {
    let mut work = pool[0].clone();
    let mut out = vec![out; outs];
    let mut next = 0;
    Box::new(move || {
        work.copy_from_slice(&pool[next]);
        next = (next + 1) % pool.len();
        let t = Instant::now();
        warp(black_box(&work), &mut out);
        black_box(&out);
        t.elapsed()
    })
}

/// The four warps' passes on `samples` points per texel, named as their benchmark ids.
fn variants<'a>(
    g: &'a Guide<'a>,
    unsorted: &'a [Vec<[f32; 2]>],
    sorted: &'a [Vec<[f32; 2]>],
    unsorted8: &'a [Vec<(f32x8, f32x8)>],
    sorted8: &'a [Vec<(f32x8, f32x8)>],
) -> [(&'static str, Pass<'a>); 4] {
    let n = POINTS as usize;
    let w = Warped {
        u: [0.0; 2],
        pdf: 0.0,
    };
    let zero = f32x8::splat(0.0);
    let w8 = warp::Warped8 {
        x: zero,
        y: zero,
        pdf: zero,
    };
    let s = move |p: &[[f32; 2]], o: &mut [Warped]| scalar(g, p, o);
    let v = move |p: &[(f32x8, f32x8)], o: &mut [warp::Warped8]| x8(g, p, o);
    [
        ("scalar_unsorted", pass(unsorted, w, n, s)),
        ("scalar_presorted", pass(sorted, w, n, s)),
        ("x8_unsorted", pass(unsorted8, w8, n / 8, v)),
        ("x8_presorted", pass(sorted8, w8, n / 8, v)),
    ]
}

/// The warps timed round-robin, [`ROUNDS`] rounds of four passes each, medians printed: on
/// a shared, noisy machine the ratios of one interleaved run are steadier than criterion's
/// sequential groups (each of which can land in a different load phase).
fn interleaved(variants: &mut [(&'static str, Pass<'_>)], samples: u32) {
    let v = variants.len();
    let mut times = vec![Vec::new(); v];
    for round in 0..ROUNDS {
        // Rotate which variant goes first, so none always meets the same phase of the round.
        for k in (0..v).map(|j| (j + round) % v) {
            let t: Duration = (0..4).map(|_| (variants[k].1)()).sum();
            times[k].push(t.as_secs_f64() / 4.0);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let m: Vec<f64> = times.iter_mut().map(median).collect();
    for ((name, _), t) in variants.iter().zip(&m) {
        eprintln!(
            "interleaved median warp/{name}/{samples}: {:.1} Msamples/s ({:.2}x scalar_unsorted)",
            f64::from(POINTS) / t / 1e6,
            m[0] / t
        );
    }
}

/// Criterion timing of the same passes.
fn timed(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    variants: &mut [(&'static str, Pass<'_>)],
    samples: u32,
) {
    group.throughput(Throughput::Elements(u64::from(POINTS)));
    for (name, pass) in variants {
        group.bench_function(BenchmarkId::new(*name, samples), |b| {
            b.iter_custom(|iters| (0..iters).map(|_| pass()).sum())
        });
    }
}

fn bench(c: &mut Criterion) {
    let learned = second_iteration_records();
    let mut storage = vec![GuideNode::default(); 4096];
    let mut recs = learned.clone();
    let (g, stats) = guide::build(&mut recs, &GuideParams::default(), &mut storage);
    eprintln!(
        "guide: {} nodes, {} leaves, depth {}",
        stats.nodes, stats.leaves, stats.depth
    );
    let sets = sets();
    eprintln!("{sets} point sets of {POINTS} points per sample count, one per pass in turn");
    let mut group = c.benchmark_group("warp");
    for samples in SAMPLE_COUNTS {
        let pool: Vec<Points> = (0..sets).map(|s| points(samples, s)).collect();
        for pts in &pool {
            check(&g, &pts.unsorted);
            check(&g, &pts.presorted);
        }
        let unsorted: Vec<_> = pool.iter().map(|p| p.unsorted.clone()).collect();
        let sorted: Vec<_> = pool.iter().map(|p| p.presorted.clone()).collect();
        let unsorted8: Vec<_> = unsorted.iter().map(|p| soa(p)).collect();
        let sorted8: Vec<_> = sorted.iter().map(|p| soa(p)).collect();
        let (ps, us) = (packet_paths(&g, &sorted[0]), packet_paths(&g, &unsorted[0]));
        eprintln!(
            "{samples} samples per texel: packets in one leaf: presorted {:.0}%, unsorted {:.0}%; \
             presorted packets part at depth {:.2} of a mean leaf depth {:.2} (unsorted {:.2} of {:.2})",
            100.0 * ps.one_leaf,
            100.0 * us.one_leaf,
            ps.parting_depth,
            ps.leaf_depth,
            us.parting_depth,
            us.leaf_depth,
        );
        let mut v = variants(&g, &unsorted, &sorted, &unsorted8, &sorted8);
        interleaved(&mut v, samples);
        timed(&mut group, &mut v, samples);
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
