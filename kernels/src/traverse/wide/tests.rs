//! The wide tree's box tests, single ray ([`super::walk`]) and packet lanes
//! ([`super::packet_walk`]), against the binary traversal's `box1` and each other.
use super::packet_walk::{Lanes, boxes8};
use super::walk::Ray1x8;
use super::*;
use crate::packet::mask_of;
use crate::packet::{LANES, Ray, Ray8};
use crate::traverse::slab::exact;
use crate::traverse::slab::{slab, slab8};
use crate::traverse::{LEAF, Pre, Pre8};
use glam::Vec3;
use std::vec::Vec;
use wide::f32x8;

/// The slots of `node` that [`crate::traverse::scalar::box1_at`] keeps for `ray`, as bits.
fn reference_bits(node: &WideNode, ray: &Ray) -> u8 {
    let pre = Pre::new(ray);
    (0..WIDTH).fold(0, |bits, k| {
        let kept = crate::traverse::box1_at(node.slot_box(k), &pre, ray.tmax).is_some();
        bits | u8::from(kept) << k
    })
}

/// The wide test's slots met for `ray` in the form `EXACT`, and their entry distances: as
/// a single ray ([`Ray1x8::boxes`]) and as lane `lane` of a packet of copies ([`boxes8`]),
/// which must agree.
fn wide_bits_in<const EXACT: bool>(node: &WideNode, ray: &Ray, lane: usize) -> (u8, f32x8) {
    let (single, near) = Ray1x8::<EXACT>::new(&Pre::new(ray)).boxes(node, ray.tmax);
    let pre8 = Pre8::new(&Ray8::from_rays(&[*ray; LANES]));
    let lanes = Lanes::<EXACT>::new(&pre8);
    let (met, nearest) = boxes8(node, &lanes, 1 << lane, &[ray.tmax; LANES]);
    let packet = met
        .to_array()
        .iter()
        .enumerate()
        .fold(0u8, |bits, (k, &m)| {
            bits | u8::from(m >> lane & 1 == 1) << k
        });
    assert_eq!(single, packet, "{ray:?}");
    let inf = f32x8::splat(f32::INFINITY);
    let near = mask_of(single).select(near, inf);
    assert_eq!(
        near.to_array().map(f32::to_bits),
        nearest.to_array().map(f32::to_bits)
    );
    (single, near)
}

/// The wide test's slots met for `ray`, in the form the walks take for it
/// ([`crate::traverse::slab::exact`]).
fn fused_bits(node: &WideNode, ray: &Ray, lane: usize) -> u8 {
    if exact(&Pre::new(ray).inv) {
        wide_bits_in::<true>(node, ray, lane).0
    } else {
        wide_bits_in::<false>(node, ray, lane).0
    }
}

#[test]
fn the_fused_slab_test_keeps_every_box_the_reference_keeps() {
    let mut rng = crate::testing::Pcg32::new(19, 7);
    let mut unit = || rng.next_f32();
    let (mut kept, mut extra) = (0u32, 0u32);
    for trial in 0..20_000 {
        // Origins near the world's origin, at 10⁶, and on the boxes' faces; directions
        // generic, or with a component ±0 or subnormal (infinite inverse).
        let scale = [1.0, 100.0, 1e6][trial % 3];
        let mut node = WideNode::EMPTY;
        let mut boxes = Vec::new();
        for k in 0..WIDTH {
            let c = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale;
            let h = Vec3::new(unit(), unit(), unit()) * scale * 0.3 * unit();
            node.set_slot(k, (c - h).to_array(), (c + h).to_array(), 0, 0);
            boxes.push((c - h, c + h));
        }
        // Towards a box's centre, give or take, from near the world's origin or from 10⁶.
        let (lo, hi) = boxes[trial / 2 % WIDTH];
        let face = if trial / 4 % 2 == 0 { lo } else { hi };
        let mut org = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale;
        let aim = (lo + hi) * 0.5 - org;
        let jitter = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * 0.2;
        let mut dir = aim + jitter * aim.length();
        let axis = trial / 3 % 3;
        match trial / 9 % 4 {
            0 => {}
            // In the plane of the aimed box's face, along it (`(p − o)·∞` is NaN there);
            // every other time that plane moved to 0, where `o·inv` is exact.
            1 => {
                org[axis] = face[axis];
                dir[axis] = if trial / 72 % 2 == 0 { 0.0 } else { -0.0 };
                if trial / 36 % 2 == 0 {
                    let shift = Vec3::AXES[axis] * face[axis];
                    let k = trial / 2 % WIDTH;
                    node.set_slot(k, (lo - shift).to_array(), (hi - shift).to_array(), 0, 0);
                    org[axis] = 0.0;
                }
            }
            2 => dir[axis] = f32::from_bits(1) * if trial / 72 % 2 == 0 { 1.0 } else { -1.0 },
            // On the aimed box's face or an ulp or two off it, leaving or entering.
            _ => org[axis] = f32::from_bits(face[axis].to_bits() + (trial % 3) as u32),
        }
        let tmax = [f32::INFINITY, scale * unit()][trial % 2];
        let ray = Ray::new(org, dir.normalize_or(Vec3::X), 0.0, tmax);
        let (reference, fused) = (
            reference_bits(&node, &ray),
            fused_bits(&node, &ray, trial % LANES),
        );
        assert_eq!(reference & !fused, 0, "a box culled: {ray:?} {node:?}");
        if exact(&Pre::new(&ray).inv) {
            assert_eq!(
                reference, fused,
                "the exact form is box1's: {ray:?} {node:?}"
            );
        }
        kept += reference.count_ones();
        extra += (fused & !reference).count_ones();
    }
    assert!(kept > 5_000, "the test must keep boxes ({kept})");
    // Conservative, not loose: the fused test meets few boxes the reference culls.
    assert!(extra * 100 < kept, "{extra} extra of {kept}");
}

/// The exact form ([`crate::traverse::slab::plane8`] with `EXACT`), single ray and packet
/// lane, is [`box1`](crate::traverse::scalar::box1) bit for bit: the same slots met and the
/// same entry distances, for rays with infinite inverse components (which take it) and
/// for generic ones (which do not, but may: a packet with one such lane tests all lanes
/// so); and `Pre8::exact` marks exactly the traced lanes that take it as single rays.
#[test]
fn the_exact_slab_test_is_box1_bit_for_bit() {
    let mut rng = crate::testing::Pcg32::new(41, 3);
    let mut unit = || rng.next_f32();
    let mut kept = 0u32;
    for trial in 0..20_000 {
        let scale = [1.0, 1e3, 1e6, 1e30][trial % 4];
        let mut node = WideNode::EMPTY;
        for k in 0..WIDTH - trial % 3 {
            let c = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale;
            let h = Vec3::new(unit(), unit(), unit()) * scale * 0.3 * unit();
            node.set_slot(k, (c - h).to_array(), (c + h).to_array(), 0, 0);
        }
        let (lo, hi) = node.slot_box(trial % (WIDTH - 2));
        let mut org = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * scale * 4.0;
        // Towards the aimed box's centre, give or take.
        let jitter = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * 0.3;
        let mut dir = ((Vec3::from(lo) + Vec3::from(hi)) * 0.5 - org) / scale;
        dir = dir.normalize_or(Vec3::X) + jitter;
        let axis = trial / 4 % 3;
        let tiny = [0.0, -0.0, f32::from_bits(1), -1e-40, 3e-39][trial / 12 % 5];
        match trial / 60 % 4 {
            0 => {}
            // Inside the aimed box's slab, the axis's component tiny or ±0.
            1 => {
                org[axis] = lo[axis] + (hi[axis] - lo[axis]) * unit();
                dir[axis] = tiny;
            }
            // In a face's plane, the component tiny or ±0 (`(p − o)·∞` is NaN).
            2 => {
                org[axis] = if trial % 2 == 0 { lo[axis] } else { hi[axis] };
                dir[axis] = tiny;
            }
            // Two components tiny: along an axis, far away.
            _ => {
                org = Vec3::from(lo.map(|l| l * 0.5)) - Vec3::AXES[axis] * 1e38;
                dir = Vec3::AXES[axis] + Vec3::AXES[(axis + 1) % 3] * tiny;
            }
        }
        let tmin = [0.0, scale * unit()][trial / 2 % 2];
        let tmax = [f32::INFINITY, f32::MAX, scale * 8.0 * unit()][trial % 3];
        let ray = Ray::new(org, dir, tmin, tmax);
        if !crate::traverse::triangle::traceable(&ray) {
            continue;
        }
        let pre = Pre::new(&ray);
        let (bits, near) = wide_bits_in::<true>(&node, &ray, trial % LANES);
        for k in 0..WIDTH {
            let reference = crate::traverse::box1_at(node.slot_box(k), &pre, ray.tmax);
            assert_eq!(
                reference.map(f32::to_bits),
                (bits >> k & 1 == 1).then(|| near.as_array()[k].to_bits()),
                "slot {k}: {ray:?} {node:?}"
            );
            kept += u32::from(reference.is_some());
        }
        // The packet's mark of lanes that need the exact form: this lane and no other.
        let mut rays = [Ray::new(Vec3::ZERO, Vec3::ONE, 0.0, 1.0); LANES];
        rays[trial % LANES] = ray;
        let pre8 = Pre8::new(&Ray8::from_rays(&rays));
        assert_eq!(
            pre8.exact,
            u8::from(exact(&pre.inv)) << (trial % LANES),
            "{ray:?}"
        );
    }
    assert!(kept > 5_000, "the test must keep boxes ({kept})");
}

/// Issue 43: along an axis of infinite inverse direction, a ray inside a box's slab meets
/// the box at any distance along the others, as [`box1`](crate::traverse::scalar::box1)
/// (`(hi − o)·∞ = ∞`) does; the fused test's former stand-in `2¹⁰⁰` (slack `2⁶⁰`) culled
/// it beyond `(hi − o)·2¹⁰⁰ + 2⁶⁰`.
#[test]
fn an_infinite_inverse_meets_boxes_at_any_distance() {
    let mut node = WideNode::EMPTY;
    node.set_slot(0, [0.0, -0.25, -0.25], [0.0, 0.25, 0.25], 0, LEAF | 1);
    for x in [-1e15, -1e30, -1e38, -3e38] {
        for dy in [0.0, -0.0, 3e-45, -1.5e-40] {
            let ray = Ray::new(
                Vec3::new(x, 0.1, 0.05),
                Vec3::new(1.0, dy, 0.0),
                0.0,
                f32::MAX,
            );
            assert_eq!(reference_bits(&node, &ray), 1, "{ray:?}");
            for lane in [0, 5] {
                assert_eq!(fused_bits(&node, &ray, lane), 1, "{ray:?}");
            }
        }
    }
}

#[test]
fn the_fused_slab_test_culls_the_box_an_offset_origin_leaves() {
    // A gather ray leaves a box's top face from an origin lifted by `offset_origin` (two
    // to four ulps): the box lies behind it, and both tests must cull it (a looser
    // offset slack met 2 % more slots on the 1M-triangle city).
    let mut rng = crate::testing::Pcg32::new(23, 5);
    let mut unit = || rng.next_f32();
    for trial in 0..20_000 {
        let scale = [1.0, 100.0, 1e4, 1e6][trial % 4];
        let top = (unit() + 0.01) * scale;
        let lo = [-scale, top - scale, -scale];
        let mut node = WideNode::EMPTY;
        node.set_slot(0, lo, [scale, top, scale], 0, 0);
        let p = Vec3::new(unit() - 0.5, 0.0, unit() - 0.5) * scale + Vec3::Y * top;
        let mut org = crate::packet::offset_origin(p, Vec3::Y, 0.0);
        // Unfused (no FMA), the offsets' slack is twice as wide: lift the origin twice.
        if cfg!(not(all(target_feature = "avx", target_feature = "fma"))) {
            org = crate::packet::offset_origin(org, Vec3::Y, 0.0);
        }
        let up = Vec3::new(unit() - 0.5, unit() + 0.05, unit() - 0.5).normalize();
        let ray = Ray::new(org, up, 0.0, f32::INFINITY);
        assert_eq!(reference_bits(&node, &ray), 0, "{ray:?}");
        assert_eq!(
            fused_bits(&node, &ray, trial % LANES),
            0,
            "{ray:?} {node:?}"
        );
    }
}

#[test]
fn the_fused_slab_constants_are_the_same_8_wide_and_scalar() {
    let mut rng = crate::testing::Pcg32::new(31, 1);
    let special = [
        0.0,
        -0.0,
        f32::from_bits(1),
        1e-30,
        1e30,
        f32::INFINITY,
        3.0e38,
    ];
    for trial in 0..4000 {
        let pick = |rng: &mut crate::testing::Pcg32, k: usize| {
            let x = (rng.next_f32() - 0.5) * [1.0, 1e6, 1e-3][k % 3];
            if k.is_multiple_of(5) {
                special[k / 5 % special.len()] * x.signum()
            } else {
                x
            }
        };
        let o: [f32; LANES] = core::array::from_fn(|i| pick(&mut rng, trial + i));
        let inv: [f32; LANES] = core::array::from_fn(|i| pick(&mut rng, trial * 7 + i));
        let wide = slab8(f32x8::from(o), f32x8::from(inv)).map(f32x8::to_array);
        for i in 0..LANES {
            let scalar = slab(o[i], inv[i]);
            for c in 0..3 {
                // Bit for bit, except NaN's sign and payload.
                let (w, s) = (wide[c][i], scalar[c]);
                assert!(
                    w.to_bits() == s.to_bits() || w.is_nan() && s.is_nan(),
                    "{o:?} {inv:?}"
                );
            }
        }
    }
}
