//! What the C ABI costs over calling the kernels from Rust, in one criterion run (the
//! target: within 5 %): `sample8` (the 8-wide guided warp) and `intersect8` (packet
//! traversal). Each pair reads its inputs from and writes its outputs to the same plain
//! arrays, as a C caller's would be; the ABI side calls through a function pointer hidden
//! from the optimiser (`black_box`), as a C program calls into the static or shared library,
//! so no cross-crate inlining flatters it. `sample_packets/abi` is the batched call
//! (`guidebake_guide_sample_packets`, all packets in one call). Results are checked equal
//! before timing.
//!
//! The machine is shared (load 5 to 14 on its 2 cores while this was written), so the bench
//! measures the **CPU time of its own thread** (`CLOCK_THREAD_CPUTIME_ID`) rather than wall
//! time: time spent descheduled is not counted (cache and core sharing still are). Each pair
//! is measured in `ROUNDS` alternating rounds (`sample8/rust/1`, `sample8/abi/1`,
//! `sample8/rust/2`, …); compare the pairs round by round (figures: kernels/README.md,
//! "Overhead").
//!
//! Run: `cargo bench -p guidebake-kernels-capi --bench overhead -- --warm-up-time 0.5 --measurement-time 2`

use std::hint::black_box;
use std::time::Duration;

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use guidebake_capi::GuidebakeStatus;
use guidebake_capi::guide::{
    GuidebakeGuide, GuidebakeRecord, guidebake_guide_build, guidebake_guide_sample_packets,
    guidebake_guide_sample8,
};
use guidebake_capi::traverse::{
    GUIDEBAKE_NO_HIT, GuidebakeBvh, GuidebakeBvhNode, GuidebakeHit8, GuidebakeRay8,
    guidebake_bvh_build, guidebake_bvh_view, guidebake_intersect8,
};
use guidebake_kernels::guide::{self, GuideNode, GuideParams, Record};
use guidebake_kernels::mapping::sample_cosine_hemisphere;
use guidebake_kernels::packet::{Hit8, Ray8};
use guidebake_kernels::testing::{Pcg32, disk_and_sky};
use guidebake_kernels::traverse::{self, BvhRef, Tri};
use guidebake_kernels::warp;
use wide::{f32x8, u32x8};

/// Packets per timed iteration.
const PACKETS: usize = 256;

/// Alternating rounds of each pair.
const ROUNDS: usize = 3;

type Sample8 = unsafe extern "C" fn(
    *const GuidebakeGuide,
    *const f32,
    *const f32,
    *mut f32,
    *mut f32,
    *mut f32,
) -> GuidebakeStatus;
type SamplePackets = unsafe extern "C" fn(
    *const GuidebakeGuide,
    *const f32,
    *const f32,
    usize,
    *mut f32,
    *mut f32,
    *mut f32,
) -> GuidebakeStatus;
type Intersect8 = unsafe extern "C" fn(
    *const GuidebakeBvh,
    *const GuidebakeRay8,
    *mut GuidebakeHit8,
    *mut u8,
) -> GuidebakeStatus;

/// CPU time of the calling thread, as criterion's measurement.
struct ThreadTime;

#[repr(C)]
struct Timespec {
    sec: i64,
    nsec: i64,
}

unsafe extern "C" {
    fn clock_gettime(clock: i32, out: *mut Timespec) -> i32;
}

/// Linux's `CLOCK_THREAD_CPUTIME_ID`.
const CLOCK_THREAD_CPUTIME_ID: i32 = 3;

fn thread_cpu_time() -> Duration {
    let mut t = Timespec { sec: 0, nsec: 0 };
    // SAFETY: a valid out-pointer; the clock id is Linux's.
    let r = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    assert_eq!(r, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    Duration::new(t.sec as u64, t.nsec as u32)
}

impl Measurement for ThreadTime {
    type Intermediate = Duration;
    type Value = Duration;
    fn start(&self) -> Duration {
        thread_cpu_time()
    }
    fn end(&self, start: Duration) -> Duration {
        thread_cpu_time().saturating_sub(start)
    }
    fn add(&self, a: &Duration, b: &Duration) -> Duration {
        *a + *b
    }
    fn zero(&self) -> Duration {
        Duration::ZERO
    }
    fn to_f64(&self, d: &Duration) -> f64 {
        d.as_nanos() as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        // Values are durations in nanoseconds, as wall time's are: reuse its formatter.
        static WALL: WallTime = WallTime;
        WALL.formatter()
    }
}

fn sample8(c: &mut Criterion<ThreadTime>) {
    let mut rng = Pcg32::new(20, 8);
    let records: Vec<Record> = (0..4096)
        .map(|_| {
            let u = [rng.next_f32(), rng.next_f32()];
            Record {
                u,
                flux: disk_and_sky(u),
            }
        })
        .collect();
    let mut storage = vec![GuideNode::default(); 1024];
    let (g, _) = guide::build(&mut records.clone(), &GuideParams::default(), &mut storage);
    let mut c_storage = vec![GuideNode::default(); 1024];
    let mut c_records: Vec<GuidebakeRecord> = records
        .iter()
        .map(|r| GuidebakeRecord {
            u: r.u,
            flux: r.flux,
        })
        .collect();
    let mut handle = GuidebakeGuide { opaque: [0; 8] };
    // SAFETY: valid buffers; the storage outlives the handle.
    let s = unsafe {
        guidebake_guide_build(
            c_records.as_mut_ptr(),
            c_records.len(),
            std::ptr::null(),
            c_storage.as_mut_ptr().cast(),
            1024 * 64,
            &mut handle,
            std::ptr::null_mut(),
        )
    };
    assert_eq!(s, GuidebakeStatus::Ok);
    let xs: Vec<[f32; 8]> = (0..PACKETS)
        .map(|_| std::array::from_fn(|_| rng.next_f32()))
        .collect();
    let ys: Vec<[f32; 8]> = (0..PACKETS)
        .map(|_| std::array::from_fn(|_| rng.next_f32()))
        .collect();
    let mut out = vec![[[0.0f32; 8]; 3]; PACKETS];
    let mut out_abi = out.clone();
    let abi: Sample8 = black_box(guidebake_guide_sample8);

    let rust_pass = |out: &mut [[[f32; 8]; 3]]| {
        for ((x, y), o) in xs.iter().zip(&ys).zip(out.iter_mut()) {
            let w = warp::sample8(black_box(&g), f32x8::new(*x), f32x8::new(*y));
            *o = [w.x.to_array(), w.y.to_array(), w.pdf.to_array()];
        }
    };
    let abi_pass = |out: &mut [[[f32; 8]; 3]]| {
        for ((x, y), o) in xs.iter().zip(&ys).zip(out.iter_mut()) {
            let [ox, oy, op] = o;
            // SAFETY: 8-element arrays and a live handle.
            let s = unsafe {
                abi(
                    &handle,
                    x.as_ptr(),
                    y.as_ptr(),
                    ox.as_mut_ptr(),
                    oy.as_mut_ptr(),
                    op.as_mut_ptr(),
                )
            };
            debug_assert_eq!(s, GuidebakeStatus::Ok);
        }
    };
    // The batched call: all packets in one call, planar arrays.
    let batched: SamplePackets = black_box(guidebake_guide_sample_packets);
    let mut planar = vec![[[0.0f32; 8]; PACKETS]; 3];
    let batch_pass = |planar: &mut [[[f32; 8]; PACKETS]]| {
        let [ox, oy, op] = planar else { unreachable!() };
        // SAFETY: 8·PACKETS floats in every array and a live handle.
        let s = unsafe {
            batched(
                &handle,
                xs.as_ptr().cast(),
                ys.as_ptr().cast(),
                PACKETS,
                ox.as_mut_ptr().cast(),
                oy.as_mut_ptr().cast(),
                op.as_mut_ptr().cast(),
            )
        };
        debug_assert_eq!(s, GuidebakeStatus::Ok);
    };
    rust_pass(&mut out);
    abi_pass(&mut out_abi);
    batch_pass(&mut planar);
    assert_eq!(out, out_abi, "the ABI warps as the kernels do");
    assert!(
        out.iter()
            .enumerate()
            .all(|(p, o)| (0..3).all(|k| o[k] == planar[k][p]))
    );

    let mut group = c.benchmark_group("abi_overhead");
    group.throughput(Throughput::Elements((8 * PACKETS) as u64));
    for round in 1..=ROUNDS {
        group.bench_function(format!("sample8/rust/{round}"), |b| {
            b.iter(|| rust_pass(black_box(&mut out)))
        });
        group.bench_function(format!("sample8/abi/{round}"), |b| {
            b.iter(|| abi_pass(black_box(&mut out_abi)))
        });
        group.bench_function(format!("sample_packets/abi/{round}"), |b| {
            b.iter(|| batch_pass(black_box(&mut planar)))
        });
    }
    group.finish();
}

fn intersect8(c: &mut Criterion<ThreadTime>) {
    // A closed-ish scene: 2000 small triangles scattered in a 10-unit box, packets of eight
    // coherent cosine directions from points inside it (the gather's shape).
    let mut rng = Pcg32::new(20, 9);
    let n = 2000;
    let verts: Vec<f32> = (0..n)
        .flat_map(|_| {
            let c = [
                rng.next_f32() * 10.0,
                rng.next_f32() * 10.0,
                rng.next_f32() * 10.0,
            ];
            let mut v = [0.0f32; 9];
            for (i, x) in v.iter_mut().enumerate() {
                *x = c[i % 3] + rng.next_f32() - 0.5;
            }
            v
        })
        .collect();
    let mut nodes = vec![bytemuck::Zeroable::zeroed(); n - 1];
    let mut tris = vec![bytemuck::Zeroable::zeroed(); n];
    let (mut used, mut bvh) = (0, GuidebakeBvh { opaque: [0; 8] });
    // SAFETY: valid buffers that outlive the handle.
    unsafe {
        let s = guidebake_bvh_build(
            verts.as_ptr(),
            n,
            nodes.as_mut_ptr(),
            n - 1,
            tris.as_mut_ptr(),
            n,
            &mut used,
        );
        assert_eq!(s, GuidebakeStatus::Ok);
        assert_eq!(
            guidebake_bvh_view(nodes.as_ptr(), used, tris.as_ptr(), n, &mut bvh),
            GuidebakeStatus::Ok
        );
    }
    let nodes: &[GuidebakeBvhNode] = &nodes[..used];
    let rust_bvh = BvhRef::new(
        bytemuck::cast_slice::<_, traverse::BinaryNode>(nodes),
        bytemuck::cast_slice::<_, Tri>(&tris),
    )
    .unwrap();
    let packets: Vec<GuidebakeRay8> = (0..PACKETS)
        .map(|_| {
            let org = [
                rng.next_f32() * 10.0,
                rng.next_f32() * 10.0,
                rng.next_f32() * 10.0,
            ];
            let (cx, cy) = (rng.next_f32() * 0.9, rng.next_f32() * 0.9);
            let dirs: [Vec3; 8] = std::array::from_fn(|_| {
                sample_cosine_hemisphere([cx + 0.1 * rng.next_f32(), cy + 0.1 * rng.next_f32()])
            });
            GuidebakeRay8 {
                org: org.map(|o| [o; 8]),
                dir: [0, 1, 2].map(|a| dirs.map(|d| d[a])),
                tmin: [0.0; 8],
                tmax: [f32::INFINITY; 8],
            }
        })
        .collect();
    let fresh = GuidebakeHit8 {
        t: [f32::INFINITY; 8],
        prim: [GUIDEBAKE_NO_HIT; 8],
        ..Default::default()
    };
    let mut hits = vec![fresh; PACKETS];
    let mut hits_abi = hits.clone();
    let abi: Intersect8 = black_box(guidebake_intersect8);

    let rust_pass = |hits: &mut [GuidebakeHit8]| {
        for (p, h) in packets.iter().zip(hits.iter_mut()) {
            let rays = Ray8 {
                org: p.org.map(f32x8::new),
                dir: p.dir.map(f32x8::new),
                tmin: f32x8::new(p.tmin),
                tmax: f32x8::new(p.tmax),
            };
            let mut out = Hit8 {
                t: f32x8::new(fresh.t),
                u: f32x8::new(fresh.u),
                v: f32x8::new(fresh.v),
                prim: u32x8::new(fresh.prim),
            };
            traverse::intersect8(black_box(&rust_bvh), &rays, &mut out);
            *h = GuidebakeHit8 {
                t: out.t.to_array(),
                u: out.u.to_array(),
                v: out.v.to_array(),
                prim: out.prim.to_array(),
            };
        }
    };
    let abi_pass = |hits: &mut [GuidebakeHit8]| {
        for (p, h) in packets.iter().zip(hits.iter_mut()) {
            *h = fresh;
            // SAFETY: valid values and a live handle.
            let s = unsafe { abi(&bvh, p, h, std::ptr::null_mut()) };
            debug_assert_eq!(s, GuidebakeStatus::Ok);
        }
    };
    rust_pass(&mut hits);
    abi_pass(&mut hits_abi);
    assert_eq!(hits, hits_abi, "the ABI traces as the kernels do");
    let hit = hits
        .iter()
        .flat_map(|h| h.prim)
        .filter(|&p| p != GUIDEBAKE_NO_HIT)
        .count();
    assert!(
        hit > PACKETS,
        "the scene is hit ({hit} of {} rays)",
        8 * PACKETS
    );

    let mut group = c.benchmark_group("abi_overhead");
    group.throughput(Throughput::Elements((8 * PACKETS) as u64));
    for round in 1..=ROUNDS {
        group.bench_function(format!("intersect8/rust/{round}"), |b| {
            b.iter(|| rust_pass(black_box(&mut hits)))
        });
        group.bench_function(format!("intersect8/abi/{round}"), |b| {
            b.iter(|| abi_pass(black_box(&mut hits_abi)))
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().with_measurement(ThreadTime);
    targets = sample8, intersect8
}
criterion_main!(benches);
