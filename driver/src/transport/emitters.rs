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
//! the horizon; O(N), docs/bake.md "Next-event estimation on the bidir room").
//!
//! A world without emitters builds none of this and traces no shadow rays for them.

use glam::{DVec3, Vec3};

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
    /// Every emitter weighed at the receiver ([`LOCAL_MAX`] of them at most; beyond, as
    /// `power`): luminance × approximate solid angle × the receiver's cosine to its centroid,
    /// zero for an emitter seen from behind or wholly below the receiver's horizon. The
    /// default: at equal time it beats `power` and `tree` on the converted scenes
    /// (docs/bake.md, "Next-event estimation on the bidir room").
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

/// The picker of [`EmitterSelection`].
#[derive(Debug)]
enum Picker {
    Power(AliasTable),
    Tree(LightTree),
    /// [`EmitterSelection::Local`]: the luminance of each emitter's radiance.
    Local(Vec<f32>),
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
                Picker::Local(emitters.iter().map(|e| luminance(e.radiance)).collect())
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

    /// Samples a direction towards an emitter from receiver `p` with unit normal `n`: `pick`
    /// chooses the emitter, `u` the point on it. `None` when the sample cannot light the
    /// receiver (the emitter faces away, the point is below the receiver's horizon, or no
    /// emitter can reach it): it contributes zero and needs no shadow ray.
    pub fn sample(&self, p: Vec3, n: Vec3, pick: f32, u: [f32; 2]) -> Option<EmitterSample> {
        let (index, pmf) = self.select(p, n, pick)?;
        let e = &self.emitters[index as usize];
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

    /// The solid-angle density with which [`Self::sample`] at receiver `(p, n)` picks the
    /// direction `direction` that meets triangle `prim` at distance `t`: 0 when `prim` is not
    /// an emitter or is seen from behind.
    pub fn pdf(&self, p: Vec3, n: Vec3, prim: u32, direction: Vec3, t: f32) -> f32 {
        let Some(&index) = self.of_prim.get(prim as usize) else {
            return 0.0;
        };
        let Some(e) = self.emitters.get(index as usize) else {
            return 0.0;
        };
        if -e.normal.dot(direction) <= 0.0 {
            return 0.0;
        }
        let pdf = self.selection_pmf(p, n, index) * e.density(p, direction, t);
        if pdf.is_finite() { pdf } else { f32::MAX }
    }

    /// Picks an emitter for receiver `(p, n)` with `u` in [0, 1) by the selection in force:
    /// its index (in the order of [`Self::new`]'s emitters) and the probability of the pick;
    /// `None` when the selection finds none that can light the receiver.
    pub fn select(&self, p: Vec3, n: Vec3, u: f32) -> Option<(u32, f32)> {
        match &self.picker {
            Picker::Power(table) => Some(table.pick(u)),
            Picker::Tree(tree) => tree.pick(p, n, u),
            Picker::Local(lum) => self.local_pick(lum, p, n, u),
        }
    }

    /// The probability that [`Self::select`] at `(p, n)` picks emitter `index`.
    pub fn selection_pmf(&self, p: Vec3, n: Vec3, index: u32) -> f32 {
        match &self.picker {
            Picker::Power(table) => table.pmf(index),
            Picker::Tree(tree) => tree.pmf(p, n, index),
            Picker::Local(lum) => {
                let (w, sum) = self.local_weights(lum, p, n);
                match w.get(index as usize) {
                    Some(&wi) if sum > 0.0 => wi / sum,
                    _ => 0.0,
                }
            }
        }
    }

    /// [`EmitterSelection::Local`]'s weight of every emitter at receiver `(p, n)`, and their
    /// sum (the same arithmetic in [`Self::sample`] and [`Self::pdf`], so the pick's
    /// probability and the pmf agree bit for bit).
    fn local_weights(&self, lum: &[f32], p: Vec3, n: Vec3) -> ([f32; LOCAL_MAX], f32) {
        let mut w = [0.0; LOCAL_MAX];
        let mut sum = 0.0;
        for ((w, e), &l) in w.iter_mut().zip(&self.emitters).zip(lum) {
            *w = e.local_weight(l, p, n);
            sum += *w;
        }
        (w, sum)
    }

    /// Picks an emitter in proportion to [`Self::local_weights`] with `u` in [0, 1): its
    /// index and probability; `None` when none can light the receiver.
    fn local_pick(&self, lum: &[f32], p: Vec3, n: Vec3, u: f32) -> Option<(u32, f32)> {
        let (w, sum) = self.local_weights(lum, p, n);
        if !(sum > 0.0 && sum.is_finite()) {
            return None;
        }
        let target = u * sum;
        let mut acc = 0.0;
        let mut last = None;
        for (i, &wi) in w.iter().enumerate().take(lum.len()) {
            if wi > 0.0 {
                acc += wi;
                last = Some(i);
                if target < acc {
                    break;
                }
            }
        }
        // Rounding can leave `target` at or above the last sum: the last emitter of weight.
        last.map(|i| (i as u32, w[i] / sum))
    }
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

    /// [`EmitterSelection::Local`]'s weight of this emitter (luminance `lum`) at receiver
    /// `(p, n)`: `lum · min(A cos θ_e / d², 2π) · max(cos θ_r, floor)` to its centroid at
    /// distance d. Zero only where nothing it emits can reach the receiver: `p` behind its
    /// plane (as [`Self::point_sampling`] decides), or every corner below `p`'s horizon (then
    /// the whole triangle is). Positive otherwise, so the selection stays unbiased.
    fn local_weight(&self, lum: f32, p: Vec3, n: Vec3) -> f32 {
        let height = (p - self.a).dot(self.normal);
        if !(height > 0.0) {
            return 0.0;
        }
        let above = self.corners().into_iter().any(|v| {
            let to = v - p;
            to.dot(n) > -1e-5 * to.abs().max_element()
        });
        if !above {
            return 0.0;
        }
        let to = self.a + (self.ab + self.ac) * (1.0 / 3.0) - p;
        let d2 = to.length_squared();
        let d = d2.sqrt();
        let omega = (self.area * height / (d2 * d)).min(core::f32::consts::TAU);
        let cos_r = (n.dot(to) / d).max(LOCAL_COS_FLOOR);
        let w = lum * omega * cos_r;
        if w.is_finite() {
            w.max(f32::MIN_POSITIVE)
        } else {
            f32::MAX
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
        let Picker::Local(lum) = &world.picker else {
            panic!("six emitters are weighed locally");
        };
        for (p, n) in [
            (Vec3::ZERO, Vec3::Z),
            (
                Vec3::new(0.3, 0.2, 0.1),
                Vec3::new(0.3, -0.2, 1.0).normalize(),
            ),
            (Vec3::new(1.0, 0.0, 0.0), Vec3::X),
        ] {
            let (w, sum) = world.local_weights(lum, p, n);
            let pmf: Vec<f64> = (0..tris.len())
                .map(|i| f64::from(w[i]) / f64::from(sum))
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
                let (i, q) = world.local_pick(lum, p, n, rng.next_f32()).unwrap();
                assert!(pmf[i as usize] > 0.0);
                assert_eq!(
                    q,
                    w[i as usize] / sum,
                    "the pick's probability is the pmf's"
                );
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
