//! Group `traverse`: rays/s of the 8-wide packet traversal on both layouts (binary, two child
//! boxes per node; wide, eight) against the single-ray walks, obvhs's own CwBvh traversal and
//! (feature `embree`) Embree 3, on the same ray sets: coherent gather packets, shadow rays
//! towards a light, incoherent random rays; scenes: the Veach ajar room (if
//! `../shared/scenes` is present) and a procedural ~1M-triangle city.
//!
//! Every comparator's results are checked against the scalar reference once before timing;
//! both layouts' packet and single-ray results must equal it exactly.
//!
//! `cargo bench --bench traverse -- --warm-up-time 1 --measurement-time 5`
//! `cargo bench --bench traverse --features embree -- --warm-up-time 1 --measurement-time 5`
//! Environment:
//! - `TRAVERSE_DUEL=N`: also time the gather and the shadow tracers round-robin for N rounds
//!   (ratios per round: robust on a loaded machine; 0 times none); `-- no_such_bench` skips
//!   criterion.
//! - `TRAVERSE_ONLY=name,...`: in the duel, time only those entries (for a profiler). Under
//!   callgrind, only their passes are counted: `TRAVERSE_ONLY=wide_packet8 TRAVERSE_DUEL=3
//!   valgrind --tool=callgrind --instr-atstart=no --cache-sim=yes --D1=49152,12,64
//!   --LL=2097152,16,64 target/release/deps/traverse-* --bench no_such_bench` (the passes
//!   switch callgrind's instrumentation on and off; natively a few no-op instructions).
//! - `TRAVERSE_SCENES=ajar` (or `city1m`, or `none`): the scenes to run.
//! - `TRAVERSE_PRESET=very_slow` (a `Preset::name`): the build preset of our trees and CwBvh.
//! - `TRAVERSE_PRESETS=1`: build every obvhs preset and time it (build time vs trace time).
//! - `TRAVERSE_SIZES=1e5,1e6,1e7` (`TRAVERSE_SIZE_PRESETS=medium,very_slow`): cities of about
//!   that many triangles: build seconds, the wide tree's size and surface-area cost, and
//!   gather Mrays/s per preset and layout, and
//!   Embree's `rtcIntersect8` on the same packets; `TRAVERSE_GLB=a.glb,...` likewise for the
//!   triangles of scene files.
//! - `TRAVERSE_EMBREE_CONFIG=verbose=2`: appended to Embree's device configuration; `verbose=2`
//!   prints its BVH's statistics (surface-area cost, nodes, leaves), to set beside the wide
//!   tree's cost that every run prints in the same terms.
//!
//! A `gather_resorted` set (each texel's rotated points fully re-sorted) feeds Embree's
//! `rtcIntersect16` two of our packets at a time.

use guidebake_suite::traverse_scenes as scenes;

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Vec3, Vec3A};
use guidebake::bvh::{Bvh, Preset};
use guidebake_kernels::packet::{Hit8, LANES, Ray8};
use guidebake_kernels::traverse::{
    BvhRef, LEAF, Layout, Tree, WideNode, intersect_brute, intersect1, intersect8, occluded1,
    occluded8,
};
use obvhs::cwbvh::{CwBvh, builder::build_cwbvh_from_tris};
use obvhs::ray::{Ray as ORay, RayHit};
use obvhs::triangle::Triangle;

/// Gather set: texels × 256 directions.
const TEXELS: usize = 256;
const PER_TEXEL: usize = 256;

struct Scene {
    name: &'static str,
    soup: Vec<[Vec3; 3]>,
    bvh: Bvh,
    cw: CwBvh,
    cw_tris: Vec<Triangle>,
    light: Vec3,
}

/// The preset named by `TRAVERSE_PRESET` (a [`Preset::name`]), else [`Preset::DEFAULT`].
fn preset() -> Preset {
    let name = std::env::var("TRAVERSE_PRESET").unwrap_or_default();
    Preset::ALL
        .into_iter()
        .find(|p| p.name() == name)
        .unwrap_or(Preset::DEFAULT)
}

/// The binary tree of a bench's BVH (every bench BVH is built with it, as the comparator).
fn binary(bvh: &Bvh) -> BvhRef<'_> {
    bvh.binary().expect("built with the binary tree")
}

fn scene(name: &'static str, soup: Vec<[Vec3; 3]>, light: Vec3) -> Scene {
    let bvh = Bvh::build_with_binary(&soup, preset()).expect("scene BVH");
    let cw_tris: Vec<Triangle> = soup
        .iter()
        .map(|t| Triangle {
            v0: t[0].into(),
            v1: t[1].into(),
            v2: t[2].into(),
        })
        .collect();
    let mut core = std::time::Duration::ZERO;
    let cw = build_cwbvh_from_tris(&cw_tris, preset().params(), &mut core);
    // obvhs traversal indexes primitives in BVH order: lay the triangles out in that order.
    let cw_tris = cw
        .primitive_indices
        .iter()
        .map(|&i| cw_tris[i as usize])
        .collect();
    Scene {
        name,
        soup,
        bvh,
        cw,
        cw_tris,
        light,
    }
}

/// Whether scene `name` is selected by `TRAVERSE_SCENES` (comma-separated; unset: all).
fn wanted(name: &str) -> bool {
    std::env::var("TRAVERSE_SCENES").map_or(true, |v| v.split(',').any(|s| s == name))
}

fn scenes() -> Vec<Scene> {
    let mut out = Vec::new();
    match scenes::converted_dir().filter(|_| wanted("ajar")) {
        Some(dir) => {
            let soup = scenes::load_glb(&dir.join("bitterli_veach_ajar_no_teapots.glb"));
            let (lo, hi) = bounds(&soup);
            out.push(scene(
                "ajar",
                soup,
                (lo + hi) * 0.5 + Vec3::new(0.0, 0.3 * (hi.y - lo.y), 0.0),
            ));
        }
        None if wanted("ajar") => {
            println!("skipping the ajar room: ../shared/scenes/converted not found")
        }
        None => {}
    }
    if wanted("city1m") {
        let city = scenes::city(106, 3, 4);
        out.push(scene("city1m", city, Vec3::new(53.0, 12.0, 53.0)));
    }
    out
}

/// The wide tree's surface-area cost as Embree's `BVHNStatistics` reports it (`verbose=2`):
/// each inner node costs its half area, each leaf its half area per block of four triangles,
/// all relative to the root's half area. Returns (inner, leaves).
fn wide_sah(nodes: &[WideNode]) -> (f64, f64) {
    let half_area = |lo: [f32; 3], hi: [f32; 3]| {
        let e = [0, 1, 2].map(|a| f64::from(hi[a] - lo[a]).max(0.0));
        e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
    };
    let slot =
        |n: &WideNode, c: usize| ([0, 1, 2].map(|a| n.lo[a][c]), [0, 1, 2].map(|a| n.hi[a][c]));
    let root = &nodes[0];
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for c in (0..8).filter(|&c| root.meta[c] != LEAF) {
        let (l, h) = slot(root, c);
        for a in 0..3 {
            lo[a] = lo[a].min(l[a]);
            hi[a] = hi[a].max(h[a]);
        }
    }
    let root_area = half_area(lo, hi);
    let (mut inner, mut leaves) = (1.0, 0.0);
    for n in nodes {
        for c in (0..8).filter(|&c| n.meta[c] != LEAF) {
            let (l, h) = slot(n, c);
            let a = half_area(l, h) / root_area;
            if n.meta[c] == 0 {
                inner += a;
            } else {
                leaves += a * ((n.meta[c] & !LEAF) as f64 / 4.0).ceil();
            }
        }
    }
    (inner, leaves)
}

fn bounds(soup: &[[Vec3; 3]]) -> (Vec3, Vec3) {
    soup.iter()
        .flatten()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        })
}

// ---------------------------------------------------------------------------------------------
// Tracers. Each returns a checksum (hits, or the sum of prim ids) so the work is not elided.

fn packet8(view: &impl Tree, packets: &[Ray8]) -> u64 {
    let mut sum = 0u64;
    for p in packets {
        let mut hits = Hit8::NONE;
        intersect8(view, p, &mut hits);
        sum += hits
            .prim
            .to_array()
            .iter()
            .map(|&x| u64::from(x))
            .sum::<u64>();
    }
    sum
}

fn scalar(view: &impl Tree, packets: &[Ray8]) -> u64 {
    let mut sum = 0u64;
    for p in packets {
        for lane in 0..LANES {
            sum +=
                intersect1(view, &p.lane(lane)).map_or(u64::from(u32::MAX), |h| u64::from(h.prim));
        }
    }
    sum
}

fn occl8(view: &impl Tree, packets: &[Ray8]) -> u64 {
    packets
        .iter()
        .map(|p| u64::from(occluded8(view, p).count_ones()))
        .sum()
}

fn occl1(view: &impl Tree, packets: &[Ray8]) -> u64 {
    packets
        .iter()
        .map(|p| (0..LANES).filter(|&l| occluded1(view, &p.lane(l))).count() as u64)
        .sum()
}

fn oray(p: &Ray8, lane: usize) -> ORay {
    let r = p.lane(lane);
    ORay::new(Vec3A::from(r.org), Vec3A::from(r.dir), r.tmin, r.tmax)
}

fn obvhs_closest(s: &Scene, packets: &[Ray8]) -> u64 {
    let mut sum = 0u64;
    for p in packets {
        for lane in 0..LANES {
            let mut hit = RayHit::none();
            let prim = if s.cw.ray_traverse(oray(p, lane), &mut hit, |ray, id| {
                s.cw_tris[id].intersect(ray)
            }) {
                s.cw.primitive_indices[hit.primitive_id as usize]
            } else {
                u32::MAX
            };
            sum += u64::from(prim);
        }
    }
    sum
}

fn obvhs_occluded(s: &Scene, packets: &[Ray8]) -> u64 {
    let mut n = 0u64;
    for p in packets {
        for lane in 0..LANES {
            n += u64::from(
                !s.cw
                    .ray_traverse_miss(oray(p, lane), |ray, id| s.cw_tris[id].intersect(ray)),
            );
        }
    }
    n
}

/// Per-ray agreement of a comparator's primitive ids with the scalar reference; the watertight
/// and Möller tests may legitimately differ on rays through edges, so a tiny rate is allowed.
fn check_prims(what: &str, reference: &[u32], other: &[u32]) {
    let differ = reference.iter().zip(other).filter(|(a, b)| a != b).count();
    let rate = differ as f64 / reference.len() as f64;
    println!(
        "check {what}: {differ} of {} rays differ from the scalar reference",
        reference.len()
    );
    assert!(
        rate < 2e-3,
        "{what}: {differ} of {} rays differ",
        reference.len()
    );
}

fn prims_of(view: &impl Tree, packets: &[Ray8]) -> Vec<u32> {
    packets
        .iter()
        .flat_map(|p| {
            (0..LANES).map(move |l| intersect1(view, &p.lane(l)).map_or(u32::MAX, |h| h.prim))
        })
        .collect()
}

/// Both layouts' packet and scalar traversals against the binary scalar reference.
fn check_ours(s: &Scene, packets: &[Ray8], reference: &[u32]) {
    for view in [Layout::Binary(binary(&s.bvh)), Layout::Wide(s.bvh.wide())] {
        // Brute force on a sample (it is O(triangles) per ray), exact equality everywhere else.
        for p in packets.iter().step_by(packets.len() / 16 + 1) {
            for l in 0..LANES {
                let r = p.lane(l);
                assert_eq!(
                    intersect1(&view, &r),
                    intersect_brute(binary(&s.bvh).tris(), &r),
                    "{}: scalar vs brute",
                    s.name
                );
            }
        }
        let mut got = Vec::with_capacity(reference.len());
        for p in packets {
            let mut hits = Hit8::NONE;
            intersect8(&view, p, &mut hits);
            got.extend(hits.prim.to_array());
        }
        assert_eq!(got, reference, "{}: packet8 vs scalar", s.name);
        assert_eq!(prims_of(&view, packets), reference, "{}: scalar", s.name);
    }
}

fn bench(c: &mut Criterion) {
    #[cfg(feature = "embree")]
    embree_rt::ftz_daz();
    let mut group = c.benchmark_group("traverse");
    for s in scenes() {
        let view = binary(&s.bvh);
        let wide = s.bvh.wide();
        let binary_bytes = std::mem::size_of_val(view.nodes()) + std::mem::size_of_val(view.tris());
        println!(
            "{}: {} triangles, {} binary nodes, {} wide nodes, {} leaf triangles, build {:?}; \
             {:.1} MB resident as the bake keeps it (wide nodes and leaf rows), {:.1} MB more \
             for the binary tree (nodes and triangles)",
            s.name,
            s.soup.len(),
            view.nodes().len(),
            wide.nodes().len(),
            view.tris().len(),
            s.bvh.build_time(),
            (s.bvh.bytes() - binary_bytes) as f64 / 1e6,
            binary_bytes as f64 / 1e6,
        );
        let (inner, leaves) = wide_sah(wide.nodes());
        println!(
            "{}: wide tree SAH (Embree's statistics: inner nodes 1, leaves one per block of four \
             triangles, relative to the root's half area): {:.3} = inner {inner:.3} + leaves \
             {leaves:.3}",
            s.name,
            inner + leaves
        );
        let sets = [
            (
                "gather",
                scenes::gather_packets(&s.soup, TEXELS, PER_TEXEL, 1),
            ),
            (
                "shadow",
                scenes::shadow_packets(&s.soup, s.light, 0.5, TEXELS * PER_TEXEL / LANES, 2),
            ),
            (
                "incoherent",
                scenes::incoherent_packets(&s.soup, TEXELS * PER_TEXEL / LANES / 4, 3),
            ),
        ];
        #[cfg(feature = "embree")]
        let em = embree_rt::EmbreeScene::new(&s.soup);
        for (kind, packets) in &sets {
            let rays = (packets.len() * LANES) as u64;
            group.throughput(Throughput::Elements(rays));
            let id = |what: &str| format!("{}/{kind}_{what}", s.name);
            let reference = prims_of(&view, packets);
            if *kind == "shadow" {
                let blocked: Vec<u32> = packets
                    .iter()
                    .flat_map(|p| (0..LANES).map(move |l| u32::from(occluded1(&view, &p.lane(l)))))
                    .collect();
                for layout in [Layout::Binary(view), Layout::Wide(wide)] {
                    let packet_blocked: Vec<u32> = packets
                        .iter()
                        .flat_map(|p| {
                            let m = occluded8(&layout, p);
                            (0..LANES).map(move |l| u32::from(m >> l & 1))
                        })
                        .collect();
                    assert_eq!(blocked, packet_blocked, "{}: occluded8", s.name);
                    let single: Vec<u32> = packets
                        .iter()
                        .flat_map(|p| {
                            (0..LANES).map(move |l| u32::from(occluded1(&layout, &p.lane(l))))
                        })
                        .collect();
                    assert_eq!(blocked, single, "{}: occluded1", s.name);
                }
                let ob: Vec<u32> = packets
                    .iter()
                    .flat_map(|p| {
                        (0..LANES).map(|l| {
                            u32::from(!s.cw.ray_traverse_miss(oray(p, l), |ray, i| {
                                s.cw_tris[i].intersect(ray)
                            }))
                        })
                    })
                    .collect();
                check_prims(&id("obvhs"), &blocked, &ob);
                #[cfg(feature = "embree")]
                check_prims(
                    &id("embree_occluded8"),
                    &blocked,
                    &em.occluded8_all(packets, true),
                );
                group.bench_function(id("occluded8"), |b| {
                    b.iter(|| occl8(&view, black_box(packets)))
                });
                group.bench_function(id("wide_occluded8"), |b| {
                    b.iter(|| occl8(&wide, black_box(packets)))
                });
                group.bench_function(id("scalar"), |b| {
                    b.iter(|| occl1(&view, black_box(packets)))
                });
                group.bench_function(id("wide_scalar"), |b| {
                    b.iter(|| occl1(&wide, black_box(packets)))
                });
                group.bench_function(id("obvhs"), |b| {
                    b.iter(|| obvhs_occluded(&s, black_box(packets)))
                });
                #[cfg(feature = "embree")]
                for coherent in [true, false] {
                    let name = if coherent {
                        "embree_occluded8_coherent"
                    } else {
                        "embree_occluded8_incoherent"
                    };
                    group.bench_function(id(name), |b| {
                        b.iter(|| em.occluded8_count(black_box(packets), coherent))
                    });
                }
                continue;
            }
            check_ours(&s, packets, &reference);
            let ob: Vec<u32> = packets
                .iter()
                .flat_map(|p| {
                    (0..LANES).map(|l| {
                        let mut hit = RayHit::none();
                        if s.cw.ray_traverse(oray(p, l), &mut hit, |ray, id| {
                            s.cw_tris[id].intersect(ray)
                        }) {
                            s.cw.primitive_indices[hit.primitive_id as usize]
                        } else {
                            u32::MAX
                        }
                    })
                })
                .collect();
            check_prims(&id("obvhs_cwbvh"), &reference, &ob);
            #[cfg(feature = "embree")]
            {
                check_prims(
                    &id("embree_intersect8"),
                    &reference,
                    &em.intersect8_prims(packets, true),
                );
                check_prims(
                    &id("embree_intersect1"),
                    &reference,
                    &em.intersect1_prims(packets, true),
                );
            }
            group.bench_function(id("packet8"), |b| {
                b.iter(|| packet8(&view, black_box(packets)))
            });
            group.bench_function(id("wide_packet8"), |b| {
                b.iter(|| packet8(&wide, black_box(packets)))
            });
            group.bench_function(id("scalar"), |b| {
                b.iter(|| scalar(&view, black_box(packets)))
            });
            group.bench_function(id("wide_scalar"), |b| {
                b.iter(|| scalar(&wide, black_box(packets)))
            });
            group.bench_function(id("obvhs_cwbvh"), |b| {
                b.iter(|| obvhs_closest(&s, black_box(packets)))
            });
            #[cfg(feature = "embree")]
            for coherent in [true, false] {
                let tag = if coherent { "coherent" } else { "incoherent" };
                group.bench_function(id(&format!("embree_intersect8_{tag}")), |b| {
                    b.iter(|| em.intersect8_sum(black_box(packets), coherent))
                });
                group.bench_function(id(&format!("embree_intersect1_{tag}")), |b| {
                    b.iter(|| em.intersect1_sum(black_box(packets), coherent))
                });
            }
        }
        // The comparator's best case: each texel's rotated points fully re-sorted, so 16
        // consecutive rays (two of our packets) are as coherent as 8 were.
        let resorted = scenes::gather_packets_ordered(
            &s.soup,
            TEXELS,
            PER_TEXEL,
            1,
            scenes::GatherOrder::Resorted,
        );
        let rays = (resorted.len() * LANES) as u64;
        group.throughput(Throughput::Elements(rays));
        let id = |what: &str| format!("{}/gather_resorted_{what}", s.name);
        let reference = prims_of(&view, &resorted);
        check_ours(&s, &resorted, &reference);
        group.bench_function(id("packet8"), |b| {
            b.iter(|| packet8(&view, black_box(&resorted)))
        });
        group.bench_function(id("wide_packet8"), |b| {
            b.iter(|| packet8(&wide, black_box(&resorted)))
        });
        #[cfg(feature = "embree")]
        {
            check_prims(
                &id("embree_intersect16"),
                &reference,
                &em.intersect16_prims(&resorted, true),
            );
            for coherent in [true, false] {
                let tag = if coherent { "coherent" } else { "incoherent" };
                group.bench_function(id(&format!("embree_intersect16_{tag}")), |b| {
                    b.iter(|| em.intersect16_sum(black_box(&resorted), coherent))
                });
                group.bench_function(id(&format!("embree_intersect8_{tag}")), |b| {
                    b.iter(|| em.intersect8_sum(black_box(&resorted), coherent))
                });
            }
        }
        if let Some(rounds) = std::env::var("TRAVERSE_DUEL")
            .ok()
            .and_then(|v| v.parse::<usize>().ok())
            .filter(|&rounds| rounds > 0)
        {
            let gather = &sets[0].1;
            #[cfg_attr(not(feature = "embree"), allow(unused_mut))]
            let mut entries: Vec<DuelEntry<'_>> = vec![
                (
                    "packet8".into(),
                    gather.len(),
                    Box::new(|| packet8(&view, gather)),
                ),
                (
                    "wide_packet8".into(),
                    gather.len(),
                    Box::new(|| packet8(&wide, gather)),
                ),
                (
                    "scalar".into(),
                    gather.len(),
                    Box::new(|| scalar(&view, gather)),
                ),
                (
                    "wide_scalar".into(),
                    gather.len(),
                    Box::new(|| scalar(&wide, gather)),
                ),
                (
                    "obvhs_cwbvh".into(),
                    gather.len(),
                    Box::new(|| obvhs_closest(&s, gather)),
                ),
                (
                    "resorted_packet8".into(),
                    resorted.len(),
                    Box::new(|| packet8(&view, &resorted)),
                ),
                (
                    "resorted_wide_packet8".into(),
                    resorted.len(),
                    Box::new(|| packet8(&wide, &resorted)),
                ),
            ];
            #[cfg(feature = "embree")]
            for coherent in [true, false] {
                let tag = if coherent { "coherent" } else { "incoherent" };
                let em = &em;
                entries.push((
                    format!("embree_intersect8_{tag}"),
                    gather.len(),
                    Box::new(move || em.intersect8_sum(gather, coherent)),
                ));
                entries.push((
                    format!("embree_intersect1_{tag}"),
                    gather.len(),
                    Box::new(move || em.intersect1_sum(gather, coherent)),
                ));
                let resorted = &resorted;
                entries.push((
                    format!("resorted_embree_intersect16_{tag}"),
                    resorted.len(),
                    Box::new(move || em.intersect16_sum(resorted, coherent)),
                ));
                entries.push((
                    format!("resorted_embree_intersect8_{tag}"),
                    resorted.len(),
                    Box::new(move || em.intersect8_sum(resorted, coherent)),
                ));
            }
            duel(
                s.name,
                "gather",
                &entries,
                rounds,
                &["embree_intersect8_coherent", "embree_intersect8_incoherent"],
            );
            let shadow = &sets[1].1;
            #[cfg_attr(not(feature = "embree"), allow(unused_mut))]
            let mut entries: Vec<DuelEntry<'_>> = vec![
                (
                    "occluded8".into(),
                    shadow.len(),
                    Box::new(|| occl8(&view, shadow)),
                ),
                (
                    "wide_occluded8".into(),
                    shadow.len(),
                    Box::new(|| occl8(&wide, shadow)),
                ),
                (
                    "scalar".into(),
                    shadow.len(),
                    Box::new(|| occl1(&view, shadow)),
                ),
                (
                    "wide_scalar".into(),
                    shadow.len(),
                    Box::new(|| occl1(&wide, shadow)),
                ),
                (
                    "obvhs_cwbvh".into(),
                    shadow.len(),
                    Box::new(|| obvhs_occluded(&s, shadow)),
                ),
            ];
            #[cfg(feature = "embree")]
            for coherent in [true, false] {
                let tag = if coherent { "coherent" } else { "incoherent" };
                let em = &em;
                entries.push((
                    format!("embree_occluded8_{tag}"),
                    shadow.len(),
                    Box::new(move || em.occluded8_count(shadow, coherent)),
                ));
            }
            duel(
                s.name,
                "shadow",
                &entries,
                rounds,
                &["embree_occluded8_coherent", "embree_occluded8_incoherent"],
            );
        }
        if std::env::var_os("TRAVERSE_PRESETS").is_some() {
            presets(&s, &sets[0].1);
        }
    }
    group.finish();
    sizes();
}

/// A duel contestant: name, packets per pass, one pass over its ray set (returns a checksum).
type DuelEntry<'a> = (String, usize, Box<dyn Fn() -> u64 + 'a>);

/// Round-robin timing of one ray set's tracers: each round runs every entry once over its ray
/// set (the start rotating from round to round), so all entries see the same machine load
/// within a few tens of milliseconds. Prints per entry the median Mrays/s and the median over
/// rounds of its per-round ratio to `obvhs_cwbvh`, to the first entry (our binary packet
/// traversal) and to the faster of the `embree` entries (per round).
fn duel(scene: &str, set: &str, entries: &[DuelEntry<'_>], rounds: usize, embree: &[&str]) {
    // `TRAVERSE_ONLY=name,...` times only those entries (for a profiler); no ratios.
    if let Ok(only) = std::env::var("TRAVERSE_ONLY") {
        for (name, packets, run) in entries.iter().filter(|e| only.split(',').any(|o| o == e.0)) {
            let start = Instant::now();
            callgrind::instrument(true);
            for _ in 0..rounds {
                black_box(run());
            }
            callgrind::instrument(false);
            let rate = (packets * LANES * rounds) as f64 / start.elapsed().as_secs_f64() / 1e6;
            println!("only {scene} {set} {name}: {rate:.2} Mrays/s");
        }
        return;
    }
    let n = entries.len();
    let mut rates = vec![Vec::with_capacity(rounds); n];
    for round in 0..rounds {
        for k in 0..n {
            let (_, packets, run) = &entries[(round + k) % n];
            let start = Instant::now();
            black_box(run());
            let secs = start.elapsed().as_secs_f64();
            rates[(round + k) % n].push((packets * LANES) as f64 / secs / 1e6);
        }
    }
    let index = |name: &str| entries.iter().position(|e| e.0 == name);
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let obvhs = index("obvhs_cwbvh").expect("obvhs entry");
    let embree8: Vec<usize> = embree.iter().filter_map(|e| index(e)).collect();
    println!(
        "duel {scene} {set}: {rounds} rounds; median Mrays/s, median per-round ratio to obvhs \
         CwBvh, to {} and to Embree's faster {} (per round)",
        entries[0].0,
        embree
            .first()
            .map_or("-", |e| e.trim_end_matches("_coherent"))
    );
    for (k, (name, _, _)) in entries.iter().enumerate() {
        let ratio_to = |other: &[usize]| {
            if other.is_empty() {
                return f64::NAN;
            }
            median(
                (0..rounds)
                    .map(|r| {
                        let best = other.iter().map(|&o| rates[o][r]).fold(0.0, f64::max);
                        rates[k][r] / best
                    })
                    .collect(),
            )
        };
        println!(
            "duel {scene} {set} {name:<36} {:>7.2} Mrays/s  x{:.2} obvhs  x{:.2} binary  x{:.2} embree8",
            median(rates[k].clone()),
            ratio_to(&[obvhs]),
            ratio_to(&[0]),
            ratio_to(&embree8)
        );
    }
}

/// Build time vs gather trace time of every obvhs preset (printed; not a criterion
/// measurement: a build is seconds long on the 1M scene). The traces run round-robin, one
/// pass per preset and layout per round, so every preset sees the same load; medians over
/// the rounds.
fn presets(s: &Scene, packets: &[Ray8]) {
    let built: Vec<(Preset, Bvh)> = Preset::ALL
        .iter()
        .map(|&p| (p, Bvh::build_with_binary(&s.soup, p).expect("preset BVH")))
        .collect();
    report_builds(s.name, &built, packets, 15);
}

/// Traces `packets` through each of `built` (binary and wide packets, round-robin, `rounds`
/// rounds) and prints build seconds and median Mrays/s.
fn report_builds(name: &str, built: &[(Preset, Bvh)], packets: &[Ray8], rounds: usize) {
    let mut rates = vec![[Vec::with_capacity(rounds), Vec::with_capacity(rounds)]; built.len()];
    for round in 0..rounds {
        for k in 0..built.len() {
            let i = (round + k) % built.len();
            let bvh = &built[i].1;
            for (layout, rate) in rates[i].iter_mut().enumerate() {
                let start = Instant::now();
                if layout == 0 {
                    black_box(packet8(&binary(bvh), packets));
                } else {
                    black_box(packet8(&bvh.wide(), packets));
                }
                rate.push((packets.len() * LANES) as f64 / start.elapsed().as_secs_f64() / 1e6);
            }
        }
    }
    for ((preset, bvh), r) in built.iter().zip(rates) {
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let [binary_rates, wide_rates] = r;
        let (inner, leaves) = wide_sah(bvh.wide().nodes());
        println!(
            "preset {name} {:>10}: {} triangles, build {:>9.3} s, {} nodes, {} wide nodes (SAH \
             {:.2} = inner {inner:.2} + leaves {leaves:.2}), gather packet8 {:.2} Mrays/s, wide \
             {:.2} Mrays/s (median of {rounds})",
            preset.name(),
            binary(bvh).tris().len(),
            bvh.build_time().as_secs_f64(),
            binary(bvh).nodes().len(),
            bvh.wide().nodes().len(),
            inner + leaves,
            median(binary_rates),
            median(wide_rates),
        );
    }
}

/// A named world's triangles, made when its turn comes (one big world in memory at a time).
type World = dyn Fn() -> Vec<[Vec3; 3]>;

/// `TRAVERSE_SIZES=1e5,1e6,...`: procedural cities of about these many triangles, built with
/// each preset of `TRAVERSE_SIZE_PRESETS` (names, comma-separated; default `medium,very_slow`):
/// build seconds and gather Mrays/s (256 texels × 64 directions).
///
/// `TRAVERSE_GLB=a.glb,b.glb,...` does the same for the triangles of scene files (e.g. the
/// cities of `guidebake synth`, docs/farm.md "Scale runs").
fn sizes() {
    let names = std::env::var("TRAVERSE_SIZE_PRESETS").unwrap_or("medium,very_slow".into());
    let wanted: Vec<Preset> = Preset::ALL
        .into_iter()
        .filter(|p| names.split(',').any(|n| n == p.name()))
        .collect();
    let mut worlds: Vec<(String, Box<World>)> = Vec::new();
    if let Ok(list) = std::env::var("TRAVERSE_SIZES") {
        for size in list.split(',').map(str::to_owned) {
            let triangles: f64 = size.parse().expect("TRAVERSE_SIZES: numbers like 1e6");
            // About side² · 90 triangles with 3 × 3 quads per box face.
            let side = (triangles / 90.0).sqrt().round().max(2.0) as usize;
            worlds.push((
                format!("city{size}"),
                Box::new(move || scenes::city(side, 3, 4)),
            ));
        }
    }
    if let Ok(list) = std::env::var("TRAVERSE_GLB") {
        for path in list.split(',').map(std::path::PathBuf::from) {
            let name = path
                .file_stem()
                .map_or("glb".into(), |s| s.to_string_lossy().into());
            worlds.push((name, Box::new(move || scenes::load_glb(&path))));
        }
    }
    for (name, soup) in worlds {
        let soup = soup();
        let packets = scenes::gather_packets(&soup, TEXELS, 64, 1);
        let built: Vec<(Preset, Bvh)> = wanted
            .iter()
            .map(|&p| (p, Bvh::build_with_binary(&soup, p).expect("BVH")))
            .collect();
        report_builds(&name, &built, &packets, 5);
        #[cfg(feature = "embree")]
        report_embree(&name, &soup, &packets, 5);
    }
}

/// Embree's `rtcIntersect8` on the same gather packets as [`report_builds`]: whether its
/// rays slow down as much as ours when the world grows (docs/farm.md, "Scale runs").
#[cfg(feature = "embree")]
fn report_embree(name: &str, soup: &[[Vec3; 3]], packets: &[Ray8], rounds: usize) {
    let start = Instant::now();
    let em = embree_rt::EmbreeScene::new(soup);
    let build = start.elapsed().as_secs_f64();
    let mut rates: Vec<f64> = (0..rounds)
        .map(|_| {
            let start = Instant::now();
            black_box(em.intersect8_sum(packets, true));
            (packets.len() * LANES) as f64 / start.elapsed().as_secs_f64() / 1e6
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    println!(
        "embree {name}: {} triangles, build {build:.3} s, gather rtcIntersect8 {:.2} Mrays/s \
         (median of {rounds})",
        soup.len(),
        rates[rounds / 2],
    );
}

#[cfg(feature = "embree")]
mod embree_rt {
    //! Embree 3 through `embree::sys`: one triangle geometry, build quality HIGH, FTZ/DAZ on,
    //! 32-byte aligned valid masks, COHERENT or INCOHERENT context flags.
    use embree::sys::*;
    use glam::Vec3;
    use guidebake_kernels::packet::{LANES, Ray8};

    /// Flush-to-zero and denormals-are-zero, as Embree recommends.
    pub fn ftz_daz() {
        #[cfg(target_arch = "x86_64")]
        {
            let mut csr: u32 = 0;
            // SAFETY: stmxcsr/ldmxcsr read and write this thread's MXCSR only; setting FTZ
            // (bit 15) and DAZ (bit 6) changes denormal handling, nothing else.
            unsafe {
                core::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack));
                csr |= (1 << 15) | (1 << 6);
                core::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, readonly));
            }
        }
    }

    #[repr(C, align(32))]
    struct Valid([i32; 8]);

    #[repr(C, align(64))]
    struct Valid16([i32; 16]);

    pub struct EmbreeScene {
        device: RTCDevice,
        scene: RTCScene,
    }

    fn context(coherent: bool) -> RTCIntersectContext {
        RTCIntersectContext {
            flags: if coherent {
                RTCIntersectContextFlags::COHERENT
            } else {
                RTCIntersectContextFlags::INCOHERENT
            },
            filter: None,
            instID: [u32::MAX],
        }
    }

    impl EmbreeScene {
        pub fn new(soup: &[[Vec3; 3]]) -> Self {
            // SAFETY: plain Embree C API use: the device and scene live as long as `self`; the
            // buffers Embree allocates are written within their `soup.len()`-sized bounds.
            unsafe {
                // `TRAVERSE_EMBREE_CONFIG` appends to the device's configuration (e.g.
                // `verbose=2` prints the BVH's statistics at commit).
                let extra = std::env::var("TRAVERSE_EMBREE_CONFIG").unwrap_or_default();
                let config = std::ffi::CString::new(format!("threads=1,{extra}"))
                    .expect("TRAVERSE_EMBREE_CONFIG has no NUL");
                let device = rtcNewDevice(config.as_ptr());
                assert!(!device.is_null(), "rtcNewDevice failed");
                let scene = rtcNewScene(device);
                rtcSetSceneBuildQuality(scene, RTCBuildQuality::HIGH);
                let geom = rtcNewGeometry(device, RTCGeometryType::TRIANGLE);
                rtcSetGeometryBuildQuality(geom, RTCBuildQuality::HIGH);
                let n = soup.len();
                let vb = rtcSetNewGeometryBuffer(
                    geom,
                    RTCBufferType::VERTEX,
                    0,
                    RTCFormat::FLOAT3,
                    12,
                    3 * n,
                ) as *mut f32;
                let ib =
                    rtcSetNewGeometryBuffer(geom, RTCBufferType::INDEX, 0, RTCFormat::UINT3, 12, n)
                        as *mut u32;
                assert!(!vb.is_null() && !ib.is_null());
                let verts = std::slice::from_raw_parts_mut(vb, 9 * n);
                let idx = std::slice::from_raw_parts_mut(ib, 3 * n);
                for (i, t) in soup.iter().enumerate() {
                    for k in 0..3 {
                        verts[9 * i + 3 * k..9 * i + 3 * k + 3].copy_from_slice(&t[k].to_array());
                        idx[3 * i + k] = (3 * i + k) as u32;
                    }
                }
                rtcCommitGeometry(geom);
                rtcAttachGeometry(scene, geom);
                rtcReleaseGeometry(geom);
                rtcCommitScene(scene);
                Self { device, scene }
            }
        }

        fn rayhit8(p: &Ray8) -> (Valid, RTCRayHit8) {
            let lanes = |v: wide::f32x8| v.to_array();
            let active = p.active().to_bitmask();
            let valid = Valid(std::array::from_fn(|i| {
                if active >> i & 1 == 1 { -1 } else { 0 }
            }));
            // SAFETY: RTCRayHit8 is plain old data (floats and integers); all-zero is valid.
            let mut rh: RTCRayHit8 = unsafe { std::mem::zeroed() };
            rh.ray.org_x = lanes(p.org[0]);
            rh.ray.org_y = lanes(p.org[1]);
            rh.ray.org_z = lanes(p.org[2]);
            rh.ray.dir_x = lanes(p.dir[0]);
            rh.ray.dir_y = lanes(p.dir[1]);
            rh.ray.dir_z = lanes(p.dir[2]);
            rh.ray.tnear = lanes(p.tmin);
            rh.ray.tfar = lanes(p.tmax);
            rh.ray.mask = [u32::MAX; 8];
            rh.hit.geomID = [u32::MAX; 8];
            rh.hit.primID = [u32::MAX; 8];
            (valid, rh)
        }

        fn intersect8(&self, p: &Ray8, coherent: bool) -> [u32; 8] {
            let (valid, mut rh) = Self::rayhit8(p);
            let mut ctx = context(coherent);
            // SAFETY: `valid` and `rh` are 32-byte aligned and live across the call.
            unsafe { rtcIntersect8(valid.0.as_ptr(), self.scene, &mut ctx, &mut rh) };
            std::array::from_fn(|i| {
                if rh.hit.geomID[i] == u32::MAX {
                    u32::MAX
                } else {
                    rh.hit.primID[i]
                }
            })
        }

        /// Two of our packets as one `RTCRayHit16` (64-byte aligned valid mask).
        fn intersect16(&self, p: &[Ray8], coherent: bool) -> [u32; 16] {
            let lanes = |f: &dyn Fn(&Ray8) -> wide::f32x8| -> [f32; 16] {
                let (a, b) = (f(&p[0]).to_array(), f(&p[1]).to_array());
                std::array::from_fn(|i| if i < 8 { a[i] } else { b[i - 8] })
            };
            let active = [p[0].active().to_bitmask(), p[1].active().to_bitmask()];
            let valid = Valid16(std::array::from_fn(|i| {
                if active[i / 8] >> (i % 8) & 1 == 1 {
                    -1
                } else {
                    0
                }
            }));
            // SAFETY: RTCRayHit16 is plain old data (floats and integers); all-zero is valid.
            let mut rh: RTCRayHit16 = unsafe { std::mem::zeroed() };
            rh.ray.org_x = lanes(&|r| r.org[0]);
            rh.ray.org_y = lanes(&|r| r.org[1]);
            rh.ray.org_z = lanes(&|r| r.org[2]);
            rh.ray.dir_x = lanes(&|r| r.dir[0]);
            rh.ray.dir_y = lanes(&|r| r.dir[1]);
            rh.ray.dir_z = lanes(&|r| r.dir[2]);
            rh.ray.tnear = lanes(&|r| r.tmin);
            rh.ray.tfar = lanes(&|r| r.tmax);
            rh.ray.mask = [u32::MAX; 16];
            rh.hit.geomID = [u32::MAX; 16];
            rh.hit.primID = [u32::MAX; 16];
            let mut ctx = context(coherent);
            // SAFETY: `valid` (64-byte aligned) and `rh` live across the call.
            unsafe { rtcIntersect16(valid.0.as_ptr(), self.scene, &mut ctx, &mut rh) };
            std::array::from_fn(|i| {
                if rh.hit.geomID[i] == u32::MAX {
                    u32::MAX
                } else {
                    rh.hit.primID[i]
                }
            })
        }

        pub fn intersect16_prims(&self, packets: &[Ray8], coherent: bool) -> Vec<u32> {
            packets
                .chunks_exact(2)
                .flat_map(|p| self.intersect16(p, coherent))
                .collect()
        }

        pub fn intersect16_sum(&self, packets: &[Ray8], coherent: bool) -> u64 {
            packets
                .chunks_exact(2)
                .map(|p| {
                    self.intersect16(p, coherent)
                        .iter()
                        .map(|&x| u64::from(x))
                        .sum::<u64>()
                })
                .sum()
        }

        fn intersect1(&self, p: &Ray8, lane: usize, coherent: bool) -> u32 {
            let r = p.lane(lane);
            // SAFETY: RTCRayHit is plain old data; all-zero is valid.
            let mut rh: RTCRayHit = unsafe { std::mem::zeroed() };
            rh.ray.org_x = r.org.x;
            rh.ray.org_y = r.org.y;
            rh.ray.org_z = r.org.z;
            rh.ray.dir_x = r.dir.x;
            rh.ray.dir_y = r.dir.y;
            rh.ray.dir_z = r.dir.z;
            rh.ray.tnear = r.tmin;
            rh.ray.tfar = r.tmax;
            rh.ray.mask = u32::MAX;
            rh.hit.geomID = u32::MAX;
            let mut ctx = context(coherent);
            // SAFETY: `rh` and `ctx` live across the call.
            unsafe { rtcIntersect1(self.scene, &mut ctx, &mut rh) };
            if rh.hit.geomID == u32::MAX {
                u32::MAX
            } else {
                rh.hit.primID
            }
        }

        fn occluded8(&self, p: &Ray8, coherent: bool) -> u8 {
            let (valid, mut rh) = Self::rayhit8(p);
            let mut ctx = context(coherent);
            // SAFETY: `valid` and the ray are 32-byte aligned and live across the call.
            unsafe { rtcOccluded8(valid.0.as_ptr(), self.scene, &mut ctx, &mut rh.ray) };
            (0..LANES).fold(0, |m, i| {
                m | u8::from(rh.ray.tfar[i] == f32::NEG_INFINITY) << i
            })
        }

        pub fn intersect8_prims(&self, packets: &[Ray8], coherent: bool) -> Vec<u32> {
            packets
                .iter()
                .flat_map(|p| self.intersect8(p, coherent))
                .collect()
        }

        pub fn intersect1_prims(&self, packets: &[Ray8], coherent: bool) -> Vec<u32> {
            packets
                .iter()
                .flat_map(|p| (0..LANES).map(move |l| self.intersect1(p, l, coherent)))
                .collect()
        }

        pub fn occluded8_all(&self, packets: &[Ray8], coherent: bool) -> Vec<u32> {
            packets
                .iter()
                .flat_map(|p| {
                    let m = self.occluded8(p, coherent);
                    (0..LANES).map(move |l| u32::from(m >> l & 1))
                })
                .collect()
        }

        pub fn intersect8_sum(&self, packets: &[Ray8], coherent: bool) -> u64 {
            packets
                .iter()
                .map(|p| {
                    self.intersect8(p, coherent)
                        .iter()
                        .map(|&x| u64::from(x))
                        .sum::<u64>()
                })
                .sum()
        }

        pub fn intersect1_sum(&self, packets: &[Ray8], coherent: bool) -> u64 {
            packets
                .iter()
                .map(|p| {
                    (0..LANES)
                        .map(|l| u64::from(self.intersect1(p, l, coherent)))
                        .sum::<u64>()
                })
                .sum()
        }

        pub fn occluded8_count(&self, packets: &[Ray8], coherent: bool) -> u64 {
            packets
                .iter()
                .map(|p| u64::from(self.occluded8(p, coherent).count_ones()))
                .sum()
        }
    }

    impl Drop for EmbreeScene {
        fn drop(&mut self) {
            // SAFETY: created in `new`, released once here.
            unsafe {
                rtcReleaseScene(self.scene);
                rtcReleaseDevice(self.device);
            }
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);

/// Callgrind's `START_INSTRUMENTATION` / `STOP_INSTRUMENTATION` client requests (valgrind's
/// `callgrind.h`), so that `--instr-atstart=no` counts only the passes of `TRAVERSE_ONLY`
/// (instruction counts, simulated cache misses: docs/traverse.md, "How it is measured"). Natively
/// the request is a sequence of rotations that leaves every register as it was.
mod callgrind {
    /// Switches instrumentation on or off (no effect outside valgrind or off x86-64).
    pub fn instrument(on: bool) {
        // VG_USERREQ_TOOL_BASE('C', 'T') + 4 (start) or + 5 (stop).
        let request: u64 = (u64::from(b'C') << 24 | u64::from(b'T') << 16) + if on { 4 } else { 5 };
        #[cfg(target_arch = "x86_64")]
        {
            let args = [request, 0, 0, 0, 0, 0];
            // SAFETY: valgrind's client-request preamble: four rotations of `rdi` by 128 bits
            // in all (no change), then `xchg rbx, rbx` (no change); valgrind recognises the
            // sequence and reads the request from `args` through `rax`, answering in `rdx`.
            unsafe {
                core::arch::asm!(
                    "rol rdi, 3", "rol rdi, 13", "rol rdi, 61", "rol rdi, 51", "xchg rbx, rbx",
                    inout("rdx") 0u64 => _,
                    in("rax") args.as_ptr(),
                    inout("rdi") 0u64 => _,
                    options(nostack),
                );
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = request;
    }
}
