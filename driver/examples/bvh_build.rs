//! Builds the bake's BVH over a scene's triangles and reports its time, size and the peak
//! resident memory of each step (Linux: `/proc/self/status`' VmHWM, reset between steps
//! through `/proc/self/clear_refs`):
//!
//!   cargo run --release -p guidebake --example bvh_build -- SCENE.toml PRESET [--stages]
//!
//! `--whole` builds in one piece (as before regions), `--region N` in regions of N triangles.
//! `--duel` builds the whole tree and the regions' and traces the same gather-like rays through
//! both, round-robin (single rays and packets of eight), checking that every hit is the same.
//! `--tile K` builds over K×K copies of the world side by side.
//! PRESET: fastest, very_fast, fast, medium, slow, very_slow. `--stages` runs obvhs's steps
//! one by one (splits, PLOC, reinsertion, collapse, reinsertion) to see which one peaks.
use std::time::Instant;

use glam::Vec3A;
use guidebake::bvh::{Bvh, Preset};
use guidebake::scene::Scene;
use guidebake_kernels::packet::{Hit8, Ray, Ray8};
use guidebake_kernels::traverse::{intersect1, intersect8};
use obvhs::{
    bvh2::leaf_collapser::collapse, bvh2::reinsertion::ReinsertionOptimizer, ploc::PlocBuilder,
    splits::split_aabbs_preset, triangle::Triangle,
};

fn status(key: &str) -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap();
    s.lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// Resets VmHWM to the current RSS.
fn reset_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn mb(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

fn step<T>(name: &str, f: impl FnOnce() -> T) -> T {
    let before = status("VmRSS:");
    reset_peak();
    let t = Instant::now();
    let r = f();
    let took = t.elapsed();
    println!(
        "{name:>22}: {:7.2} s  rss {:7.1} -> {:7.1} MB  peak {:7.1} MB (+{:.1})",
        took.as_secs_f64(),
        mb(before),
        mb(status("VmRSS:")),
        mb(status("VmHWM:")),
        mb(status("VmHWM:").saturating_sub(before))
    );
    r
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = Scene::load(std::path::Path::new(&args[1])).unwrap();
    let preset = Preset::ALL
        .into_iter()
        .find(|p| p.name() == args[2])
        .expect("preset name");
    let mut corners = scene.triangle_positions();
    drop(scene);
    // `--tile K`: K×K copies of the world side by side (a bigger world of the same density).
    if let Some(k) = args.iter().position(|a| a == "--tile") {
        let k: usize = args[k + 1].parse().unwrap();
        let (lo, hi) = corners.iter().flatten().fold(
            (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
            |(lo, hi), v| (lo.min(*v), hi.max(*v)),
        );
        let one = std::mem::take(&mut corners);
        corners.reserve_exact(one.len() * k * k);
        for i in 0..k * k {
            let shift = glam::Vec3::new(
                (i % k) as f32 * (hi.x - lo.x),
                0.0,
                (i / k) as f32 * (hi.z - lo.z),
            );
            corners.extend(one.iter().map(|t| t.map(|v| v + shift)));
        }
    }
    println!("{} triangles, preset {}", corners.len(), preset.name());
    if args.iter().any(|a| a == "--stages") {
        stages(&corners, preset);
        return;
    }
    let region = match args.iter().position(|a| a == "--region") {
        Some(i) => args[i + 1].parse().unwrap(),
        None if args.iter().any(|a| a == "--whole") => usize::MAX,
        None => 1 << 17,
    };
    if args.iter().any(|a| a == "--duel") {
        duel(&corners, preset, region);
        return;
    }
    let bvh = step("Bvh::build", || {
        Bvh::build_in_regions_of(&corners, preset, region).unwrap()
    });
    println!(
        "tree {:.1} MB ({} wide nodes), build {:.2} s",
        bvh.bytes() as f64 / (1 << 20) as f64,
        bvh.wide_nodes().len(),
        bvh.build_time().as_secs_f64()
    );
}

fn stages(corners: &[[glam::Vec3; 3]], preset: Preset) {
    let config = preset.params();
    let triangles: Vec<Triangle> = step("triangles", || {
        corners
            .iter()
            .map(|t| Triangle {
                v0: Vec3A::from(t[0]),
                v1: Vec3A::from(t[1]),
                v2: Vec3A::from(t[2]),
            })
            .collect()
    });
    let (mut aabbs, mut indices) = step("aabbs", || {
        let aabbs: Vec<_> = triangles.iter().map(|t| t.aabb()).collect();
        (aabbs, (0..triangles.len() as u32).collect::<Vec<_>>())
    });
    if config.pre_split {
        step("splits", || {
            let largest = aabbs.iter().map(|a| a.half_area()).fold(0.0, f32::max);
            let avg = aabbs.iter().map(|a| a.half_area()).sum::<f32>() / aabbs.len() as f32;
            split_aabbs_preset(&mut aabbs, &mut indices, &triangles, avg, largest);
        });
        println!(
            "    references {} (x{:.2})",
            aabbs.len(),
            aabbs.len() as f64 / triangles.len() as f64
        );
    }
    let mut bvh2 = step("ploc", || {
        PlocBuilder::with_capacity(aabbs.len()).build(
            config.ploc_search_distance,
            &aabbs,
            indices,
            config.sort_precision,
            config.search_depth_threshold,
        )
    });
    drop(aabbs);
    bvh2.uses_spatial_splits = config.pre_split;
    println!(
        "    bvh2 nodes {} prims {}",
        bvh2.nodes.len(),
        bvh2.primitive_indices.len()
    );
    let mut opt = ReinsertionOptimizer::default();
    step("reinsertion", || {
        opt.run(&mut bvh2, config.reinsertion_batch_ratio, None)
    });
    step("collapse", || {
        collapse(
            &mut bvh2,
            config.max_prims_per_leaf.clamp(1, 255),
            config.collapse_traversal_cost,
        )
    });
    step("reinsertion 2", || {
        opt.run(
            &mut bvh2,
            config.reinsertion_batch_ratio
                * config.post_collapse_reinsertion_batch_ratio_multiplier,
            None,
        )
    });
    drop(opt);
    println!(
        "    bvh2 nodes {} prims {}",
        bvh2.nodes.len(),
        bvh2.primitive_indices.len()
    );
}

/// Gather-like rays: from random points of random triangles, offset along the normal, cosine
/// distributed about it; eight per texel (a packet).
fn gather_rays(soup: &[[glam::Vec3; 3]], texels: usize) -> Vec<[Ray; 8]> {
    use guidebake_kernels::testing::Pcg32;
    let mut rng = Pcg32::new(41, 3);
    let mut f = move || rng.next_f32();
    (0..texels)
        .map(|_| {
            let t = &soup[((f() as f64) * soup.len() as f64) as usize % soup.len()];
            let (mut a, mut b) = (f(), f());
            if a + b > 1.0 {
                (a, b) = (1.0 - a, 1.0 - b);
            }
            let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or(glam::Vec3::Y);
            let p = t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b + n * 1e-3;
            let (u, v) = n.any_orthonormal_pair();
            std::array::from_fn(|_| {
                let (r, phi) = (f().sqrt(), f() * std::f32::consts::TAU);
                let d = u * r * phi.cos() + v * r * phi.sin() + n * (1.0 - r * r).max(0.0).sqrt();
                Ray::new(p, d, 0.0, f32::INFINITY)
            })
        })
        .collect()
}

fn duel(corners: &[[glam::Vec3; 3]], preset: Preset, region: usize) {
    let whole = Bvh::build_in_regions_of(corners, preset, usize::MAX).unwrap();
    let cut = Bvh::build_in_regions_of(corners, preset, region).unwrap();
    println!(
        "whole: build {:.2} s, {:.1} MB, {} wide nodes; regions of {region}: build {:.2} s, {:.1} MB, {} wide nodes",
        whole.build_time().as_secs_f64(),
        whole.bytes() as f64 / (1 << 20) as f64,
        whole.wide_nodes().len(),
        cut.build_time().as_secs_f64(),
        cut.bytes() as f64 / (1 << 20) as f64,
        cut.wide_nodes().len(),
    );
    let rays = gather_rays(corners, 1 << 16);
    let packets: Vec<Ray8> = rays
        .iter()
        .map(|r| Ray8::from_origin(r[0].org, &r.map(|r| r.dir), 0.0, f32::INFINITY))
        .collect();
    // Same hits, ray by ray and packet by packet.
    let mut hits = 0;
    for (r, p) in rays.iter().zip(&packets) {
        for ray in r {
            let a = intersect1(&whole.wide(), ray);
            assert_eq!(a, intersect1(&cut.wide(), ray));
            hits += a.is_some() as usize;
        }
        let (mut a, mut b) = (Hit8::NONE, Hit8::NONE);
        assert_eq!(
            intersect8(&whole.wide(), p, &mut a),
            intersect8(&cut.wide(), p, &mut b)
        );
        assert_eq!(a, b);
    }
    println!(
        "{} rays, {hits} hit: the same hits through both trees",
        rays.len() * 8
    );
    let trees = [("whole", &whole), ("regions", &cut)];
    let mut rates = [[Vec::new(), Vec::new()], [Vec::new(), Vec::new()]];
    for round in 0..7 {
        for k in 0..2 {
            let i = (round + k) % 2;
            let tree = trees[i].1.wide();
            let t = Instant::now();
            let mut n = 0u32;
            for r in &rays {
                for ray in r {
                    n += intersect1(&tree, ray).is_some() as u32;
                }
            }
            std::hint::black_box(n);
            rates[i][0].push((rays.len() * 8) as f64 / t.elapsed().as_secs_f64() / 1e6);
            let t = Instant::now();
            for p in &packets {
                let mut h = Hit8::NONE;
                n += intersect8(&tree, p, &mut h) as u32;
            }
            std::hint::black_box(n);
            rates[i][1].push((rays.len() * 8) as f64 / t.elapsed().as_secs_f64() / 1e6);
        }
    }
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    for (i, (name, _)) in trees.iter().enumerate() {
        println!(
            "{name:>8}: single rays {:.2} Mrays/s, packets of 8 {:.2} Mrays/s (medians of 7)",
            median(&rates[i][0]),
            median(&rates[i][1])
        );
    }
    let ratios =
        |k: usize| -> Vec<f64> { (0..7).map(|r| rates[1][k][r] / rates[0][k][r]).collect() };
    println!(
        "regions / whole: single {:.3}, packets {:.3} (median per-round ratios)",
        median(&ratios(0)),
        median(&ratios(1))
    );
}
