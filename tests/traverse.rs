//! Per-ray checks of the packet traversal, on the binary and on the wide layout of every
//! tree: every ray's result from `intersect8`, `intersect1` and the brute-force oracle must
//! be equal — hit or not, primitive id, and `t`, `u`, `v` bit for bit (the scalar and 8-wide
//! arithmetic are the same IEEE operations; equal `t` goes to the smallest primitive id).
//! Occlusion likewise. Rays that start within ulps of another triangle (texels in corners)
//! are held to the traversal contract instead (`closest_hit_allowed`, `occlusion_allowed`).

use guidebake_suite::traverse_scenes as scenes;

use glam::Vec3;
use guidebake::bvh::{Bvh, Preset};
use guidebake_kernels::packet::{Hit, Hit8, LANES, Ray, Ray8, offset_origin, triangle_extent};
use guidebake_kernels::testing::Pcg32;
use guidebake_kernels::traverse::{
    Layout, Tri, closest_hit_allowed, intersect_brute, intersect1, intersect8, occluded_brute,
    occluded1, occluded8, occlusion_allowed,
};

/// The triangles of `bvh`'s binary tree, in leaf order (built with
/// [`Bvh::build_with_binary`]): brute force's input.
fn tris(bvh: &Bvh) -> &[Tri] {
    bvh.binary().expect("built with the binary tree").tris()
}

/// The binary and the wide view of `bvh` (built with [`Bvh::build_with_binary`]): every
/// check runs on both.
fn layouts(bvh: &Bvh) -> [Layout<'_>; 2] {
    let binary = bvh.binary().expect("built with the binary tree");
    [Layout::Binary(binary), Layout::Wide(bvh.wide())]
}

/// [`check_layout`] on both layouts of `bvh`; the rays that hit.
fn check_packets(bvh: &Bvh, packets: &[Ray8], what: &str) -> usize {
    let [binary, wide] = layouts(bvh);
    let tris = tris(bvh);
    let hits = check_layout(&binary, tris, packets, &format!("{what}, binary"));
    assert_eq!(
        check_layout(&wide, tris, packets, &format!("{what}, wide")),
        hits
    );
    hits
}

/// Compares every lane of every packet with the scalar traversal and the oracle (brute force
/// over `tris`, the tree's triangles).
fn check_layout(bvh: &Layout<'_>, tris: &[Tri], packets: &[Ray8], what: &str) -> usize {
    let mut hits_seen = 0;
    for (p, packet) in packets.iter().enumerate() {
        let mut hits = Hit8::NONE;
        let mask = intersect8(bvh, packet, &mut hits);
        let blocked = occluded8(bvh, packet);
        for lane in 0..LANES {
            let ray = packet.lane(lane);
            let oracle = intersect_brute(tris, &ray);
            assert_eq!(
                intersect1(bvh, &ray),
                oracle,
                "{what}: packet {p} lane {lane}: {ray:?}"
            );
            assert_eq!(
                hits.lane(lane),
                oracle,
                "{what}: packet {p} lane {lane} (8-wide): {ray:?}"
            );
            assert_eq!(
                mask >> lane & 1 == 1,
                oracle.is_some(),
                "{what}: mask, packet {p}"
            );
            let occ = occluded_brute(tris, &ray);
            assert_eq!(
                occ,
                oracle.is_some(),
                "{what}: occlusion oracle vs closest hit: {ray:?}"
            );
            assert_eq!(occluded1(bvh, &ray), occ, "{what}: occluded1: {ray:?}");
            assert_eq!(
                blocked >> lane & 1 == 1,
                occ,
                "{what}: occluded8 lane {lane}: {ray:?}"
            );
            hits_seen += usize::from(oracle.is_some());
        }
    }
    hits_seen
}

fn random_soup(rng: &mut Pcg32, count: usize, scale: f32, offset: Vec3) -> Vec<[Vec3; 3]> {
    let mut v = |s: f32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * s;
    (0..count)
        .map(|_| {
            let c = v(scale) + offset;
            [
                c + v(0.3 * scale / 4.0),
                c + v(0.3 * scale / 4.0),
                c + v(0.3 * scale / 4.0),
            ]
        })
        .collect()
}

fn unit_dir(rng: &mut Pcg32) -> Vec3 {
    loop {
        let d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        if d.length_squared() > 1e-4 && d.length_squared() <= 1.0 {
            return d;
        }
    }
}

/// Random rays through the soup's box, random `tmin`/`tmax`, some packets sharing an origin with
/// coherent directions (a gather packet), some incoherent.
fn random_packets(rng: &mut Pcg32, count: usize, scale: f32, offset: Vec3) -> Vec<Ray8> {
    (0..count)
        .map(|i| {
            let org = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale + offset;
            let axis = unit_dir(rng);
            let rays: [Ray; LANES] = std::array::from_fn(|_| {
                let (o, d) = if i % 2 == 0 {
                    (org, (axis + unit_dir(rng) * 0.2).normalize())
                } else {
                    (
                        Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale + offset,
                        unit_dir(rng),
                    )
                };
                let tmin = if rng.next_u32().is_multiple_of(4) {
                    rng.next_f32() * scale * 0.3
                } else {
                    0.0
                };
                let tmax = if rng.next_u32().is_multiple_of(4) {
                    tmin + rng.next_f32() * scale
                } else {
                    f32::INFINITY
                };
                Ray::new(o, d, tmin, tmax)
            });
            Ray8::from_rays(&rays)
        })
        .collect()
}

#[test]
fn random_soups_every_preset_match_the_oracle() {
    let mut rng = Pcg32::new(2026, 1);
    for (count, scale) in [(1, 1.0), (7, 1.0), (300, 10.0), (2000, 50.0)] {
        let soup = random_soup(&mut rng, count, scale, Vec3::ZERO);
        let packets = random_packets(&mut rng, 60, scale, Vec3::ZERO);
        for preset in Preset::ALL {
            let bvh = Bvh::build_with_binary(&soup, preset).unwrap();
            let hits = check_packets(&bvh, &packets, &format!("{count} tris, {preset:?}"));
            if count >= 300 {
                assert!(hits > 20, "the ray set must exercise hits ({hits})");
            }
        }
    }
}

#[test]
fn origins_at_1e6_match_the_oracle() {
    let mut rng = Pcg32::new(6, 2);
    let offset = Vec3::new(1.0e6, -1.0e6, 1.0e6);
    let soup = random_soup(&mut rng, 500, 20.0, offset);
    let packets = random_packets(&mut rng, 80, 20.0, offset);
    let bvh = Bvh::build_with_binary(&soup, Preset::DEFAULT).unwrap();
    assert!(check_packets(&bvh, &packets, "1e6") > 20);
}

#[test]
fn non_finite_zero_and_negative_tmin_rays_never_hit_and_leave_lanes_untouched() {
    let mut rng = Pcg32::new(9, 3);
    let soup = random_soup(&mut rng, 200, 1.0, Vec3::ZERO);
    let bvh = Bvh::build_with_binary(&soup, Preset::DEFAULT).unwrap();
    for view in layouts(&bvh) {
        let good = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z, 0.0, f32::INFINITY);
        let bad = [
            Ray::new(Vec3::new(f32::NAN, 0.5, -1.0), Vec3::Z, 0.0, f32::INFINITY),
            Ray::new(
                Vec3::new(0.5, f32::INFINITY, -1.0),
                Vec3::Z,
                0.0,
                f32::INFINITY,
            ),
            Ray::new(good.org, Vec3::new(0.0, f32::NAN, 1.0), 0.0, f32::INFINITY),
            Ray::new(
                good.org,
                Vec3::new(f32::NEG_INFINITY, 0.0, 1.0),
                0.0,
                f32::INFINITY,
            ),
            Ray::new(good.org, Vec3::ZERO, 0.0, f32::INFINITY),
            Ray::new(good.org, Vec3::splat(1e-39), 0.0, f32::INFINITY),
            Ray::new(good.org, Vec3::Z, f32::NAN, f32::INFINITY),
            Ray::new(good.org, Vec3::Z, -1.0, f32::INFINITY),
        ];
        let sentinel = Hit {
            t: -7.0,
            u: 3.0,
            v: 4.0,
            prim: 12345,
        };
        for (i, ray) in bad.iter().enumerate() {
            assert_eq!(intersect1(&view, ray), None, "{ray:?}");
            assert!(!occluded1(&view, ray), "{ray:?}");
            // The bad ray in lane i, good rays elsewhere.
            let mut rays = [good; LANES];
            rays[i % LANES] = *ray;
            let packet = Ray8::from_rays(&rays);
            let mut hits = Hit8::NONE;
            for lane in 0..LANES {
                hits.set_lane(lane, &sentinel);
            }
            let mask = intersect8(&view, &packet, &mut hits);
            assert_eq!(mask >> (i % LANES) & 1, 0);
            assert_eq!(hits.lane(i % LANES), Some(sentinel), "{ray:?}");
            assert_eq!(occluded8(&view, &packet) >> (i % LANES) & 1, 0);
            for lane in (0..LANES).filter(|&l| l != i % LANES) {
                assert_eq!(
                    hits.lane(lane),
                    intersect_brute(tris(&bvh), &good).or(Some(sentinel))
                );
            }
        }
        // Huge but finite directions are traced normally.
        let huge = Ray::new(good.org, Vec3::new(1e-30, 3e-30, 1e30), 0.0, f32::INFINITY);
        check_layout(
            &view,
            tris(&bvh),
            &[Ray8::from_rays(&[huge, good])],
            "huge direction",
        );
    }
}

#[test]
fn inactive_lanes_with_1_to_8_active_come_back_untouched() {
    let mut rng = Pcg32::new(12, 4);
    let soup = random_soup(&mut rng, 400, 4.0, Vec3::ZERO);
    let bvh = Bvh::build_with_binary(&soup, Preset::DEFAULT).unwrap();
    for view in layouts(&bvh) {
        let sentinel = Hit {
            t: 99.0,
            u: -1.0,
            v: -2.0,
            prim: 777,
        };
        for active in 1..=LANES {
            for trial in 0..20 {
                let mut packet = random_packets(&mut rng, 1, 4.0, Vec3::ZERO)[0];
                // A random subset of `active` lanes stays active.
                let mut lanes: Vec<usize> = (0..LANES).collect();
                for k in (1..LANES).rev() {
                    lanes.swap(k, rng.next_u32() as usize % (k + 1));
                }
                for &lane in &lanes[active..] {
                    packet.set_lane(lane, &Ray::INACTIVE);
                }
                let before = packet;
                let mut hits = Hit8::NONE;
                for lane in 0..LANES {
                    hits.set_lane(lane, &sentinel);
                }
                let mask = intersect8(&view, &packet, &mut hits);
                let blocked = occluded8(&view, &packet);
                assert_eq!(packet, before, "rays must not change");
                for lane in 0..LANES {
                    let ray = packet.lane(lane);
                    let oracle = intersect_brute(tris(&bvh), &ray);
                    if lanes[active..].contains(&lane) {
                        assert_eq!(
                            hits.lane(lane),
                            Some(sentinel),
                            "inactive lane {lane}, trial {trial}"
                        );
                        assert_eq!((mask | blocked) >> lane & 1, 0);
                    } else {
                        assert_eq!(
                            hits.lane(lane),
                            oracle.or(Some(sentinel)),
                            "active lane {lane}"
                        );
                        assert_eq!(blocked >> lane & 1 == 1, oracle.is_some());
                    }
                }
            }
        }
        let mut none = Hit8::NONE;
        assert_eq!(intersect8(&view, &Ray8::INACTIVE, &mut none), 0);
        assert_eq!(none, Hit8::NONE);
        assert_eq!(occluded8(&view, &Ray8::INACTIVE), 0);
    }
}

/// A closed, star-shaped mesh: a subdivided octahedron with jittered radii.
fn closed_mesh(rng: &mut Pcg32, level: u32, center: Vec3, radius: f32) -> Vec<[Vec3; 3]> {
    let mut tris: Vec<[Vec3; 3]> = Vec::new();
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    for sx in [-1.0f32, 1.0] {
        for sy in [-1.0f32, 1.0] {
            for sz in [-1.0f32, 1.0] {
                let t = [axes[0] * sx, axes[1] * sy, axes[2] * sz];
                tris.push(if sx * sy * sz > 0.0 {
                    t
                } else {
                    [t[0], t[2], t[1]]
                });
            }
        }
    }
    for _ in 0..level {
        tris = tris
            .iter()
            .flat_map(|t| {
                let m = |a: Vec3, b: Vec3| ((a + b) * 0.5).normalize();
                let (ab, bc, ca) = (m(t[0], t[1]), m(t[1], t[2]), m(t[2], t[0]));
                [[t[0], ab, ca], [ab, t[1], bc], [ca, bc, t[2]], [ab, bc, ca]]
            })
            .collect();
    }
    // Jitter each distinct vertex once (keyed by its bits) so shared vertices stay shared.
    let mut jitter = std::collections::HashMap::new();
    let mut place = |v: Vec3| {
        *jitter
            .entry(v.to_array().map(f32::to_bits))
            .or_insert_with(|| center + v * radius * (0.8 + 0.4 * rng.next_f32()))
    };
    tris.iter().map(|t| t.map(&mut place)).collect()
}

#[test]
fn rays_through_shared_edges_and_vertices_of_a_closed_mesh_never_miss() {
    let mut rng = Pcg32::new(77, 5);
    for (center, radius) in [
        (Vec3::new(0.1, 0.2, 0.3), 1.0),
        (Vec3::new(1.0e6, 2.5e5, -1.0e6), 3.0),
    ] {
        let mesh = closed_mesh(&mut rng, 3, center, radius);
        let bvh = Bvh::build_with_binary(&mesh, Preset::DEFAULT).unwrap();
        for view in layouts(&bvh) {
            let mut misses = 0;
            let mut rays = Vec::new();
            for t in &mesh {
                for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                    // Through a point on the shared edge and through the shared vertex, along the
                    // line through the centre: the mesh is star-shaped about it, so the line crosses
                    // the surface there, from inside and from outside alike. (A ray from an
                    // arbitrary outside point may only graze a ridge, and may rightly miss.)
                    for target in [a + (b - a) * rng.next_f32(), a] {
                        rays.push(Ray::new(center, target - center, 0.0, f32::INFINITY));
                        let from = target + (target - center) * 3.0;
                        rays.push(Ray::new(from, center - from, 0.0, f32::INFINITY));
                    }
                }
            }
            for chunk in rays.chunks(LANES) {
                let packet = Ray8::from_rays(chunk);
                let mut hits = Hit8::NONE;
                let mask = intersect8(&view, &packet, &mut hits);
                let blocked = occluded8(&view, &packet);
                for (lane, ray) in chunk.iter().enumerate() {
                    let one = intersect1(&view, ray);
                    misses += usize::from(one.is_none());
                    assert_eq!(one, intersect_brute(tris(&bvh), ray));
                    assert_eq!(hits.lane(lane), one);
                    assert_eq!(mask >> lane & 1 == 1, one.is_some());
                    assert_eq!(blocked >> lane & 1 == 1, one.is_some());
                }
            }
            assert_eq!(misses, 0, "rays slipped through shared edges at {center}");
        }
    }
}

#[test]
fn grazing_rays_match_the_oracle() {
    // Rays in and just off the plane of an axis-aligned and of a tilted grid of triangles.
    let mut rng = Pcg32::new(31, 6);
    for tilt in [0.0f32, 0.37] {
        let rot = glam::Quat::from_rotation_x(tilt);
        let mut soup = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let p = |a: f32, b: f32| rot * Vec3::new(i as f32 + a, 0.0, j as f32 + b);
                soup.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
                soup.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
            }
        }
        let bvh = Bvh::build_with_binary(&soup, Preset::DEFAULT).unwrap();
        let packets: Vec<Ray8> = (0..100)
            .map(|_| {
                let rays: [Ray; LANES] = std::array::from_fn(|_| {
                    let o =
                        rot * Vec3::new(-1.0, (rng.next_f32() - 0.5) * 1e-5, rng.next_f32() * 20.0);
                    let lift = [0.0, 1e-7, -1e-7, 1e-3][rng.next_u32() as usize % 4];
                    let d = rot * Vec3::new(1.0, lift, rng.next_f32() - 0.5);
                    Ray::new(o, d, 0.0, f32::INFINITY)
                });
                Ray8::from_rays(&rays)
            })
            .collect();
        let hits = check_packets(&bvh, &packets, &format!("grazing, tilt {tilt}"));
        assert!(hits > 0, "some grazing rays must hit");
    }
}

#[test]
fn converted_scenes_match_the_oracle() {
    let Some(dir) = scenes::converted_dir() else {
        println!("skipping: ../shared/scenes/converted not found");
        return;
    };
    for name in [
        "bitterli_cornell_box",
        "bitterli_veach_bidir",
        "bitterli_veach_ajar_no_teapots",
    ] {
        let soup = scenes::load_glb(&dir.join(format!("{name}.glb")));
        assert!(!soup.is_empty(), "{name}: no triangles");
        let gather = scenes::gather_packets(&soup, 6, 64, 1);
        let shadow = scenes::shadow_packets(&soup, soup[0][0] + Vec3::splat(0.1), 0.2, 24, 2);
        let random = scenes::incoherent_packets(&soup, 24, 3);
        for preset in Preset::ALL {
            let bvh = Bvh::build_with_binary(&soup, preset).unwrap();
            let what = format!("{name} {preset:?}");
            let hits = check_packets(&bvh, &gather, &format!("{what} gather"));
            // Surfaces are two-sided and origins face a random side, so rays leaving the
            // outer side of a wall miss: ask only that a fair share hit.
            assert!(hits > gather.len(), "{what}: only {hits} gather rays hit");
            check_packets(&bvh, &shadow, &format!("{what} shadow"));
            check_packets(&bvh, &random, &format!("{what} random"));
        }
    }
}

#[test]
fn offset_origins_avoid_self_intersection_at_1e6() {
    let mut rng = Pcg32::new(404, 7);
    for offset in [
        Vec3::ZERO,
        Vec3::splat(1.0e3),
        Vec3::new(1.0e6, -1.0e6, 1.0e6),
    ] {
        let soup = random_soup(&mut rng, 300, 8.0, offset);
        let bvh = Bvh::build_with_binary(&soup, Preset::DEFAULT).unwrap();
        for view in layouts(&bvh) {
            let (mut self_hits, mut raw_self_hits) = (0, 0);
            for s in scenes::surface_points(&soup, 20000, 8) {
                let n = if rng.next_u32() & 1 == 0 { s.n } else { -s.n };
                let d = scenes::cosine_dir(n, [rng.next_f32(), rng.next_f32()]);
                let origin = offset_origin(s.p, n, triangle_extent(s.p, &soup[s.prim as usize]));
                let safe = Ray::new(origin, d, 0.0, f32::INFINITY);
                self_hits +=
                    usize::from(intersect1(&view, &safe).is_some_and(|h| h.prim == s.prim));
                let raw = Ray::new(s.p, d, 0.0, f32::INFINITY);
                raw_self_hits +=
                    usize::from(intersect1(&view, &raw).is_some_and(|h| h.prim == s.prim));
            }
            assert_eq!(self_hits, 0, "self-intersections at offset {offset}");
            if offset.x.abs() >= 1.0e6 {
                // Without the offset the same rays do hit their own triangle: the check can fail.
                assert!(raw_self_hits > 0, "expected raw self-hits at {offset}");
            }
        }
    }
}

/// Gather packets as the bake traces them from texels in corners: points on a triangle a
/// hair inside one of its edges (10⁻⁴ to 10⁻⁷ of the way to the opposite vertex), where a
/// neighbouring wall, frame or sliver meets it, lifted with [`offset_origin`] to the side a
/// random sign picks; eight cosine directions each.
fn corner_packets(soup: &[[Vec3; 3]], count: usize, seed: u64) -> Vec<Ray8> {
    let mut rng = Pcg32::new(seed, 9);
    scenes::surface_points(soup, count, seed)
        .into_iter()
        .map(|s| {
            let tri = &soup[s.prim as usize];
            let i = rng.next_u32() as usize % 3;
            let (a, b, c) = (tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]);
            let on_edge = a.lerp(b, rng.next_f32());
            let inside = [1.0e-4, 1.0e-5, 1.0e-6, 1.0e-7][rng.next_u32() as usize % 4];
            let p = on_edge.lerp(c, inside);
            let n = if rng.next_u32() & 1 == 0 { s.n } else { -s.n };
            let origin = offset_origin(p, n, triangle_extent(p, tri));
            let dirs: [Vec3; LANES] =
                core::array::from_fn(|_| scenes::cosine_dir(n, [rng.next_f32(), rng.next_f32()]));
            Ray8::from_origin(origin, &dirs, 0.0, f32::INFINITY)
        })
        .collect()
}

/// Every traversal's answer for every lane of `packets` through `bvh`, checked against the
/// traversal contract (`closest_hit_allowed`, `occlusion_allowed`); the number of answers
/// that differ from brute force (over `tris`, the tree's triangles).
fn check_contract(bvh: &Layout<'_>, tris: &[Tri], packets: &[Ray8], what: &str) -> usize {
    let mut differ = 0;
    for (p, packet) in packets.iter().enumerate() {
        let mut hits = Hit8::NONE;
        intersect8(bvh, packet, &mut hits);
        let blocked = occluded8(bvh, packet);
        for lane in 0..LANES {
            let ray = packet.lane(lane);
            let (oracle, occ) = (intersect_brute(tris, &ray), occluded_brute(tris, &ray));
            for (how, got) in [
                ("intersect8", hits.lane(lane)),
                ("intersect1", intersect1(bvh, &ray)),
            ] {
                if got != oracle {
                    differ += 1;
                    assert!(
                        closest_hit_allowed(bvh, &ray, got),
                        "{what}: {how} packet {p} lane {lane}: {got:?} (brute force {oracle:?}) {ray:?}"
                    );
                }
            }
            for (how, got) in [
                ("occluded8", blocked >> lane & 1 == 1),
                ("occluded1", occluded1(bvh, &ray)),
            ] {
                if got != occ {
                    differ += 1;
                    assert!(
                        occlusion_allowed(bvh, &ray, got),
                        "{what}: {how} packet {p} lane {lane}: {got} (brute force {occ}) {ray:?}"
                    );
                }
            }
        }
    }
    differ
}

/// Rays the bake traces from texels in corners can start within a few ulps of another
/// triangle. The watertight test's `t` is then the rounded quotient of terms far larger
/// than itself and can come out positive for a plane crossed behind the origin (module docs
/// of `traverse`, "Hits outside their own box"): such a hit lies outside its leaf's box, so
/// a traversal may or may not test that leaf, and the two layouts and the packet and
/// single-ray walks may answer differently. Every answer must still keep the contract.
#[test]
fn corner_rays_of_a_bake_keep_the_contract_on_both_layouts() {
    let mut soups = vec![("city", scenes::city(6, 2, 3))];
    match scenes::converted_dir() {
        Some(dir) => soups.extend(
            ["bitterli_veach_bidir", "bitterli_veach_ajar_no_teapots"]
                .map(|name| (name, scenes::load_glb(&dir.join(format!("{name}.glb"))))),
        ),
        None => println!("skipping the converted scenes: ../shared/scenes/converted not found"),
    }
    for (name, soup) in &soups {
        let packets = corner_packets(soup, 3000, 17);
        let bvh = Bvh::build_with_binary(soup, Preset::DEFAULT).unwrap();
        for view in layouts(&bvh) {
            let what = format!(
                "{name} {}",
                if matches!(view, Layout::Wide(_)) {
                    "wide"
                } else {
                    "binary"
                }
            );
            let differ = check_contract(&view, tris(&bvh), &packets, &what);
            println!(
                "{what}: {differ} of {} answers differ from brute force",
                packets.len() * LANES * 4
            );
            // 11 and 13 on 2026-11-27: the rays reach the case this test is for (if the
            // triangle test ever makes t's sign exact, this count drops to 0 and may go).
            if *name == "city" {
                assert!(differ > 0, "{what}: no corner ray left the oracle");
            }
        }
    }
}

/// The first such ray found (a bake of Veach's bidir scene, 2026-11-27): it starts 2·10⁻⁶
/// from the edge of a sliver of the door frame (triangle 658), beyond it. In exact arithmetic
/// the ray meets that triangle's plane at t = −2.9·10⁻⁶; the watertight test reports
/// t = +1.15·10⁻⁶, a point outside the sliver's box. Brute force and the binary packet walk
/// report it; the single-ray walks and the wide packet walk cull the sliver's leaf and go
/// on to the wall at 0.152. Both answers keep the contract.
#[test]
fn a_hit_behind_the_origin_rounded_ahead_of_it_is_allowed_either_way() {
    let sliver = [
        Vec3::new(-2.414856, 1.6, 2.663052),
        Vec3::new(-2.414856, 0.2, 2.663052),
        Vec3::new(-2.411322, 0.2, 2.659688),
    ];
    let wall = [
        Vec3::new(-3.0, -5.0, -5.0),
        Vec3::new(-3.0, 10.0, -5.0),
        Vec3::new(-3.0, -5.0, 10.0),
    ];
    let mut rng = Pcg32::new(658, 1);
    let mut soup = random_soup(&mut rng, 200, 2.0, Vec3::new(6.0, 0.0, 6.0));
    soup.push(sliver);
    soup.push(wall);
    let ray = Ray::new(
        Vec3::new(-2.4148579, 0.86818504, 2.6630523),
        Vec3::new(-0.69441444, -0.71014196, 0.11613388),
        0.0,
        f32::INFINITY,
    );
    let near = intersect_brute(
        tris(&Bvh::build_with_binary(&soup, Preset::DEFAULT).unwrap()),
        &ray,
    );
    // The exact crossing lies behind the origin: a triangle test that gets t's sign right
    // makes brute force miss the sliver, and these asserts go.
    let near = near.expect("brute force reports the sliver");
    assert_eq!(near.prim, 200, "{near:?}");
    assert!(near.t > 0.0 && near.t < 1.0e-5, "{near:?}");
    for preset in Preset::ALL {
        let bvh = Bvh::build_with_binary(&soup, preset).unwrap();
        for view in layouts(&bvh) {
            let packet = Ray8::from_origin(ray.org, &[ray.dir; LANES], 0.0, f32::INFINITY);
            check_contract(&view, tris(&bvh), &[packet], &format!("{preset:?}"));
            let got = intersect1(&view, &ray).expect("the sliver or the wall");
            assert!(got.prim == 200 || got.prim == 201, "{preset:?}: {got:?}");
        }
    }
}
