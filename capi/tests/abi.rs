//! Property test of the C ABI's boundary: for thousands of seeded random calls with
//! arbitrary lengths, null pointers, misaligned pointers, invalid handles and hostile values
//! (NaN, ±∞, points outside [0,1)², garbage BVH nodes), every call
//! - returns (no crash) with a status other than `Panic` (a panic would mean a kernel
//!   precondition the ABI fails to check),
//! - never writes outside the buffers it was given: every buffer sits between guard canaries
//!   that must come back intact,
//! - leaves its outputs untouched when it reports an argument error.
//!
//! Runs in the dev profile, where the kernels' `debug_assert!`s are live.

use bytemuck::{Pod, Zeroable};
use guidebake_capi::GuidebakeStatus as S;
use guidebake_capi::cluster::*;
use guidebake_capi::estimator::*;
use guidebake_capi::guide::*;
use guidebake_capi::sampling::*;
use guidebake_capi::traverse::*;
use guidebake_kernels::testing::Pcg32;

/// Canary elements on each side of a buffer.
const GUARD: usize = 4;
const CANARY: u8 = 0xA5;

/// A buffer of `len` `T`s between `GUARD` canary elements on each side.
struct Guarded<T: Pod> {
    all: Vec<T>,
    len: usize,
}

impl<T: Pod> Guarded<T> {
    fn new(len: usize, fill: impl FnMut(usize) -> T) -> Self {
        let mut all = vec![T::zeroed(); len + 2 * GUARD];
        bytemuck::cast_slice_mut::<T, u8>(&mut all).fill(CANARY);
        for (slot, v) in all[GUARD..GUARD + len].iter_mut().zip((0..len).map(fill)) {
            *slot = v;
        }
        Self { all, len }
    }
    fn ptr(&mut self) -> *mut T {
        self.all[GUARD..].as_mut_ptr()
    }
    fn body(&self) -> &[T] {
        &self.all[GUARD..GUARD + self.len]
    }
    /// The canaries are intact.
    fn check(&self, what: &str) {
        let bytes = |s: &[T]| {
            bytemuck::cast_slice::<T, u8>(s)
                .iter()
                .all(|&b| b == CANARY)
        };
        assert!(bytes(&self.all[..GUARD]), "{what}: wrote before the buffer");
        assert!(
            bytes(&self.all[GUARD + self.len..]),
            "{what}: wrote after the buffer"
        );
    }
}

/// True with probability 1/n.
fn one_in(rng: &mut Pcg32, n: u32) -> bool {
    rng.next_u32().is_multiple_of(n)
}

/// Hostile and ordinary floats.
fn any_f32(rng: &mut Pcg32) -> f32 {
    match rng.next_u32() % 10 {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => -f32::INFINITY,
        3 => -rng.next_f32(),
        4 => 1.0,
        5 => f32::from_bits(rng.next_u32()),
        _ => rng.next_f32(),
    }
}

/// A point coordinate: mostly inside [0,1), sometimes not.
fn coord(rng: &mut Pcg32) -> f32 {
    if one_in(rng, 16) {
        any_f32(rng)
    } else {
        rng.next_f32()
    }
}

fn len(rng: &mut Pcg32, max: usize) -> usize {
    match rng.next_u32() % 8 {
        0 => 0,
        1 => 1,
        _ => rng.next_u32() as usize % (max + 1),
    }
}

/// Null (1 in 12), misaligned by one byte (1 in 12, with a buffer long enough that the
/// claimed range still lies inside it), or the buffer.
fn pick<T: Pod>(rng: &mut Pcg32, buf: &mut Guarded<T>) -> *mut T {
    match rng.next_u32() % 12 {
        0 => core::ptr::null_mut(),
        1 if align_of::<T>() > 1 && buf.len > 1 => buf.ptr().cast::<u8>().wrapping_add(1).cast(),
        _ => buf.ptr(),
    }
}

fn known(status: S) {
    assert_ne!(
        status,
        S::Panic,
        "a panic was caught: a precondition the ABI does not check"
    );
}

/// Counts successes and refusals of one call, so a test that only ever took one branch fails.
#[derive(Default)]
struct Tally {
    ok: usize,
    refused: usize,
}

impl Tally {
    fn add(&mut self, s: S) -> S {
        known(s);
        if s == S::Ok {
            self.ok += 1
        } else {
            self.refused += 1
        }
        s
    }
    fn both(&self, what: &str) {
        let n = self.ok + self.refused;
        assert!(
            self.ok * 10 > n && self.refused * 20 > n,
            "{what}: {} ok, {} refused",
            self.ok,
            self.refused
        );
    }
}

#[test]
fn sampling_calls_stay_in_their_buffers() {
    let mut rng = Pcg32::new(20, 1);
    let (mut presort, mut points, mut cosine) =
        (Tally::default(), Tally::default(), Tally::default());
    for case in 0..3000 {
        let n = len(&mut rng, 64);
        let mut order = Guarded::new(n, |_| 0u32);
        let p = pick(&mut rng, &mut order);
        let claimed = if one_in(&mut rng, 4) {
            len(&mut rng, 64)
        } else {
            n
        };
        // SAFETY: `p` is null, or valid for `n` elements (the claimed length is checked
        // against n first: a different claim must fail before any access).
        let s = presort.add(unsafe { guidebake_presort(n as u32, p, claimed.min(n)) });
        order.check("presort");
        if s == S::Ok {
            let mut sorted = order.body().to_vec();
            sorted.sort_unstable();
            assert!(
                sorted.iter().copied().eq(0..n as u32),
                "case {case}: not a permutation"
            );
        }
        let mut out = Guarded::new(n, |_| 7u32);
        let mut rot = Guarded::new(2, |_| rng.next_u32());
        let (o, r, q) = (
            pick(&mut rng, &mut order),
            pick(&mut rng, &mut rot),
            pick(&mut rng, &mut out),
        );
        // SAFETY: each pointer is null or valid for its length.
        known(unsafe { guidebake_reorder_after_rotation(o, n, r, q, n) });
        out.check("reorder");

        let count = len(&mut rng, 10);
        let mut idx = Guarded::new(count, |_| rng.next_u32());
        let mut xs = Guarded::new(8, |_| -1.0f32);
        let mut ys = Guarded::new(8, |_| -1.0f32);
        let (i, x, y) = (
            pick(&mut rng, &mut idx),
            pick(&mut rng, &mut xs),
            pick(&mut rng, &mut ys),
        );
        // SAFETY: as above; `count` larger than 8 is refused before any read.
        let s = points.add(unsafe { guidebake_packet_points8(i, count, rot.ptr(), x, y) });
        xs.check("packet x");
        ys.check("packet y");
        if s != S::Ok {
            assert!(
                xs.body().iter().all(|&v| v == -1.0),
                "case {case}: wrote on failure"
            );
        }

        let mut u = [
            Guarded::new(8, |_| coord(&mut rng)),
            Guarded::new(8, |_| coord(&mut rng)),
        ];
        let mut d: [Guarded<f32>; 3] = core::array::from_fn(|_| Guarded::new(8, |_| 5.0));
        let ptrs = [
            pick(&mut rng, &mut d[0]),
            pick(&mut rng, &mut d[1]),
            pick(&mut rng, &mut d[2]),
        ];
        let (ux, uy) = (pick(&mut rng, &mut u[0]), pick(&mut rng, &mut u[1]));
        // SAFETY: as above.
        let s = cosine
            .add(unsafe { guidebake_sample_cosine_hemisphere8(ux, uy, ptrs[0], ptrs[1], ptrs[2]) });
        for b in &d {
            b.check("cosine");
            if s != S::Ok {
                assert!(
                    b.body().iter().all(|&v| v == 5.0),
                    "case {case}: wrote on failure"
                );
            }
        }
    }
}

#[repr(C, align(64))]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Line([u8; 64]);

#[test]
fn guide_calls_stay_in_their_buffers() {
    let mut rng = Pcg32::new(20, 2);
    let node = guidebake_guide_node_size();
    let (mut build, mut sample, mut packets_tally) =
        (Tally::default(), Tally::default(), Tally::default());
    for case in 0..1500 {
        let n = len(&mut rng, 600);
        let mut records = Guarded::new(n, |_| GuidebakeRecord {
            u: [coord(&mut rng), coord(&mut rng)],
            flux: if one_in(&mut rng, 10) {
                any_f32(&mut rng)
            } else {
                10.0 * rng.next_f32()
            },
        });
        let lines = len(&mut rng, 400);
        let mut storage = Guarded::new(lines, |_| Line([0x11; 64]));
        // Storage claimed in bytes: sometimes not a whole number of nodes.
        let bytes = (lines * node).saturating_sub(rng.next_u32() as usize % 3 * 17);
        let mut params = guidebake_guide_params_default();
        match rng.next_u32() % 8 {
            0 => params.size = rng.next_u32() % 40,
            6 => params.second_moment = rng.next_u32() % 3,
            5 => params.uniform = any_f32(&mut rng),
            1 => params.max_depth = rng.next_u32() % 40,
            2 => params.alpha = any_f32(&mut rng),
            3 => params.ambient = any_f32(&mut rng),
            4 => params.min_flux_fraction = any_f32(&mut rng),
            _ => {}
        }
        let mut stats = Guarded::new(1, |_| GuidebakeGuideStats {
            size: if one_in(&mut rng, 8) {
                rng.next_u32() % 80
            } else {
                size_of::<GuidebakeGuideStats>() as u32
            },
            ..Default::default()
        });
        let mut handle = Guarded::new(1, |_| GuidebakeGuide { opaque: [0; 8] });
        let (r, st, h) = (
            pick(&mut rng, &mut records),
            pick(&mut rng, &mut storage),
            pick(&mut rng, &mut handle),
        );
        let stats_ptr = if one_in(&mut rng, 2) {
            core::ptr::null_mut()
        } else {
            stats.ptr()
        };
        let params_ptr = if one_in(&mut rng, 4) {
            core::ptr::null()
        } else {
            &raw const params
        };
        // SAFETY: every pointer is null or valid for what it claims (the storage for `bytes`
        // ≤ its size).
        let s = build.add(unsafe {
            guidebake_guide_build(r, n, params_ptr, st.cast(), bytes, h, stats_ptr)
        });
        records.check("records");
        storage.check("storage");
        stats.check("stats");
        handle.check("handle");
        if s != S::Ok {
            assert!(
                storage.body().iter().all(|l| l.0 == [0x11; 64]),
                "case {case}: wrote on failure"
            );
            continue;
        }
        // Warps through the guide just built (or a zeroed handle: invalid).
        let g: *const GuidebakeGuide = if one_in(&mut rng, 10) {
            &GuidebakeGuide { opaque: [0; 8] }
        } else {
            handle.ptr()
        };
        for _ in 0..8 {
            let mut x = Guarded::new(8, |_| coord(&mut rng));
            let mut y = Guarded::new(8, |_| coord(&mut rng));
            let mut o: [Guarded<f32>; 3] = core::array::from_fn(|_| Guarded::new(8, |_| -2.0));
            let (px, py) = (pick(&mut rng, &mut x), pick(&mut rng, &mut y));
            let op = [
                pick(&mut rng, &mut o[0]),
                pick(&mut rng, &mut o[1]),
                pick(&mut rng, &mut o[2]),
            ];
            // SAFETY: as above; the handle's storage is alive and unchanged.
            let s = sample.add(unsafe { guidebake_guide_sample8(g, px, py, op[0], op[1], op[2]) });
            // SAFETY: as above.
            known(unsafe { guidebake_guide_pdf8(g, px, py, op[2]) });
            for b in &o {
                b.check("sample8");
            }
            if s == S::Ok {
                let (xs, ys) = (o[0].body(), o[1].body());
                assert!(
                    xs.iter().chain(ys).all(|v| (0.0..1.0).contains(v)),
                    "case {case}"
                );
            }
        }
        // Many packets at once: arbitrary counts, in place or not.
        let packets = len(&mut rng, 6);
        let mut x = Guarded::new(8 * packets, |_| coord(&mut rng));
        let mut y = Guarded::new(8 * packets, |_| coord(&mut rng));
        let mut o: [Guarded<f32>; 3] =
            core::array::from_fn(|_| Guarded::new(8 * packets, |_| -2.0));
        let claimed = if one_in(&mut rng, 4) {
            len(&mut rng, 6)
        } else {
            packets
        }
        .min(packets);
        let (px, py) = (pick(&mut rng, &mut x), pick(&mut rng, &mut y));
        let in_place = one_in(&mut rng, 3);
        let op = if in_place {
            [px, py, pick(&mut rng, &mut o[2])]
        } else {
            [
                pick(&mut rng, &mut o[0]),
                pick(&mut rng, &mut o[1]),
                pick(&mut rng, &mut o[2]),
            ]
        };
        // SAFETY: null or valid for `claimed` ≤ `packets` packets.
        let s = packets_tally.add(unsafe {
            guidebake_guide_sample_packets(g, px, py, claimed, op[0], op[1], op[2])
        });
        for b in o.iter().chain([&x, &y]) {
            b.check("sample_packets");
        }
        if s != S::Ok {
            assert!(
                o[2].body().iter().all(|&v| v == -2.0),
                "case {case}: wrote on failure"
            );
        }
    }
}

#[test]
fn estimator_and_cluster_calls_stay_in_their_buffers() {
    let mut rng = Pcg32::new(20, 3);
    let (mut combine, mut clusters) = (Tally::default(), Tally::default());
    for case in 0..2000 {
        let n = len(&mut rng, 40);
        let mut w = Guarded::new(1, |_| GuidebakeWelford::default());
        let mut rgb = Guarded::new(3 * n, |_| any_f32(&mut rng));
        let (wp, rp) = (pick(&mut rng, &mut w), pick(&mut rng, &mut rgb));
        // SAFETY: null or valid.
        known(unsafe { guidebake_welford_push_n(wp, rp, n) });
        w.check("welford");
        let k = len(&mut rng, 6);
        let mut batches = Guarded::new(k, |_| w.body()[0]);
        let mut weights = Guarded::new(len(&mut rng, 6), |_| f64::from(any_f32(&mut rng)));
        let mut out = Guarded::new(1, |_| GuidebakeEstimate::default());
        let (b, wt, o) = (
            pick(&mut rng, &mut batches),
            pick(&mut rng, &mut weights),
            pick(&mut rng, &mut out),
        );
        // SAFETY: null or valid.
        unsafe {
            combine.add(guidebake_combine_default(b, k, o));
            known(guidebake_combine_average(b, k, o));
            known(guidebake_combine_graybill_deal(
                b,
                k,
                f64::from(any_f32(&mut rng)),
                o,
            ));
            known(guidebake_combine_weighted(b, k, wt, weights.len, o));
        }
        out.check("estimate");

        let t = len(&mut rng, 100);
        let mut pos = Guarded::new(3 * t, |_| {
            if one_in(&mut rng, 50) {
                any_f32(&mut rng)
            } else {
                rng.next_f32()
            }
        });
        let mut nrm = Guarded::new(3 * t, |_| {
            if one_in(&mut rng, 50) {
                any_f32(&mut rng)
            } else {
                rng.next_f32() - 0.5
            }
        });
        let perm_len = if one_in(&mut rng, 4) {
            len(&mut rng, 100)
        } else {
            t
        };
        let ranges_len = len(&mut rng, 100);
        let mut perm = Guarded::new(perm_len, |_| 0u32);
        let mut ranges = Guarded::new(ranges_len, |_| GuidebakeClusterRange::default());
        let mut params = guidebake_cluster_params_default();
        if one_in(&mut rng, 4) {
            params.max_texels = rng.next_u32() % 4;
            params.max_normal_angle_deg = any_f32(&mut rng) * 200.0;
        }
        let mut count = usize::MAX;
        let (pp, np, mp, rp) = (
            pick(&mut rng, &mut pos),
            pick(&mut rng, &mut nrm),
            pick(&mut rng, &mut perm),
            pick(&mut rng, &mut ranges),
        );
        // SAFETY: null or valid for the claimed lengths.
        let s = unsafe {
            guidebake_build_clusters(pp, np, t, &params, mp, perm_len, rp, ranges_len, &mut count)
        };
        clusters.add(s);
        perm.check("permutation");
        ranges.check("ranges");
        if s == S::Ok {
            assert!(count <= ranges_len, "case {case}");
            let covered: u32 = ranges.body()[..count].iter().map(|r| r.end - r.start).sum();
            assert_eq!(covered as usize, t, "case {case}");
        } else {
            assert_eq!(count, usize::MAX, "case {case}: wrote the count on failure");
        }
    }
    combine.both("combine_default");
    clusters.both("build_clusters");
}

#[test]
fn traversal_calls_stay_in_their_buffers() {
    let mut rng = Pcg32::new(20, 4);
    let (mut build, mut view, mut trace) = (Tally::default(), Tally::default(), Tally::default());
    for case in 0..1500 {
        let tris = len(&mut rng, 50);
        let mut verts = Guarded::new(9 * tris, |_| {
            if one_in(&mut rng, 200) {
                any_f32(&mut rng)
            } else {
                4.0 * rng.next_f32()
            }
        });
        let (node_cap, tri_cap) = (len(&mut rng, 60), len(&mut rng, 60));
        let mut nodes = Guarded::new(node_cap, |_| GuidebakeBvhNode::zeroed());
        let mut out_tris = Guarded::new(tri_cap, |_| GuidebakeTri::zeroed());
        let mut used = 0usize;
        let (v, np, tp) = (
            pick(&mut rng, &mut verts),
            pick(&mut rng, &mut nodes),
            pick(&mut rng, &mut out_tris),
        );
        // SAFETY: null or valid for the claimed lengths.
        let s = build
            .add(unsafe { guidebake_bvh_build(v, tris, np, node_cap, tp, tri_cap, &mut used) });
        nodes.check("nodes");
        out_tris.check("tris");
        if s != S::Ok || one_in(&mut rng, 4) {
            // Garbage layouts: the view must refuse them or make them safe to trace.
            used = node_cap;
            for n in &mut nodes.all[GUARD..GUARD + node_cap] {
                for (i, c) in n.child.iter_mut().enumerate() {
                    *c = rng.next_u32() % 64;
                    n.meta[i] = match rng.next_u32() % 3 {
                        0 => 0,
                        1 => GUIDEBAKE_BVH_LEAF | (rng.next_u32() % 8),
                        _ => rng.next_u32(),
                    };
                }
                n.lo = [[-1.0; 2]; 3];
                n.hi = [[5.0; 2]; 3];
            }
        }
        let mut bvh = GuidebakeBvh { opaque: [0; 8] };
        // SAFETY: the arrays are valid for the claimed lengths and outlive `bvh`.
        let s = unsafe {
            guidebake_bvh_view(
                nodes.ptr(),
                used.min(node_cap),
                out_tris.ptr(),
                tri_cap,
                &mut bvh,
            )
        };
        view.add(s);
        for _ in 0..4 {
            let mut rays = Guarded::new(1, |_| GuidebakeRay8 {
                org: core::array::from_fn(|_| {
                    core::array::from_fn(|_| {
                        if one_in(&mut rng, 20) {
                            any_f32(&mut rng)
                        } else {
                            4.0 * rng.next_f32()
                        }
                    })
                }),
                dir: core::array::from_fn(|_| {
                    core::array::from_fn(|_| {
                        if one_in(&mut rng, 20) {
                            any_f32(&mut rng)
                        } else {
                            rng.next_f32() - 0.5
                        }
                    })
                }),
                tmin: core::array::from_fn(|_| {
                    if one_in(&mut rng, 20) {
                        any_f32(&mut rng)
                    } else {
                        0.0
                    }
                }),
                tmax: core::array::from_fn(|_| {
                    if one_in(&mut rng, 20) {
                        any_f32(&mut rng)
                    } else {
                        f32::INFINITY
                    }
                }),
            });
            let mut hits = Guarded::new(1, |_| GuidebakeHit8 {
                t: [f32::INFINITY; 8],
                prim: [GUIDEBAKE_NO_HIT; 8],
                ..Default::default()
            });
            let mut mask = Guarded::new(1, |_| 0u8);
            let (rp, hp, mp) = (
                pick(&mut rng, &mut rays),
                pick(&mut rng, &mut hits),
                pick(&mut rng, &mut mask),
            );
            // SAFETY: null or valid; `bvh` is valid or refused by its magic.
            let si = trace.add(unsafe { guidebake_intersect8(&bvh, rp, hp, mp) });
            // SAFETY: as above.
            known(unsafe { guidebake_occluded8(&bvh, rp, mp) });
            hits.check("hits");
            mask.check("mask");
            if si == S::Ok {
                for (l, &p) in hits.body()[0].prim.iter().enumerate() {
                    assert!(
                        p == GUIDEBAKE_NO_HIT || (p as usize) < tris,
                        "case {case} lane {l}: prim {p}"
                    );
                }
            }
        }
    }
}
