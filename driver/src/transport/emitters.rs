//! Emissive triangles as lights: the set next-event estimation samples, and the density it
//! samples them with, which multiple importance sampling needs for the emission that gather
//! and path rays hit ([`super::direct`], [`super::path`]).
//!
//! Every triangle whose material emits is an emitter: Lambertian, radiance `emission` from
//! its front face (winding order) only, uniform over the triangle (a glTF emissive texture is
//! averaged into the material's emission when the scene is loaded). A receiver at `p` with
//! normal `n` samples one emitter by the [`EmitterSelection`] in force, then one point `y`
//! uniformly by area on it (the square-root map of Shirley & Chiu; sampling the spherical
//! triangle by solid angle, Arvo 1995, was not built). The solid-angle density of the
//! direction to `y` is `P(e | p, n) · |y − p|² / (A · cos θ_e)`.
//!
//! Selection ([`EmitterSelection`]): in proportion to power (area × luminance of the
//! emission) by Vose's alias table ([`super::alias`], O(1), the same at every receiver), or
//! by the light tree ([`super::light_tree`], O(log N)), which prefers the emitters that
//! matter at the receiver and picks none where none can light it, or — in worlds of at most
//! [`LOCAL_MAX`] emitters — by each emitter's own weight at the receiver (`local`: power over
//! squared distance, its cosine and the receiver's, zero for one seen from behind or below
//! the horizon; docs/bake.md "Next-event estimation on the bidir room"). `local` weighs
//! every emitter at once, one per lane of an `f32x8`, from structure-of-arrays rows built
//! by [`Emitters::new`] (`LocalRows`; `Emitter::local_weight` is the scalar reference, equal
//! bit for bit).
//!
//! [`Emitters::at`] makes the selection at one receiver once (`local`'s weights, running sums
//! and probabilities) for every pick and density asked there: the eight next-event samples
//! of a texel ([`super::direct`]), and a path vertex's sample and the MIS density of the ray
//! that leaves it ([`super::path`]). The pick and the pmf read the same probabilities, so
//! they agree bit for bit, as MIS needs. [`Emitters::sample`], [`Emitters::pdf`],
//! [`Emitters::select`] and [`Emitters::selection_pmf`] make it for one call.
//!
//! A world without emitters builds none of this and traces no shadow rays for them.

use glam::{DVec3, Vec3};
use wide::f32x8;

use super::alias::AliasTable;
use super::light_tree::{EmitterBounds, LightTree};

/// How next-event estimation picks an emitter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum EmitterSelection {
    /// In proportion to power, the same at every receiver (Vose's alias table).
    Power,
    /// By the light tree: power, distance and orientation of clusters of emitters as seen
    /// from the receiver (Conty Estevez & Kulla 2018).
    Tree,
    /// Every emitter weighed at the receiver (8 of them at most, `LOCAL_MAX`; beyond, as
    /// `power`): luminance × approximate solid angle × the receiver's cosine to its centroid,
    /// zero for an emitter seen from behind or wholly below the receiver's horizon. The
    /// default: at equal time it beats `power` and `tree` on the bidir and ajar rooms and is
    /// level on the Cornell box (docs/bake.md, "Next-event estimation on the bidir room").
    #[default]
    Local,
}

impl std::fmt::Display for EmitterSelection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            EmitterSelection::Power => "power",
            EmitterSelection::Tree => "tree",
            EmitterSelection::Local => "local",
        })
    }
}

/// One emissive triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Emitter {
    /// The scene triangle (BVH primitive id).
    prim: u32,
    /// First corner and the two edges from it.
    a: Vec3,
    ab: Vec3,
    ac: Vec3,
    /// Unit front normal.
    normal: Vec3,
    area: f32,
    radiance: Vec3,
}

/// Marks a triangle that is not an emitter in [`Emitters::of_prim`].
const NOT_AN_EMITTER: u32 = u32::MAX;

/// Most emitters [`EmitterSelection::Local`] weighs one by one at every receiver; a world
/// with more is sampled in proportion to power.
pub const LOCAL_MAX: usize = 8;

/// Receiver cosine below which [`EmitterSelection::Local`] stops lowering an emitter's
/// weight: an emitter whose centroid is at or below the horizon but a corner above it keeps
/// this share of the weight it would have facing the receiver.
const LOCAL_COS_FLOOR: f32 = 0.05;

/// Share of the distance from a receiver to an emitter's farthest corner by which a corner
/// may lie below the receiver's horizon and still count as above it in
/// [`EmitterSelection::Local`]'s horizon test (rounding of corners in the receiver's plane).
const LOCAL_HORIZON_SLACK: f32 = 1e-5;

/// The picker of [`EmitterSelection`].
#[derive(Debug)]
enum Picker {
    Power(AliasTable),
    Tree(LightTree),
    /// [`EmitterSelection::Local`]: every emitter's data in one lane.
    Local(Box<LocalRows>),
}

/// What [`EmitterSelection::Local`] weighs, one emitter per lane of an `f32x8` (structure of
/// arrays, [`LOCAL_MAX`] lanes): every emitter is weighed at once. Lanes past the last
/// emitter have a zero normal, so their height above the plane is 0 and their weight 0.
#[derive(Debug)]
struct LocalRows {
    /// First corner (its plane's point for the behind test).
    a: [f32x8; 3],
    /// Unit front normal.
    normal: [f32x8; 3],
    /// Centroid: where the weight's distance and cosines are measured.
    centroid: [f32x8; 3],
    /// The three corners less the centroid (the horizon test).
    corners: [[f32x8; 3]; 3],
    /// Distance from the centroid to the farthest corner.
    radius: f32x8,
    area: f32x8,
    /// Luminance of the radiance.
    lum: f32x8,
    /// Emitters (lanes in use).
    len: usize,
}

/// One emitter as a lane of [`LocalRows`], and as [`Emitter::local_weight`] reads it: the
/// same values in both, so the scalar and the 8-wide weight agree bit for bit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct LocalLane {
    a: Vec3,
    normal: Vec3,
    centroid: Vec3,
    corners: [Vec3; 3],
    radius: f32,
    area: f32,
    lum: f32,
}

impl LocalRows {
    fn new(emitters: &[Emitter]) -> Self {
        assert!(emitters.len() <= LOCAL_MAX);
        let mut lanes = [LocalLane::default(); LOCAL_MAX];
        for (lane, e) in lanes.iter_mut().zip(emitters) {
            *lane = e.local_lane();
        }
        let row = |f: &dyn Fn(&LocalLane) -> f32| f32x8::new(lanes.map(|l| f(&l)));
        let row3 =
            |f: &dyn Fn(&LocalLane) -> Vec3| [row(&|l| f(l).x), row(&|l| f(l).y), row(&|l| f(l).z)];
        Self {
            a: row3(&|l| l.a),
            normal: row3(&|l| l.normal),
            centroid: row3(&|l| l.centroid),
            corners: [0, 1, 2].map(|k| row3(&|l| l.corners[k])),
            radius: row(&|l| l.radius),
            area: row(&|l| l.area),
            lum: row(&|l| l.lum),
            len: emitters.len(),
        }
    }

    /// Every emitter's weight at receiver `(p, n)` at once: [`Emitter::local_weight`] lane
    /// by lane, the same operations in the same order (no fused multiply-add), so the same
    /// bits; 0 in the lanes past the last emitter.
    fn weights(&self, p: Vec3, n: Vec3) -> [f32; LOCAL_MAX] {
        let [px, py, pz] = p.to_array().map(f32x8::splat);
        let [nx, ny, nz] = n.to_array().map(f32x8::splat);
        let dot = |x: f32x8, y: f32x8, z: f32x8, v: &[f32x8; 3]| x * v[0] + y * v[1] + z * v[2];
        let height = dot(px - self.a[0], py - self.a[1], pz - self.a[2], &self.normal);
        let (tx, ty, tz) = (
            self.centroid[0] - px,
            self.centroid[1] - py,
            self.centroid[2] - pz,
        );
        let d2 = tx * tx + ty * ty + tz * tz;
        let d = d2.sqrt();
        let cn = nx * tx + ny * ty + nz * tz;
        let [c0, c1, c2] = self.corners.each_ref().map(|c| dot(nx, ny, nz, c) + cn);
        let highest = c0.fast_max(c1).fast_max(c2);
        let slack = (d + self.radius) * f32x8::splat(-LOCAL_HORIZON_SLACK);
        // A cos θ_e / d² = A h / d³ and cos θ_r = (n · to) d² / d³: one division.
        let r = f32x8::ONE / (d2 * d);
        let omega = (self.area * height * r).fast_min(f32x8::splat(core::f32::consts::TAU));
        let cos_r = (cn * d2 * r).fast_max(f32x8::splat(LOCAL_COS_FLOOR));
        let w = (self.lum * omega * cos_r)
            .fast_max(f32x8::splat(f32::MIN_POSITIVE))
            .fast_min(f32x8::splat(f32::MAX));
        let lit = height.simd_gt(f32x8::ZERO) & highest.simd_gt(slack);
        lit.select(w, f32x8::ZERO).to_array()
    }
}

/// The emissive triangles of a world and how to sample them.
#[derive(Debug)]
pub struct Emitters {
    emitters: Vec<Emitter>,
    /// Emitter index of every scene triangle ([`NOT_AN_EMITTER`] for the others).
    of_prim: Vec<u32>,
    picker: Picker,
}

/// One next-event sample of an emitter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmitterSample {
    /// The emitter's scene triangle.
    pub prim: u32,
    /// The sampled point on it.
    pub point: Vec3,
    /// Its front normal.
    pub normal: Vec3,
    /// Unit direction from the receiver to `point`.
    pub direction: Vec3,
    /// Radiance leaving `point` towards the receiver.
    pub radiance: Vec3,
    /// Solid-angle density of `direction` under this sampling, > 0 and finite.
    pub pdf: f32,
}

/// Luminance of linear RGB (Rec. 709), the emitters' power measure.
pub fn luminance(c: Vec3) -> f32 {
    guidebake_kernels::estimator::luminance_f32(c.to_array())
}

impl Emitters {
    /// The emitters among `triangles` (corners, unit front normal and emitted radiance per
    /// scene triangle, in primitive order); `None` when none emits (a world without emitters
    /// samples none). Triangles of no power (no area, black or non-finite emission) are not
    /// emitters: nothing can hit them, or they give nothing.
    pub fn new(
        triangles: impl ExactSizeIterator<Item = ([Vec3; 3], Vec3, Vec3)>,
        selection: EmitterSelection,
    ) -> Option<Self> {
        let mut of_prim = vec![NOT_AN_EMITTER; triangles.len()];
        let mut emitters = Vec::new();
        for (prim, ([a, b, c], normal, radiance)) in triangles.enumerate() {
            let area = 0.5 * (b - a).cross(c - a).length();
            let power = area * luminance(radiance);
            if !(power > 0.0 && power.is_finite() && radiance.is_finite()) {
                continue;
            }
            of_prim[prim] = emitters.len() as u32;
            emitters.push(Emitter {
                prim: prim as u32,
                a,
                ab: b - a,
                ac: c - a,
                normal,
                area,
                radiance,
            });
        }
        if emitters.is_empty() {
            return None;
        }
        let picker = match selection {
            EmitterSelection::Power => {
                let powers: Vec<f32> = emitters.iter().map(Emitter::power).collect();
                Picker::Power(AliasTable::new(&powers)?)
            }
            EmitterSelection::Tree => {
                let bounds: Vec<EmitterBounds> = emitters.iter().map(Emitter::bounds).collect();
                Picker::Tree(LightTree::build(&bounds)?)
            }
            EmitterSelection::Local if emitters.len() <= LOCAL_MAX => {
                Picker::Local(Box::new(LocalRows::new(&emitters)))
            }
            EmitterSelection::Local => {
                let powers: Vec<f32> = emitters.iter().map(Emitter::power).collect();
                Picker::Power(AliasTable::new(&powers)?)
            }
        };
        Some(Self {
            emitters,
            of_prim,
            picker,
        })
    }

    /// Number of emitters.
    pub fn len(&self) -> usize {
        self.emitters.len()
    }

    /// Always false: a world without emitters has no [`Emitters`].
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// Emitter selection at receiver `(p, n)`: what [`EmittersAt::sample`],
    /// [`EmittersAt::pdf`], [`EmittersAt::select`] and [`EmittersAt::selection_pmf`] need
    /// there, computed once (`local`'s weights of every emitter) for any number of picks and
    /// densities at the same receiver.
    pub fn at(&self, p: Vec3, n: Vec3) -> EmittersAt<'_> {
        let local = match &self.picker {
            Picker::Local(rows) => Some(LocalWeights::new(rows, p, n)),
            Picker::Power(_) | Picker::Tree(_) => None,
        };
        EmittersAt {
            emitters: self,
            p,
            n,
            local,
        }
    }

    /// Samples a direction towards an emitter from receiver `p` with unit normal `n`
    /// ([`EmittersAt::sample`]; several samples at one receiver: [`Self::at`] once).
    pub fn sample(&self, p: Vec3, n: Vec3, pick: f32, u: [f32; 2]) -> Option<EmitterSample> {
        self.at(p, n).sample(pick, u)
    }

    /// The solid-angle density with which [`Self::sample`] at receiver `(p, n)` picks the
    /// direction `direction` that meets triangle `prim` at distance `t`
    /// ([`EmittersAt::pdf`]); weighs no emitter where `prim` cannot be sampled.
    pub fn pdf(&self, p: Vec3, n: Vec3, prim: u32, direction: Vec3, t: f32) -> f32 {
        if self.front_emitter(prim, direction).is_none() {
            return 0.0;
        }
        self.at(p, n).pdf(prim, direction, t)
    }

    /// Picks an emitter for receiver `(p, n)` with `u` in [0, 1) ([`EmittersAt::select`]).
    #[inline]
    pub fn select(&self, p: Vec3, n: Vec3, u: f32) -> Option<(u32, f32)> {
        match &self.picker {
            Picker::Power(table) => Some(table.pick(u)),
            Picker::Tree(tree) => tree.pick(p, n, u),
            Picker::Local(_) => self.at(p, n).select(u),
        }
    }

    /// The probability that [`Self::select`] at `(p, n)` picks emitter `index`
    /// ([`EmittersAt::selection_pmf`]).
    #[inline]
    pub fn selection_pmf(&self, p: Vec3, n: Vec3, index: u32) -> f32 {
        match &self.picker {
            Picker::Power(table) => table.pmf(index),
            Picker::Tree(tree) => tree.pmf(p, n, index),
            Picker::Local(_) => self.at(p, n).selection_pmf(index),
        }
    }

    /// The emitter index of triangle `prim` and the emitter, if it is one and `direction`
    /// meets its front face.
    fn front_emitter(&self, prim: u32, direction: Vec3) -> Option<(u32, &Emitter)> {
        let &index = self.of_prim.get(prim as usize)?;
        let e = self.emitters.get(index as usize)?;
        (-e.normal.dot(direction) > 0.0).then_some((index, e))
    }
}

/// [`EmitterSelection::Local`]'s selection at one receiver: the running sums of its
/// weights (the pick) and each emitter's probability (the pick's and the pmf's: the same
/// numbers, so they agree bit for bit, as MIS needs).
#[derive(Clone, Copy, Debug, PartialEq)]
struct LocalWeights {
    /// Running sums of the weights ([`LocalRows::weights`]) in emitter order; lanes past the
    /// last emitter are never read.
    cdf: f32x8,
    /// Each emitter's weight over their sum; 0 past the last emitter, and everywhere when
    /// none can light the receiver.
    pmf: [f32; LOCAL_MAX],
    /// The weights' sum; 0 when none can light the receiver (or it overflows).
    sum: f32,
    /// Emitters.
    len: u32,
}

impl LocalWeights {
    fn new(rows: &LocalRows, p: Vec3, n: Vec3) -> Self {
        let w = rows.weights(p, n);
        let mut cdf = [0.0; LOCAL_MAX];
        let mut sum = 0.0;
        for (c, &wi) in cdf.iter_mut().zip(&w).take(rows.len) {
            sum += wi;
            *c = sum;
        }
        let (pmf, sum) = if sum > 0.0 && sum < f32::INFINITY {
            ((f32x8::new(w) / f32x8::splat(sum)).to_array(), sum)
        } else {
            ([0.0; LOCAL_MAX], 0.0)
        };
        Self {
            cdf: f32x8::new(cdf),
            pmf,
            sum,
            len: rows.len as u32,
        }
    }

    /// Picks an emitter in proportion to the weights with `u` in [0, 1): the first whose
    /// running sum exceeds `u · sum` (never one of weight 0), its index and probability;
    /// `None` when none can light the receiver.
    fn pick(&self, u: f32) -> Option<(u32, f32)> {
        if self.sum <= 0.0 {
            return None;
        }
        let target = f32x8::splat(u * self.sum);
        let below = self.cdf.simd_le(target).to_bitmask() & ((1 << self.len) - 1);
        let mut i = below.count_ones() as usize;
        if i == self.len as usize {
            // Rounding can leave `u · sum` at or above the last sum: the last emitter of
            // weight.
            i = self.pmf.iter().rposition(|&q| q > 0.0)?;
        }
        Some((i as u32, self.pmf[i]))
    }

    /// The probability that [`Self::pick`] picks emitter `index`.
    fn pmf(&self, index: u32) -> f32 {
        self.pmf.get(index as usize).copied().unwrap_or(0.0)
    }
}

/// Emitter selection at one receiver ([`Emitters::at`]): `local`'s weights computed once,
/// for the eight next-event samples of a texel or a path vertex's sample and the MIS
/// density of the ray that leaves it.
#[derive(Clone, Copy, Debug)]
pub struct EmittersAt<'a> {
    emitters: &'a Emitters,
    p: Vec3,
    n: Vec3,
    /// `Some` under [`Picker::Local`].
    local: Option<LocalWeights>,
}

impl EmittersAt<'_> {
    /// The receiver's point.
    pub fn point(&self) -> Vec3 {
        self.p
    }

    /// The receiver's unit normal.
    pub fn normal(&self) -> Vec3 {
        self.n
    }

    /// Samples a direction towards an emitter from the receiver: `pick` chooses the emitter,
    /// `u` the point on it. `None` when the sample cannot light the receiver (the emitter
    /// faces away, the point is below the receiver's horizon, or no emitter can reach it):
    /// it contributes zero and needs no shadow ray.
    pub fn sample(&self, pick: f32, u: [f32; 2]) -> Option<EmitterSample> {
        let (p, n) = (self.p, self.n);
        let (index, pmf) = self.select(pick)?;
        let e = &self.emitters.emitters[index as usize];
        let (point, density) = e.sample_point(p, u)?;
        let to = point - p;
        let direction = to.normalize_or_zero();
        if !(-e.normal.dot(direction) > 0.0 && n.dot(direction) > 0.0) {
            return None;
        }
        let pdf = pmf * density;
        (pdf > 0.0 && pdf.is_finite()).then_some(EmitterSample {
            prim: e.prim,
            point,
            normal: e.normal,
            direction,
            radiance: e.radiance,
            pdf,
        })
    }

    /// The solid-angle density with which [`Self::sample`] picks the direction `direction`
    /// that meets triangle `prim` at distance `t`: 0 when `prim` is not an emitter or is
    /// seen from behind.
    pub fn pdf(&self, prim: u32, direction: Vec3, t: f32) -> f32 {
        let Some((index, e)) = self.emitters.front_emitter(prim, direction) else {
            return 0.0;
        };
        let pdf = self.selection_pmf(index) * e.density(self.p, direction, t);
        if pdf.is_finite() { pdf } else { f32::MAX }
    }

    /// Picks an emitter with `u` in [0, 1) by the selection in force: its index (in the
    /// order of [`Emitters::new`]'s emitters) and the probability of the pick; `None` when
    /// the selection finds none that can light the receiver.
    #[inline]
    pub fn select(&self, u: f32) -> Option<(u32, f32)> {
        match (&self.emitters.picker, &self.local) {
            (_, Some(local)) => local.pick(u),
            (Picker::Power(table), None) => Some(table.pick(u)),
            (Picker::Tree(tree), None) => tree.pick(self.p, self.n, u),
            (Picker::Local(_), None) => unreachable!("Emitters::at weighs local emitters"),
        }
    }

    /// The probability that [`Self::select`] picks emitter `index`.
    #[inline]
    pub fn selection_pmf(&self, index: u32) -> f32 {
        match (&self.emitters.picker, &self.local) {
            (_, Some(local)) => local.pmf(index),
            (Picker::Power(table), None) => table.pmf(index),
            (Picker::Tree(tree), None) => tree.pmf(self.p, self.n, index),
            (Picker::Local(_), None) => unreachable!("Emitters::at weighs local emitters"),
        }
    }
}

/// `a > b ? a : b`, as `maxps` (and `f32x8::fast_max`) computes it, NaN included.
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `a < b ? a : b`, as `minps` (and `f32x8::fast_min`) computes it, NaN included.
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// Solid angles (sr) within which an emitter is sampled by solid angle: below, the
/// spherical triangle is too thin for Arvo's formulas in floating point, and area sampling is
/// uniform in solid angle anyway; above, the receiver is so close to the triangle's plane that
/// the sphere's cap degenerates (pbrt-v4's bounds).
const SPHERICAL_SOLID_ANGLES: core::ops::RangeInclusive<f64> = 3e-4..=6.22;

/// Receivers nearer an emitter than this (its area over the squared distance to its
/// centroid) sample it by solid angle; farther ones by area, which is as good there and
/// cheaper. Measured on the converted scenes (docs/bake.md): solid-angle sampling of every
/// emitter cost 1.5× the gather time on the Cornell box for a 4% lower RMSE.
const SOLID_ANGLE_FROM: f32 = 0.1;

/// How [`Emitter::sample_point`] samples an emitter from a receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PointSampling {
    /// Uniformly by area.
    Area,
    /// Uniformly in the solid angle (sr) the triangle subtends.
    SolidAngle(f64),
}

impl Emitter {
    fn power(&self) -> f32 {
        self.area * luminance(self.radiance)
    }

    fn bounds(&self) -> EmitterBounds {
        EmitterBounds {
            corners: self.corners(),
            normal: self.normal,
            power: self.power(),
        }
    }

    fn corners(&self) -> [Vec3; 3] {
        [self.a, self.a + self.ab, self.a + self.ac]
    }

    /// This emitter as a lane of [`LocalRows`].
    fn local_lane(&self) -> LocalLane {
        let centroid = self.a + (self.ab + self.ac) * (1.0 / 3.0);
        let corners = self.corners().map(|v| v - centroid);
        LocalLane {
            a: self.a,
            normal: self.normal,
            centroid,
            corners,
            radius: corners.map(Vec3::length).into_iter().fold(0.0, f32::max),
            area: self.area,
            lum: luminance(self.radiance),
        }
    }

    /// [`EmitterSelection::Local`]'s weight of this emitter at receiver `(p, n)`, the scalar
    /// reference of [`LocalRows::weights`]: `lum · min(A cos θ_e / d², 2π) · max(cos θ_r,
    /// floor)` to its centroid at distance d. Zero only where nothing it emits can reach the
    /// receiver: `p` behind its plane (as [`Self::point_sampling`] decides), or every corner
    /// below `p`'s horizon (then the whole triangle is; a corner may dip below it by
    /// [`LOCAL_HORIZON_SLACK`] of the distance to the farthest corner, a bound on the
    /// rounding). Positive otherwise, so the selection stays unbiased.
    #[cfg_attr(not(test), allow(dead_code))]
    fn local_weight(&self, p: Vec3, n: Vec3) -> f32 {
        let l = self.local_lane();
        let dot = |x: f32, y: f32, z: f32, v: Vec3| x * v.x + y * v.y + z * v.z;
        let height = dot(p.x - l.a.x, p.y - l.a.y, p.z - l.a.z, l.normal);
        let to = l.centroid - p;
        let d2 = to.x * to.x + to.y * to.y + to.z * to.z;
        let d = d2.sqrt();
        let cn = dot(n.x, n.y, n.z, to);
        let [c0, c1, c2] = l.corners.map(|c| dot(n.x, n.y, n.z, c) + cn);
        let highest = max_ps(max_ps(c0, c1), c2);
        let slack = (d + l.radius) * -LOCAL_HORIZON_SLACK;
        let r = 1.0 / (d2 * d);
        let omega = min_ps(l.area * height * r, core::f32::consts::TAU);
        let cos_r = max_ps(cn * d2 * r, LOCAL_COS_FLOOR);
        // Never 0 where it can light the receiver, never infinite.
        let w = min_ps(max_ps(l.lum * omega * cos_r, f32::MIN_POSITIVE), f32::MAX);
        if height > 0.0 && highest > slack {
            w
        } else {
            0.0
        }
    }

    /// The solid angle the triangle subtends at `p` (Van Oosterom & Strackee 1983), in f64;
    /// 0 when `p` lies behind it (it emits from its front only) or in its plane.
    fn solid_angle(&self, p: Vec3) -> f64 {
        if (p - self.a).dot(self.normal) <= 0.0 {
            return 0.0;
        }
        let [a, b, c] = self.corners().map(|v| (v - p).as_dvec3());
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let triple = a.dot(b.cross(c)).abs();
        let below = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        2.0 * triple.atan2(below)
    }

    /// How this emitter is sampled from `p` (the same in [`Self::sample_point`] and
    /// [`Self::density`]); `None` when `p` is behind it.
    fn point_sampling(&self, p: Vec3) -> Option<PointSampling> {
        if (p - self.a).dot(self.normal) <= 0.0 {
            return None;
        }
        let centroid = self.a + (self.ab + self.ac) * (1.0 / 3.0);
        if self.area < SOLID_ANGLE_FROM * (centroid - p).length_squared() {
            return Some(PointSampling::Area);
        }
        let omega = self.solid_angle(p);
        Some(if SPHERICAL_SOLID_ANGLES.contains(&omega) {
            PointSampling::SolidAngle(omega)
        } else {
            PointSampling::Area
        })
    }

    /// Where next-event estimation samples this emitter from `p`: uniformly in the solid
    /// angle it subtends (Arvo 1995) when `p` is near it, so a receiver next to an emitter
    /// gets bounded weights, else uniformly by area ([`Self::point_sampling`]). Returns the
    /// point and the solid-angle density of its direction (given this emitter).
    fn sample_point(&self, p: Vec3, u: [f32; 2]) -> Option<(Vec3, f32)> {
        match self.point_sampling(p)? {
            PointSampling::SolidAngle(omega) => {
                let [a, b, c] = self.corners().map(|v| (v - p).as_dvec3().normalize());
                let dir = sample_spherical_triangle(a, b, c, omega, u)?.as_vec3();
                let t = (self.a - p).dot(self.normal) / dir.dot(self.normal);
                let point = p + dir * t;
                (t > 0.0 && point.is_finite()).then_some((point, (1.0 / omega) as f32))
            }
            PointSampling::Area => {
                let su = u[0].sqrt();
                let point = self.a + self.ab * (1.0 - su) + self.ac * (u[1] * su);
                let to = point - p;
                let d = to.length();
                Some((point, self.area_density(to / d, d)))
            }
        }
    }

    /// The solid-angle density of [`Self::sample_point`] from `p` for the direction
    /// `direction` that meets the triangle at distance `t`.
    fn density(&self, p: Vec3, direction: Vec3, t: f32) -> f32 {
        match self.point_sampling(p) {
            None => 0.0,
            Some(PointSampling::SolidAngle(omega)) => (1.0 / omega) as f32,
            Some(PointSampling::Area) => self.area_density(direction, t),
        }
    }

    /// The solid-angle density of area sampling for `direction` meeting the triangle at
    /// distance `t`: t² / (A cos θ_e).
    fn area_density(&self, direction: Vec3, t: f32) -> f32 {
        let cos_emitter = -self.normal.dot(direction);
        if cos_emitter <= 0.0 {
            return 0.0;
        }
        t * t / (self.area * cos_emitter)
    }
}

/// A direction uniformly distributed over the spherical triangle of unit vectors `a`, `b`,
/// `c` of solid angle `area` (Arvo, *Stratified Sampling of Spherical Triangles*, 1995); in
/// f64, `None` where the triangle is too degenerate to sample.
fn sample_spherical_triangle(
    a: DVec3,
    b: DVec3,
    c: DVec3,
    area: f64,
    u: [f32; 2],
) -> Option<DVec3> {
    // The angle at vertex a, between the great circles a–b and a–c.
    let n_ab = a.cross(b).try_normalize()?;
    let n_ac = a.cross(c).try_normalize()?;
    let cos_alpha = n_ab.dot(n_ac).clamp(-1.0, 1.0);
    let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
    let alpha = cos_alpha.acos();
    // The sub-triangle a–b–ĉ of area u₀ · area: ĉ on the arc a–c.
    let sub = f64::from(u[0]) * area;
    let (s, t) = (sub - alpha).sin_cos();
    let uu = t - cos_alpha;
    let v = s + sin_alpha * a.dot(b);
    let q = ((v * t - uu * s) * cos_alpha - v) / ((v * s + uu * t) * sin_alpha);
    let q = q.clamp(-1.0, 1.0);
    let c_hat = a * q + (c - a * c.dot(a)).try_normalize()? * (1.0 - q * q).max(0.0).sqrt();
    // Uniform in z along the arc b–ĉ.
    let z = 1.0 - f64::from(u[1]) * (1.0 - c_hat.dot(b));
    let z = z.clamp(-1.0, 1.0);
    let dir = b * z + (c_hat - b * c_hat.dot(b)).try_normalize()? * (1.0 - z * z).max(0.0).sqrt();
    dir.is_finite().then_some(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::Pcg32;

    fn emitter(corners: [Vec3; 3]) -> Emitter {
        let [a, b, c] = corners;
        Emitter {
            prim: 0,
            a,
            ab: b - a,
            ac: c - a,
            normal: (b - a).cross(c - a).normalize(),
            area: 0.5 * (b - a).cross(c - a).length(),
            radiance: Vec3::ONE,
        }
    }

    /// The triangle's four midpoint children, `depth` times: 4^depth cells covering it.
    fn subdivide(t: [Vec3; 3], depth: u32) -> Vec<[Vec3; 3]> {
        if depth == 0 {
            return vec![t];
        }
        let [a, b, c] = t;
        let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
        [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            .into_iter()
            .flat_map(|s| subdivide(s, depth - 1))
            .collect()
    }

    /// Which cell of `cells` (coplanar) the point `y` lies in.
    fn cell_of(cells: &[[Vec3; 3]], normal: Vec3, y: Vec3) -> usize {
        let inside = |[a, b, c]: [Vec3; 3]| {
            let edge = |p: Vec3, q: Vec3| (q - p).cross(y - p).dot(normal) >= -1e-6;
            edge(a, b) && edge(b, c) && edge(c, a)
        };
        cells
            .iter()
            .position(|&t| inside(t))
            .expect("inside the triangle")
    }

    #[test]
    fn sampled_points_are_uniform_in_solid_angle_chi_square() {
        let corners = [
            Vec3::new(-1.0, -0.5, 1.0),
            Vec3::new(1.5, -0.5, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        // Facing down (towards the receivers below).
        let tri = emitter([corners[0], corners[2], corners[1]]);
        let cells = subdivide(corners, 2);
        for p in [
            Vec3::new(0.1, 0.0, 0.9),
            Vec3::new(2.0, 0.3, 0.2),
            Vec3::new(0.0, 0.0, -1.5),
        ] {
            let Some(PointSampling::SolidAngle(omega)) = tri.point_sampling(p) else {
                panic!("{p}: near enough to sample by solid angle");
            };
            let want: Vec<f64> = cells
                .iter()
                .map(|&[a, b, c]| emitter([a, c, b]).solid_angle(p) / omega)
                .collect();
            assert!((want.iter().sum::<f64>() - 1.0).abs() < 1e-6);
            let n = 200_000;
            let mut counts = vec![0u32; cells.len()];
            let mut rng = Pcg32::new(5, 9);
            for _ in 0..n {
                let (y, density) = tri
                    .sample_point(p, [rng.next_f32(), rng.next_f32()])
                    .unwrap();
                assert!((f64::from(density) - 1.0 / omega).abs() < 1e-6 / omega);
                counts[cell_of(&cells, Vec3::Z, y)] += 1;
            }
            let chi2: f64 = counts
                .iter()
                .zip(&want)
                .map(|(&k, &w)| (f64::from(k) - w * n as f64).powi(2) / (w * n as f64))
                .sum();
            // 15 degrees of freedom: P(χ² > 37.7) = 0.001.
            assert!(
                chi2 < 37.7,
                "{p}: χ² = {chi2}, counts {counts:?}, want {want:?}"
            );
        }
    }

    /// A world of `emitters` (corners, radiance 1) under `selection`.
    fn world_of(tris: &[[Vec3; 3]], selection: EmitterSelection) -> Emitters {
        let it = tris.iter().map(|&[a, b, c]| {
            let n = (b - a).cross(c - a).normalize();
            ([a, b, c], n, Vec3::splat(1.0 + a.x.abs()))
        });
        Emitters::new(it.collect::<Vec<_>>().into_iter(), selection).unwrap()
    }

    /// `local` picks every emitter with the probability its pmf says (χ² over the emitters),
    /// never one that cannot light the receiver, and the pmfs of a receiver sum to 1.
    #[test]
    fn local_picks_follow_their_pmf_chi_square() {
        // Six triangles around a receiver: facing it near and far, one seen from behind, one
        // below its horizon, one straddling it, one grazing.
        let tris = [
            [
                Vec3::new(-0.2, -0.2, 0.5),
                Vec3::new(0.0, 0.3, 0.5),
                Vec3::new(0.3, -0.2, 0.5),
            ],
            [
                Vec3::new(1.0, 1.0, 3.0),
                Vec3::new(1.5, 2.0, 3.0),
                Vec3::new(2.0, 1.0, 3.0),
            ],
            [
                Vec3::new(-1.0, 0.0, 1.0),
                Vec3::new(-0.5, 0.0, 1.0),
                Vec3::new(-1.0, 0.5, 1.0),
            ],
            [
                Vec3::new(0.0, 2.0, -1.0),
                Vec3::new(0.5, 2.0, -0.5),
                Vec3::new(-0.5, 2.0, -0.5),
            ],
            [
                Vec3::new(2.0, -0.5, -0.3),
                Vec3::new(2.0, 0.5, -0.3),
                Vec3::new(2.0, 0.0, 0.6),
            ],
            [
                Vec3::new(-2.0, -1.0, 0.1),
                Vec3::new(-2.0, 1.0, 0.1),
                Vec3::new(-2.0, 0.0, 0.8),
            ],
        ];
        let world = world_of(&tris, EmitterSelection::Local);
        assert!(
            matches!(world.picker, Picker::Local(_)),
            "six emitters are weighed locally"
        );
        for (p, n) in [
            (Vec3::ZERO, Vec3::Z),
            (
                Vec3::new(0.3, 0.2, 0.1),
                Vec3::new(0.3, -0.2, 1.0).normalize(),
            ),
            (Vec3::new(1.0, 0.0, 0.0), Vec3::X),
        ] {
            let at = world.at(p, n);
            let pmf: Vec<f64> = (0..tris.len())
                .map(|i| f64::from(at.selection_pmf(i as u32)))
                .collect();
            assert!((pmf.iter().sum::<f64>() - 1.0).abs() < 1e-5, "{p}: {pmf:?}");
            for (i, [a, b, c]) in tris.iter().enumerate() {
                let behind = (p - *a).dot((*b - *a).cross(*c - *a)) <= 0.0;
                let below = [a, b, c].iter().all(|v| (**v - p).dot(n) < 0.0);
                assert_eq!(pmf[i] == 0.0, behind || below, "{p}: emitter {i}: {pmf:?}");
            }
            let draws = 200_000;
            let mut counts = vec![0u32; tris.len()];
            let mut rng = Pcg32::new(11, 3);
            for _ in 0..draws {
                let (i, q) = at.select(rng.next_f32()).unwrap();
                assert!(pmf[i as usize] > 0.0);
                assert_eq!(
                    q.to_bits(),
                    at.selection_pmf(i).to_bits(),
                    "the pick's probability is the pmf's"
                );
                assert_eq!(q.to_bits(), world.selection_pmf(p, n, i).to_bits());
                counts[i as usize] += 1;
            }
            let live: Vec<usize> = (0..tris.len()).filter(|&i| pmf[i] > 0.0).collect();
            let chi2: f64 = live
                .iter()
                .map(|&i| {
                    let want = pmf[i] * f64::from(draws);
                    (f64::from(counts[i]) - want).powi(2) / want
                })
                .sum();
            // At most 5 degrees of freedom: P(χ² > 20.5) = 0.001.
            assert!(
                chi2 < 20.5,
                "{p}: χ² = {chi2}, counts {counts:?}, pmf {pmf:?}"
            );
        }
    }

    /// The 8-wide weights are the scalar reference's, bit for bit, at random receivers
    /// around eight emitters of every orientation (some far, tiny, huge, or in the
    /// receiver's plane), and at receivers on an emitter's plane, at its centroid and its
    /// corners; and the pick's probability is the pmf's.
    #[test]
    fn wide_local_weights_are_the_scalar_ones_bit_for_bit() {
        let mut rng = Pcg32::new(7, 21);
        let mut r = move || 4.0 * rng.next_f32() - 2.0;
        for world in 0..40 {
            let count = 1 + world % LOCAL_MAX;
            let mut tris: Vec<[Vec3; 3]> = (0..count)
                .map(|_| {
                    let a = Vec3::new(r(), r(), r());
                    let s = [1e-3, 0.3, 1.0, 40.0][world % 4];
                    [
                        a,
                        a + Vec3::new(r(), r(), r()) * s,
                        a + Vec3::new(r(), r(), r()) * s,
                    ]
                })
                .collect();
            // One emitter in the plane z = 0 of the receivers below.
            tris[0] = [
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ];
            let it = tris.iter().map(|&[a, b, c]| {
                let n = (b - a).cross(c - a).normalize();
                ([a, b, c], n, Vec3::new(1.0 + r().abs(), 2.0, 0.5))
            });
            let emitters =
                Emitters::new(it.collect::<Vec<_>>().into_iter(), EmitterSelection::Local).unwrap();
            let Picker::Local(rows) = &emitters.picker else {
                panic!("{count} emitters are weighed locally");
            };
            let mut receivers: Vec<(Vec3, Vec3)> = (0..200)
                .map(|_| {
                    (
                        Vec3::new(r(), r(), r()) * 3.0,
                        Vec3::new(r(), r(), r()).normalize_or(Vec3::Z),
                    )
                })
                .collect();
            for e in &emitters.emitters {
                let c = e.a + (e.ab + e.ac) * (1.0 / 3.0);
                receivers.extend(e.corners().map(|v| (v, e.normal)));
                receivers.push((c, -e.normal));
                receivers.push((c + e.normal * 1e-4, Vec3::Z));
            }
            receivers.push((Vec3::new(0.2, 0.0, 0.0), Vec3::Z));
            receivers.push((Vec3::new(0.2, 0.0, 1e-3), Vec3::X));
            for (p, n) in receivers {
                let wide = rows.weights(p, n);
                for (i, e) in emitters.emitters.iter().enumerate() {
                    assert_eq!(
                        wide[i].to_bits(),
                        e.local_weight(p, n).to_bits(),
                        "emitter {i} of {count} at {p}, {n}"
                    );
                }
                assert!(wide[count..].iter().all(|&w| w == 0.0));
                let at = emitters.at(p, n);
                if let Some((i, q)) = at.select(0.5 * (r() + 2.0) / 2.0) {
                    assert!(wide[i as usize] > 0.0);
                    assert_eq!(q.to_bits(), at.selection_pmf(i).to_bits());
                    assert_eq!(q.to_bits(), emitters.selection_pmf(p, n, i).to_bits());
                }
            }
        }
    }

    /// Beyond [`LOCAL_MAX`] emitters `local` samples by power, as `power` does.
    #[test]
    fn local_falls_back_to_power_in_a_world_of_many_emitters() {
        let tris: Vec<[Vec3; 3]> = (0..=LOCAL_MAX)
            .map(|i| {
                let x = i as f32;
                [
                    Vec3::new(x, 0.0, 1.0),
                    Vec3::new(x, 1.0, 1.0),
                    Vec3::new(x + 1.0, 0.0, 1.0),
                ]
            })
            .collect();
        assert!(matches!(
            world_of(&tris, EmitterSelection::Local).picker,
            Picker::Power(_)
        ));
        assert!(matches!(
            world_of(&tris[..LOCAL_MAX], EmitterSelection::Local).picker,
            Picker::Local(_)
        ));
    }
}
