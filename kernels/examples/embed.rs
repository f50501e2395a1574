//! A tiny baker embedding the kernels: 32 texels under a square area light, clustered, each
//! cluster learning a guide over 4 iterations, 8-wide warps, packet tracing, Graybill–Deal
//! with the global ρ — checked against the analytic irradiance of the polygon light.
//!
//! The same baker in C and C++ through the C ABI is `examples/c/embed.c` and
//! `examples/cpp/embed.cpp`; the three print the same text, bit for bit (CI diffs them).
//! Their BVHs differ (the ABI's helper builds one there, here it is written by hand: one
//! root, the light's and the walls' triangles as its two leaves), which shows that the
//! traversal's hits do not depend on the tree.
//!
//! Run: `cargo run -p guidebake-kernels --example embed --release`

use glam::Vec3;
use guidebake_kernels::cluster::{ClusterParams, ClusterRange, build_clusters};
use guidebake_kernels::estimator::{
    GraybillDeal, RhoAccumulator, Welford, luminance, plain_average,
};
use guidebake_kernels::guide::{self, Guide, GuideNode, GuideParams, Record};
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere_x8};
use guidebake_kernels::packet::{Hit8, Ray8};
use guidebake_kernels::presort::{packet_u_x8, presorted, reorder_after_rotation_into};
use guidebake_kernels::sobol::rotation;
use guidebake_kernels::traverse::{self, BvhRef, LEAF};
use guidebake_kernels::warp;
use wide::f32x8;

const N: usize = 64; // gather samples per texel and iteration (a multiple of 8)
const K: usize = 4; // learning iterations; iteration 0 uses the uniform guide
const SEED: u32 = 7;
const TEXELS: usize = 32;
const LIGHT: [f32; 3] = [4.0, 3.5, 3.0]; // radiance of the light (prims 0, 1)
const TILT: f64 = 40.0; // degrees: texels 16..31 lean toward +x

/// The scene: the light (prims 0, 1), a square at z = 1, and two black walls (prims 2..5) at
/// x = ±3 that rays toward the light never meet.
fn triangles() -> [[[f32; 3]; 3]; 6] {
    let q = |a: [f32; 3], b: [f32; 3], c: [f32; 3], d: [f32; 3]| [[a, b, c], [a, c, d]];
    let [l0, l1] = q(
        [-0.5, -0.5, 1.0],
        [0.5, -0.5, 1.0],
        [0.5, 0.5, 1.0],
        [-0.5, 0.5, 1.0],
    );
    let [w0, w1] = q(
        [3.0, -3.0, 0.0],
        [3.0, 3.0, 0.0],
        [3.0, 3.0, 2.0],
        [3.0, -3.0, 2.0],
    );
    let [w2, w3] = q(
        [-3.0, -3.0, 0.0],
        [-3.0, 3.0, 0.0],
        [-3.0, 3.0, 2.0],
        [-3.0, -3.0, 2.0],
    );
    [l0, l1, w0, w1, w2, w3]
}

/// Texel `i`: a 4×4 grid on z = 0, twice (flat, then tilted normals).
fn texel(i: usize) -> ([f32; 3], [f32; 3]) {
    let (gx, gy) = ((i % 4) as f32, ((i / 4) % 4) as f32);
    let p = [-0.375 + 0.25 * gx, -0.375 + 0.25 * gy, 0.0];
    let a = TILT.to_radians();
    let n = if i < 16 {
        [0.0, 0.0, 1.0]
    } else {
        [a.sin() as f32, 0.0, a.cos() as f32]
    };
    (p, n)
}

/// Irradiance per unit radiance from the light at `p` with normal `n` (Lambert's polygon
/// formula): ½ |Σ_edges angle · n · normalize(a × b)|.
fn analytic(p: [f32; 3], n: [f32; 3]) -> f64 {
    let v = [
        [-0.5, -0.5, 1.0],
        [0.5, -0.5, 1.0],
        [0.5, 0.5, 1.0],
        [-0.5, 0.5, 1.0],
    ];
    let unit = |w: [f64; 3]| {
        let l = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        [w[0] / l, w[1] / l, w[2] / l]
    };
    let dir = |k: usize| unit([0, 1, 2].map(|c| v[k][c] - f64::from(p[c])));
    let mut sum = 0.0;
    for k in 0..4 {
        let (a, b) = (dir(k), dir((k + 1) % 4));
        let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let c = unit([
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]);
        sum +=
            dot.acos() * (f64::from(n[0]) * c[0] + f64::from(n[1]) * c[1] + f64::from(n[2]) * c[2]);
    }
    0.5 * sum.abs()
}

fn main() {
    // The BVH: a root whose two leaves are the light and the walls.
    let tris: Vec<traverse::Tri> = triangles()
        .iter()
        .enumerate()
        .map(|(i, t)| traverse::Tri::new(t.map(Vec3::from_array), i as u32))
        .collect();
    let mut root = traverse::BinaryNode::EMPTY;
    root.set_box(0, Vec3::new(-0.5, -0.5, 1.0), Vec3::new(0.5, 0.5, 1.0));
    root.set_box(1, Vec3::new(-3.0, -3.0, 0.0), Vec3::new(3.0, 3.0, 2.0));
    (root.child, root.meta) = ([0, 2], [LEAF | 2, LEAF | 4]);
    let nodes = [root];
    let bvh = BvhRef::new(&nodes, &tris).expect("valid layout");

    let (pos, nrm): (Vec<[f32; 3]>, Vec<[f32; 3]>) = (0..TEXELS).map(texel).unzip();
    let params = ClusterParams {
        max_texels: 8,
        ..ClusterParams::default()
    };
    let (mut perm, mut ranges) = (vec![0u32; TEXELS], vec![ClusterRange::default(); TEXELS]);
    let clusters =
        build_clusters(&pos, &nrm, &params, &mut perm, &mut ranges).expect("valid texels");

    let order = presorted(N as u32);
    let mut packet_order = vec![0u32; N];
    let mut storage = vec![GuideNode::default(); 1024]; // one cluster's guide at a time
    let mut records = Vec::<Record>::with_capacity(8 * N);
    let mut batches = vec![[Welford::new(); K]; TEXELS];
    let mut cluster_of = [0usize; TEXELS];
    for (c, range) in ranges[..clusters].iter().enumerate() {
        let texels = &perm[range.start as usize..range.end as usize];
        // k is the learning iteration (it seeds the rotation), not only an index.
        #[allow(clippy::needless_range_loop)]
        for k in 0..K {
            let g = if k == 0 {
                Guide::uniform(&mut storage)
            } else {
                guide::build(&mut records, &GuideParams::default(), &mut storage).0
            };
            records.clear();
            for &t in texels {
                let t = t as usize;
                cluster_of[t] = c;
                let (p, n) = texel(t);
                let (tb, bb) = orthonormal_basis(Vec3::from_array(n));
                let (tb, bb) = (tb.to_array(), bb.to_array());
                let r = rotation(SEED, t as u64, k as u32);
                reorder_after_rotation_into(&order, r, &mut packet_order);
                for packet in packet_order.chunks_exact(8) {
                    let [x, y] = packet_u_x8(packet, r);
                    let w = warp::sample8(&g, x, y);
                    let [lx, ly, lz] =
                        sample_cosine_hemisphere_x8([w.x, w.y]).map(|v| v.to_array());
                    let dir: [f32x8; 3] = core::array::from_fn(|a| {
                        f32x8::new(core::array::from_fn(|i| {
                            tb[a] * lx[i] + bb[a] * ly[i] + n[a] * lz[i]
                        }))
                    });
                    let rays = Ray8 {
                        org: p.map(f32x8::splat),
                        dir,
                        tmin: f32x8::splat(0.0),
                        tmax: f32x8::splat(f32::INFINITY),
                    };
                    let mut hits = Hit8::NONE;
                    traverse::intersect8(&bvh, &rays, &mut hits);
                    let (prim, pdf) = (hits.prim.to_array(), w.pdf.to_array());
                    let (wx, wy) = (w.x.to_array(), w.y.to_array());
                    for l in 0..8 {
                        let radiance = if prim[l] < 2 { LIGHT } else { [0.0; 3] };
                        // p(ω) = pdf · cosθ/π, so L·cosθ/p(ω) = π·L/pdf: an irradiance sample.
                        batches[t][k].push(radiance.map(|c| core::f32::consts::PI * c / pdf[l]));
                        let lum = luminance(radiance.map(f64::from)) as f32;
                        records.push(Record {
                            u: [wx[l], wy[l]],
                            flux: lum / pdf[l],
                        });
                    }
                }
            }
        }
    }

    let gd = GraybillDeal::default(); // the bake's default combination, times ρ
    let mut rho = RhoAccumulator::new();
    for b in &batches {
        rho.add_texel(&plain_average(b), &gd.combine(b));
    }
    let rho = rho.rho();
    println!(
        "guidebake embed: {TEXELS} texels in {clusters} clusters, {K} iterations of {N} samples, rho = {:016x} ({rho:.6})",
        rho.to_bits()
    );
    let light = luminance(LIGHT.map(f64::from));
    let (mut total, mut reference, mut variance, mut worst) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (t, b) in batches.iter().enumerate() {
        let lum = gd.combine(b).luminance().expect("every texel has samples") * rho;
        // The combination's standard deviation: 1 / Σ_k (n_k / σ̂²_k).
        let precision: f64 = b
            .iter()
            .map(|w| w.count() as f64 / w.luminance_variance().unwrap())
            .sum();
        let sigma = (1.0 / precision).sqrt();
        let (p, n) = texel(t);
        let exact = light * analytic(p, n);
        let z = (lum - exact) / sigma;
        println!(
            "texel {t:2}: cluster {}, luminance {:016x} = {lum:.6}, analytic {exact:.6}, z = {z:+.2}",
            cluster_of[t],
            lum.to_bits()
        );
        (total, reference, variance, worst) = (
            total + lum,
            reference + exact,
            variance + sigma * sigma,
            worst.max(z.abs()),
        );
    }
    let z = (total - reference) / variance.sqrt();
    println!(
        "total: {:016x} = {total:.6}, analytic {reference:.6}, z = {z:+.2}",
        total.to_bits()
    );
    if worst < 3.0 && z.abs() < 3.0 {
        println!("OK: every texel and the total within 3 sigma of the analytic irradiance");
    } else {
        println!("FAIL: largest |z| {worst:.2}, total z {z:+.2}");
        std::process::exit(1);
    }
}
