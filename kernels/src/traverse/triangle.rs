//! # traverse::triangle: per-ray constants and the watertight triangle test
//!
//! Woop, Benthin & Wald, *Watertight Ray/Triangle Intersection*, JCGT 2(1), 2013, for one ray
//! ([`tri1`], the reference) and for eight ([`Pre8::tri8`], the same IEEE operations lane for
//! lane), with the closest-hit acceptance (tie rule) and occlusion tests built on them.

use super::Tri;
use super::slab::{NEAR_DOWN, slab8};
use crate::packet::{Hit, LANES, NO_HIT, Ray, Ray8, set_lanes};
use glam::Vec3;
use wide::{f32x8, u32x8};

/// Per-ray constants of the box and watertight tests.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pre {
    pub(super) org: [f32; 3],
    pub(super) inv: [f32; 3],
    /// Shear permutation `[kx, ky, kz]`.
    pub(super) k: [usize; 3],
    /// Shear `[d[kx]/d[kz], d[ky]/d[kz], 1/d[kz]]`.
    pub(super) s: [f32; 3],
    pub(super) tmin: f32,
}

impl Pre {
    pub(super) fn new(ray: &Ray) -> Self {
        let d = ray.dir.to_array();
        let a = ray.dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            core::mem::swap(&mut kx, &mut ky);
        }
        Self {
            org: ray.org.to_array(),
            inv: d.map(|d| 1.0 / d),
            k: [kx, ky, kz],
            s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
            tmin: ray.tmin,
        }
    }
}

/// Edge functions in `f64`, Woop et al. 2013's fallback when one is exactly zero.
///
/// The products of two `f32`s are exact in `f64` and their difference is rounded once, so the
/// signs are exact. The `f64` values are returned as they are: rounded to `f32`, a nonzero
/// value below 2⁻¹⁵⁰ becomes ±0, and a point a subnormal distance outside an edge would pass
/// the inside test (found by the `traverse` fuzz target: origins 10⁻⁴³ beyond a box face
/// at 0 hit a triangle the box test had culled, so the BVH missed hits brute force found).
pub(super) fn uvw_f64(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> [f64; 3] {
    let d = |p: f32| f64::from(p);
    [
        d(c[0]) * d(b[1]) - d(c[1]) * d(b[0]),
        d(a[0]) * d(c[1]) - d(a[1]) * d(c[0]),
        d(b[0]) * d(a[1]) - d(b[1]) * d(a[0]),
    ]
}

/// Whether edge functions of mixed signs put the point outside the triangle (zeros are on
/// an edge, inside).
#[inline(always)]
pub(super) fn outside<T: PartialOrd + Default>(u: T, v: T, w: T) -> bool {
    let zero = T::default();
    (u < zero || v < zero || w < zero) && (u > zero || v > zero || w > zero)
}

/// Watertight ray/triangle test (Woop, Benthin & Wald 2013, two-sided): `(t, u, v)` of the
/// hit, before any comparison with the ray's interval. `u`, `v` weight vertices 1 and 2.
///
/// This is the reference the 8-wide [`tri8`] reproduces operation for operation.
pub(super) fn tri1(pre: &Pre, tri: &Tri) -> Option<(f32, f32, f32)> {
    let [kx, ky, kz] = pre.k;
    let rel = |v: &[f32; 3]| {
        [
            v[kx] - pre.org[kx],
            v[ky] - pre.org[ky],
            v[kz] - pre.org[kz],
        ]
    };
    let (a, b, c) = (rel(&tri.v[0]), rel(&tri.v[1]), rel(&tri.v[2]));
    let shear = |p: [f32; 3]| [p[0] - pre.s[0] * p[2], p[1] - pre.s[1] * p[2]];
    let (a2, b2, c2) = (shear(a), shear(b), shear(c));
    let mut u = c2[0] * b2[1] - c2[1] * b2[0];
    let mut v = a2[0] * c2[1] - a2[1] * c2[0];
    let mut w = b2[0] * a2[1] - b2[1] * a2[0];
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // The inside test on the exact signs, then the values rounded for `t`, `u`, `v`.
        let exact = uvw_f64(a2, b2, c2);
        if outside(exact[0], exact[1], exact[2]) {
            return None;
        }
        [u, v, w] = exact.map(|e| e as f32);
    } else if outside(u, v, w) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let tt = u * (pre.s[2] * a[2]) + v * (pre.s[2] * b[2]) + w * (pre.s[2] * c[2]);
    Some((tt / det, v / det, w / det))
}

/// Closest-hit acceptance with the tie rule (equal `t`: smaller primitive id wins).
pub(super) fn accept(t: f32, prim: u32, tmin: f32, best: &Hit) -> bool {
    t >= tmin && t <= best.t && (t < best.t || prim < best.prim)
}

/// Intersects `tri` and keeps the hit if [`accept`] says so.
pub(super) fn closest1(pre: &Pre, tri: &Tri, best: &mut Hit) {
    if let Some((t, u, v)) = tri1(pre, tri)
        && accept(t, tri.prim, pre.tmin, best)
    {
        *best = Hit {
            t,
            u,
            v,
            prim: tri.prim,
        };
    }
}

/// The start of a closest-hit search: `t = min(tmax, f32::MAX)`, no primitive.
pub(super) fn no_hit(tmax: f32) -> Hit {
    Hit {
        t: tmax.min(f32::MAX),
        u: 0.0,
        v: 0.0,
        prim: NO_HIT,
    }
}

pub(super) fn occludes1(pre: &Pre, tri: &Tri, tmax: f32) -> bool {
    tri1(pre, tri).is_some_and(|(t, _, _)| t >= pre.tmin && t <= tmax)
}

/// [`Ray::is_traceable`] plus `tmin ≥ 0` (see the module docs).
pub(super) fn traceable(ray: &Ray) -> bool {
    ray.is_traceable() && ray.tmin >= 0.0
}

/// Per-packet constants. Lanes that are not traced carry `tmin = +∞` and harmless finite
/// values everywhere else.
pub(super) struct Pre8 {
    pub(super) org: [f32x8; 3],
    pub(super) inv: [f32x8; 3],
    /// The wide walks' fused slab test per axis ([`slab8`]): the inverse direction and the
    /// near and far planes' offsets (of no use in the lanes of [`Pre8::exact`], where an
    /// inverse is infinite).
    pub(super) slab_inv: [f32x8; 3],
    pub(super) c_near: [f32x8; 3],
    pub(super) c_far: [f32x8; 3],
    /// Permuted origin `o[kx], o[ky], o[kz]` per lane.
    pub(super) porg: [f32x8; 3],
    pub(super) s: [f32x8; 3],
    /// `k[i]` per lane (0, 1 or 2), for [`Pre8::rel`]'s lane-wise permutation and
    /// [`Pre1x8::lane`].
    pub(super) k: [u32x8; 3],
    /// Lanes whose direction has the sign bit set, per axis.
    pub(super) neg: [f32x8; 3],
    /// The shared direction sign bits when all traced lanes have the same ones.
    pub(super) octant: Option<[bool; 3]>,
    /// The shared permutation when all traced lanes have the same one.
    pub(super) uniform: Option<[usize; 3]>,
    pub(super) tmin: f32x8,
    /// `tmin · (1 − 2⁻¹⁸)` for the box test.
    pub(super) tmin_down: f32x8,
    /// The directions (the stub's in lanes not traced), for [`Pre8::lane`].
    pub(super) dir: [f32x8; 3],
    /// Bit mask of traced lanes.
    pub(super) traced: u8,
    /// Traced lanes that need the wide walks' exact slab test (an infinite inverse direction
    /// component, [`exact`](super::slab::exact)).
    pub(super) exact: u8,
}

impl Pre8 {
    /// The packet's constants, computed 8-wide with the same IEEE operations as [`Pre::new`]
    /// per lane (so every lane's values equal its scalar [`Pre`]'s bit for bit); untraced
    /// lanes get the stub ray (origin 0, direction +x, `tmin = +∞`).
    #[inline(always)]
    pub(super) fn new(rays: &Ray8) -> Self {
        let (zero, one) = (f32x8::ZERO, f32x8::ONE);
        let live = rays.traceable() & rays.tmin.simd_ge(zero);
        let traced = live.to_bitmask() as u8;
        let org = rays.org.map(|o| live.bitselect(o, zero));
        let d = [
            live.bitselect(rays.dir[0], one),
            live.bitselect(rays.dir[1], zero),
            live.bitselect(rays.dir[2], zero),
        ];
        let tmin = live.bitselect(rays.tmin, f32x8::splat(f32::INFINITY));
        let inv = d.map(|x| one / x);
        // Shear axes as in `Pre::new`: kz the largest |d| (ties to the lower axis), kx/ky the
        // next two cyclically, swapped when d[kz] < 0.
        let a = d.map(f32x8::abs);
        let kz0 = a[0].simd_ge(a[1]) & a[0].simd_ge(a[2]);
        let kz1 = !kz0 & a[1].simd_ge(a[2]);
        let kz2 = !(kz0 | kz1);
        let dkz = kz0.bitselect(d[0], kz1.bitselect(d[1], d[2]));
        let sw = dkz.simd_lt(zero);
        let sel = [
            [(kz2 & !sw) | (kz1 & sw), (kz0 & !sw) | (kz2 & sw)],
            [(kz1 & !sw) | (kz2 & sw), (kz2 & !sw) | (kz0 & sw)],
            [kz0, kz1],
        ];
        let pick =
            |v: &[f32x8; 3], i: usize| sel[i][0].bitselect(v[0], sel[i][1].bitselect(v[1], v[2]));
        let (dx, dy, dz) = (pick(&d, 0), pick(&d, 1), pick(&d, 2));
        let neg = inv.map(f32x8::is_sign_negative);
        let slabs = [0, 1, 2].map(|a| slab8(org[a], inv[a]));
        let infinite = inv.map(|x| x.abs().simd_eq(f32x8::splat(f32::INFINITY)));
        let exact = (infinite[0] | infinite[1] | infinite[2]).to_bitmask() as u8 & traced;
        // Lanes agree when a mask is all-traced or none-traced.
        let same = |m: f32x8| {
            let bits = m.to_bitmask() as u8 & traced;
            bits == 0 || bits == traced
        };
        let lead = traced.trailing_zeros().min(7);
        let bit = |m: f32x8| m.to_bitmask() >> lead & 1 == 1;
        let octant = neg.iter().all(|&m| same(m)).then(|| neg.map(bit));
        let uniform = (same(kz0) && same(kz1) && same(sw)).then(|| {
            let kz = if bit(kz0) {
                0
            } else if bit(kz1) {
                1
            } else {
                2
            };
            let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
            if bit(sw) { [ky, kx, kz] } else { [kx, ky, kz] }
        });
        Self {
            porg: [pick(&org, 0), pick(&org, 1), pick(&org, 2)],
            s: [dx / dz, dy / dz, one / dz],
            org,
            inv,
            slab_inv: slabs.map(|[inv, _, _]| inv),
            c_near: slabs.map(|[_, near, _]| near),
            c_far: slabs.map(|[_, _, far]| far),
            k: sel.map(|[is0, is1]| {
                // 0 where `is0`, else 1 where `is1`, else 2 (the masks are all ones or zeros).
                let (is0, is1): (u32x8, u32x8) = (bytemuck::cast(is0), bytemuck::cast(is1));
                !is0 & (u32x8::ONE + (!is1 & u32x8::ONE))
            }),
            neg,
            octant,
            uniform,
            tmin,
            tmin_down: tmin * f32x8::splat(NEAR_DOWN),
            dir: d,
            traced,
            exact,
        }
    }

    /// Lane `i`'s scalar constants (for the rare per-lane paths); `i` must be traced.
    pub(super) fn lane(&self, i: usize) -> Pre {
        let at = |v: &[f32x8; 3]| Vec3::from(v.map(|x| x.as_array()[i]));
        let tmin = self.tmin.as_array()[i];
        Pre::new(&Ray::new(at(&self.org), at(&self.dir), tmin, f32::INFINITY))
    }

    /// Vertex `v` (its coordinate on each axis) relative to the origin in each lane's
    /// permuted axes.
    #[inline(always)]
    pub(super) fn rel(&self, v: impl Fn(usize) -> f32) -> [f32x8; 3] {
        match self.uniform {
            Some(k) => [0, 1, 2].map(|i| f32x8::splat(v(k[i])) - self.porg[i]),
            // One lane-wise permute per axis (`vpermps`: each lane takes `v[k[i]]`) in place of two
            // blends (docs/traverse.md, "What each kept change bought"); the same values.
            #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
            None => {
                use core::arch::x86_64::{__m256, _mm256_permutevar8x32_ps};
                let v: __m256 =
                    bytemuck::cast(f32x8::from([v(0), v(1), v(2), 0.0, 0.0, 0.0, 0.0, 0.0]));
                [0, 1, 2].map(|i| {
                    // SAFETY: AVX2 is enabled at compile time (the `cfg` above), so `vpermps`
                    // exists on every CPU this code runs on.
                    let pick = unsafe { _mm256_permutevar8x32_ps(v, bytemuck::cast(self.k[i])) };
                    bytemuck::cast::<__m256, f32x8>(pick) - self.porg[i]
                })
            }
            #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
            None => {
                let c = [0, 1, 2].map(|a| f32x8::splat(v(a)));
                [0, 1, 2].map(|i| {
                    let is =
                        |j: u32| bytemuck::cast::<u32x8, f32x8>(self.k[i].simd_eq(u32x8::splat(j)));
                    is(0).bitselect(c[0], is(1).bitselect(c[1], c[2])) - self.porg[i]
                })
            }
        }
    }

    /// [`tri1`] for eight lanes: `(t, U, V, W, det, ok)` where `ok` marks lanes with a hit
    /// computed in `f32`, and `zero` lanes that need the scalar `f64` fallback.
    #[inline(always)]
    pub(super) fn tri8(&self, tri: impl TriAt) -> Tri8 {
        let a = self.rel(|axis| tri.at(0, axis));
        let b = self.rel(|axis| tri.at(1, axis));
        let c = self.rel(|axis| tri.at(2, axis));
        watertight8(a, b, c, &self.s)
    }
}

/// [`tri1`]'s arithmetic after the vertices are taken relative to the origin (`a`, `b`, `c`
/// in the permuted axes), eight at a time: eight rays against one triangle ([`Pre8::tri8`])
/// or one ray against eight triangles ([`Pre1x8::tris8`]), the same IEEE operations in the
/// same order per lane.
#[inline(always)]
fn watertight8(a: [f32x8; 3], b: [f32x8; 3], c: [f32x8; 3], s: &[f32x8; 3]) -> Tri8 {
    let shear = |p: &[f32x8; 3]| [p[0] - s[0] * p[2], p[1] - s[1] * p[2]];
    let (a2, b2, c2) = (shear(&a), shear(&b), shear(&c));
    let u = c2[0] * b2[1] - c2[1] * b2[0];
    let v = a2[0] * c2[1] - a2[1] * c2[0];
    let w = b2[0] * a2[1] - b2[1] * a2[0];
    let zero = f32x8::ZERO;
    let any_zero = u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero);
    let neg = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
    let pos = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
    let det = u + v + w;
    let sz = s[2];
    let tt = u * (sz * a[2]) + v * (sz * b[2]) + w * (sz * c[2]);
    let ok = !(neg & pos) & det.simd_ne(zero) & !any_zero;
    Tri8 {
        tt,
        v,
        w,
        det,
        ok,
        any_zero,
    }
}

/// [`Pre8::tri8`]'s result; `t = tt / det` is divided only when some lane may hit.
pub(super) struct Tri8 {
    pub(super) tt: f32x8,
    pub(super) v: f32x8,
    pub(super) w: f32x8,
    pub(super) det: f32x8,
    pub(super) ok: f32x8,
    pub(super) any_zero: f32x8,
}

/// Closest-hit state of a packet.
pub(super) struct Best8 {
    pub(super) t: f32x8,
    pub(super) u: f32x8,
    pub(super) v: f32x8,
    pub(super) prim: u32x8,
}

impl Best8 {
    pub(super) fn lane(&self, i: usize) -> Hit {
        Hit {
            t: self.t.as_array()[i],
            u: self.u.as_array()[i],
            v: self.v.as_array()[i],
            prim: self.prim.as_array()[i],
        }
    }
}

#[inline(always)]
pub(super) fn closest8(pre: &Pre8, tri: impl TriAt, best: &mut Best8) {
    let r = pre.tri8(tri);
    let live = pre.tmin.simd_le(best.t);
    if !((r.ok | r.any_zero) & live).any() {
        return;
    }
    let t = r.tt / r.det;
    let cand = r.ok & t.simd_ge(pre.tmin) & t.simd_le(best.t);
    let strict = cand & t.simd_lt(best.t);
    if strict.any() {
        let m: u32x8 = bytemuck::cast(strict);
        best.t = strict.bitselect(t, best.t);
        best.u = strict.bitselect(r.v / r.det, best.u);
        best.v = strict.bitselect(r.w / r.det, best.v);
        best.prim = m.bitselect(u32x8::splat(tri.prim()), best.prim);
    }
    // Rare lanes: exact ties on t (tie rule) and zero edge functions (f64 fallback).
    let rare = ((cand & !strict) | (r.any_zero & live)).to_bitmask();
    if rare != 0 {
        closest8_rare(pre, &tri.tri(), best, rare as u8);
    }
}

/// The scalar path of [`closest8`]'s rare lanes (kept out of the inlined hot loop).
#[cold]
#[inline(never)]
pub(super) fn closest8_rare(pre: &Pre8, tri: &Tri, best: &mut Best8, rare: u8) {
    for i in 0..LANES {
        if rare >> i & 1 == 1 {
            let mut hit = best.lane(i);
            closest1(&pre.lane(i), tri, &mut hit);
            set_lane(best, i, &hit);
        }
    }
}

pub(super) fn set_lane(best: &mut Best8, i: usize, hit: &Hit) {
    best.t.as_mut_array()[i] = hit.t;
    best.u.as_mut_array()[i] = hit.u;
    best.v.as_mut_array()[i] = hit.v;
    best.prim.as_mut_array()[i] = hit.prim;
}

/// Lanes `tri` blocks on `[tmin, tmax]`, as a bit mask.
#[inline(always)]
pub(super) fn occludes8(pre: &Pre8, tri: impl TriAt, tmax: f32x8) -> u8 {
    let r = pre.tri8(tri);
    if !(r.ok | r.any_zero).any() {
        return 0;
    }
    let t = r.tt / r.det;
    let hit = r.ok & t.simd_ge(pre.tmin) & t.simd_le(tmax);
    let mut bits = hit.to_bitmask() as u8;
    let zero = (r.any_zero & pre.tmin.simd_le(tmax)).to_bitmask() as u8;
    if zero != 0 {
        bits |= occludes8_rare(pre, &tri.tri(), tmax, zero);
    }
    bits
}

/// The scalar `f64` fallback of [`occludes8`]'s lanes with a zero edge function.
#[cold]
#[inline(never)]
pub(super) fn occludes8_rare(pre: &Pre8, tri: &Tri, tmax: f32x8, zero: u8) -> u8 {
    (0..LANES).fold(0, |bits, i| {
        let blocked = zero >> i & 1 == 1 && occludes1(&pre.lane(i), tri, tmax.as_array()[i]);
        bits | u8::from(blocked) << i
    })
}

// ---------------------------------------------------------------------------------------------
// One ray against a leaf's triangles, eight at a time.

/// Rows per triangle in a leaf's structure-of-arrays block ([`super::WideRef`]'s `rows`):
/// vertex `c`, axis `a` in row `3c + a`, the primitive id's bits in row 9.
pub(super) const ROWS: usize = 10;

/// Row of the primitive ids.
pub(super) const PRIM_ROW: usize = 9;

/// A triangle eight rays are tested against ([`Pre8::tri8`]): a [`Tri`], or one triangle of
/// a leaf's rows ([`RowTri`]), read where it lies.
pub(super) trait TriAt: Copy {
    /// Vertex `c`'s coordinate on axis `a`.
    fn at(self, c: usize, a: usize) -> f32;
    /// The primitive id.
    fn prim(self) -> u32;
    /// The triangle as a [`Tri`] (for the rare lanes' scalar paths).
    fn tri(self) -> Tri;
}

impl TriAt for &Tri {
    #[inline(always)]
    fn at(self, c: usize, a: usize) -> f32 {
        self.v[c][a]
    }

    #[inline(always)]
    fn prim(self) -> u32 {
        self.prim
    }

    fn tri(self) -> Tri {
        *self
    }
}

/// Triangle `i` of the leaf of `n` triangles whose rows are `leaf` (`ROWS · n` values),
/// its bounds checked once ([`RowTri::new`]) rather than per coordinate (nine checks a
/// triangle in the packet walk's leaf test: docs/traverse.md, "What each kept change bought").
#[derive(Clone, Copy)]
pub(super) struct RowTri<'a> {
    leaf: &'a [f32],
    n: usize,
    i: usize,
}

impl<'a> RowTri<'a> {
    /// # Panics
    /// When `i ≥ n` or `leaf` holds fewer than `ROWS · n` values (free where the caller's
    /// slice and range show it, as the walks' do).
    #[inline(always)]
    pub(super) fn new(leaf: &'a [f32], n: usize, i: usize) -> Self {
        assert!(
            i < n && leaf.len() >= ROWS * n,
            "triangle outside its leaf's rows"
        );
        Self { leaf, n, i }
    }

    /// Row `r < ROWS` of the triangle.
    #[inline(always)]
    fn row(self, r: usize) -> f32 {
        assert!(r < ROWS);
        // SAFETY: `r < ROWS` and `i < n` (checked in `new`) give `r·n + i < ROWS·n ≤
        // leaf.len()` (checked in `new`).
        unsafe { *self.leaf.get_unchecked(r * self.n + self.i) }
    }
}

impl TriAt for RowTri<'_> {
    #[inline(always)]
    fn at(self, c: usize, a: usize) -> f32 {
        assert!(a < 3);
        self.row(3 * c + a)
    }

    #[inline(always)]
    fn prim(self) -> u32 {
        self.row(PRIM_ROW).to_bits()
    }

    fn tri(self) -> Tri {
        Tri {
            v: [0, 1, 2].map(|c| [0, 1, 2].map(|a| self.at(c, a))),
            prim: self.prim(),
            pad: [0; 2],
        }
    }
}

/// One ray's watertight-test constants splatted over eight triangles.
#[derive(Debug, PartialEq)]
pub(super) struct Pre1x8 {
    k: [usize; 3],
    /// Permuted origin `o[kx], o[ky], o[kz]`.
    porg: [f32x8; 3],
    s: [f32x8; 3],
    tmin: f32x8,
}

impl Pre1x8 {
    pub(super) fn new(pre: &Pre) -> Self {
        Self {
            k: pre.k,
            porg: pre.k.map(|k| f32x8::splat(pre.org[k])),
            s: pre.s.map(f32x8::splat),
            tmin: f32x8::splat(pre.tmin),
        }
    }

    /// [`Pre1x8::new`] of lane `i` of a packet (traced), from the packet's constants, which
    /// equal the lane's scalar ones bit for bit.
    #[inline(always)]
    pub(super) fn lane(pre: &Pre8, i: usize) -> Self {
        let k = pre
            .uniform
            .unwrap_or_else(|| pre.k.map(|k| k.as_array()[i] as usize));
        let at = |v: &f32x8| f32x8::splat(v.as_array()[i]);
        Self {
            k,
            porg: pre.porg.each_ref().map(at),
            s: pre.s.each_ref().map(at),
            tmin: at(&pre.tmin),
        }
    }

    /// [`tri1`] for triangles `8j .. 8j + 8` of `leaf`. Lanes past its `n` triangles read
    /// the next rows: garbage the caller masks off.
    #[inline(always)]
    fn tris8(&self, leaf: &LeafRows<'_>, j: usize) -> Tri8 {
        let row = |c: usize, i: usize| leaf.load(c, i, j) - self.porg[i];
        let vertex = |c: usize| [row(c, 0), row(c, 1), row(c, 2)];
        watertight8(vertex(0), vertex(1), vertex(2), &self.s)
    }
}

/// A leaf's `n` triangles as rows (row `r` at `r·n`), its length checked once: at least
/// `ROWS·n + 8` values (the layout pads the last leaf with eight), so that each of the nine
/// vertex rows' 8-wide loads stays inside without a check of its own; and the offsets of the
/// rows of one ray's permuted axes, computed once a leaf. (Checked per load, the offsets and
/// checks were 145 of the ~700 instructions a shadow ray of the Veach room executed; the
/// axes' offsets and their checks computed per load, 39 of its ~543: docs/traverse.md,
/// "What each kept change bought".)
#[derive(Clone, Copy)]
pub(super) struct LeafRows<'a> {
    rows: &'a [f32],
    n: usize,
    /// `(k[i] & 3)·n` for the ray's axis permutation `k` (each `k[i] < 3`; the mask bounds
    /// the offset by `3n` whatever `k` holds).
    axis: [usize; 3],
}

impl<'a> LeafRows<'a> {
    /// The leaf of `n` triangles whose rows start at `rows[0]`, read in the axis order `k`.
    ///
    /// # Panics
    /// When `rows` is shorter than `ROWS·n + 8` for `n > 0`: a layout [`super::WideRef::new`]
    /// accepted never is.
    #[inline(always)]
    pub(super) fn new(rows: &'a [f32], n: usize, k: [usize; 3]) -> Self {
        assert!(n == 0 || rows.len() >= ROWS * n + 8, "leaf rows too short");
        Self {
            rows,
            n,
            axis: k.map(|k| (k & 3) * n),
        }
    }

    /// Lanes `8j .. 8j + 8` of the row of vertex `c < 3`, permuted axis `i < 3` (`8j < n`).
    #[inline(always)]
    fn load(&self, c: usize, i: usize, j: usize) -> f32x8 {
        assert!(c < 3 && 8 * j < self.n);
        let at = 3 * c * self.n + self.axis[i] + 8 * j;
        // SAFETY: `8j < n` and `8j` a multiple of 8 give `8j ≤ n − 1`, and `axis[i] ≤ 3n`
        // (`new` masks `k[i]` to at most 3), so `at + 8 ≤ 6n + 3n + (n − 1) + 8 < ROWS·n + 8
        // ≤ rows.len()` (checked in `new`, `n > 0` here; `ROWS·n + 8` does not overflow for
        // rows that exist); `[f32; 8]` needs the alignment of `f32` only.
        f32x8::from(unsafe { self.rows.as_ptr().add(at).cast::<[f32; 8]>().read() })
    }

    /// The primitive id of triangle `i < n`.
    #[inline(always)]
    fn prim(&self, i: usize) -> u32 {
        RowTri::new(self.rows, self.n, i).prim()
    }
}

/// The mask of the first `n` lanes (all eight from `n ≥ 8`).
#[inline(always)]
fn first_lanes(n: usize) -> u8 {
    if n >= 8 { u8::MAX } else { (1u8 << n) - 1 }
}

/// [`closest1`] over the `n` triangles of a leaf stored as rows, eight per pass: the
/// candidates of a pass are accepted in triangle order, then its lanes with a zero edge
/// function go through [`closest1`] (the result does not depend on the order: the tie rule
/// picks the least `(t, prim)`).
///
/// The single pass of a leaf of up to eight triangles (every leaf [`super::collapse`] makes)
/// is written out of the loop, here and in [`occludes_rows`]: in the loop the nine rows'
/// addresses were hoisted and spilled to the stack, and a pass shared by both as a closure
/// was called out of line (docs/traverse.md, "What each kept change bought").
#[inline(always)]
pub(super) fn closest_rows(
    pre: impl Fn() -> Pre,
    p8: &Pre1x8,
    leaf: &[f32],
    n: usize,
    best: &mut Hit,
) {
    let rows = LeafRows::new(leaf, n, p8.k);
    if n <= 8 {
        if n > 0 {
            closest_pass(&pre, p8, &rows, 0, best);
        }
    } else {
        for j in 0..n.div_ceil(8) {
            closest_pass(&pre, p8, &rows, j, best);
        }
    }
}

/// Pass `j` of [`closest_rows`]: triangles `8j .. 8j + 8`.
#[inline(always)]
fn closest_pass(
    pre: &impl Fn() -> Pre,
    p8: &Pre1x8,
    rows: &LeafRows<'_>,
    j: usize,
    best: &mut Hit,
) {
    let tmin = p8.tmin.as_array()[0];
    let valid = first_lanes(rows.n - 8 * j);
    let r = p8.tris8(rows, j);
    if r.ok.to_bitmask() as u8 & valid != 0 {
        let t = r.tt / r.det;
        let cand = r.ok & t.simd_ge(p8.tmin) & t.simd_le(f32x8::splat(best.t));
        for i in set_lanes(cand.to_bitmask() as u8 & valid) {
            let ti = t.as_array()[i];
            let prim = rows.prim(8 * j + i);
            if accept(ti, prim, tmin, best) {
                let det = r.det.as_array()[i];
                *best = Hit {
                    t: ti,
                    u: r.v.as_array()[i] / det,
                    v: r.w.as_array()[i] / det,
                    prim,
                };
            }
        }
    }
    let zero = r.any_zero.to_bitmask() as u8 & valid;
    if zero != 0 {
        closest_rows_rare(&pre(), rows.rows, rows.n, 8 * j, zero, best);
    }
}

/// The `f64` fallback of [`closest_rows`]' lanes with a zero edge function.
#[cold]
#[inline(never)]
fn closest_rows_rare(pre: &Pre, leaf: &[f32], n: usize, first: usize, zero: u8, best: &mut Hit) {
    for i in 0..8 {
        if zero >> i & 1 == 1 {
            closest1(pre, &RowTri::new(leaf, n, first + i).tri(), best);
        }
    }
}

/// Whether any of the `n` triangles of a leaf stored as rows blocks the ray on
/// `[tmin, tmax]`: [`occludes1`], eight triangles per pass (one written out, as in
/// [`closest_rows`]).
#[inline(always)]
pub(super) fn occludes_rows(
    pre: impl Fn() -> Pre,
    p8: &Pre1x8,
    leaf: &[f32],
    n: usize,
    tmax: f32,
) -> bool {
    let rows = LeafRows::new(leaf, n, p8.k);
    if n <= 8 {
        n > 0 && occludes_pass(&pre, p8, &rows, 0, tmax)
    } else {
        (0..n.div_ceil(8)).any(|j| occludes_pass(&pre, p8, &rows, j, tmax))
    }
}

/// Pass `j` of [`occludes_rows`]: triangles `8j .. 8j + 8`.
#[inline(always)]
fn occludes_pass(
    pre: &impl Fn() -> Pre,
    p8: &Pre1x8,
    rows: &LeafRows<'_>,
    j: usize,
    tmax: f32,
) -> bool {
    let valid = first_lanes(rows.n - 8 * j);
    let r = p8.tris8(rows, j);
    if r.ok.to_bitmask() as u8 & valid != 0 {
        let t = r.tt / r.det;
        let hit = r.ok & t.simd_ge(p8.tmin) & t.simd_le(f32x8::splat(tmax));
        if hit.to_bitmask() as u8 & valid != 0 {
            return true;
        }
    }
    let zero = r.any_zero.to_bitmask() as u8 & valid;
    zero != 0 && occludes_rows_rare(&pre(), rows.rows, rows.n, 8 * j, zero, tmax)
}

/// The `f64` fallback of [`occludes_rows`]' lanes with a zero edge function.
#[cold]
#[inline(never)]
fn occludes_rows_rare(
    pre: &Pre,
    leaf: &[f32],
    n: usize,
    first: usize,
    zero: u8,
    tmax: f32,
) -> bool {
    (0..8)
        .any(|i| zero >> i & 1 == 1 && occludes1(pre, &RowTri::new(leaf, n, first + i).tri(), tmax))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::Pcg32;
    use glam::Vec3;
    use std::vec::Vec;

    /// A leaf's rows as [`super::super::leaf_rows`] lays them out, between two other leaves'
    /// rows so that the lanes past `n` read foreign values.
    fn rows_of(leaf: &[Tri], pad: &[Tri]) -> (Vec<f32>, usize) {
        let mut rows = Vec::new();
        let push = |rows: &mut Vec<f32>, tris: &[Tri]| {
            for r in 0..9 {
                rows.extend(tris.iter().map(|t| t.v[r / 3][r % 3]));
            }
            rows.extend(tris.iter().map(|t| f32::from_bits(t.prim)));
        };
        push(&mut rows, pad);
        let start = rows.len();
        push(&mut rows, leaf);
        push(&mut rows, pad);
        rows.extend([f32::NAN; 8]);
        (rows, start)
    }

    /// One ray against a leaf of 1..20 triangles, eight per pass, equals [`closest1`] and
    /// [`occludes1`] triangle by triangle, bit for bit: random triangles, exact duplicates
    /// under other ids (ties on `t`), rays through shared vertices and edges (zero edge
    /// functions), axis-aligned and signed-zero directions, random `tmin`/`tmax`.
    #[test]
    fn eight_triangles_per_pass_equal_the_scalar_test() {
        let mut rng = Pcg32::new(7, 9);
        let v3 = |rng: &mut Pcg32, s: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * s - Vec3::splat(s / 2.0)
        };
        let mut hits = 0;
        for trial in 0..4000 {
            let n = trial % 20 + 1;
            let shared = [v3(&mut rng, 2.0), v3(&mut rng, 2.0)];
            let leaf: Vec<Tri> = (0..n)
                .map(|i| {
                    let mut v = [v3(&mut rng, 2.0), v3(&mut rng, 2.0), v3(&mut rng, 2.0)];
                    if rng.next_u32().is_multiple_of(3) {
                        // A shared edge.
                        v[0] = shared[0];
                        v[1] = shared[1];
                    }
                    Tri::new(v, (i as u32 * 7919) % 61)
                })
                .collect();
            let mut leaf = leaf;
            if n > 2 && trial % 4 == 0 {
                // A duplicate under another id: a tie on t.
                leaf[n - 1].v = leaf[0].v;
            }
            let pad: Vec<Tri> = (0..5)
                .map(|i| Tri::new([v3(&mut rng, 9.0), v3(&mut rng, 9.0), v3(&mut rng, 9.0)], i))
                .collect();
            let (rows, start) = rows_of(&leaf, &pad);
            let org = v3(&mut rng, 6.0);
            let target = match trial % 3 {
                0 => shared[0],
                1 => (shared[0] + shared[1]) * 0.5,
                _ => v3(&mut rng, 2.0),
            };
            let mut dir = target - org;
            if trial % 7 == 0 {
                dir.x = if trial % 14 == 0 { 0.0 } else { -0.0 };
            }
            let (tmin, tmax) = if trial % 5 == 0 {
                (rng.next_f32(), 0.5 + rng.next_f32())
            } else {
                (0.0, f32::INFINITY)
            };
            let ray = Ray::new(org, dir, tmin, tmax);
            if !traceable(&ray) {
                continue;
            }
            let pre = Pre::new(&ray);
            let pre8 = Pre1x8::new(&pre);
            let mut want = no_hit(tmax);
            for tri in &leaf {
                closest1(&pre, tri, &mut want);
            }
            let mut got = no_hit(tmax);
            closest_rows(|| pre, &pre8, &rows[start..], n, &mut got);
            let bits = |h: &Hit| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim);
            assert_eq!(bits(&got), bits(&want), "trial {trial}, n {n}: {ray:?}");
            hits += usize::from(want.prim != NO_HIT);
            let tmax = tmax.min(f32::MAX);
            let blocked = leaf.iter().any(|tri| occludes1(&pre, tri, tmax));
            assert_eq!(
                occludes_rows(|| pre, &pre8, &rows[start..], n, tmax),
                blocked,
                "trial {trial}: {ray:?}"
            );
            for (i, tri) in leaf.iter().enumerate() {
                assert_eq!(RowTri::new(&rows[start..], n, i).tri(), *tri);
            }
        }
        assert!(hits > 1000, "{hits} hits");
    }

    /// [`Pre1x8::lane`] (from a packet's constants) equals [`Pre1x8::new`] of the lane's own
    /// ray, bit for bit, for packets of mixed shear permutations and signs.
    #[test]
    fn a_packets_lane_constants_equal_the_lanes_own() {
        let mut rng = Pcg32::new(3, 5);
        let bits = |p: &Pre1x8| {
            let b = |v: &[f32x8; 3]| v.map(|x| x.to_array().map(f32::to_bits));
            (
                p.k,
                b(&p.porg),
                b(&p.s),
                p.tmin.to_array().map(f32::to_bits),
            )
        };
        for trial in 0..500 {
            let rays: Vec<Ray> = (0..LANES)
                .map(|_| {
                    let c = |rng: &mut Pcg32| rng.next_f32() * 2.0 - 1.0;
                    let d = Vec3::new(c(&mut rng), c(&mut rng), c(&mut rng));
                    let o = Vec3::new(c(&mut rng), c(&mut rng), c(&mut rng)) * 1e3;
                    let d = if trial % 2 == 0 {
                        d
                    } else {
                        Vec3::new(d.x.abs(), 0.1, 0.2)
                    };
                    Ray::new(o, d, rng.next_f32(), f32::INFINITY)
                })
                .collect();
            let packet = Ray8::from_rays(&rays);
            let pre = Pre8::new(&packet);
            for (i, ray) in rays.iter().enumerate() {
                let own = Pre1x8::new(&Pre::new(ray));
                assert_eq!(
                    bits(&Pre1x8::lane(&pre, i)),
                    bits(&own),
                    "lane {i}: {ray:?}"
                );
            }
        }
    }

    /// Rays through the shared vertex of a fan and along its shared edges hit it (the `f64`
    /// path of [`closest_rows`]), like the scalar test.
    #[test]
    fn eight_triangles_per_pass_take_the_f64_path_on_shared_edges() {
        let centre = Vec3::new(0.25, -0.5, 0.0);
        let fan: Vec<Tri> = (0..11u32)
            .map(|i| {
                let a = |k: u32| {
                    let phi = k as f32 * core::f32::consts::TAU / 11.0;
                    centre + Vec3::new(phi.cos(), phi.sin(), 0.0)
                };
                Tri::new([centre, a(i), a(i + 1)], 40 - i)
            })
            .collect();
        let (rows, start) = rows_of(&fan, &fan[..3]);
        let mut rays = Vec::new();
        for (k, tri) in fan.iter().enumerate() {
            let (p, q) = (Vec3::from(tri.v[0]), Vec3::from(tri.v[1]));
            for target in [p, (p + q) * 0.5, q] {
                let org = target + Vec3::new(0.01 * k as f32, -0.02, 3.0);
                rays.push(Ray::new(org, target - org, 0.0, f32::INFINITY));
            }
        }
        let mut rare = 0;
        for ray in &rays {
            let pre = Pre::new(ray);
            let mut want = no_hit(ray.tmax);
            for tri in &fan {
                closest1(&pre, tri, &mut want);
            }
            let mut got = no_hit(ray.tmax);
            closest_rows(
                || pre,
                &Pre1x8::new(&pre),
                &rows[start..],
                fan.len(),
                &mut got,
            );
            assert_eq!(got, want, "{ray:?}");
            assert_ne!(got.prim, NO_HIT, "a ray through the fan missed it: {ray:?}");
            let r = Pre1x8::new(&pre).tris8(&LeafRows::new(&rows[start..], fan.len(), pre.k), 0);
            rare += usize::from(r.any_zero.any());
        }
        assert!(rare > 0, "no ray took the f64 path");
    }
}
