//! Everything a gather ray can meet, shared read-only by every worker: the BVH in the
//! kernels' layout, per-triangle shading data, the lights (analytic lights and emissive
//! triangles), the sky, and the transport settings.
//!
//! It lives in [`crate::transport`], below the bake, and how light is carried lives beside
//! it: next-event estimation ([`crate::transport::direct`]), what leaves a gather hit
//! ([`crate::transport::path`]), the emitters ([`crate::transport::emitters`]). Light kinds the scene lacks cost nothing:
//! no light, no shadow rays; no emitter, no emitter table; a black sky, no lookups; a black
//! surface, no continuation.

use glam::Vec3;
use guidebake_kernels::packet::{offset_origin, triangle_extent};
use guidebake_kernels::traverse::WideRef;

use super::settings::{EmitterSampling, Transport};

use crate::bvh::{Bvh, BvhError, Preset};
use crate::output::result_file::{FinishedResults, TexelResult};
use crate::scene::texture::{HitAlbedo, VaryingAlbedo};
use crate::scene::{Scene, Sky};
use crate::transport::emitters::{EmitterSelection, Emitters};
use crate::transport::lights::{AnalyticLight, analytic_lights};
use crate::transport::series::PreviousPass;
use crate::transport::sky::{sky_is_black, sky_radiance};

/// Shading data of one triangle, indexed by BVH primitive id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Unit geometric normal (winding order), the front side.
    pub normal: Vec3,
    /// Diffuse albedo where it is constant; the material's average where it varies (zero
    /// only where it is zero everywhere on the triangle).
    pub albedo: Vec3,
    /// Radiance emitted from the front side.
    pub emission: Vec3,
    /// Index of its varying albedo ([`World::albedo_at`]), or [`CONSTANT_ALBEDO`].
    pub varying: u32,
}

/// [`Surface::varying`] of a triangle whose albedo is constant.
pub const CONSTANT_ALBEDO: u32 = u32::MAX;

/// Edge of a block of texels that shares one factor (about a cluster's extent).
pub const BLOCK: u32 = 8;

/// Each page's block factors: the spatial budget's share of `--spp` per [`BLOCK`]² texels
/// (`--budget`), which the gather reads through [`World::budget_factor`]; made from the
/// passes before by [`crate::bake::budget`].
#[derive(Clone, Debug, PartialEq)]
pub struct SpatialBudget {
    pub(crate) pages: Vec<Blocks>,
}

/// One page's factors, a row of blocks after another.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Blocks {
    pub(crate) columns: u32,
    pub(crate) factors: Vec<f32>,
}

impl SpatialBudget {
    /// The factor of the texel at `pixel` of `page` (1 outside the pages).
    pub fn factor(&self, page: u32, [x, y]: [u32; 2]) -> f32 {
        self.pages.get(page as usize).map_or(1.0, |b| {
            let i = (y / BLOCK) as usize * b.columns as usize + (x / BLOCK) as usize;
            b.factors.get(i).copied().unwrap_or(1.0)
        })
    }
}

/// The scene as the bake sees it.
#[derive(Debug)]
pub struct World {
    bvh: Bvh,
    corners: Vec<[Vec3; 3]>,
    surfaces: Vec<Surface>,
    varying: Vec<VaryingAlbedo>,
    lights: Vec<AnalyticLight>,
    emitters: Option<Emitters>,
    emitter_sampling: EmitterSampling,
    sky: Sky,
    sky_black: bool,
    transport: Transport,
    bounces: u32,
    previous: Option<PreviousPass>,
    earlier: Option<PreviousPass>,
    budget: Option<SpatialBudget>,
    guide_seeds: Option<FinishedResults>,
}

/// Where a gather ray hit: the primitive, the ray parameter and the barycentric weights of
/// the triangle's second and third vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// BVH primitive id (scene triangle index).
    pub prim: u32,
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weight of the second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
}

impl World {
    /// Builds the BVH over the scene's triangles and gathers its lights: the analytic ones,
    /// and the emissive triangles, sampled by the default [`EmitterSelection`] with MIS.
    ///
    /// # Errors
    /// [`BvhError`] when the BVH cannot be built (a non-finite vertex).
    pub fn new(scene: &Scene, preset: Preset) -> Result<Self, BvhError> {
        Self::tracing(scene, scene.traced_triangles().as_deref(), preset)
    }

    /// [`World::new`] whose rays meet only the triangles `traced` names (all for `None`): the
    /// roles a texel file records (`scene::roles`; a `sky`, `skip` or `no-shadow` surface is
    /// passed through). A triangle rays pass through emits nothing.
    ///
    /// # Errors
    /// As [`World::new`].
    pub fn tracing(
        scene: &Scene,
        traced: Option<&[u32]>,
        preset: Preset,
    ) -> Result<Self, BvhError> {
        let corners = scene.triangle_positions();
        let bvh = Bvh::build_over(&corners, traced, preset)?;
        let mut lit = vec![traced.is_none(); corners.len()];
        for &t in traced.unwrap_or_default() {
            lit[t as usize] = true;
        }
        let mut varying = Vec::new();
        let surfaces: Vec<Surface> = scene
            .triangles
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let m = &scene.materials[t.material as usize];
                let index = match scene.hit_albedo(i) {
                    HitAlbedo::Constant(_) => CONSTANT_ALBEDO,
                    HitAlbedo::Varying(a) => {
                        varying.push(a);
                        (varying.len() - 1) as u32
                    }
                };
                Surface {
                    normal: t.geometric_normal(),
                    albedo: m.albedo,
                    emission: if lit[i] { m.emission } else { Vec3::ZERO },
                    varying: index,
                }
            })
            .collect();
        let mut world = Self {
            bvh,
            corners,
            surfaces,
            varying,
            lights: analytic_lights(scene),
            emitters: None,
            emitter_sampling: EmitterSampling::default(),
            sky_black: sky_is_black(&scene.sky),
            sky: scene.sky.clone(),
            transport: Transport::Series,
            bounces: 1,
            previous: None,
            earlier: None,
            budget: None,
            guide_seeds: None,
        };
        world.set_emitters(EmitterSampling::default(), EmitterSelection::default());
        Ok(world)
    }

    /// Sets the transport at gather hits: `path` with at most `bounces` vertices, or
    /// `series` (whose indirect light comes from [`Self::set_previous_pass`]).
    pub fn set_transport(&mut self, transport: Transport, bounces: u32) {
        self.transport = transport;
        self.bounces = bounces.max(1);
    }

    /// Sets how emissive triangles are lit by: next-event estimation, hits, or both with MIS;
    /// and how next-event estimation picks one. Builds the emitters' table or tree (none
    /// when the scene has no emitter, or when only hits find them).
    pub fn set_emitters(&mut self, sampling: EmitterSampling, selection: EmitterSelection) {
        self.emitter_sampling = sampling;
        self.emitters = match sampling {
            EmitterSampling::Hits => None,
            EmitterSampling::Mis | EmitterSampling::Nee => {
                let triangles = self.corners.iter().zip(&self.surfaces);
                Emitters::new(
                    triangles.map(|(c, s)| (*c, s.normal, s.emission)),
                    selection,
                )
            }
        };
    }

    /// The previous series pass, looked up at gather hits (`None` in the first pass).
    pub fn set_previous_pass(&mut self, previous: Option<PreviousPass>) {
        self.previous = previous;
    }

    /// The series pass before the previous one, read one bounce beyond a gather hit within
    /// [`NEAR_PATH_TEXELS`](crate::transport::series::NEAR_PATH_TEXELS) of the ray's origin
    /// (`None` in the first gather pass, whose previous pass is the direct pass).
    pub fn set_earlier_pass(&mut self, earlier: Option<PreviousPass>) {
        self.earlier = earlier;
    }

    /// Takes both pass images out, the previous one first (a run keeps the previous pass's
    /// image as the next pass's earlier one).
    pub fn take_pass_images(&mut self) -> (Option<PreviousPass>, Option<PreviousPass>) {
        (self.previous.take(), self.earlier.take())
    }

    /// The point of triangle `prim` closest to `p`, moved a thousandth of the way towards the
    /// triangle's centroid but never more than `max_shift`: a ray origin on the triangle, never
    /// exactly on an edge it shares with a neighbouring wall (where it could slip through the
    /// corner and see the sky), and never far from `p` on a huge triangle. `p` itself when
    /// `prim` is not a triangle of the scene.
    pub fn onto_triangle(&self, prim: u32, p: Vec3, max_shift: f32) -> Vec3 {
        match self.corners.get(prim as usize) {
            Some(c) => onto_triangle(p, c, max_shift),
            None => p,
        }
    }

    /// `p`, a point on triangle `prim`, offset off the surface towards `n` for a ray to leave
    /// from ([`offset_origin`]): by a few ulps of its coordinates and of the triangle's size
    /// seen from it, plus `travelled`, the length of the ray that computed `p` (0 for a point
    /// interpolated on the triangle), whose rounding grows with it.
    pub fn leave_surface(&self, prim: u32, p: Vec3, n: Vec3, travelled: f32) -> Vec3 {
        let extent = self
            .corners
            .get(prim as usize)
            .map_or(0.0, |c| triangle_extent(p, c));
        offset_origin(p, n, extent + travelled.max(0.0))
    }

    /// The geometric normal of triangle `prim` on the side of `toward` (for offsetting ray
    /// origins off the surface itself, not off a shading normal that may lie near its
    /// plane); `toward` when `prim` is not a triangle of the scene.
    pub fn facing_normal(&self, prim: u32, toward: Vec3) -> Vec3 {
        match self.surfaces.get(prim as usize) {
            Some(s) if s.normal.dot(toward) < 0.0 => -s.normal,
            Some(s) => s.normal,
            None => toward,
        }
    }

    /// The BVH's wide view, which every ray the bake traces walks: single rays (shadow rays
    /// at hits, path continuations; 1.1–1.4× the binary single-ray walk in the duel, up to
    /// 7 % less CPU for whole bakes, docs/traverse.md, "Whole bakes") and 8-ray
    /// packets (gather and next-event packets; whole bakes of the three converted rooms
    /// level or faster than through the binary tree, docs/traverse.md, "Whole bakes").
    pub fn wide_bvh(&self) -> WideRef<'_> {
        self.bvh.wide()
    }

    /// The BVH's build statistics source.
    pub fn bvh_owner(&self) -> &Bvh {
        &self.bvh
    }

    /// The analytic lights.
    pub fn lights(&self) -> &[AnalyticLight] {
        &self.lights
    }

    /// The emissive triangles next-event estimation samples (`None`: it samples none).
    pub fn emitters(&self) -> Option<&Emitters> {
        self.emitters.as_ref()
    }

    /// How emitters are found ([`EmitterSampling`]); with no emitter sampled, as by hits.
    pub fn emitter_sampling(&self) -> EmitterSampling {
        if self.emitters.is_some() {
            self.emitter_sampling
        } else {
            EmitterSampling::Hits
        }
    }

    /// Whether next-event estimation has any light to sample (else it traces nothing).
    pub fn has_direct_light(&self) -> bool {
        !self.lights.is_empty() || self.emitters.is_some()
    }

    /// The albedo of `surface` at `hit` on it: its constant albedo, or its texture × factor ×
    /// vertex colour at the hit's barycentrics ([`HitAlbedo`]).
    #[inline]
    pub fn albedo_at(&self, surface: &Surface, hit: &SurfaceHit) -> Vec3 {
        match self.varying.get(surface.varying as usize) {
            None => surface.albedo,
            Some(a) => a.at(hit.u, hit.v),
        }
    }

    /// Per-triangle shading data, by primitive id.
    pub fn surfaces(&self) -> &[Surface] {
        &self.surfaces
    }

    /// The transport at gather hits.
    pub fn transport(&self) -> Transport {
        self.transport
    }

    /// Most path vertices (`path`) or passes (`series`).
    pub fn bounces(&self) -> u32 {
        self.bounces
    }

    /// The previous series pass, if any.
    pub fn previous_pass(&self) -> Option<&PreviousPass> {
        self.previous.as_ref()
    }

    /// The series pass before the previous one, if any.
    pub fn earlier_pass(&self) -> Option<&PreviousPass> {
        self.earlier.as_ref()
    }

    /// The spatial budget this pass spends its samples by (`None`: every texel the same).
    pub fn set_budget(&mut self, budget: Option<SpatialBudget>) {
        self.budget = budget;
    }

    /// How many times the uniform count of samples the texel at `pixel` of `page` takes.
    pub fn budget_factor(&self, page: u32, pixel: [u32; 2]) -> f32 {
        self.budget.as_ref().map_or(1.0, |b| b.factor(page, pixel))
    }

    /// The results of the pass before this one, whose texels hold the guide seeds of this
    /// pass's clusters (`None`: the clusters' first iteration gathers with cosine points;
    /// [`BakeSettings::reads_guide_seeds`](super::settings::BakeSettings::reads_guide_seeds)).
    pub fn set_guide_seeds(&mut self, seeds: Option<FinishedResults>) {
        self.guide_seeds = seeds;
    }

    /// Whether this pass's clusters read the guide seeds the pass before kept.
    pub fn reads_guide_seeds(&self) -> bool {
        self.guide_seeds.is_some()
    }

    /// Texel `texel`'s cell of its cluster's guide seed, if this pass reads seeds.
    pub fn guide_seed(&self, texel: u64) -> Option<f32> {
        self.seeding_result(texel).map(|r| r.seed)
    }

    /// Texel `texel`'s result in the pass that kept the guide seeds, if this pass reads
    /// seeds: besides its cell, what its cosine samples measured there (mean, error, samples).
    pub fn seeding_result(&self, texel: u64) -> Option<TexelResult> {
        self.guide_seeds.as_ref()?.get(texel)
    }

    /// Radiance of the sky along `dir` (zero without a lookup when the sky is black).
    pub fn sky(&self, dir: Vec3) -> Vec3 {
        if self.sky_black {
            Vec3::ZERO
        } else {
            sky_radiance(&self.sky, dir)
        }
    }
}

/// The point of triangle `c` closest to `p`, moved a thousandth of the way towards its
/// centroid but never more than `max_shift` ([`World::onto_triangle`]).
pub fn onto_triangle(p: Vec3, c: &[Vec3; 3], max_shift: f32) -> Vec3 {
    let q = closest_point_on_triangle(p, c[0], c[1], c[2]);
    let shift = ((c[0] + c[1] + c[2]) / 3.0 - q) * 1e-3;
    let length = shift.length();
    if length > max_shift && length > 0.0 {
        q + shift * (max_shift / length)
    } else {
        q + shift
    }
}

/// Closest point to `p` on triangle `abc` (Ericson, *Real-Time Collision Detection*, 5.1.5).
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    if !(v.is_finite() && w.is_finite()) {
        return a; // degenerate triangle
    }
    a + ab * v + ac * w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_points_lie_on_the_triangle() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let near = |p: Vec3, want: Vec3| {
            let q = closest_point_on_triangle(p, a, b, c);
            assert!((q - want).length() < 1e-6, "{p:?} -> {q:?}, want {want:?}");
        };
        near(Vec3::new(0.2, 0.2, 5.0), Vec3::new(0.2, 0.2, 0.0));
        near(Vec3::new(-1.0, -1.0, 0.0), a);
        near(Vec3::new(0.5, -3.0, 1.0), Vec3::new(0.5, 0.0, 0.0));
        near(Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.5, 0.5, 0.0));
        near(Vec3::new(3.0, -1.0, 0.0), b);
        assert!(closest_point_on_triangle(Vec3::ONE, a, a, a).is_finite());
    }
}
