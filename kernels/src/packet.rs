//! # packet: `Ray8` / `Hit8`, eight rays in structure-of-arrays form
//!
//! Silvennoinen & Sloan 2019, §2.4: a texel's final-gather rays leave one origin and, once the
//! Sobol points are presorted, each group of eight directions is coherent. [`Ray8`] carries such
//! a group (or any eight rays) lane by lane for the 8-wide traversal in
//! [`traverse`](crate::traverse); [`Ray`] / [`Hit`] are the single-ray forms used by the scalar
//! reference and by callers that fill packets lane by lane.
//!
//! Conventions (Embree's `RTCRay8`, with its inactive-lane rule):
//! - a lane is **active** when `tmin <= tmax`; an inactive lane has `tmin = +∞`, `tmax = −∞`
//!   ([`Ray8::INACTIVE`]) and the traversal leaves its `Hit8` lane untouched;
//! - a lane is **traceable** when it is active, its origin and direction are finite, and the
//!   direction's largest component is at least `f32::MIN_POSITIVE` ([`Ray::is_traceable`]).
//!   Active lanes that are not traceable (NaN/∞ components, zero direction) never hit; their
//!   `Hit8` lanes are left untouched as well, so NaN and ∞ never reach an output;
//! - masks are all-ones or all-zeros per lane (`f32x8` compare results); bit masks are `u8`
//!   with bit `i` for lane `i`.
//!
//! Hits are reported on `[tmin, tmax]`, both ends included; `t` is the ray parameter, so
//! directions need not be unit length.
//!
//! Rays leaving a surface start at [`offset_origin`] (Wächter & Binder, Ray Tracing Gems
//! ch. 6), which lifts the surface point off its own triangle by a few ulps.

use glam::Vec3;
use wide::{f32x8, u32x8};

/// Number of lanes in a packet.
pub const LANES: usize = 8;

/// The lanes (or a wide node's slots) of `bits` as a mask vector: lane `i` all ones where
/// bit `i` is set, zero elsewhere. Without a branch per lane (a branch per lane on the live
/// lanes mispredicted where lanes finish at random: docs/traverse.md, "What each kept change
/// bought").
#[inline(always)]
pub(crate) fn mask_of(bits: u8) -> wide::f32x8 {
    use wide::u32x8;
    const BITS: u32x8 = u32x8::new([1, 2, 4, 8, 16, 32, 64, 128]);
    bytemuck::cast(!(u32x8::splat(u32::from(bits)) & BITS).simd_eq(u32x8::ZERO))
}

/// The lanes whose bit is set in the lane mask `bits` (as the packet traversals return
/// them), lowest first.
#[inline(always)]
pub fn set_lanes(bits: u8) -> impl Iterator<Item = usize> {
    let mut rest = bits;
    core::iter::from_fn(move || {
        (rest != 0).then(|| {
            let i = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            i
        })
    })
}

/// Primitive id of a lane that has not hit anything.
pub const NO_HIT: u32 = u32::MAX;

/// One ray: `origin + t · dir` for `t` in `[tmin, tmax]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub org: Vec3,
    /// Direction (any length above `f32::MIN_POSITIVE` in its largest component).
    pub dir: Vec3,
    /// Smallest accepted hit distance (inclusive).
    pub tmin: f32,
    /// Largest accepted hit distance (inclusive); `f32::INFINITY` for an unbounded ray.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `[tmin, tmax]`.
    pub const fn new(org: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Self {
            org,
            dir,
            tmin,
            tmax,
        }
    }

    /// The inactive ray: `tmin = +∞`, `tmax = −∞`.
    pub const INACTIVE: Self = Self::new(Vec3::ZERO, Vec3::ZERO, f32::INFINITY, f32::NEG_INFINITY);

    /// Whether the ray is active (`tmin <= tmax`; false when either is NaN).
    pub fn is_active(&self) -> bool {
        self.tmin <= self.tmax
    }

    /// Whether the traversal will trace this ray: active, finite origin and direction, and a
    /// direction whose largest component is at least `f32::MIN_POSITIVE`.
    pub fn is_traceable(&self) -> bool {
        self.is_active()
            && self.org.is_finite()
            && self.dir.is_finite()
            && self.dir.abs().max_element() >= f32::MIN_POSITIVE
    }
}

/// One hit: distance, barycentrics and primitive id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// Primitive id (index into the caller's triangle soup).
    pub prim: u32,
}

/// Eight rays, structure of arrays, 32-byte aligned lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct Ray8 {
    /// Origins, x, y, z.
    pub org: [f32x8; 3],
    /// Directions, x, y, z.
    pub dir: [f32x8; 3],
    /// Smallest accepted hit distances.
    pub tmin: f32x8,
    /// Largest accepted hit distances.
    pub tmax: f32x8,
}

impl Ray8 {
    /// All eight lanes inactive.
    pub const INACTIVE: Self = Self {
        org: [f32x8::ZERO; 3],
        dir: [f32x8::ZERO; 3],
        tmin: f32x8::splat(f32::INFINITY),
        tmax: f32x8::splat(f32::NEG_INFINITY),
    };

    /// Eight rays from up to eight single rays; lanes past `rays.len()` are inactive.
    ///
    /// # Panics
    /// If `rays.len() > 8`.
    pub fn from_rays(rays: &[Ray]) -> Self {
        assert!(rays.len() <= LANES, "a Ray8 holds at most 8 rays");
        let mut packet = Self::INACTIVE;
        for (lane, ray) in rays.iter().enumerate() {
            packet.set_lane(lane, ray);
        }
        packet
    }

    /// Eight rays sharing one origin (a texel's gather packet), all over `[tmin, tmax]`.
    pub fn from_origin(org: Vec3, dirs: &[Vec3; LANES], tmin: f32, tmax: f32) -> Self {
        let column = |f: fn(&Vec3) -> f32| f32x8::new(core::array::from_fn(|i| f(&dirs[i])));
        Self {
            org: [
                f32x8::splat(org.x),
                f32x8::splat(org.y),
                f32x8::splat(org.z),
            ],
            dir: [column(|d| d.x), column(|d| d.y), column(|d| d.z)],
            tmin: f32x8::splat(tmin),
            tmax: f32x8::splat(tmax),
        }
    }

    /// Writes lane `lane`.
    ///
    /// # Panics
    /// If `lane >= 8`.
    pub fn set_lane(&mut self, lane: usize, ray: &Ray) {
        let put = |v: &mut f32x8, x: f32| v.as_mut_array()[lane] = x;
        put(&mut self.org[0], ray.org.x);
        put(&mut self.org[1], ray.org.y);
        put(&mut self.org[2], ray.org.z);
        put(&mut self.dir[0], ray.dir.x);
        put(&mut self.dir[1], ray.dir.y);
        put(&mut self.dir[2], ray.dir.z);
        put(&mut self.tmin, ray.tmin);
        put(&mut self.tmax, ray.tmax);
    }

    /// Reads lane `lane`.
    ///
    /// # Panics
    /// If `lane >= 8`.
    pub fn lane(&self, lane: usize) -> Ray {
        let get = |v: &f32x8| v.as_array()[lane];
        Ray {
            org: Vec3::new(get(&self.org[0]), get(&self.org[1]), get(&self.org[2])),
            dir: Vec3::new(get(&self.dir[0]), get(&self.dir[1]), get(&self.dir[2])),
            tmin: get(&self.tmin),
            tmax: get(&self.tmax),
        }
    }

    /// Lane mask of active lanes (`tmin <= tmax`).
    pub fn active(&self) -> f32x8 {
        self.tmin.simd_le(self.tmax)
    }

    /// Lane mask of traceable lanes, lane for lane equal to [`Ray::is_traceable`].
    pub fn traceable(&self) -> f32x8 {
        let finite = |v: &[f32x8; 3]| v[0].is_finite() & v[1].is_finite() & v[2].is_finite();
        let largest = self.dir[0]
            .abs()
            .max(self.dir[1].abs())
            .max(self.dir[2].abs());
        self.active()
            & finite(&self.org)
            & finite(&self.dir)
            & largest.simd_ge(f32x8::splat(f32::MIN_POSITIVE))
    }
}

/// Eight hits, structure of arrays. A lane the traversal did not hit keeps its old value.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct Hit8 {
    /// Ray parameters of the hits.
    pub t: f32x8,
    /// Barycentric weights of the second vertices.
    pub u: f32x8,
    /// Barycentric weights of the third vertices.
    pub v: f32x8,
    /// Primitive ids, [`NO_HIT`] where nothing was hit.
    pub prim: u32x8,
}

impl Hit8 {
    /// No lane hit: `t = +∞`, barycentrics 0, primitive [`NO_HIT`].
    pub const NONE: Self = Self {
        t: f32x8::splat(f32::INFINITY),
        u: f32x8::ZERO,
        v: f32x8::ZERO,
        prim: u32x8::splat(NO_HIT),
    };

    /// Lane `lane` as a [`Hit`], or `None` when its primitive is [`NO_HIT`].
    ///
    /// # Panics
    /// If `lane >= 8`.
    pub fn lane(&self, lane: usize) -> Option<Hit> {
        let prim = self.prim.as_array()[lane];
        (prim != NO_HIT).then(|| Hit {
            t: self.t.as_array()[lane],
            u: self.u.as_array()[lane],
            v: self.v.as_array()[lane],
            prim,
        })
    }

    /// Writes lane `lane`.
    ///
    /// # Panics
    /// If `lane >= 8`.
    pub fn set_lane(&mut self, lane: usize, hit: &Hit) {
        self.t.as_mut_array()[lane] = hit.t;
        self.u.as_mut_array()[lane] = hit.u;
        self.v.as_mut_array()[lane] = hit.v;
        self.prim.as_mut_array()[lane] = hit.prim;
    }
}

// ---------------------------------------------------------------------------------------------
// Ray origins.

/// Offsets a surface point along its geometric normal so a ray leaving it does not hit its own
/// surface, by as little as the rounding allows.
///
/// Two errors decide on which side of its own plane a ray's origin ends up (after Wächter &
/// Binder, *A Fast and Robust Method for Avoiding Self-Intersection*, Ray Tracing Gems ch. 6,
/// 2019, whose per-axis scaling this keeps):
/// - **where the point is**: `p` was interpolated from the vertices and rounded, and the
///   offset origin is rounded again, so on axis `i` it is off by a few ulps of `|p_i|` —
///   the floating-point spacing, which grows with the distance from the world's origin;
/// - **where the surface is**: the watertight test ([`intersect1`](crate::traverse::intersect1)) works with the vertices
///   relative to the origin, so its distances err by a few ulps of the triangle's size seen
///   from the origin, `extent` — the largest `|v − p|` over the triangle's vertices
///   ([`triangle_extent`]), plus the hit distance for a point computed as `o + t·d`.
///
/// So axis `i` moves by `n_i · (2·|p_i| + 4·extent) · ε` (ε = [`f32::EPSILON`]): two to four
/// ulps of the coordinate plus four ulps of the triangle's size. That is 25 cm at 10⁶ along
/// the normal axis (the f32 spacing there is 6.25 cm), 2.4 mm at 10⁴, 0.5 µm on a 1 m
/// triangle at the origin and 0.7 mm on a 1.4 km one. One to two ulps of the coordinate
/// left self-hits on `tests/traverse.rs`'s random soups (2 of 4 000 points, rays leaving
/// straight up that hit their own triangle 2·10⁻⁸ ahead: the interpolated point was off by
/// about an ulp on each axis); 1.5 to 3 ulps left none in 40 000.
/// (Wächter & Binder's 256 ulps were 16 m at 10⁶. Their fixed 1.5·10⁻⁵ near the origin was
/// too little for a grazing ray on a kilometre-sized triangle, where the test's distance is
/// only known to ~10⁻⁴. Both were failures of `tests/stress.rs`.) Sideways coordinates do
/// not lift the origin: `n_i` is 0 on the axes the surface extends along.
///
/// `n` must be the side the ray leaves from (flip it for rays into the back side); it need not
/// be unit length but should be about unit scale.
pub fn offset_origin(p: Vec3, n: Vec3, extent: f32) -> Vec3 {
    const POINT_ULPS: f32 = 2.0 * f32::EPSILON;
    const EXTENT_ULPS: f32 = 4.0 * f32::EPSILON;
    let lift = |p: f32, n: f32| p + n * (POINT_ULPS * p.abs() + EXTENT_ULPS * extent);
    Vec3::new(lift(p.x, n.x), lift(p.y, n.y), lift(p.z, n.z))
}

/// The size of triangle `tri` seen from `p` for [`offset_origin`]: the largest coordinate
/// of `v − p` over its vertices (0 for a non-finite triangle).
pub fn triangle_extent(p: Vec3, tri: &[Vec3; 3]) -> f32 {
    let e = tri
        .iter()
        .fold(0.0f32, |e, &v| e.max((v - p).abs().max_element()));
    if e.is_finite() { e } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;

    fn random_ray(rng: &mut Pcg32) -> Ray {
        let mut f = || rng.next_f32() * 2.0 - 1.0;
        Ray::new(
            Vec3::new(f(), f(), f()),
            Vec3::new(f(), f(), f()),
            0.0,
            f32::INFINITY,
        )
    }

    #[test]
    fn lanes_round_trip_and_unset_lanes_are_inactive() {
        let mut rng = Pcg32::new(7, 1);
        for n in 0..=LANES {
            let rays: [Ray; LANES] = core::array::from_fn(|_| random_ray(&mut rng));
            let packet = Ray8::from_rays(&rays[..n]);
            for (lane, ray) in rays.iter().enumerate() {
                let want = if lane < n { *ray } else { Ray::INACTIVE };
                assert_eq!(packet.lane(lane), want);
            }
            assert_eq!(packet.active().to_bitmask(), (1u32 << n) - 1);
        }
    }

    #[test]
    fn traceable_mask_matches_the_scalar_rule() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::MIN_POSITIVE,
            f32::MIN_POSITIVE / 2.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e30,
        ];
        let mut rng = Pcg32::new(3, 9);
        for _ in 0..400 {
            let mut pick = || specials[(rng.next_u32() % specials.len() as u32) as usize];
            let rays: [Ray; LANES] = core::array::from_fn(|_| {
                Ray::new(
                    Vec3::new(pick(), pick(), pick()),
                    Vec3::new(pick(), pick(), pick()),
                    pick(),
                    pick(),
                )
            });
            let packet = Ray8::from_rays(&rays);
            let mask = packet.traceable().to_bitmask();
            let active = packet.active().to_bitmask();
            for (lane, ray) in rays.iter().enumerate() {
                assert_eq!(mask >> lane & 1 == 1, ray.is_traceable(), "{ray:?}");
                assert_eq!(active >> lane & 1 == 1, ray.is_active(), "{ray:?}");
            }
        }
    }

    #[test]
    fn shared_origin_packet_matches_lanes() {
        let dirs: [Vec3; LANES] = core::array::from_fn(|i| Vec3::new(i as f32, 1.0, -2.0));
        let org = Vec3::new(1.0, 2.0, 3.0);
        let packet = Ray8::from_origin(org, &dirs, 0.5, 9.0);
        for (lane, dir) in dirs.iter().enumerate() {
            assert_eq!(packet.lane(lane), Ray::new(org, *dir, 0.5, 9.0));
        }
    }

    #[test]
    fn hit_lanes_round_trip() {
        let mut hits = Hit8::NONE;
        assert_eq!(hits.lane(3), None);
        let hit = Hit {
            t: 2.0,
            u: 0.25,
            v: 0.5,
            prim: 17,
        };
        hits.set_lane(3, &hit);
        assert_eq!(hits.lane(3), Some(hit));
        assert_eq!(hits.lane(2), None);
    }

    #[test]
    fn offset_origin_moves_along_the_normal_at_every_scale() {
        for (p, extent) in [
            (Vec3::ZERO, 1.0),
            (Vec3::splat(0.01), 0.001),
            (Vec3::new(1.0e6, -1.0e6, 3.0), 10.0),
            (Vec3::splat(-5.0e4), 1.0e3),
        ] {
            let n = Vec3::new(0.6, -0.8, 0.0);
            let q = offset_origin(p, n, extent);
            let moved = q - p;
            assert!(
                moved.x > 0.0 && moved.y < 0.0 && moved.z == 0.0,
                "{p} -> {q}"
            );
            // Scale-aware: a few ulps of the coordinate and of the triangle's size, so the
            // move grows with both but stays tiny beside them.
            let scale = p.abs().max_element() + extent;
            assert!(moved.length() < scale * 1e-6, "{p} {extent} -> {moved}");
        }
        // At 10⁶ along the normal axis: two to four ulps (6.25 cm each).
        let q = offset_origin(Vec3::new(0.0, 0.0, 1.0e6), Vec3::Z, 1.0);
        assert!((0.125..=0.25).contains(&(q.z - 1.0e6)), "{q}");
    }

    #[test]
    fn triangle_extent_is_the_farthest_vertex_coordinate() {
        let tri = [
            Vec3::ZERO,
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, -5.0, 1.0),
        ];
        assert_eq!(triangle_extent(Vec3::new(1.0, 0.0, 0.0), &tri), 5.0);
        let bad = [Vec3::ZERO, Vec3::splat(f32::NAN), Vec3::X];
        assert_eq!(triangle_extent(Vec3::ZERO, &bad), 1.0);
        let inf = [Vec3::ZERO, Vec3::splat(f32::INFINITY), Vec3::X];
        assert_eq!(triangle_extent(Vec3::ZERO, &inf), 0.0);
    }
}
