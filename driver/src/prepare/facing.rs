//! Which sides of each surface can be seen: the side a lightmap texel describes, and the sides
//! a gather ray may hit without having started inside geometry (docs/bake.md, "The visible
//! side of a surface").
//!
//! The scenes are two-sided Lambertian, but a lightmap texel stores one irradiance, gathered
//! over one hemisphere, and scene files do not say which side matters: the converted
//! Bitterli scenes have no normals and arbitrary winding. A texel on the wrong side gathers
//! from the inside of a closed object or from outside the room — black under path transport,
//! a leak under series transport.
//!
//! **The seen side is the side light reaches.** A viewer stands where light is: the inside of
//! a closed block sees only itself, the outside of a room with no sky sees nothing, the
//! underside of a floor under an open sky sees the inside of the level. [`seen_sides`] traces
//! a few fixed rays from both sides of every triangle and solves, on those rays, a coarse
//! light transport over the triangles' sides — a radiosity with one irradiance per side and
//! a reflectance of [`REACH`] — lit by the scene's own lights in their own units: the sky
//! seen by rays that escape *upwards* (no one stands under the ground, so the sky below the
//! horizon is left out), the sun (one shadow ray per sample point), and the emissive
//! triangles and analytic lights, whose power is traced from them ([`LIGHT_RAYS`] rays a
//! light, flux over area on the sides the rays meet).
//!
//! **A consistent winding is kept.** Open space is consistent — from a seen side every
//! surface met is seen from that side — so the rays also tell whether the scene is wound
//! consistently ([`winding_consistency`]): a game level, whose fronts are what its engine
//! draws, is, and then the winding decides, turned inside out as a whole only where the
//! fronts are dark and the backs lit ([`DARK_FRONTS`]). That keeps the arena side of a
//! level's outer wall even where the sun lights its other side more, and a dim corridor
//! seen from inside. A scene wound at random (the
//! converted Bitterli scenes) is decided triangle by triangle: each is seen from its brighter
//! side, or from both where the darker one gets at least [`TWO_SIDED`] of the brighter's
//! light; a triangle no light reaches keeps the old rule, the side whose rays escape the
//! scene less often, ties keeping the winding. Either way a side not chosen is seen too where
//! its rays mostly meet seen sides: both sides of a thin wall standing in open space.
//!
//! The decision is per triangle, from light averaged over its sample points, so a floor
//! running under a block is still seen from above; the texels under the block are the ones
//! [`Visibility::inside_geometry`] finds, which `prepare` marks so the bake skips them
//! (docs/bake.md, "Texels inside geometry").
//!
//! Emission is unaffected: it stays front-facing by winding.

use glam::Vec3;
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
use guidebake_kernels::packet::{Hit8, NO_HIT, Ray, Ray8, offset_origin, triangle_extent};
use guidebake_kernels::traverse::{WideRef, intersect8, occluded1};
use rayon::prelude::*;

use crate::bvh::{Bvh, BvhError, Preset};
use crate::scene::{Scene, SceneLight};
use crate::texels::{FLAG_PARTIAL, SEEN_BACK, SEEN_FRONT, TEXELS_BACK, TexelRecord};
use crate::transport::emitters::luminance;
use crate::transport::sky::sky_radiance;
use crate::transport::world::onto_triangle;

/// Rays per sample point and side: one packet.
const RAYS: usize = 8;
/// Most sample points per triangle and side (fewer on scenes of many triangles, see
/// [`points_per_triangle`]).
const MAX_POINTS: usize = 8;
/// The rays traced in all, about, above which triangles get fewer sample points.
const RAY_BUDGET: usize = 1 << 24;
/// The share of the irradiance of the sides a side's rays meet that it receives: light
/// reaches through a few reflections (a room lit through a door) but fades with each, and a
/// closed cavity does not multiply what leaks into it (a block's inside, through a floor
/// coplanar with its bottom face, gathers 1 / (1 − REACH) times the leak).
const REACH: f32 = 0.5;
/// Iterations of the transport: `REACH^ITERATIONS` ≈ 10⁻⁹.
const ITERATIONS: usize = 30;
/// Rays traced from each light (an analytic light, or the emissive triangles together), and
/// at most this many per emissive triangle ([`Probe::light_paths`]).
const LIGHT_RAYS: usize = 4096;
/// A triangle is seen from both sides where its darker side gets at least this share of the
/// brighter side's light, or where the darker side's rays meet open space
/// ([`SideRays::meets_open_space`]: at least [`OPEN_SHARE`] of them meet seen sides, and
/// [`OPEN_RATIO`] times as many as meet unseen ones).
const TWO_SIDED: f32 = 0.5;
const OPEN_SHARE: f32 = 0.25;
const OPEN_RATIO: f32 = 4.0;
/// A scene whose [`winding_consistency`] reaches this keeps its winding as a whole: its fronts
/// are what an engine that culls back faces shows. Below, each triangle is seen from its
/// brighter side.
const CONSISTENT_WINDING: f64 = 0.8;
/// A consistently wound scene is turned inside out only where its fronts, over its area, get
/// less than this share of the light its backs get — next to none: wound the wrong way round
/// (a closed room wound outwards, whose outside no light reaches). A courtyard whose outer
/// walls the sun lights more than its inside keeps its winding, and so does a room lit only
/// through a door ajar under a bright sky (the demo's: its inside gets 8 % of its outside's
/// light; at 0.25 it was turned inside out).
const DARK_FRONTS: f64 = 0.01;

/// What [`seen_sides`] decided, for the prepare report.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FacingReport {
    /// Triangles seen from their winding's front only.
    pub front: u64,
    /// Triangles seen from their back only (their texels face against the winding).
    pub back: u64,
    /// Triangles seen from both sides (a thin wall in open space).
    pub both: u64,
    /// Of those, triangles that no light reached, oriented by the rays that escape the scene.
    pub unlit: u64,
    /// Degenerate triangles (no side).
    pub degenerate: u64,
    /// Rays traced.
    pub rays: u64,
    /// The share of rays that met a triangle on the same side of its winding as the side they
    /// left ([`winding_consistency`]).
    pub winding_consistency: f64,
    /// Whether the winding was kept as a whole ([`CONSISTENT_WINDING`]).
    pub winding_kept: bool,
}

/// The scene's surfaces and the sides they are seen from, kept to find the texels that lie
/// inside geometry ([`Self::inside_geometry`]).
pub struct Visibility {
    bvh: Bvh,
    corners: Vec<[Vec3; 3]>,
    normals: Vec<Vec3>,
    sides: Vec<u32>,
    /// Per side ([`node`]): the irradiance (luminance) it gets from the sky above and the sun
    /// directly, and all it gets through the coarse transport.
    light: Vec<SideLight>,
}

/// What one side of a triangle receives in the coarse transport of [`seen_sides`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SideLight {
    /// From the sky above and the sun, directly.
    pub direct: f32,
    /// Direct and through reflections ([`REACH`]).
    pub total: f32,
}

/// Texel sample points of [`Visibility::inside_geometry`], each with one packet of rays.
const TEXEL_POINTS: usize = 8;
/// A texel lies inside geometry when more than this share of its rays meet a side that faces
/// no open space (Unity's "backface tolerance" of 0.9 keeps texels whose rays meet seen sides
/// at least 90 % of the time).
pub const INSIDE_SHARE: f32 = 0.1;

impl Visibility {
    /// For every triangle, the sides that face open space: [`SEEN_FRONT`] and/or
    /// [`SEEN_BACK`], and [`TEXELS_BACK`] where its texels describe its back, the brighter or
    /// only seen side (module docs); 0 for a degenerate triangle.
    #[must_use]
    pub fn sides(&self) -> &[u32] {
        &self.sides
    }

    /// What the two sides of triangle `t` receive (its winding's front first): the light
    /// `prepare` looks at to find a shell that keeps the sun and sky out (`prepare::shell`).
    #[must_use]
    pub fn side_light(&self, t: usize) -> [SideLight; 2] {
        [self.light[2 * t], self.light[2 * t + 1]]
    }

    /// Whether `texel` lies inside geometry: more than [`INSIDE_SHARE`] of 64 fixed rays from
    /// points spread over its footprint (its centre if it is partly covered), over the
    /// hemisphere of its normal, meet a side of a surface that faces no open space — the floor
    /// under a block, a face resting on another. Its value would be the inside's (black, or
    /// whatever leaks in), so the bake leaves it out and the lightmap's dilation fills it
    /// from its neighbours (docs/bake.md, "Texels inside geometry").
    #[must_use]
    pub fn inside_geometry(&self, texel: &TexelRecord) -> bool {
        let Some(c) = self.corners.get(texel.triangle as usize) else {
            return false;
        };
        let n = texel.normal();
        let g = self.normals[texel.triangle as usize];
        let side = if g.dot(n) < 0.0 { -g } else { g };
        let view = self.bvh.wide();
        let footprint = Vec3::from(texel.dpdu).length() + Vec3::from(texel.dpdv).length();
        let jitter = texel.flags & FLAG_PARTIAL == 0;
        let mut unseen = 0;
        for k in 0..TEXEL_POINTS {
            let [a, b] = if jitter {
                fibonacci_square(k, TEXEL_POINTS).map(|v| v - 0.5)
            } else {
                [0.0; 2]
            };
            let p = texel.position() + Vec3::from(texel.dpdu) * a + Vec3::from(texel.dpdv) * b;
            let on = onto_triangle(p, c, 0.01 * footprint);
            let origin = offset_origin(on, side, triangle_extent(on, c));
            let (dirs, hits) = trace_cosine(&view, origin, n, k);
            for (lane, &u) in hits.prim.to_array().iter().enumerate() {
                if u != NO_HIT {
                    let front = self.normals[u as usize].dot(dirs[lane]) < 0.0;
                    let flag = if front { SEEN_FRONT } else { SEEN_BACK };
                    unseen += u32::from(self.sides[u as usize] & flag == 0);
                }
            }
        }
        unseen as f32 > INSIDE_SHARE * (TEXEL_POINTS * RAYS) as f32
    }
}

/// For every triangle of `scene`, the sides that face open space (module docs), with the
/// scene's BVH for [`Visibility::inside_geometry`].
///
/// # Errors
/// [`BvhError`] when the scene's BVH cannot be built (a non-finite vertex).
pub fn seen_sides(scene: &Scene) -> Result<(Visibility, FacingReport), BvhError> {
    let corners = scene.triangle_positions();
    let points = points_per_triangle(corners.len());
    let rays = (points * RAYS * 2 * corners.len()) as f64;
    // Rays pass through the surfaces whose roles say so (`scene::roles`).
    let bvh = Bvh::build_over(
        &corners,
        scene.traced_triangles().as_deref(),
        Preset::for_rays(corners.len(), rays),
    )?;
    let probe = Probe::new(scene, &corners, bvh.wide(), points);
    let sides: Vec<SideRays> = (0..2 * corners.len() as u32)
        .into_par_iter()
        .map(|node| probe.sample(node))
        .collect();
    let mut direct: Vec<f32> = sides.iter().map(|s| s.direct).collect();
    let mut light_rays = 0;
    for path in probe.light_paths() {
        light_rays += path.rays;
        for (node, flux) in path.deposits {
            let area = 0.5 * probe.doubled_area[(node / 2) as usize];
            direct[node as usize] += flux / area;
        }
    }
    let light = transport(&sides, &direct);
    let consistency = winding_consistency(&sides);
    // A consistently wound scene keeps its winding as a whole, unless its fronts are dark
    // where its backs are lit; others are decided triangle by triangle.
    let whole = (consistency >= CONSISTENT_WINDING).then(|| {
        let lit = |side: usize| -> f64 {
            (0..corners.len())
                .map(|t| f64::from(probe.doubled_area[t]) * f64::from(light[2 * t + side]))
                .sum()
        };
        if lit(0) >= DARK_FRONTS * lit(1) {
            SEEN_FRONT
        } else {
            SEEN_BACK
        }
    });
    let mut report = FacingReport {
        rays: sides.iter().map(|s| u64::from(s.rays)).sum::<u64>() + light_rays,
        winding_consistency: consistency,
        winding_kept: whole.is_some(),
        ..FacingReport::default()
    };
    let brighter: Vec<u32> = (0..corners.len())
        .map(|t| match whole {
            Some(side) if sides[2 * t].rays > 0 => side,
            _ => seen_of(
                &sides[2 * t],
                &sides[2 * t + 1],
                light[2 * t],
                light[2 * t + 1],
            ),
        })
        .collect();
    let seen = (0..corners.len())
        .map(|t| {
            let mut flags = brighter[t];
            if flags & (SEEN_FRONT | SEEN_BACK) == SEEN_BACK
                || (flags != 0 && light[2 * t + 1] > light[2 * t] && whole.is_none())
            {
                flags |= TEXELS_BACK;
            }
            // The darker side is seen too where its rays mostly meet seen sides: a wall
            // standing in open space on both sides, lit much more on one.
            for (flag, side) in [(SEEN_FRONT, &sides[2 * t]), (SEEN_BACK, &sides[2 * t + 1])] {
                if flags != 0 && flags & flag == 0 && side.meets_open_space(&brighter) {
                    flags |= flag;
                }
            }
            let role = scene.role(t);
            match flags & (SEEN_FRONT | SEEN_BACK) {
                // A surface rays pass through that has no texels has no side (`sample`).
                0 if !(role.traced() || role.has_texels()) => {}
                0 => report.degenerate += 1,
                SEEN_FRONT => report.front += 1,
                SEEN_BACK => report.back += 1,
                _ => report.both += 1,
            }
            report.unlit += u64::from(flags != 0 && light[2 * t].max(light[2 * t + 1]) <= 0.0);
            flags
        })
        .collect();
    let normals = probe.normals;
    let light = sides
        .iter()
        .zip(&light)
        .map(|(s, &total)| SideLight {
            direct: s.direct,
            total,
        })
        .collect();
    Ok((
        Visibility {
            bvh,
            corners,
            normals,
            sides: seen,
            light,
        },
        report,
    ))
}

/// The seen sides of one triangle from its two sides' rays and light (module docs).
fn seen_of(front: &SideRays, back: &SideRays, lf: f32, lb: f32) -> u32 {
    if front.rays == 0 {
        return 0;
    }
    if lf.max(lb) <= 0.0 || !(lf + lb).is_finite() {
        return if back.escaped + 4 <= front.escaped {
            SEEN_BACK
        } else {
            SEEN_FRONT
        };
    }
    if lf.min(lb) >= TWO_SIDED * lf.max(lb) {
        SEEN_FRONT | SEEN_BACK
    } else if lf >= lb {
        SEEN_FRONT
    } else {
        SEEN_BACK
    }
}

/// Sample points per triangle and side: [`MAX_POINTS`], fewer once the scene would trace more
/// than [`RAY_BUDGET`] rays, at least one.
fn points_per_triangle(triangles: usize) -> usize {
    (RAY_BUDGET / (2 * RAYS * triangles.max(1))).clamp(1, MAX_POINTS)
}

/// Barycentric weights (of the second and third vertices) of the sample points, spread over
/// the triangle; the first `n` are used.
const POINTS: [[f32; 2]; MAX_POINTS] = [
    [1.0 / 3.0, 1.0 / 3.0],
    [0.6, 0.2],
    [0.2, 0.6],
    [0.2, 0.2],
    [0.45, 0.45],
    [0.1, 0.45],
    [0.45, 0.1],
    [0.8, 0.1],
];

/// The side of triangle `t`: node `2t` is its winding's front, `2t + 1` its back.
fn node(t: u32, front: bool) -> u32 {
    2 * t + u32::from(!front)
}

/// What the rays from one side of one triangle met.
#[derive(Clone, Debug, Default)]
struct SideRays {
    /// Rays traced (0 for a degenerate triangle).
    rays: u32,
    /// Rays that left the scene.
    escaped: u32,
    /// Irradiance (luminance) from the sky above and the sun, averaged over the side's points.
    direct: f32,
    /// The sides the other rays met ([`node`]).
    met: Vec<u32>,
}

impl SideRays {
    /// Whether these rays mostly meet sides seen under `seen` (per triangle, as
    /// [`Visibility::sides`]): at least [`OPEN_SHARE`] of them, and [`OPEN_RATIO`] times as
    /// many as meet unseen sides.
    fn meets_open_space(&self, seen: &[u32]) -> bool {
        let (mut open, mut closed) = (0u32, 0u32);
        for &m in &self.met {
            let flag = if m % 2 == 0 { SEEN_FRONT } else { SEEN_BACK };
            if seen[(m / 2) as usize] & flag != 0 {
                open += 1;
            } else {
                closed += 1;
            }
        }
        open as f32 >= OPEN_SHARE * self.rays as f32 && open as f32 >= OPEN_RATIO * closed as f32
    }
}

/// The share of the rays that met a triangle that met it on the same side of its winding as
/// the side of theirs they left: open space is consistent — from a surface's seen side every
/// surface met is seen from that side — so in a scene wound consistently (every front facing
/// open space, as engines that cull back faces need) nearly every ray pairs front with front
/// or back with back, and in one wound at random about half do. Measured on 2026-11-28: the
/// zdm2 level 0.93, the converted Veach ajar room 0.89, the converted Cornell box 0.62, the
/// converted Veach bidir room 0.59.
fn winding_consistency(sides: &[SideRays]) -> f64 {
    let (same, met) = sides
        .iter()
        .enumerate()
        .fold((0u64, 0u64), |(same, met), (n, s)| {
            let alike = s.met.iter().filter(|&&m| m % 2 == n as u32 % 2).count();
            (same + alike as u64, met + s.met.len() as u64)
        });
    same as f64 / met.max(1) as f64
}

/// The irradiance every side receives through the rays' graph: `E = direct + REACH · mean E
/// of the sides its rays met`, by Jacobi iteration from `E = direct`.
fn transport(sides: &[SideRays], direct: &[f32]) -> Vec<f32> {
    let mut light = direct.to_vec();
    for _ in 0..ITERATIONS {
        light = sides
            .par_iter()
            .zip(direct)
            .map(|(s, d)| {
                if s.rays == 0 {
                    return 0.0;
                }
                let reflected: f32 = s.met.iter().map(|&m| light[m as usize]).sum();
                d + REACH * reflected / s.rays as f32
            })
            .collect();
    }
    light
}

/// The flux one light's rays bring to the sides they meet first.
struct LightPaths {
    rays: u64,
    /// (side, flux) per ray that met a side ([`node`]).
    deposits: Vec<(u32, f32)>,
}

/// The scene as the rays see it.
struct Probe<'a> {
    scene: &'a Scene,
    corners: &'a [[Vec3; 3]],
    normals: Vec<Vec3>,
    doubled_area: Vec<f32>,
    bvh: WideRef<'a>,
    points: usize,
    /// Towards the sun, and its irradiance (luminance), when there is one.
    sun: Option<(Vec3, f32)>,
}

/// The scenes' up axis (glTF's +Y): the sky lights what escapes upwards.
const UP: Vec3 = Vec3::Y;

impl<'a> Probe<'a> {
    fn new(scene: &'a Scene, corners: &'a [[Vec3; 3]], bvh: WideRef<'a>, points: usize) -> Self {
        let mut sun = scene
            .sun
            .as_ref()
            .map(|s| (s.direction.normalize_or_zero(), luminance(s.irradiance)));
        for light in &scene.lights {
            if let SceneLight::Directional {
                direction,
                irradiance,
            } = light
            {
                sun = sun.or(Some((
                    -direction.normalize_or_zero(),
                    luminance(*irradiance),
                )));
            }
        }
        Self {
            scene,
            corners,
            normals: scene
                .triangles
                .iter()
                .map(|t| t.geometric_normal())
                .collect(),
            doubled_area: scene.triangles.iter().map(|t| 2.0 * t.area()).collect(),
            bvh,
            points,
            sun,
        }
    }

    /// Traces the rays of side `node` ([`node`]).
    fn sample(&self, node: u32) -> SideRays {
        let t = (node / 2) as usize;
        let c = &self.corners[t];
        let n = self.normals[t] * if node.is_multiple_of(2) { 1.0 } else { -1.0 };
        let mut out = SideRays::default();
        // A surface rays pass through and that has no texels has no side to decide.
        let role = self.scene.role(t);
        if n == Vec3::ZERO || !(role.traced() || role.has_texels()) {
            return out;
        }
        for (k, [b1, b2]) in POINTS.iter().take(self.points).enumerate() {
            let p = c[0] * (1.0 - b1 - b2) + c[1] * b1 + c[2] * b2;
            self.sample_point(p, c, n, k, &mut out);
        }
        out.direct /= self.points as f32;
        out
    }

    /// The side of triangle `u` that a ray along `dir` meets ([`node`]).
    fn met(&self, u: u32, dir: Vec3) -> u32 {
        node(u, self.normals[u as usize].dot(dir) < 0.0)
    }

    /// One packet of [`RAYS`] cosine-distributed rays from point `p` of triangle `c`, over
    /// the hemisphere of `n`, and a shadow ray to the sun; `k` turns the pattern from point to
    /// point. Adds the point's irradiance from the sky above and the sun to `out.direct`.
    fn sample_point(&self, p: Vec3, c: &[Vec3; 3], n: Vec3, k: usize, out: &mut SideRays) {
        let origin = offset_origin(p, n, triangle_extent(p, c));
        let (dirs, hits) = trace_cosine(&self.bvh, origin, n, k);
        out.rays += RAYS as u32;
        let mut sky = 0.0;
        for (lane, &u) in hits.prim.to_array().iter().enumerate() {
            if u == NO_HIT {
                out.escaped += 1;
                if dirs[lane].dot(UP) > 0.0 {
                    sky += luminance(sky_radiance(&self.scene.sky, dirs[lane]));
                }
            } else {
                out.met.push(self.met(u, dirs[lane]));
            }
        }
        // Cosine-distributed rays: E = π × the mean radiance they see.
        out.direct += core::f32::consts::PI * sky / RAYS as f32;
        if let Some((sun, irradiance)) = self.sun
            && sun.dot(n) > 0.0
            && !occluded1(&self.bvh, &Ray::new(origin, sun, 0.0, f32::INFINITY))
        {
            out.direct += irradiance * sun.dot(n);
        }
    }

    /// The power of every light traced to the sides it meets first: the emissive triangles
    /// together (their fronts, by power), and each point, spot and sphere light.
    fn light_paths(&self) -> Vec<LightPaths> {
        let mut lights: Vec<LightPaths> = Vec::new();
        lights.extend(self.emitter_paths());
        for light in &self.scene.lights {
            let (position, intensity) = match light {
                SceneLight::Directional { .. } => continue,
                SceneLight::Point {
                    position,
                    intensity,
                } => (*position, luminance(*intensity)),
                SceneLight::Spot {
                    position,
                    intensity,
                    ..
                } => (*position, luminance(*intensity)),
                SceneLight::Sphere {
                    center,
                    radius,
                    radiance,
                } => (
                    *center,
                    core::f32::consts::PI * radius * radius * luminance(*radiance),
                ),
            };
            let flux = 4.0 * core::f32::consts::PI * intensity / LIGHT_RAYS as f32;
            let rays: Vec<Ray> = (0..LIGHT_RAYS)
                .map(|i| {
                    Ray::new(
                        position,
                        fibonacci_sphere(i, LIGHT_RAYS),
                        0.0,
                        f32::INFINITY,
                    )
                })
                .collect();
            lights.push(self.trace_light(&rays, &vec![flux; LIGHT_RAYS]));
        }
        lights
    }

    /// The emissive triangles' power, [`LIGHT_RAYS`] rays at most per triangle and in all
    /// at least that many, spread by power (area × π × luminance), cosine-distributed from
    /// points on their fronts.
    fn emitter_paths(&self) -> Option<LightPaths> {
        let power: Vec<(u32, f32)> = self
            .scene
            .triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let m = &self.scene.materials[tri.material as usize];
                (
                    t as u32,
                    core::f32::consts::PI * luminance(m.emission) * tri.area(),
                )
            })
            .filter(|&(t, p)| p > 0.0 && p.is_finite() && self.scene.role(t as usize).traced())
            .collect();
        let total: f32 = power.iter().map(|p| p.1).sum();
        if power.is_empty() || !total.is_finite() {
            return None;
        }
        let count = (LIGHT_RAYS * power.len()).clamp(LIGHT_RAYS, LIGHT_RAYS * 64);
        let mut rays = Vec::with_capacity(count);
        let mut carried = Vec::with_capacity(count);
        for &(t, p) in &power {
            let n = ((count as f64 * f64::from(p / total)).ceil() as usize).max(1);
            let c = &self.corners[t as usize];
            let normal = self.normals[t as usize];
            let (tangent, bitangent) = orthonormal_basis(normal);
            for i in 0..n {
                let [b1, b2] = fibonacci_triangle(i, n);
                let q = c[0] * (1.0 - b1 - b2) + c[1] * b1 + c[2] * b2;
                let d = sample_cosine_hemisphere([
                    ((i as f32 + 0.5) / n as f32),
                    (i as f32 * 0.754_877_7).fract(),
                ]);
                let dir = (tangent * d.x + bitangent * d.y + normal * d.z).normalize_or(normal);
                rays.push(Ray::new(
                    offset_origin(q, normal, triangle_extent(q, c)),
                    dir,
                    0.0,
                    f32::INFINITY,
                ));
                carried.push(p / n as f32);
            }
        }
        Some(self.trace_light(&rays, &carried))
    }

    /// Traces `rays` in packets; ray `i` carries `flux[i]` to the side it meets.
    fn trace_light(&self, rays: &[Ray], flux: &[f32]) -> LightPaths {
        let deposits = rays
            .par_chunks(RAYS)
            .enumerate()
            .flat_map_iter(|(j, chunk)| {
                let mut hits = Hit8::NONE;
                intersect8(&self.bvh, &Ray8::from_rays(chunk), &mut hits);
                let prims = hits.prim.to_array();
                (0..chunk.len())
                    .filter(move |&lane| prims[lane] != NO_HIT)
                    .map(move |lane| {
                        (
                            self.met(prims[lane], chunk[lane].dir),
                            flux[j * RAYS + lane],
                        )
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        LightPaths {
            rays: rays.len() as u64,
            deposits,
        }
    }
}

/// One packet of [`cosine_packet`]'s directions over the hemisphere of `n` (pattern `k`) traced
/// from `origin` on `view`: the directions and what each met.
pub(super) fn trace_cosine(
    view: &WideRef<'_>,
    origin: Vec3,
    n: Vec3,
    k: usize,
) -> ([Vec3; RAYS], Hit8) {
    let (tangent, bitangent) = orthonormal_basis(n);
    let dirs = cosine_packet(tangent, bitangent, n, k);
    let mut hits = Hit8::NONE;
    intersect8(
        view,
        &Ray8::from_origin(origin, &dirs, 0.0, f32::INFINITY),
        &mut hits,
    );
    (dirs, hits)
}

/// [`RAYS`] cosine-distributed directions over the hemisphere of `n` (with its tangent frame),
/// stratified 4 × 2, the pattern turned by `k` (one per sample point).
fn cosine_packet(tangent: Vec3, bitangent: Vec3, n: Vec3, k: usize) -> [Vec3; RAYS] {
    let turn = k as f32 * 0.618_034;
    core::array::from_fn(|i| {
        let u = [
            ((i % 4) as f32 + 0.5) / 4.0,
            (((i / 4) as f32 + 0.5) / 2.0 + turn).fract(),
        ];
        let d = sample_cosine_hemisphere(u);
        (tangent * d.x + bitangent * d.y + n * d.z).normalize_or(n)
    })
}

/// Direction `i` of `n` spread evenly over the sphere (a Fibonacci lattice).
fn fibonacci_sphere(i: usize, n: usize) -> Vec3 {
    let k = i as f32 + 0.5;
    let z = 1.0 - 2.0 * k / n as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = k * 2.399_963;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Point `i` of `n` spread over the unit square (a Fibonacci lattice).
fn fibonacci_square(i: usize, n: usize) -> [f32; 2] {
    [(i as f32 + 0.5) / n as f32, (i as f32 * 0.618_034).fract()]
}

/// Point `i` of `n` spread over a triangle: barycentric weights of its second and third
/// vertices ([`fibonacci_square`] folded onto the triangle).
fn fibonacci_triangle(i: usize, n: usize) -> [f32; 2] {
    let [u, v] = fibonacci_square(i, n);
    if u + v > 1.0 {
        [1.0 - u, 1.0 - v]
    } else {
        [u, v]
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec2;

    use super::*;
    use crate::scene::{Sky, Triangle};
    use crate::test_support::{grey_and_lamp, outward_box_faces};

    /// Two triangles per quad `(corner, u, v)`, wound so that `u × v` is their front.
    fn quads(quads: &[(Vec3, Vec3, Vec3)], material: u32) -> Vec<Triangle> {
        let tri = |p: [Vec3; 3]| Triangle {
            positions: p,
            normals: [Vec3::ZERO; 3],
            lightmap_uv: Some([Vec2::ZERO, Vec2::X, Vec2::Y]),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material,
        };
        quads
            .iter()
            .flat_map(|&(c, u, v)| [tri([c, c + u, c + u + v]), tri([c, c + u + v, c + v])])
            .collect()
    }

    /// Flips every other triangle's winding, as the converted Bitterli scenes' are arbitrary.
    fn scramble(triangles: &mut [Triangle]) {
        for (i, t) in triangles.iter_mut().enumerate() {
            if i % 3 == 1 {
                t.positions.swap(1, 2);
            }
        }
    }

    /// The side triangle `t` is seen from, as a world direction (its normal on that side).
    fn seen_normal(t: &Triangle, flags: u32) -> Vec3 {
        match flags & (SEEN_FRONT | SEEN_BACK) {
            SEEN_FRONT => t.geometric_normal(),
            SEEN_BACK => -t.geometric_normal(),
            _ => Vec3::ZERO,
        }
    }

    /// A room 10 × 4 × 10 open on its +z side (no front wall), lit by a lamp under its
    /// ceiling, with a closed 2 m box standing on its floor: walls seen from inside, the box
    /// from outside, whatever the winding.
    #[test]
    fn a_room_open_on_one_side_is_seen_from_inside_and_a_box_in_it_from_outside() {
        let room = outward_box_faces(Vec3::new(-5.0, 0.0, -5.0), Vec3::new(10.0, 4.0, 10.0));
        // Drop the +z face (the one whose corner is at z = 5 and spans x, y).
        let walls: Vec<_> = room
            .into_iter()
            .filter(|(c, u, v)| !(c.z == 5.0 && u.z == 0.0 && v.z == 0.0))
            .collect();
        let mut triangles = quads(&walls, 0);
        let cube = outward_box_faces(Vec3::new(-1.0, 0.0, -1.0), Vec3::splat(2.0));
        let box_start = triangles.len();
        triangles.extend(quads(&cube, 0));
        let lamp_start = triangles.len();
        // A lamp facing down, 0.1 below the ceiling.
        triangles.extend(quads(&[(Vec3::new(-0.5, 3.9, -0.5), Vec3::X, Vec3::Z)], 1));
        scramble(&mut triangles[..lamp_start]);
        let scene = Scene::of_triangles("room", triangles, grey_and_lamp(0.5, 10.0));
        let (visibility, report) = seen_sides(&scene).unwrap();
        let sides = visibility.sides();
        for (i, t) in scene.triangles.iter().enumerate() {
            let n = seen_normal(t, sides[i]);
            let centre = (t.positions[0] + t.positions[1] + t.positions[2]) / 3.0;
            if i < box_start {
                let inwards = Vec3::new(0.0, 2.0, 0.0) - centre;
                assert!(
                    n.dot(inwards) > 0.0,
                    "wall triangle {i} seen from {n}: {report:?}"
                );
            } else if i - box_start == 8 || i - box_start == 9 {
                // The bottom face lies on the floor: no side of it is seen.
            } else if i < lamp_start {
                let outwards = centre - Vec3::Y;
                assert!(
                    n.dot(outwards) > 0.0,
                    "box triangle {i} seen from {n}: {report:?}"
                );
            } else {
                // Its back faces the ceiling across a 0.1 m gap of open space.
                assert_ne!(
                    sides[i] & SEEN_FRONT,
                    0,
                    "the lamp is seen from its emitting side"
                );
            }
        }
    }

    /// Ground under a sky with a closed box on it: the ground from above, the box from outside;
    /// a thin wall standing on the ground is seen from both sides.
    #[test]
    fn ground_under_a_sky_is_seen_from_above_and_a_thin_wall_from_both_sides() {
        let mut quads_ = vec![(Vec3::new(-20.0, 0.0, 20.0), Vec3::X * 40.0, Vec3::Z * -40.0)];
        quads_.extend(outward_box_faces(
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::splat(2.0),
        ));
        // A thin wall 4 m wide, 2 m tall, at x = 6.
        quads_.push((Vec3::new(6.0, 0.0, -2.0), Vec3::Y * 2.0, Vec3::Z * 4.0));
        let mut triangles = quads(&quads_, 0);
        scramble(&mut triangles);
        let mut scene = Scene::of_triangles("ground", triangles, grey_and_lamp(0.5, 10.0));
        scene.sky = Sky::Constant(Vec3::ONE);
        let (visibility, report) = seen_sides(&scene).unwrap();
        let sides = visibility.sides();
        for (i, t) in scene.triangles.iter().enumerate() {
            let centre = (t.positions[0] + t.positions[1] + t.positions[2]) / 3.0;
            let n = seen_normal(t, sides[i]);
            match i {
                0 | 1 => assert!(n.y > 0.9, "ground seen from {n}: {report:?}"),
                // The box's bottom face lies on the ground: no side of it is seen.
                10 | 11 => {}
                14 | 15 => assert_eq!(
                    sides[i] & (SEEN_FRONT | SEEN_BACK),
                    SEEN_FRONT | SEEN_BACK,
                    "thin wall: {report:?}"
                ),
                _ => assert!(
                    n.dot(centre - Vec3::Y) > 0.0,
                    "box {i} seen from {n}: {report:?}"
                ),
            }
        }
    }

    /// A courtyard wound consistently, fronts facing in, open to a sky and a low sun that
    /// lights the outside of its west wall: the winding is kept, so that wall is seen from
    /// the courtyard although its other side gets more light.
    #[test]
    fn a_consistently_wound_courtyard_keeps_its_winding() {
        let faces: Vec<_> = outward_box_faces(Vec3::new(-4.0, 0.0, -4.0), Vec3::new(8.0, 3.0, 8.0))
            .into_iter()
            // Turned inwards, without the roof.
            .map(|(c, u, v)| (c, v, u))
            .filter(|(c, u, v)| !(c.y == 3.0 && u.y == 0.0 && v.y == 0.0))
            .collect();
        let mut scene =
            Scene::of_triangles("courtyard", quads(&faces, 0), grey_and_lamp(0.5, 10.0));
        scene.sky = Sky::Constant(Vec3::splat(0.2));
        scene.sun = Some(crate::scene::Sun {
            direction: Vec3::new(-1.0, 0.15, 0.0).normalize(),
            angular_radius: 0.0,
            irradiance: Vec3::splat(5.0),
        });
        let (visibility, report) = seen_sides(&scene).unwrap();
        assert!(report.winding_kept, "{report:?}");
        assert!(
            visibility.sides().iter().all(|&s| s & SEEN_FRONT != 0),
            "{:?} {report:?}",
            visibility.sides()
        );
    }

    /// The demo's room, wound inwards, lit only through its door ajar under a bright sky and a
    /// low sun: its inside gets 8 % of the light its outside gets, and it is seen from inside
    /// (a dim room is still where the viewer stands; with the flip at 25 % its texels described
    /// the walls' outsides and `guidebake demo` baked a flat sky-lit room).
    #[test]
    fn a_room_lit_through_its_door_under_a_bright_sky_keeps_its_winding() {
        let scene = crate::demo::ajar_room();
        let (visibility, report) = seen_sides(&scene).unwrap();
        assert!(report.winding_kept, "{report:?}");
        let fronts = visibility
            .sides()
            .iter()
            .filter(|&&s| s & SEEN_FRONT != 0 && s & TEXELS_BACK == 0)
            .count();
        assert_eq!(fronts, scene.triangles.len(), "{report:?}");
    }

    /// A closed room with no sky and a lamp inside: its walls are seen from inside, even
    /// wound outwards and with a consistent winding (the light, not the winding, decides).
    #[test]
    fn a_closed_lit_room_wound_outwards_is_seen_from_inside() {
        let mut triangles = quads(&outward_box_faces(Vec3::splat(-2.0), Vec3::splat(4.0)), 0);
        triangles.extend(quads(&[(Vec3::new(-0.5, 1.9, -0.5), Vec3::X, Vec3::Z)], 1));
        let scene = Scene::of_triangles("closed", triangles, grey_and_lamp(0.5, 10.0));
        let (visibility, _) = seen_sides(&scene).unwrap();
        let sides = visibility.sides();
        assert!(
            sides[..12].iter().all(|&s| s == SEEN_BACK | TEXELS_BACK),
            "{sides:?}"
        );
    }
}
