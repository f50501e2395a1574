//! The ABI computes what the kernels compute, bit for bit: each C function against the Rust
//! call it wraps, on seeded inputs, plus the rules of the boundary (versioned params, handle
//! checks, error messages).

use std::ffi::CStr;

use bytemuck::Zeroable;

use glam::Vec3;
use guidebake_capi::GuidebakeStatus as S;
use guidebake_capi::cluster::*;
use guidebake_capi::estimator::*;
use guidebake_capi::guide::*;
use guidebake_capi::guidebake_last_error;
use guidebake_capi::sampling::*;
use guidebake_capi::traverse::*;
use guidebake_kernels::cluster::{ClusterParams, ClusterRange, build_clusters};
use guidebake_kernels::estimator::{GraybillDeal, Welford, plain_average};
use guidebake_kernels::guide::{self, GuideNode, GuideParams, Record};
use guidebake_kernels::packet::{Hit8, Ray, Ray8};
use guidebake_kernels::presort::{packet_u_x8, presorted};
use guidebake_kernels::sobol::rotation;
use guidebake_kernels::testing::{Pcg32, disk_and_sky};
use guidebake_kernels::traverse::{self, BvhRef, Tri, intersect_brute};
use guidebake_kernels::warp;
use wide::f32x8;

fn last_error() -> String {
    // SAFETY: always a NUL-terminated buffer.
    unsafe { CStr::from_ptr(guidebake_last_error()) }
        .to_string_lossy()
        .into_owned()
}

fn records(rng: &mut Pcg32, n: usize) -> Vec<Record> {
    (0..n)
        .map(|_| {
            let u = [rng.next_f32(), rng.next_f32()];
            Record {
                u,
                flux: disk_and_sky(u),
            }
        })
        .collect()
}

/// Builds a guide through the ABI from `recs` into `storage` (which the handle borrows),
/// with `params` (null: the defaults); the status, the handle and the build's statistics.
fn c_build(
    recs: &[Record],
    params: *const GuidebakeGuideParams,
    storage: &mut [GuideNode],
) -> (S, GuidebakeGuide, GuidebakeGuideStats) {
    let mut c_recs: Vec<GuidebakeRecord> = recs
        .iter()
        .map(|r| GuidebakeRecord {
            u: r.u,
            flux: r.flux,
        })
        .collect();
    let mut handle = GuidebakeGuide { opaque: [0; 8] };
    let mut st = GuidebakeGuideStats {
        size: size_of::<GuidebakeGuideStats>() as u32,
        ..Default::default()
    };
    // SAFETY: every buffer is valid for its length; the caller keeps `storage` while it
    // uses the handle.
    let s = unsafe {
        guidebake_guide_build(
            c_recs.as_mut_ptr(),
            c_recs.len(),
            params,
            storage.as_mut_ptr().cast(),
            size_of_val(storage),
            &mut handle,
            &mut st,
        )
    };
    (s, handle, st)
}

#[test]
fn guide_build_sample8_and_pdf8_match_the_kernels() {
    // The defaults (null params), the defensive mixture through `params->uniform`, the
    // second-moment target through `params->second_moment`.
    for (uniform, second_moment) in [(None, false), (Some(0.25f32), false), (Some(0.0), true)] {
        guide_matches_the_kernels(uniform, second_moment);
    }
}

fn guide_matches_the_kernels(uniform: Option<f32>, second_moment: bool) {
    let mut rng = Pcg32::new(1, 20);
    let recs = records(&mut rng, 2000);
    let mut storage = vec![GuideNode::default(); 1024];
    let kernel_params = GuideParams {
        uniform: uniform.unwrap_or(0.0),
        second_moment,
        ..GuideParams::default()
    };
    let (g, stats) = guide::build(&mut recs.clone(), &kernel_params, &mut storage);
    let mut c_storage = vec![GuideNode::default(); 1024];
    let mut p = guidebake_guide_params_default();
    p.uniform = uniform.unwrap_or(0.0);
    p.second_moment = u32::from(second_moment);
    let params = if uniform.is_some() {
        &raw const p
    } else {
        std::ptr::null()
    };
    let (s, handle, st) = c_build(&recs, params, &mut c_storage);
    assert_eq!(s, S::Ok, "{}", last_error());
    assert_eq!(
        (st.nodes, st.leaves, st.accepted, st.has_start_table),
        (stats.nodes, stats.leaves, stats.accepted, 1)
    );
    for _ in 0..500 {
        let x: [f32; 8] = std::array::from_fn(|_| rng.next_f32());
        let y: [f32; 8] = std::array::from_fn(|_| rng.next_f32());
        let want = warp::sample8(&g, f32x8::new(x), f32x8::new(y));
        let (mut ox, mut oy, mut op, mut pp) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        // SAFETY: 8-element arrays; the handle's storage is alive.
        unsafe {
            assert_eq!(
                guidebake_guide_sample8(
                    &handle,
                    x.as_ptr(),
                    y.as_ptr(),
                    ox.as_mut_ptr(),
                    oy.as_mut_ptr(),
                    op.as_mut_ptr()
                ),
                S::Ok
            );
            assert_eq!(
                guidebake_guide_pdf8(&handle, ox.as_ptr(), oy.as_ptr(), pp.as_mut_ptr()),
                S::Ok
            );
        }
        assert_eq!(ox.map(f32::to_bits), want.x.to_array().map(f32::to_bits));
        assert_eq!(oy.map(f32::to_bits), want.y.to_array().map(f32::to_bits));
        assert_eq!(op.map(f32::to_bits), want.pdf.to_array().map(f32::to_bits));
        assert_eq!(
            pp.map(f32::to_bits),
            op.map(f32::to_bits),
            "pdf8 equals the warp's pdf"
        );
        if let Some(c) = uniform {
            assert!(
                op.iter().all(|&q| q >= c * (1.0 - 1e-4)),
                "{op:?} below {c}"
            );
        }
    }
}

#[test]
fn sample_packets_equals_sample8_per_packet_and_works_in_place() {
    let mut rng = Pcg32::new(6, 20);
    let recs = records(&mut rng, 1500);
    let mut storage = vec![GuideNode::default(); 1024];
    let (g, _) = guide::build(&mut recs.clone(), &GuideParams::default(), &mut storage);
    let mut c_storage = vec![GuideNode::default(); 1024];
    let (s, h, _) = c_build(&recs, std::ptr::null(), &mut c_storage);
    assert_eq!(s, S::Ok);
    let packets = 37;
    let mut x: Vec<f32> = (0..8 * packets).map(|_| rng.next_f32()).collect();
    let mut y: Vec<f32> = (0..8 * packets).map(|_| rng.next_f32()).collect();
    let mut pdf = vec![0.0f32; 8 * packets];
    let want: Vec<_> = (0..packets)
        .map(|p| {
            warp::sample8(
                &g,
                f32x8::new(x[8 * p..][..8].try_into().unwrap()),
                f32x8::new(y[8 * p..][..8].try_into().unwrap()),
            )
        })
        .collect();
    // A point outside [0,1)² in the last packet: refused, nothing written.
    let last = x[8 * packets - 1];
    x[8 * packets - 1] = 1.0;
    let (xp, yp) = (x.as_mut_ptr(), y.as_mut_ptr());
    // SAFETY: in place, every array 8·packets floats.
    let s =
        unsafe { guidebake_guide_sample_packets(&h, xp, yp, packets, xp, yp, pdf.as_mut_ptr()) };
    assert_eq!(s, S::InvalidArgument);
    assert!(pdf.iter().all(|&p| p == 0.0));
    x[8 * packets - 1] = last;
    // SAFETY: as above.
    let s =
        unsafe { guidebake_guide_sample_packets(&h, xp, yp, packets, xp, yp, pdf.as_mut_ptr()) };
    assert_eq!(s, S::Ok, "{}", last_error());
    for (p, w) in want.iter().enumerate() {
        assert_eq!(x[8 * p..][..8], w.x.to_array());
        assert_eq!(y[8 * p..][..8], w.y.to_array());
        assert_eq!(pdf[8 * p..][..8], w.pdf.to_array());
    }
    // Partial overlap is refused.
    // SAFETY: every range lies inside the arrays.
    let s = unsafe {
        guidebake_guide_sample_packets(&h, xp, yp, packets - 1, xp.add(8), yp, pdf.as_mut_ptr())
    };
    assert_eq!(s, S::Overlap);
}

#[test]
fn versioned_params_read_only_what_the_caller_knows() {
    let mut rng = Pcg32::new(2, 20);
    let recs = records(&mut rng, 3000);
    let build = |params: &GuidebakeGuideParams| {
        let mut storage = vec![GuideNode::default(); 2048];
        let (s, _, st) = c_build(&recs, params, &mut storage);
        (s, st.depth)
    };
    let mut p = guidebake_guide_params_default();
    p.max_depth = 3;
    assert_eq!(build(&p), (S::Ok, 3));
    // A caller compiled when only `size` and `min_records` existed: max_depth is defaulted.
    p.size = 8;
    let (s, depth) = build(&p);
    assert_eq!(s, S::Ok);
    assert!(depth > 3, "{depth}");
    // A caller newer than the library, or one that forgot `size`: refused.
    p.size = size_of::<GuidebakeGuideParams>() as u32 + 4;
    assert_eq!(build(&p).0, S::InvalidArgument);
    assert!(
        last_error().starts_with("guidebake_guide_build: `params->size`"),
        "{}",
        last_error()
    );
    p.size = 0;
    assert_eq!(build(&p).0, S::InvalidArgument);
    // The target flag: anything but 0 or 1 is refused, naming the field; a caller compiled
    // before it (its `size` ends at `uniform`) gets the flux target whatever lies beyond.
    let mut p = guidebake_guide_params_default();
    p.second_moment = 2;
    assert_eq!(build(&p).0, S::InvalidArgument);
    assert!(
        last_error().contains("`params->second_moment` is 2"),
        "{}",
        last_error()
    );
    p.size = std::mem::offset_of!(GuidebakeGuideParams, second_moment) as u32;
    assert_eq!(build(&p).0, S::Ok);
}

#[test]
fn handles_and_storage_are_checked() {
    let mut storage = vec![GuideNode::default(); 4];
    let mut handle = GuidebakeGuide { opaque: [0; 8] };
    let (x, mut o) = ([0.5f32; 8], [0.0f32; 8]);
    // SAFETY: valid arrays; the zeroed handle is refused by its magic.
    unsafe {
        let s = guidebake_guide_sample8(
            &handle,
            x.as_ptr(),
            x.as_ptr(),
            o.as_mut_ptr(),
            o.as_mut_ptr(),
            o.as_mut_ptr(),
        );
        assert_eq!(s, S::InvalidHandle);
        let base = storage.as_mut_ptr().cast::<u8>();
        assert_eq!(
            guidebake_guide_uniform(base.add(8).cast(), 128, &mut handle),
            S::Misaligned
        );
        assert_eq!(
            guidebake_guide_uniform(base.cast(), 63, &mut handle),
            S::Capacity
        );
        assert_eq!(guidebake_guide_uniform(base.cast(), 64, &mut handle), S::Ok);
        let s = guidebake_guide_sample8(
            &handle,
            x.as_ptr(),
            x.as_ptr(),
            o.as_mut_ptr(),
            o.as_mut_ptr(),
            o.as_mut_ptr(),
        );
        assert_eq!(s, S::Ok);
        assert_eq!(
            o, [1.0; 8],
            "the uniform guide's pdf, written last into the aliased output"
        );
        let bad = [0.5, 0.5, 1.0, 0.5, 0.5, 0.5, 0.5, 0.5f32];
        let s = guidebake_guide_sample8(
            &handle,
            bad.as_ptr(),
            x.as_ptr(),
            o.as_mut_ptr(),
            o.as_mut_ptr(),
            o.as_mut_ptr(),
        );
        assert_eq!(s, S::InvalidArgument);
        assert_eq!(
            last_error(),
            "guidebake_guide_sample8: point 2 = (1, 0.5) is outside [0,1)^2"
        );
    }
}

#[test]
fn sampling_matches_the_kernels() {
    let order = presorted(256);
    let mut c_order = vec![0u32; 256];
    // SAFETY: valid buffer.
    assert_eq!(
        unsafe { guidebake_presort(256, c_order.as_mut_ptr(), 256) },
        S::Ok
    );
    assert_eq!(order, c_order);
    let mut r = [0u32; 2];
    // SAFETY: valid buffer.
    assert_eq!(
        unsafe { guidebake_rotation(3, 99, 2, r.as_mut_ptr()) },
        S::Ok
    );
    assert_eq!(r, rotation(3, 99, 2));
    for len in 1..=8 {
        let packet = &order[16..16 + len];
        let [x, y] = packet_u_x8(packet, r);
        let (mut ox, mut oy) = ([0.0f32; 8], [0.0f32; 8]);
        // SAFETY: valid buffers.
        let s = unsafe {
            guidebake_packet_points8(
                packet.as_ptr(),
                len,
                r.as_ptr(),
                ox.as_mut_ptr(),
                oy.as_mut_ptr(),
            )
        };
        assert_eq!(s, S::Ok);
        assert_eq!((ox, oy), (x.to_array(), y.to_array()));
    }
}

#[test]
fn estimators_match_the_kernels() {
    let mut rng = Pcg32::new(3, 20);
    let mut batches = [Welford::new(); 4];
    let mut c_batches = [GuidebakeWelford::default(); 4];
    for (k, (b, c)) in batches.iter_mut().zip(&mut c_batches).enumerate() {
        let samples: Vec<f32> = (0..3 * (10 << k))
            .map(|_| 3.0 * rng.next_f32() / (k + 1) as f32)
            .collect();
        for s in samples.chunks_exact(3) {
            b.push([s[0], s[1], s[2]]);
        }
        // SAFETY: valid buffers.
        assert_eq!(
            unsafe { guidebake_welford_push_n(c, samples.as_ptr(), samples.len() / 3) },
            S::Ok
        );
    }
    let (mut gd, mut avg) = (GuidebakeEstimate::default(), GuidebakeEstimate::default());
    // SAFETY: valid buffers.
    unsafe {
        assert_eq!(
            guidebake_combine_default(c_batches.as_ptr(), 4, &mut gd),
            S::Ok
        );
        assert_eq!(
            guidebake_combine_average(c_batches.as_ptr(), 4, &mut avg),
            S::Ok
        );
    }
    let want = GraybillDeal::default().combine(&batches);
    assert_eq!(gd.luminance.to_bits(), want.luminance().unwrap().to_bits());
    assert_eq!(
        avg.luminance.to_bits(),
        plain_average(&batches).luminance().unwrap().to_bits()
    );
    // ρ: two shards merged, through bytes, equal one accumulator over all texels.
    let (mut a, mut b, mut all) = (
        GuidebakeRho::default(),
        GuidebakeRho::default(),
        GuidebakeRho::default(),
    );
    let mut bytes = [0u8; 96];
    let (mut ra, mut rall) = (0.0, 0.0);
    // SAFETY: valid values.
    unsafe {
        for i in 0..3 {
            let acc = if i == 0 { &mut a } else { &mut b };
            let scaled = GuidebakeEstimate {
                luminance: gd.luminance * (1.0 + i as f64),
                ..gd
            };
            assert_eq!(guidebake_rho_add_texel(acc, &avg, &scaled), S::Ok);
            assert_eq!(guidebake_rho_add_texel(&mut all, &avg, &scaled), S::Ok);
        }
        assert_eq!(guidebake_rho_to_bytes(&b, bytes.as_mut_ptr()), S::Ok);
        assert_eq!(guidebake_rho_from_bytes(bytes.as_ptr(), &mut b), S::Ok);
        assert_eq!(guidebake_rho_merge(&mut a, &b), S::Ok);
        assert_eq!(guidebake_rho_value(&a, &mut ra), S::Ok);
        assert_eq!(guidebake_rho_value(&all, &mut rall), S::Ok);
    }
    assert_eq!(ra.to_bits(), rall.to_bits());
    assert!(ra < 1.0, "{ra}");
}

#[test]
fn clusters_match_the_kernels() {
    let mut rng = Pcg32::new(4, 20);
    let n = 500;
    let pos: Vec<[f32; 3]> = (0..n)
        .map(|_| [rng.next_f32(), rng.next_f32(), rng.next_f32()])
        .collect();
    let nrm: Vec<[f32; 3]> = (0..n)
        .map(|_| [rng.next_f32() - 0.5, rng.next_f32() - 0.5, 1.0])
        .collect();
    let (mut perm, mut ranges) = (vec![0u32; n], vec![ClusterRange::default(); n]);
    let count = build_clusters(
        &pos,
        &nrm,
        &ClusterParams::default(),
        &mut perm,
        &mut ranges,
    )
    .unwrap();
    let (mut c_perm, mut c_ranges) = (vec![0u32; n], vec![GuidebakeClusterRange::default(); n]);
    let mut c_count = 0;
    // SAFETY: valid buffers.
    let s = unsafe {
        guidebake_build_clusters(
            pos.as_ptr().cast(),
            nrm.as_ptr().cast(),
            n,
            std::ptr::null(),
            c_perm.as_mut_ptr(),
            n,
            c_ranges.as_mut_ptr(),
            n,
            &mut c_count,
        )
    };
    assert_eq!(s, S::Ok);
    assert_eq!((c_count, &c_perm), (count, &perm));
    assert!(
        c_ranges[..count]
            .iter()
            .zip(&ranges)
            .all(|(c, r)| (c.start, c.end) == (r.start, r.end))
    );
    // Too few ranges: a capacity error with the kernel's message.
    // SAFETY: valid buffers.
    let s = unsafe {
        guidebake_build_clusters(
            pos.as_ptr().cast(),
            nrm.as_ptr().cast(),
            n,
            std::ptr::null(),
            c_perm.as_mut_ptr(),
            n,
            c_ranges.as_mut_ptr(),
            2,
            &mut c_count,
        )
    };
    assert_eq!(s, S::Capacity);
    assert!(
        last_error().contains("cluster range buffer is full"),
        "{}",
        last_error()
    );
}

#[test]
fn bvh_build_and_packet_traversal_match_the_kernels() {
    let mut rng = Pcg32::new(5, 20);
    let n = 300;
    let verts: Vec<f32> = (0..n)
        .flat_map(|_| {
            let c = [
                rng.next_f32() * 8.0,
                rng.next_f32() * 8.0,
                rng.next_f32() * 8.0,
            ];
            let mut v = [0.0f32; 9];
            for (i, x) in v.iter_mut().enumerate() {
                *x = c[i % 3] + rng.next_f32() - 0.5;
            }
            v
        })
        .collect();
    let soup: Vec<Tri> = verts
        .chunks_exact(9)
        .enumerate()
        .map(|(i, v)| {
            Tri::new(
                [0, 1, 2].map(|k| Vec3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2])),
                i as u32,
            )
        })
        .collect();
    let (mut nn, mut nt, mut used) = (0, 0, 0);
    // SAFETY: valid out-pointers.
    assert_eq!(
        unsafe { guidebake_bvh_build_sizes(n, &mut nn, &mut nt) },
        S::Ok
    );
    let mut nodes = vec![GuidebakeBvhNode::zeroed(); nn];
    let mut tris = vec![GuidebakeTri::zeroed(); nt];
    let mut bvh = GuidebakeBvh { opaque: [0; 8] };
    // SAFETY: valid buffers that outlive the handle.
    unsafe {
        let s = guidebake_bvh_build(
            verts.as_ptr(),
            n,
            nodes.as_mut_ptr(),
            nn,
            tris.as_mut_ptr(),
            nt,
            &mut used,
        );
        assert_eq!(s, S::Ok, "{}", last_error());
        assert_eq!(
            guidebake_bvh_view(nodes.as_ptr(), used, tris.as_ptr(), nt, &mut bvh),
            S::Ok
        );
    }
    let kernel_nodes: &[traverse::BinaryNode] = bytemuck::cast_slice(&nodes[..used]);
    let kernel_tris: &[Tri] = bytemuck::cast_slice(&tris);
    let rust_bvh = BvhRef::new(kernel_nodes, kernel_tris).unwrap();
    for _ in 0..300 {
        let org = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 8.0;
        let dirs: [Vec3; 8] = std::array::from_fn(|_| {
            Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            )
        });
        let rays = Ray8::from_origin(org, &dirs, 0.0, f32::INFINITY);
        let mut want = Hit8::NONE;
        let want_mask = traverse::intersect8(&rust_bvh, &rays, &mut want);
        let c_rays = GuidebakeRay8 {
            org: rays.org.map(|v| v.to_array()),
            dir: rays.dir.map(|v| v.to_array()),
            tmin: rays.tmin.to_array(),
            tmax: rays.tmax.to_array(),
        };
        let mut hits = GuidebakeHit8 {
            t: [f32::INFINITY; 8],
            prim: [GUIDEBAKE_NO_HIT; 8],
            ..Default::default()
        };
        let (mut mask, mut blocked) = (0u8, 0u8);
        // SAFETY: valid values.
        unsafe {
            assert_eq!(
                guidebake_intersect8(&bvh, &c_rays, &mut hits, &mut mask),
                S::Ok
            );
            assert_eq!(guidebake_occluded8(&bvh, &c_rays, &mut blocked), S::Ok);
        }
        assert_eq!(
            (mask, blocked),
            (want_mask, traverse::occluded8(&rust_bvh, &rays))
        );
        assert_eq!(hits.prim, want.prim.to_array());
        assert_eq!(
            hits.t.map(f32::to_bits),
            want.t.to_array().map(f32::to_bits)
        );
        // And the ABI's tree finds what testing every triangle finds.
        for (l, d) in dirs.iter().enumerate() {
            let brute = intersect_brute(&soup, &Ray::new(org, *d, 0.0, f32::INFINITY));
            assert_eq!(
                brute.map(|h| h.prim),
                (hits.prim[l] != GUIDEBAKE_NO_HIT).then_some(hits.prim[l])
            );
        }
    }
}
