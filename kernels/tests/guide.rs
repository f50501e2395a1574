//! Statistical and differential tests of the learned guide and its hierarchical warp
//! chi-square tests of `sample` against `pdf` for degenerate and learned
//! guides, pdf normalization, `pdf(sample(u)) == sample(u).pdf`, `invert(sample(u)) ≈ u`,
//! and the 8-wide warp against the scalar reference bit for bit.
//!
//! On a chi-square failure the histogram and its expectation are written to
//! `target/chi2/<name>.txt` for a person to look at.

use guidebake_kernels::guide::{
    self, BuildStats, Guide, GuideNode, GuideParams, MAX_DEPTH, Record, START_GRID,
};
use guidebake_kernels::sobol::ONE_MINUS_EPSILON;
use guidebake_kernels::testing::{Pcg32, chi_square, disk_and_sky, learning_records};
use guidebake_kernels::warp;
use std::io::Write;
use wide::f32x8;

/// Chi-square tests in this file, for the Šidák correction.
const CHI2_TESTS: u32 = 7;
const ALPHA: f64 = 0.01;
/// Odd histogram resolution, so cell edges never line up with the quadtree's dyadic edges.
const RES: usize = 31;
const SAMPLES: usize = 200_000;

/// Learning records of the disk-and-sky radiance: `n` samples drawn from `previous` (uniform
/// when `None`), flux L/p.
fn learn_records(previous: Option<&Guide<'_>>, n: usize, seed: u64) -> Vec<Record> {
    learning_records(previous, n, seed, disk_and_sky)
}

fn build<'a>(
    records: &mut [Record],
    params: GuideParams,
    storage: &'a mut [GuideNode],
) -> (Guide<'a>, BuildStats) {
    guide::build(records, &params, storage)
}

/// The guide learned in two iterations: uniform samples, then samples of the first guide.
fn learned(storage: &mut [GuideNode], capacity: usize) -> (Guide<'_>, BuildStats) {
    learned_with(storage, capacity, 0.0)
}

/// [`learned`], the second guide mixed with the uniform density by the share `uniform`.
fn learned_with(
    storage: &mut [GuideNode],
    capacity: usize,
    uniform: f32,
) -> (Guide<'_>, BuildStats) {
    let mut first = vec![GuideNode::default(); 4096];
    let mut r0 = learn_records(None, 300, 1);
    let (g0, _) = build(&mut r0, GuideParams::default(), &mut first);
    let mut r1 = learn_records(Some(&g0), 600, 2);
    let params = GuideParams {
        uniform,
        ..GuideParams::default()
    };
    build(&mut r1, params, &mut storage[..capacity])
}

/// Expected counts per cell of a window [lo, hi)² split into RES² cells, plus one last cell
/// for everything outside the window: the leaves' constant densities integrated exactly.
fn expected(g: &Guide<'_>, lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let mut e = vec![0.0; RES * RES + 1];
    let cell = (hi - lo) / RES as f64;
    let mut inside = 0.0;
    g.for_each_leaf(|l| {
        let (x0, y0, s) = (
            f64::from(l.origin[0]),
            f64::from(l.origin[1]),
            f64::from(l.size),
        );
        let range = |a: f64| {
            let i0 = (((a - lo) / cell).floor().max(0.0) as usize).min(RES);
            let i1 = ((((a + s) - lo) / cell).ceil().max(0.0) as usize).min(RES);
            i0..i1
        };
        for j in range(y0) {
            let cy0 = lo + j as f64 * cell;
            let oy = ((y0 + s).min(cy0 + cell) - y0.max(cy0)).max(0.0);
            for i in range(x0) {
                let cx0 = lo + i as f64 * cell;
                let ox = ((x0 + s).min(cx0 + cell) - x0.max(cx0)).max(0.0);
                let m = f64::from(l.pdf) * ox * oy * n as f64;
                e[j * RES + i] += m;
                inside += m;
            }
        }
    });
    e[RES * RES] = (n as f64 - inside).max(0.0);
    e
}

/// Warps `SAMPLES` uniform points, histograms them over the window and runs the chi-square
/// test; on failure writes the histogram under target/chi2.
fn chi2_check(name: &str, g: &Guide<'_>, lo: f64, hi: f64, seed: u64) {
    let mut rng = Pcg32::new(seed, 99);
    let mut observed = vec![0.0; RES * RES + 1];
    for _ in 0..SAMPLES {
        let w = warp::sample(g, [rng.next_f32(), rng.next_f32()]);
        let (x, y) = (f64::from(w.u[0]), f64::from(w.u[1]));
        let cell = if (lo..hi).contains(&x) && (lo..hi).contains(&y) {
            let i = (((x - lo) / (hi - lo) * RES as f64) as usize).min(RES - 1);
            let j = (((y - lo) / (hi - lo) * RES as f64) as usize).min(RES - 1);
            j * RES + i
        } else {
            RES * RES
        };
        observed[cell] += 1.0;
    }
    let e = expected(g, lo, hi, SAMPLES);
    let r = chi_square(&observed, &e, 5.0);
    if !r.passes(ALPHA, CHI2_TESTS) {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../target/chi2");
        std::fs::create_dir_all(dir).unwrap();
        let path = format!("{dir}/{name}.txt");
        let mut f = std::fs::File::create(&path).unwrap();
        writeln!(
            f,
            "# {name}: {r:?}\n# window [{lo}, {hi})^2, {RES}x{RES} cells + outside"
        )
        .unwrap();
        writeln!(f, "# row j, then per cell: observed/expected").unwrap();
        for j in 0..RES {
            let row: Vec<String> = (0..RES)
                .map(|i| format!("{}/{:.1}", observed[j * RES + i], e[j * RES + i]))
                .collect();
            writeln!(f, "{j}: {}", row.join(" ")).unwrap();
        }
        writeln!(f, "outside: {}/{:.1}", observed[RES * RES], e[RES * RES]).unwrap();
        panic!("{name}: chi-square rejects sample against pdf: {r:?}; histogram in {path}");
    }
}

/// The properties every guide must have besides the chi-square fit.
fn check_consistency(name: &str, g: &Guide<'_>, seed: u64) {
    // pdf integrates to 1, leaf by leaf ...
    let mut total = 0.0f64;
    g.for_each_leaf(|l| total += f64::from(l.pdf) * f64::from(l.size) * f64::from(l.size));
    assert!(
        (total - 1.0).abs() < 1e-5,
        "{name}: leaves integrate to {total}"
    );
    // ... and through `pdf` itself: its lookup (descending by the squares' midpoints) at
    // each leaf's centre, times the leaf's area. Independent of the stored leaf list's pdfs.
    let mut through_pdf = 0.0f64;
    g.for_each_leaf(|l| {
        let h = l.size * 0.5;
        let p = warp::pdf(g, [l.origin[0] + h, l.origin[1] + h]);
        through_pdf += f64::from(p) * f64::from(l.size) * f64::from(l.size);
    });
    assert!(
        (through_pdf - 1.0).abs() < 1e-5,
        "{name}: pdf integrates to {through_pdf}"
    );
    // A coarse midpoint grid must agree where the guide has no leaves below the grid's cell.
    let depth = g.nodes().iter().map(|n| n.depth()).max().unwrap_or(0);
    if depth <= 8 {
        let m = 256;
        let mut grid = 0.0f64;
        for j in 0..m {
            for i in 0..m {
                let u = [(i as f32 + 0.5) / m as f32, (j as f32 + 0.5) / m as f32];
                grid += f64::from(warp::pdf(g, u));
            }
        }
        grid /= (m * m) as f64;
        assert!((grid - 1.0).abs() < 1e-5, "{name}: grid integral {grid}");
    }

    // invert(sample(u)) ≈ u: the warped point is rounded to f32 (spacing ≤ 2⁻²⁴) inside a
    // leaf of side 2^-depth, so u is known to ≈ 2^(depth−24) per axis at best.
    let tol = 16.0 * (depth as f32 - 24.0).exp2() + 4e-7;
    let mut worst = 0.0f32;
    let mut rng = Pcg32::new(seed, 5);
    for k in 0..50_000 {
        let u = match k {
            0 => [0.0, 0.0],
            1 => [ONE_MINUS_EPSILON, ONE_MINUS_EPSILON],
            2 => [0.0, ONE_MINUS_EPSILON],
            _ => [rng.next_f32(), rng.next_f32()],
        };
        let s = warp::sample(g, u);
        assert!(
            (0.0..1.0).contains(&s.u[0]) && (0.0..1.0).contains(&s.u[1]),
            "{name}: {u:?} -> {s:?}"
        );
        assert!(s.pdf.is_finite() && s.pdf > 0.0, "{name}: {u:?} -> {s:?}");
        assert_eq!(
            s.pdf.to_bits(),
            warp::pdf(g, s.u).to_bits(),
            "{name}: {u:?} -> {s:?}"
        );
        let back = warp::invert(g, s.u);
        worst = worst
            .max((back[0] - u[0]).abs())
            .max((back[1] - u[1]).abs());
    }
    assert!(
        worst <= tol,
        "{name}: invert(sample(u)) off by {worst} > {tol} (depth {depth})"
    );
}

fn check_all(name: &str, g: &Guide<'_>, seed: u64) {
    chi2_check(name, g, 0.0, 1.0, seed);
    check_consistency(name, g, seed);
}

#[test]
fn uniform_guide() {
    let mut storage = [GuideNode::default(); 1];
    let g = Guide::uniform(&mut storage);
    check_all("uniform", &g, 1);
}

#[test]
fn single_hot_leaf() {
    // Eight bright records inside one depth-3 cell, nothing else: the tree splits only
    // toward them and that one leaf holds most of the mass.
    let mut records: Vec<Record> = (0..8)
        .map(|k| Record {
            u: [0.3 + 0.001 * k as f32, 0.61 + 0.002 * k as f32],
            flux: 1.0,
        })
        .collect();
    let mut storage = vec![GuideNode::default(); 64];
    let params = GuideParams {
        max_depth: 3,
        ..GuideParams::default()
    };
    let (g, stats) = build(&mut records, params, &mut storage);
    assert_eq!((stats.nodes, stats.depth), (13, 3));
    let mut hot = 0.0;
    g.for_each_leaf(|l| hot = f32::max(hot, l.pdf * l.size * l.size));
    // (1 − α + α/4)³ ≈ 0.54 after smoothing, less the floor's share.
    assert!(hot > 0.4, "hot leaf mass {hot}");
    check_all("single_hot_leaf", &g, 2);
}

#[test]
fn learned_anisotropic_guide() {
    let mut storage = vec![GuideNode::default(); 4096];
    let (g, stats) = learned(&mut storage, 4096);
    assert_eq!(stats.rejected_flux + stats.rejected_point, 0);
    assert_eq!(stats.capacity_refusals, 0);
    // The disk covers 0.8% of the square; the guide must put a large share of its mass there
    // (true radiance share ≈ 44%, lowered by the floor and smoothing to ≈ 20%).
    let mut disk = 0.0f64;
    g.for_each_leaf(|l| {
        let c = [l.origin[0] + l.size / 2.0, l.origin[1] + l.size / 2.0];
        if disk_and_sky(c) > 1.0 {
            disk += f64::from(l.pdf * l.size * l.size);
        }
    });
    assert!(disk > 0.1, "disk share {disk} (uniform: 0.008)");
    check_all("learned_anisotropic", &g, 3);
}

#[test]
fn max_depth_guide() {
    // Records piled on one point of the diagonal: the tree splits down to the depth cap.
    let p = 0.417_f32;
    let mut rng = Pcg32::new(4, 4);
    let mut records: Vec<Record> = (0..200)
        .map(|_| Record {
            u: [p + 1e-6 * rng.next_f32(), p + 1e-6 * rng.next_f32()],
            flux: 1.0,
        })
        .collect();
    let mut storage = vec![GuideNode::default(); 1024];
    let params = GuideParams {
        max_depth: MAX_DEPTH,
        ..GuideParams::default()
    };
    let (g, stats) = build(&mut records, params, &mut storage);
    assert_eq!(stats.depth, MAX_DEPTH);
    assert!(stats.depth_refusals >= 1);
    check_all("max_depth", &g, 4);
    // Zoom in: a window of side 2⁻¹² around the point resolves the deepest leaves (side
    // 2⁻¹⁶); everything outside the window is one pooled cell.
    let half = 2f64.powi(-13);
    chi2_check(
        "max_depth_zoom",
        &g,
        f64::from(p) - half,
        f64::from(p) + half,
        5,
    );
}

#[test]
fn full_capacity_guide() {
    // Room for 1 + 4 + 16 nodes and one more split: the learned radiance wants many more.
    let mut storage = vec![GuideNode::default(); 25];
    let (g, stats) = learned(&mut storage, 25);
    assert_eq!(stats.nodes, 25);
    assert!(stats.capacity_refusals > 0);
    let depth2 = g.nodes().iter().filter(|n| n.depth() == 2).count();
    assert_eq!(depth2, 16, "levels above the cut are complete");
    check_all("full_capacity", &g, 6);
}

#[test]
fn zero_and_nan_flux_give_the_uniform_guide() {
    let mut storage = vec![GuideNode::default(); 64];
    let mut rng = Pcg32::new(7, 7);
    for flux in [0.0, f32::NAN, -1.0, f32::INFINITY] {
        let mut records: Vec<Record> = (0..100)
            .map(|_| Record {
                u: [rng.next_f32(), rng.next_f32()],
                flux,
            })
            .collect();
        let (g, stats) = build(&mut records, GuideParams::default(), &mut storage);
        assert!(g.is_uniform(), "flux {flux}");
        let rejected = if flux == 0.0 { 0 } else { 100 };
        assert_eq!(stats.rejected_flux, rejected, "flux {flux}");
        for _ in 0..100 {
            let u = [rng.next_f32(), rng.next_f32()];
            assert_eq!(warp::sample(&g, u), warp::Warped { u, pdf: 1.0 });
        }
    }
}

/// Compares every lane of `sample8_lanes` with the scalar warp, bit for bit, and checks that
/// lanes beyond `lanes` come back unchanged with pdf 0. Also compares `pdf8` with the scalar
/// `pdf` at the input points and with the warp's pdf at the warped points.
fn assert_packet_matches(g: &Guide<'_>, xs: [f32; 8], ys: [f32; 8], lanes: usize) {
    let w = warp::sample8_lanes(g, f32x8::new(xs), f32x8::new(ys), lanes);
    let (wx, wy, wp) = (w.x.to_array(), w.y.to_array(), w.pdf.to_array());
    let d = warp::pdf8(g, f32x8::new(xs), f32x8::new(ys)).to_array();
    let dw = warp::pdf8(g, w.x, w.y).to_array();
    for l in 0..8 {
        assert_eq!(
            d[l].to_bits(),
            warp::pdf(g, [xs[l], ys[l]]).to_bits(),
            "pdf8 lane {l}"
        );
        if l < lanes {
            assert_eq!(
                dw[l].to_bits(),
                wp[l].to_bits(),
                "pdf8 at the warped point, lane {l}"
            );
        }
    }
    for l in 0..8 {
        if l < lanes {
            let s = warp::sample(g, [xs[l], ys[l]]);
            assert_eq!(
                [wx[l].to_bits(), wy[l].to_bits(), wp[l].to_bits()],
                [s.u[0].to_bits(), s.u[1].to_bits(), s.pdf.to_bits()],
                "lane {l} of {lanes}: ({}, {}) -> 8-wide ({}, {}, {}) vs scalar {s:?}",
                xs[l],
                ys[l],
                wx[l],
                wy[l],
                wp[l]
            );
        } else {
            assert_eq!(
                [wx[l].to_bits(), wy[l].to_bits()],
                [xs[l].to_bits(), ys[l].to_bits()]
            );
            assert_eq!(wp[l], 0.0);
        }
    }
}

/// Coherent packets: eight consecutive points of a sequence sorted along a Morton curve, a
/// stand-in for `presort` packets until that module lands.
fn coherent_packets(n: usize, rng: &mut Pcg32) -> Vec<([f32; 8], [f32; 8])> {
    let mut pts: Vec<[f32; 2]> = (0..n * 8)
        .map(|_| [rng.next_f32(), rng.next_f32()])
        .collect();
    let morton = |p: &[f32; 2]| {
        let (x, y) = ((p[0] * 65536.0) as u64, (p[1] * 65536.0) as u64);
        (0..16).fold(0u64, |m, b| {
            m | ((x >> b & 1) << (2 * b)) | ((y >> b & 1) << (2 * b + 1))
        })
    };
    pts.sort_by_key(morton);
    pts.chunks(8)
        .map(|c| {
            (
                std::array::from_fn(|l| c[l][0]),
                std::array::from_fn(|l| c[l][1]),
            )
        })
        .collect()
}

#[test]
fn sample8_matches_scalar_on_every_guide_and_packet_kind() {
    let mut learned_storage = vec![GuideNode::default(); 4096];
    let (learned_g, _) = learned(&mut learned_storage, 4096);
    let mut full_storage = vec![GuideNode::default(); 25];
    let (full_g, _) = learned(&mut full_storage, 25);
    let mut deep_storage = vec![GuideNode::default(); 1024];
    let mut rng = Pcg32::new(9, 9);
    let mut deep: Vec<Record> = (0..100)
        .map(|_| Record {
            u: [0.25 + 1e-6 * rng.next_f32(), 0.75 + 1e-6 * rng.next_f32()],
            flux: 1.0,
        })
        .collect();
    let deep_params = GuideParams {
        max_depth: MAX_DEPTH,
        ..GuideParams::default()
    };
    let (deep_g, _) = build(&mut deep, deep_params, &mut deep_storage);
    let mut zero_storage = vec![GuideNode::default(); 16];
    let mut zero: Vec<Record> = (0..50)
        .map(|k| Record {
            u: [0.01 * k as f32, 0.5],
            flux: 0.0,
        })
        .collect();
    let (zero_g, _) = build(&mut zero, GuideParams::default(), &mut zero_storage);
    let mut nan_storage = vec![GuideNode::default(); 16];
    let mut nan: Vec<Record> = (0..50)
        .map(|k| Record {
            u: [0.01 * k as f32, 0.5],
            flux: f32::NAN,
        })
        .collect();
    let (nan_g, _) = build(&mut nan, GuideParams::default(), &mut nan_storage);

    let edges = [
        0.0,
        ONE_MINUS_EPSILON,
        0.5,
        f32::from_bits(0x3eff_ffff),
        0.25,
        0.75,
        1e-30,
        0.999,
    ];
    // Both paths of `sample8`: the start table (learned, deep) and the root descent with
    // the uniform fast path (no room for the table; uniform guides).
    assert!(!learned_g.start_table().is_empty() && !deep_g.start_table().is_empty());
    assert!(full_g.start_table().is_empty() && zero_g.start_table().is_empty());
    let below = |v: f32| f32::from_bits(v.to_bits() - 1);
    for g in [&learned_g, &full_g, &deep_g, &zero_g, &nan_g] {
        // Points on and just below the start table's cell edges, where a wrong table shows.
        for _ in 0..300 {
            let cell = |rng: &mut Pcg32| (rng.next_u32() as usize % START_GRID) as f32;
            let edge = |c: f32, up: bool| {
                if up {
                    below((c + 1.0) / START_GRID as f32)
                } else {
                    c / START_GRID as f32
                }
            };
            let (cx, cy) = (cell(&mut rng), cell(&mut rng));
            let xs: [f32; 8] = std::array::from_fn(|l| edge(cx, l & 1 != 0));
            let ys: [f32; 8] = std::array::from_fn(|l| edge(cy, l & 2 != 0));
            assert_packet_matches(g, xs, ys, 8);
        }
        let coherent = coherent_packets(500, &mut rng);
        for (k, (xs, ys)) in coherent.iter().enumerate() {
            assert_packet_matches(g, *xs, *ys, 8);
            assert_packet_matches(g, *xs, *ys, 1 + k % 8);
        }
        for k in 0..500 {
            let xs: [f32; 8] = std::array::from_fn(|_| rng.next_f32());
            let ys: [f32; 8] = std::array::from_fn(|_| rng.next_f32());
            assert_packet_matches(g, xs, ys, 8);
            assert_packet_matches(g, xs, ys, 1 + k % 8);
        }
        // Edge values in every lane position and combination of axes.
        for r in 0..8 {
            let xs: [f32; 8] = std::array::from_fn(|l| edges[(l + r) % 8]);
            let ys: [f32; 8] = std::array::from_fn(|l| edges[(l * 3 + r) % 8]);
            for lanes in 1..=8 {
                assert_packet_matches(g, xs, ys, lanes);
            }
            assert_packet_matches(g, [0.0; 8], [ONE_MINUS_EPSILON; 8], 8);
            assert_packet_matches(g, [ONE_MINUS_EPSILON; 8], [0.0; 8], 8);
        }
    }
}

#[test]
fn learning_from_guided_samples_is_unbiased() {
    // Flux L/p makes the learned mass estimate the radiance share whatever guide drew the
    // samples: with no floor and no smoothing, the share of the disk learned from uniform and
    // from guided samples must agree with the truth (≈ 0.44) within sampling noise.
    let truth = {
        let (mut disk, mut all) = (0.0f64, 0.0f64);
        let m = 1000;
        for j in 0..m {
            for i in 0..m {
                let u = [(i as f32 + 0.5) / m as f32, (j as f32 + 0.5) / m as f32];
                let l = f64::from(disk_and_sky(u));
                all += l;
                disk += if l > 1.0 { l } else { 0.0 };
            }
        }
        disk / all
    };
    let raw = GuideParams {
        ambient: 0.0,
        alpha: 0.0,
        ..GuideParams::default()
    };
    let mut first = vec![GuideNode::default(); 4096];
    let mut r0 = learn_records(None, 300, 11);
    let (g0, _) = build(&mut r0, GuideParams::default(), &mut first);
    let share = |records: &[Record]| {
        let all: f64 = records.iter().map(|r| f64::from(r.flux)).sum();
        let disk: f64 = records
            .iter()
            .filter(|r| disk_and_sky(r.u) > 1.0)
            .map(|r| f64::from(r.flux))
            .sum();
        disk / all
    };
    let (mut uni, mut gui) = (0.0, 0.0);
    let runs = 20;
    for k in 0..runs {
        let ru = learn_records(None, 4000, 100 + k);
        let mut rg = learn_records(Some(&g0), 4000, 200 + k);
        uni += share(&ru) / runs as f64;
        gui += share(&rg) / runs as f64;
        // The built guide's masses are the record fluxes normalized: check one build too.
        let mut storage = vec![GuideNode::default(); 4096];
        let (g, _) = build(&mut rg, raw, &mut storage);
        let mut total = 0.0f64;
        g.for_each_leaf(|l| total += f64::from(l.pdf * l.size * l.size));
        assert!((total - 1.0).abs() < 1e-5);
    }
    assert!(
        (uni - truth).abs() < 0.06,
        "uniform learning: {uni} vs {truth}"
    );
    assert!(
        (gui - truth).abs() < 0.03,
        "guided learning: {gui} vs {truth}"
    );
}

/// The bake's defensive mixture (driver `gather.rs`, `--mix`), folded into the guide
/// (`GuideParams::uniform`): a share `c` of the uniform density (the cosine baseline) and
/// `1 − c` of the guide learned from the same records. Every leaf's density is
/// `c + (1 − c)·q` of the unmixed guide's leaf (so never below `c`), the warped points follow
/// it (chi-square, and sample / pdf / invert agree), and a weighted estimate of the
/// disk-and-sky integral agrees with the uniform one.
#[test]
fn the_defensive_mixture_samples_its_density() {
    let c = 0.25f32;
    let mut plain_storage = vec![GuideNode::default(); 4096];
    let (plain, _) = learned(&mut plain_storage, 4096);
    let mut storage = vec![GuideNode::default(); 4096];
    let (g, _) = learned_with(&mut storage, 4096, c);
    assert!(!g.is_uniform());
    let mut plain_leaves = Vec::new();
    plain.for_each_leaf(|l| plain_leaves.push(l));
    let mut leaves = Vec::new();
    g.for_each_leaf(|l| leaves.push(l));
    assert_eq!(leaves.len(), plain_leaves.len(), "the same tree");
    for (m, p) in leaves.iter().zip(&plain_leaves) {
        assert_eq!((m.origin, m.size), (p.origin, p.size));
        let want = c + (1.0 - c) * p.pdf;
        assert!((m.pdf - want).abs() <= 1e-4 * want, "{m:?}: want {want}");
        assert!(m.pdf >= c * (1.0 - 1e-4), "{m:?}");
    }
    check_all("defensive_mixture", &g, 5);
    let mut rng = Pcg32::new(21, 3);
    let (mut estimate, mut uniform) = (0.0f64, 0.0f64);
    for _ in 0..SAMPLES {
        let s = warp::sample(&g, [rng.next_f32(), rng.next_f32()]);
        estimate += f64::from(disk_and_sky(s.u)) / f64::from(s.pdf);
        uniform += f64::from(disk_and_sky([rng.next_f32(), rng.next_f32()]));
    }
    let (estimate, uniform) = (estimate / SAMPLES as f64, uniform / SAMPLES as f64);
    assert!(
        (estimate / uniform - 1.0).abs() < 0.02,
        "mixture estimate {estimate} vs uniform {uniform}"
    );
}
