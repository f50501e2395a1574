//! A light tree (light BVH) over emissive triangles: picks one emitter in proportion to an
//! upper bound of what it can deliver to a shading point, in O(depth) and without
//! allocating.
//!
//! After C. Conty Estevez and C. Kulla, "Importance Sampling of Many Lights with Adaptive
//! Tree Splitting", HPG 2018 (§4.1 the orientation bounds, §4.3 the importance, §5 the
//! SAOH build), as pbrt-v4 does it in `BVHLightSampler` and `LightBounds::Importance`
//! (`lightsamplers.{h,cpp}`, `lights.cpp`; PBR book 4th ed. §12.6.3). Our own code, with
//! these choices and deviations:
//!
//! - **Bounds of a node**: its AABB as a bounding sphere (centre, radius) and as
//!   half-extents, the total power φ (area × luminance of the emission), and a normal cone
//!   (axis, θ_o) with its chord (the largest |m − axis| over member normals m), and for
//!   inner nodes whose emitters face two to four exactly equal ways, an index into a side
//!   table of their planes; 64-byte nodes. Memory: 2N − 1 nodes, 8 bytes of trail per
//!   input emitter, 64 bytes per planes entry (797 for the 10^4 windows of the night city;
//!   0.63 N for random triangles, mostly nodes of two to four triangles). Emitters are one-sided Lambertian triangles, so θ_e = π/2 for every node.
//!   Leaves hold one emitter each.
//! - **Importance** at a point p with receiver normal n, θ_b the half-angle the sphere
//!   subtends from p, θ_w the angle between the cone axis and the direction centre → p,
//!   θ_i the angle between n and the direction p → centre:
//!   `I = φ · cos θ' · cos θ'_i / d²` with `θ' = max(0, θ_w − θ_o − θ_b)` (0 when
//!   θ' ≥ π/2) and `θ'_i = max(0, θ_i − θ_b)` (0 when ≥ π/2: a **one-sided** receiver,
//!   where pbrt takes |cos θ_i|). `n = 0` means no receiver normal (free space). When p is
//!   inside the sphere every direction is possible and `I = φ / r²`; pbrt clamps d² to
//!   half the box diagonal (a length), we clamp to r² (an area) — it only happens inside,
//!   where we return early.
//! - **Half-space tests** (ours, not in pbrt): before the angular bounds, a node is dark
//!   when p is behind every plane its emitters can have — `(p − x)·a + |p − x|·chord ≤ 0`
//!   for every x in the box, a the cone axis — or the whole box is below p's horizon
//!   (`(x − p)·n ≤ 0`). For a flat group of parallel emitters, such as one wall's windows,
//!   these are exact where the sphere's cones are loose, and they also hold for p inside
//!   the sphere. A node whose emitters face two to four exactly equal ways (a building's
//!   corner, a whole building of windows) also keeps, per way, the plane offset
//!   min x·m over those emitters' boxes: it is dark when p·m ≤ that offset for every way —
//!   which is what a texel on a building's own wall or roof is, for the building's windows.
//! - **Conservative**: I is 0 only when no point of any emitter of the node can send light
//!   into p's hemisphere, so a zero probability never hides light (that would bias the
//!   bake). To keep this true in f32 the sphere is inflated by a relative 1e-6 of its size
//!   and of its coordinates' magnitude, the cone is widened by 1e-6 in cos θ_o, the
//!   π/2 tests allow [`COS_SLACK`], and an importance that passes them is at least
//!   `f32::MIN_POSITIVE`.
//! - **Selection**: at each inner node a child is chosen with probability
//!   `I_child / (I_left + I_right)` (in f64), and the one random number is rescaled for the
//!   next level (pbrt's `SampleDiscrete`). When both children of a node reached with
//!   non-zero probability have importance 0 (tighter bounds than the parent's), the pick
//!   fails and returns `None`, as pbrt does: the probabilities of all emitters then sum to
//!   less than 1, and the missing mass is that of the dead ends — which hold no light for
//!   p, so an estimator that counts a failed pick as 0 stays unbiased.
//! - **Pmf**: every emitter keeps the trail of left/right bits from the root to its leaf
//!   (a u64 with a sentinel bit, pbrt's `bitTrail`); [`LightTree::pmf`] replays the choices
//!   along it with the same arithmetic, so it equals the probability [`LightTree::pick`]
//!   returns bit for bit (MIS needs both to agree).
//! - **Build**: pbrt's bucketed SAH with orientation (the paper's SAOH): 12 buckets of
//!   centroids on each axis, cost `φ · M_Ω · area(box)` on both sides times the
//!   regularizer `K_r = max extent / extent on the axis`; bucket cones merge by pbrt's
//!   `DirectionCone` union, and a node's own cone is checked against every member normal.
//!   When no bucket split separates the centroids, or the depth budget of the 63-bit
//!   trail runs short, the node splits at the median centroid of its widest axis instead.
//! - **Excluded**: emitters whose power is not positive and finite, or whose corners are
//!   not finite, are not in the tree (pmf 0, never picked). A zero or non-finite normal (a
//!   degenerate triangle) makes the emitter's cone the whole sphere.
//! - **Precision of u**: each level consumes about log2(1 / p_child) bits of the f32 `u`
//!   (24 bits), as in pbrt: the u values that lead to emitter i fill an interval of length
//!   pmf_i, which 2^24 grid points resolve to ±2^-24, so an emitter with pmf 10^-6 is
//!   picked with a frequency up to ±6% off its pmf (the alias table has the same limit).
//!
//! Measured (2-core EPYC shared with three other builds, 2026-11-24, `benches/lights.rs`,
//! synthetic night city, release): the tree builds 10^4 emissive triangles in 26 ms and
//! 10^6 in 3.1 s (the alias table: 0.09 ms, 11 ms); one pick plus the pmf of the picked
//! emitter takes 1.8 µs at 10^4 and 4.6 µs at 10^6 (alias: 4 ns, 6 ns), averaged over
//! city texels of which 29% see no window (their picks fail at the root); mean leaf depth
//! 13.7 at 10^4. At texels that some window can light, 87% of the tree's picks land on
//! an emitter that can light the texel and 13% fail in dead ends (alias: 29–31% useful);
//! every successful pick was useful. Steps: pbrt's bounds alone picked usefully 45% of
//! the time over all sampled texels, lit or not (random triangles: dead-end mass 0.50);
//! with the box half-space tests 68% at lit texels (random triangles 0.16); with the
//! planes of two-to-four-way nodes 87% (random triangles 0.12), for ~20–40% more time per
//! pick.

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Vec3, Vec4};
use guidebake_kernels::estimator::luminance;
use guidebake_kernels::sobol::ONE_MINUS_EPSILON;

/// How far below 0 a bound's cos θ' or cos θ'_i may round before the node counts as dark.
pub const COS_SLACK: f32 = 1e-5;

/// Chord of a node's normals above which it keeps [`Planes`] (parallel emitters have a
/// chord of ~1e-7 and need none; two walls at right angles have 0.77).
const WIDE_CHORD: f32 = 1e-3;

/// Buckets per axis of the SAOH build (pbrt-v4 uses 12).
const BUCKETS: usize = 12;

/// Deepest leaf: the trail of a leaf at depth d uses d bits plus the sentinel, in a u64.
const MAX_DEPTH: u32 = 62;

/// The high bit of [`Node::link`] marks a leaf; the other bits hold the emitter index.
const LEAF: u32 = 1 << 31;

/// What the tree needs to know about one emissive triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmitterBounds {
    /// The triangle's corners, world space.
    pub corners: [Vec3; 3],
    /// Unit normal of the emitting (front) face.
    pub normal: Vec3,
    /// Selection weight: area × luminance of the emitted radiance.
    pub power: f32,
}

impl EmitterBounds {
    /// The bounds of a triangle that emits `emission` (linear RGB radiance) from its front
    /// face, the side its winding's normal `(b − a) × (c − a)` points to. A degenerate
    /// triangle gets power 0 (not in the tree).
    #[must_use]
    pub fn from_triangle(corners: [Vec3; 3], emission: Vec3) -> EmitterBounds {
        let [a, b, c] = corners;
        let cross = (b - a).cross(c - a);
        let area = 0.5 * cross.length();
        let lum = luminance(emission.as_dvec3().to_array()) as f32;
        let power = area * lum;
        EmitterBounds {
            corners,
            normal: cross.normalize_or_zero(),
            power: if power.is_finite() && power > 0.0 {
                power
            } else {
                0.0
            },
        }
    }
}

/// A cone of directions: every direction within angle acos(`cos`) of `axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cone {
    axis: Vec3,
    cos: f32,
}

impl Cone {
    const SPHERE: Cone = Cone {
        axis: Vec3::Z,
        cos: -1.0,
    };

    /// The cone of one normal; the whole sphere when the normal is not a direction.
    fn of_normal(n: Vec3) -> Cone {
        n.try_normalize()
            .map_or(Cone::SPHERE, |axis| Cone { axis, cos: 1.0 })
    }

    /// The smallest cone holding both (pbrt-v4's `Union(DirectionCone, DirectionCone)`);
    /// only the build's cost estimate relies on it being tight, not on it being exact.
    fn union(self, b: Cone) -> Cone {
        if self.cos <= -1.0 || b.cos <= -1.0 {
            return Cone::SPHERE;
        }
        if self.axis.dot(b.axis) >= self.cos && b.cos >= 1.0 {
            return self;
        }
        let (ta, tb) = (
            self.cos.clamp(-1.0, 1.0).acos(),
            b.cos.clamp(-1.0, 1.0).acos(),
        );
        let td = angle_between(self.axis, b.axis);
        if (td + tb).min(PI) <= ta {
            return self;
        }
        if (td + ta).min(PI) <= tb {
            return b;
        }
        let theta = 0.5 * (ta + td + tb);
        let about = self.axis.cross(b.axis);
        if theta >= PI || about.length_squared() < 1e-12 {
            return Cone::SPHERE;
        }
        // Rotate a's axis towards b's by θ − θ_a about a × b (a ⊥ a × b).
        let r = theta - ta;
        let about = about.normalize();
        let axis = (self.axis * r.cos() + about.cross(self.axis) * r.sin()).normalize();
        Cone {
            axis,
            cos: theta.cos(),
        }
    }

    /// pbrt-v4's direction measure M_Ω of a cone with emission spread θ_e = π/2
    /// (the paper's eq. 1).
    fn measure(self) -> f32 {
        let theta_o = self.cos.clamp(-1.0, 1.0).acos();
        let theta_w = (theta_o + FRAC_PI_2).min(PI);
        let sin_o = (1.0 - self.cos * self.cos).max(0.0).sqrt();
        2.0 * PI * (1.0 - self.cos)
            + FRAC_PI_2
                * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o
                    + self.cos)
    }
}

/// The angle between two unit vectors, accurate near 0 and π.
fn angle_between(a: Vec3, b: Vec3) -> f32 {
    if a.dot(b) < 0.0 {
        PI - 2.0 * ((a + b).length() / 2.0).min(1.0).asin()
    } else {
        2.0 * ((b - a).length() / 2.0).min(1.0).asin()
    }
}

/// One emitter during the build.
#[derive(Clone, Copy, Debug)]
struct Prim {
    lo: Vec3,
    hi: Vec3,
    normal: Vec3,
    power: f32,
    index: u32,
}

impl Prim {
    fn centroid(&self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }
}

/// Bounds of a set of emitters while building: box, power, cone, count.
#[derive(Clone, Copy, Debug)]
struct Agg {
    lo: Vec3,
    hi: Vec3,
    power: f64,
    cone: Option<Cone>,
    count: u32,
}

impl Agg {
    const EMPTY: Agg = Agg {
        lo: Vec3::INFINITY,
        hi: Vec3::NEG_INFINITY,
        power: 0.0,
        cone: None,
        count: 0,
    };

    fn add(&mut self, p: &Prim) {
        self.merge(&Agg {
            lo: p.lo,
            hi: p.hi,
            power: f64::from(p.power),
            cone: Some(Cone::of_normal(p.normal)),
            count: 1,
        });
    }

    fn merge(&mut self, o: &Agg) {
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
        self.power += o.power;
        self.count += o.count;
        self.cone = match (self.cone, o.cone) {
            (Some(a), Some(b)) => Some(a.union(b)),
            (a, b) => a.or(b),
        };
    }

    /// The SAOH cost φ · M_Ω · surface area (without K_r).
    fn cost(&self) -> f64 {
        let d = (self.hi - self.lo).max(Vec3::ZERO);
        let area = 2.0 * f64::from(d.x * d.y + d.y * d.z + d.z * d.x);
        let m = self.cone.map_or(0.0, Cone::measure);
        self.power * f64::from(m) * area
    }
}

/// A node: bounding sphere, normal cone, power, and a link (44 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    center: Vec3,
    radius: f32,
    /// Half-extents of the box, inflated like the radius.
    half: Vec3,
    axis: Vec3,
    cos_o: f32,
    sin_o: f32,
    /// Largest |m − axis| over the member normals m (the cone's chord), 2 for a sphere.
    chord: f32,
    power: f32,
    /// Inner node: index of the right child (the left one follows the node). Leaf:
    /// [`LEAF`] | emitter index.
    link: u32,
    /// Index of the node's [`Planes`] in [`LightTree::planes`], or [`NO_PLANES`].
    planes: u32,
}

/// The planes of a node whose emitters face up to four exactly equal ways: per way the
/// unit normal m (xyz) and the smallest x·m over those emitters' boxes (w). p is behind
/// all of them when p·m ≤ w for every way. Unused ways repeat the first.
type Planes = [Vec4; 4];

/// [`Node::planes`] of a node without [`Planes`].
const NO_PLANES: u32 = u32::MAX;

impl Node {
    fn is_leaf(&self) -> bool {
        self.link & LEAF != 0
    }

    /// The half-space tests on the box (`d = p − centre`, `dist = |d|`): whether p is
    /// behind every emitter plane the box and cone allow, or the whole box is below p's
    /// horizon. Tighter than the sphere for flat groups such as one wall's windows, and
    /// valid inside the sphere too.
    fn behind_all(&self, p: Vec3, n: Vec3, d: Vec3, dist: f32, planes: Option<&Planes>) -> bool {
        let tol = 4e-6 * (p.abs().max_element() + self.center.abs().max_element() + self.radius);
        if planes.is_some_and(|g| g.iter().all(|q| p.dot(q.truncate()) - q.w <= -tol)) {
            return true;
        }
        // max over box points x and cone normals m of (p − x)·m, bounded through the axis a:
        // (p − x)·a + |p − x| |m − a|.
        let front =
            d.dot(self.axis) + support(self.half, self.axis) + (dist + self.radius) * self.chord;
        let above = n != Vec3::ZERO && -d.dot(n) + support(self.half, n) <= -tol;
        front <= -tol || above
    }
}

/// A light BVH over emissive triangles (see the module doc). `Send + Sync`; `pick` and
/// `pmf` do not allocate.
#[derive(Clone, Debug, PartialEq)]
pub struct LightTree {
    /// Depth first: a node's left child follows it.
    nodes: Vec<Node>,
    /// Per input emitter: the left (0) / right (1) choices from the root, bit d for depth
    /// d, and a sentinel bit above the last; 0 for an emitter not in the tree.
    trails: Vec<u64>,
    /// The planes of inner nodes whose emitters face two to four ways.
    planes: Vec<Planes>,
}

impl LightTree {
    /// Builds the tree over the emitters of positive, finite power and finite corners.
    ///
    /// Returns `None` when no emitter qualifies, or when there are 2^31 or more emitters.
    #[must_use]
    pub fn build(emitters: &[EmitterBounds]) -> Option<LightTree> {
        if emitters.len() >= LEAF as usize {
            return None;
        }
        let mut prims: Vec<Prim> = emitters
            .iter()
            .enumerate()
            .filter(|(_, e)| {
                e.power.is_finite() && e.power > 0.0 && e.corners.iter().all(|c| c.is_finite())
            })
            .map(|(i, e)| {
                let [a, b, c] = e.corners;
                Prim {
                    lo: a.min(b).min(c),
                    hi: a.max(b).max(c),
                    normal: e.normal,
                    power: e.power,
                    index: i as u32,
                }
            })
            .collect();
        if prims.is_empty() {
            return None;
        }
        let mut tree = LightTree {
            nodes: Vec::with_capacity(2 * prims.len() - 1),
            trails: vec![0; emitters.len()],
            planes: Vec::new(),
        };
        tree.build_node(&mut prims, 0, 0);
        Some(tree)
    }

    /// Appends the subtree over `prims` (depth `depth`, trail bits so far `trail`).
    fn build_node(&mut self, prims: &mut [Prim], depth: u32, trail: u64) {
        let here = self.nodes.len();
        let mut node = node_bounds(prims);
        if node.chord > WIDE_CHORD
            && prims.len() > 1
            && let Some(planes) = planes_of(prims)
        {
            node.planes = self.planes.len() as u32;
            self.planes.push(planes);
        }
        self.nodes.push(node);
        if let [one] = prims {
            self.nodes[here].link = LEAF | one.index;
            self.trails[one.index as usize] = trail | 1 << depth;
            return;
        }
        let mid = split(prims, depth);
        let (left, right) = prims.split_at_mut(mid);
        self.build_node(left, depth + 1, trail);
        self.nodes[here].link = self.nodes.len() as u32;
        self.build_node(right, depth + 1, trail | 1 << depth);
    }

    /// Picks an emitter for the shading point `p` with unit receiver normal `n` (or
    /// `Vec3::ZERO` for a point in free space) with one uniform `u` in [0, 1): the emitter's
    /// index in the slice given to [`LightTree::build`] and the probability of that pick,
    /// equal to [`LightTree::pmf`]. `None` when the descent ends where both children are
    /// dark (always when no emitter can light p; see the module doc), or p is not finite.
    /// A non-unit `n` is normalized, a non-finite one counts as `Vec3::ZERO`. For a
    /// two-sided surface pass the normal of the side being shaded: the receiver is
    /// one-sided.
    #[must_use]
    pub fn pick(&self, p: Vec3, n: Vec3, u: f32) -> Option<(u32, f32)> {
        if !p.is_finite() {
            return None;
        }
        let n = receiver(n);
        let mut u = f64::from(if u > 0.0 {
            u.min(ONE_MINUS_EPSILON)
        } else {
            0.0
        });
        let mut prob = 1.0f64;
        let mut at = 0usize;
        if self.nodes[0].is_leaf() {
            return (importance(&self.nodes[0], &self.planes, p, n) > 0.0)
                .then_some((self.nodes[0].link & !LEAF, 1.0));
        }
        loop {
            let node = &self.nodes[at];
            if node.is_leaf() {
                return Some((node.link & !LEAF, finish(prob)));
            }
            let (left, right) = (at + 1, node.link as usize);
            let [pl, pr] = choice(&self.nodes[left], &self.nodes[right], &self.planes, p, n)?;
            let one_below = f64::from(ONE_MINUS_EPSILON);
            if u < pl {
                (u, prob, at) = ((u / pl).min(one_below), prob * pl, left);
            } else {
                (u, prob, at) = (((u - pl) / pr).min(one_below), prob * pr, right);
            }
        }
    }

    /// The probability that [`LightTree::pick`] at (`p`, `n`) returns emitter `index`
    /// (0 for an emitter not in the tree or an index out of range).
    #[must_use]
    pub fn pmf(&self, p: Vec3, n: Vec3, index: u32) -> f32 {
        let trail = self.trails.get(index as usize).copied().unwrap_or(0);
        if trail == 0 || !p.is_finite() {
            return 0.0;
        }
        let n = receiver(n);
        let depth = 63 - trail.leading_zeros();
        if depth == 0 {
            return if importance(&self.nodes[0], &self.planes, p, n) > 0.0 {
                1.0
            } else {
                0.0
            };
        }
        let (mut prob, mut at) = (1.0f64, 0usize);
        for d in 0..depth {
            let node = &self.nodes[at];
            let (left, right) = (at + 1, node.link as usize);
            let Some([pl, pr]) = choice(&self.nodes[left], &self.nodes[right], &self.planes, p, n)
            else {
                return 0.0;
            };
            (prob, at) = if trail >> d & 1 == 0 {
                (prob * pl, left)
            } else {
                (prob * pr, right)
            };
        }
        if prob > 0.0 { finish(prob) } else { 0.0 }
    }

    /// Number of emitters in the tree (those of positive power).
    #[must_use]
    pub fn len(&self) -> usize {
        self.nodes.len().div_ceil(2)
    }

    /// Whether the tree holds no emitter; never true for a built tree.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
}

/// The receiver normal as the importance reads it: unit, or zero for "none".
fn receiver(n: Vec3) -> Vec3 {
    n.try_normalize().unwrap_or(Vec3::ZERO)
}

/// A pick's probability as f32; a positive probability stays positive.
fn finish(prob: f64) -> f32 {
    (prob as f32).max(f32::MIN_POSITIVE)
}

/// The probabilities of taking the left and the right child; `None` when both are dark.
fn choice(left: &Node, right: &Node, planes: &[Planes], p: Vec3, n: Vec3) -> Option<[f64; 2]> {
    let (l, r) = (
        f64::from(importance(left, planes, p, n)),
        f64::from(importance(right, planes, p, n)),
    );
    let sum = l + r;
    (sum > 0.0).then(|| [l / sum, r / sum])
}

/// cos and sin of max(0, a − b) from those of a and b (angles in [0, π]); sin a is only
/// evaluated when a > b.
fn minus_clamped(cos_a: f32, sin_a: impl FnOnce() -> f32, cos_b: f32, sin_b: f32) -> (f32, f32) {
    if cos_a >= cos_b {
        (1.0, 0.0)
    } else {
        let sin_a = sin_a();
        (cos_a * cos_b + sin_a * sin_b, sin_a * cos_b - cos_a * sin_b)
    }
}

fn sin_of(cos: f32) -> f32 {
    (1.0 - cos * cos).max(0.0).sqrt()
}

/// The node's importance at `p` with receiver normal `n` (module doc): an upper bound,
/// up to a constant, of the irradiance its emitters can deliver; 0 only when none can.
fn importance(node: &Node, planes: &[Planes], p: Vec3, n: Vec3) -> f32 {
    let d = p - node.center;
    let d2 = d.length_squared();
    let dist = d2.sqrt();
    if node.behind_all(p, n, d, dist, planes.get(node.planes as usize)) {
        return 0.0;
    }
    let r2 = node.radius * node.radius;
    if d2 <= r2.max(1e-30) {
        // p inside the bounding sphere: light may come from any direction.
        return at_least_tiny(node.power / r2.max(1e-30));
    }
    let to_p = d / dist;
    let sin_b = (node.radius / dist).min(1.0);
    let cos_b = sin_of(sin_b);
    // Emitter side: the smallest angle between a normal and a direction towards p.
    let cos_w = node.axis.dot(to_p).clamp(-1.0, 1.0);
    let (cos_x, sin_x) = minus_clamped(cos_w, || sin_of(cos_w), node.cos_o, node.sin_o);
    let (cos_e, _) = minus_clamped(cos_x, || sin_x, cos_b, sin_b);
    if cos_e <= -COS_SLACK {
        return 0.0;
    }
    // Receiver side: the smallest angle between n and a direction towards the node.
    let mut cos_r = 1.0;
    if n != Vec3::ZERO {
        let cos_i = (-n.dot(to_p)).clamp(-1.0, 1.0);
        cos_r = minus_clamped(cos_i, || sin_of(cos_i), cos_b, sin_b).0;
        if cos_r <= -COS_SLACK {
            return 0.0;
        }
    }
    at_least_tiny(node.power * cos_e.max(0.0) * cos_r.max(0.0) / d2)
}

/// max over the box of half-extents `h` (centred at 0) of x · v.
fn support(h: Vec3, v: Vec3) -> f32 {
    h.dot(v.abs())
}

/// A positive importance in [f32::MIN_POSITIVE, f32::MAX].
fn at_least_tiny(x: f32) -> f32 {
    if x >= f32::MIN_POSITIVE {
        x.min(f32::MAX)
    } else {
        f32::MIN_POSITIVE
    }
}

/// The node over `prims` with its link unset: sphere, checked cone, power.
fn node_bounds(prims: &[Prim]) -> Node {
    let mut agg = Agg::EMPTY;
    for p in prims {
        agg.add(p);
    }
    let cone = agg.cone.unwrap_or(Cone::SPHERE);
    // The union is built with rounding; make sure every member normal is inside.
    let mut cos = cone.cos;
    for p in prims {
        cos = cos.min(match p.normal.try_normalize() {
            Some(n) => cone.axis.dot(n),
            None => -1.0,
        });
    }
    let cos_o = (cos - 1e-6).max(-1.0);
    let mut chord = 0f32;
    for p in prims {
        chord = chord.max(match p.normal.try_normalize() {
            Some(n) => (n - cone.axis).length(),
            None => 2.0,
        });
    }
    let center = 0.5 * (agg.lo + agg.hi);
    let magnitude = agg.lo.abs().max(agg.hi.abs()).max_element();
    let half = 0.5 * (agg.hi - agg.lo) * (1.0 + 1e-6) + Vec3::splat(magnitude * 1e-6);
    Node {
        center,
        radius: half.length() * (1.0 + 1e-6),
        half,
        axis: cone.axis,
        cos_o,
        sin_o: sin_of(cos_o),
        chord: (chord * (1.0 + 1e-6) + 1e-7).min(2.0),
        power: (agg.power as f32).min(f32::MAX),
        link: 0,
        planes: NO_PLANES,
    }
}

/// The [`Planes`] of emitters that face at most four exactly equal ways; `None` otherwise
/// (or when a normal is not a direction).
fn planes_of(prims: &[Prim]) -> Option<Planes> {
    let mut ways = [Vec4::ZERO; 4];
    let mut count = 0;
    for p in prims {
        let m = p.normal.try_normalize()?;
        let offset = p.centroid().dot(m) - support(0.5 * (p.hi - p.lo), m);
        match ways[..count].iter_mut().find(|w| w.truncate() == m) {
            Some(w) => w.w = w.w.min(offset),
            None if count < 4 => {
                ways[count] = m.extend(offset);
                count += 1;
            }
            None => return None,
        }
    }
    for k in count..ways.len() {
        ways[k] = ways[0];
    }
    Some(ways)
}

/// Splits `prims` in two non-empty halves (reordering it); returns the size of the left.
fn split(prims: &mut [Prim], depth: u32) -> usize {
    let (mut clo, mut chi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for p in prims.iter() {
        let c = p.centroid();
        (clo, chi) = (clo.min(c), chi.max(c));
        (lo, hi) = (lo.min(p.lo), hi.max(p.hi));
    }
    let budget = MAX_DEPTH.saturating_sub(depth);
    if prims.len().next_power_of_two().trailing_zeros() < budget
        && let Some((axis, bucket)) = best_bucket_split(prims, clo, chi, hi - lo)
    {
        let mid = partition(prims, |p| bucket_of(p, axis, clo, chi) <= bucket);
        if mid > 0 && mid < prims.len() {
            return mid;
        }
    }
    median_split(prims, (chi - clo).max_position())
}

/// The bucket of a centroid along `axis`.
fn bucket_of(p: &Prim, axis: usize, clo: Vec3, chi: Vec3) -> usize {
    let t = (p.centroid()[axis] - clo[axis]) / (chi[axis] - clo[axis]);
    ((t * BUCKETS as f32) as usize).min(BUCKETS - 1)
}

/// The cheapest SAOH split: axis and last bucket of the left side; `None` when the
/// centroids do not spread on any axis.
fn best_bucket_split(prims: &[Prim], clo: Vec3, chi: Vec3, diag: Vec3) -> Option<(usize, usize)> {
    let mut best: Option<(f64, usize, usize)> = None;
    for axis in 0..3 {
        if chi[axis] <= clo[axis] {
            continue;
        }
        let mut buckets = [Agg::EMPTY; BUCKETS];
        for p in prims {
            buckets[bucket_of(p, axis, clo, chi)].add(p);
        }
        // Suffix aggregates: right side of a split after bucket k is suffix[k + 1].
        let mut suffix = [Agg::EMPTY; BUCKETS + 1];
        for k in (0..BUCKETS).rev() {
            suffix[k] = suffix[k + 1];
            suffix[k].merge(&buckets[k]);
        }
        let kr = f64::from(diag.max_element() / diag[axis]);
        let mut left = Agg::EMPTY;
        for k in 0..BUCKETS - 1 {
            left.merge(&buckets[k]);
            let right = &suffix[k + 1];
            if left.count == 0 || right.count == 0 {
                continue;
            }
            let cost = kr * (left.cost() + right.cost());
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    best.map(|(_, axis, k)| (axis, k))
}

/// Reorders `prims` so that those satisfying `left` come first; returns their count.
fn partition(prims: &mut [Prim], left: impl Fn(&Prim) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..prims.len() {
        if left(&prims[i]) {
            prims.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

/// Splits at the median centroid along `axis` (halves differ in size by at most one).
fn median_split(prims: &mut [Prim], axis: usize) -> usize {
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |a, b| {
        a.centroid()[axis].total_cmp(&b.centroid()[axis])
    });
    mid
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::{Pcg32, chi_square};

    fn random_unit(rng: &mut Pcg32) -> Vec3 {
        loop {
            let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
            if v.length_squared() > 1e-3 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }

    /// `count` random triangles of edge up to `size` in a cube of half-edge `spread` around
    /// `offset`, powers log-uniform over 1e-4..1e5.
    fn random_emitters(
        rng: &mut Pcg32,
        count: usize,
        spread: f32,
        size: f32,
        offset: Vec3,
    ) -> Vec<EmitterBounds> {
        (0..count)
            .map(|_| {
                let a = offset
                    + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0)
                        * spread;
                let b = a + random_unit(rng) * size * rng.next_f32();
                let c = a + random_unit(rng) * size * rng.next_f32();
                let mut e = EmitterBounds::from_triangle([a, b, c], Vec3::ONE);
                e.power = 10f32.powf(rng.next_f32() * 9.0 - 4.0);
                e
            })
            .collect()
    }

    /// Probability that a pick at (p, n) fails: the mass that reaches dead ends.
    fn dead_mass(tree: &LightTree, p: Vec3, n: Vec3) -> f64 {
        let n = receiver(n);
        fn walk(tree: &LightTree, at: usize, p: Vec3, n: Vec3) -> f64 {
            let node = &tree.nodes[at];
            if node.is_leaf() {
                return 0.0;
            }
            let right = node.link as usize;
            match choice(&tree.nodes[at + 1], &tree.nodes[right], &tree.planes, p, n) {
                None => 1.0,
                Some([pl, pr]) => {
                    let l = if pl > 0.0 {
                        pl * walk(tree, at + 1, p, n)
                    } else {
                        0.0
                    };
                    let r = if pr > 0.0 {
                        pr * walk(tree, right, p, n)
                    } else {
                        0.0
                    };
                    l + r
                }
            }
        }
        if tree.nodes[0].is_leaf() {
            return if importance(&tree.nodes[0], &tree.planes, p, n) > 0.0 {
                0.0
            } else {
                1.0
            };
        }
        walk(tree, 0, p, n)
    }

    /// Whether the emitter can deliver light to p with receiver normal n (f64, exact up to
    /// the input's rounding): p strictly in front of its plane and some corner strictly
    /// above p's tangent plane (n = 0: any corner).
    fn can_light(e: &EmitterBounds, p: Vec3, n: Vec3) -> bool {
        let p = p.as_dvec3();
        let [a, b, c] = e.corners.map(|v| v.as_dvec3());
        let front = (b - a).cross(c - a).dot(p - a) > 0.0;
        let n = n.as_dvec3();
        front && (n == glam::DVec3::ZERO || [a, b, c].iter().any(|&x| (x - p).dot(n) > 0.0))
    }

    #[test]
    fn pmfs_sum_to_one_less_the_dead_ends_and_pick_agrees_bit_for_bit() {
        let mut rng = Pcg32::new(1, 1);
        for (case, count) in [1usize, 2, 3, 10, 257, 2000].into_iter().enumerate() {
            let emitters = random_emitters(&mut rng, count, 10.0, 2.0, Vec3::ZERO);
            let tree = LightTree::build(&emitters).unwrap();
            assert_eq!(tree.len(), count);
            for q in 0..40 {
                let p =
                    (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0) * 14.0;
                let n = if q % 5 == 0 {
                    Vec3::ZERO
                } else {
                    random_unit(&mut rng)
                };
                let sum: f64 = (0..count as u32)
                    .map(|i| f64::from(tree.pmf(p, n, i)))
                    .sum();
                let dead = dead_mass(&tree, p, n);
                assert!(
                    (sum + dead - 1.0).abs() < 1e-4,
                    "case {case} query {q}: Σ pmf {sum} + dead {dead}"
                );
                for _ in 0..50 {
                    let u = rng.next_f32();
                    match tree.pick(p, n, u) {
                        Some((i, prob)) => {
                            assert_eq!(
                                prob.to_bits(),
                                tree.pmf(p, n, i).to_bits(),
                                "case {case} u {u}"
                            );
                            assert!(prob > 0.0 && prob.is_finite());
                        }
                        None => assert!(dead > 0.0, "case {case}: a pick failed with no dead end"),
                    }
                }
            }
        }
    }

    #[test]
    fn pick_frequencies_follow_the_pmf() {
        let mut rng = Pcg32::new(2, 7);
        let emitters = random_emitters(&mut rng, 300, 10.0, 3.0, Vec3::ZERO);
        let tree = LightTree::build(&emitters).unwrap();
        let queries = [
            (Vec3::new(0.5, 0.2, -0.3), Vec3::Y),
            (Vec3::new(30.0, 4.0, 2.0), Vec3::ZERO),
            (
                Vec3::new(-3.0, 9.0, 1.0),
                Vec3::new(0.3, -0.9, 0.1).normalize(),
            ),
        ];
        let count = 1_000_000u32;
        for (k, &(p, n)) in queries.iter().enumerate() {
            // One cell per emitter and one for a failed pick.
            let mut observed = vec![0.0; emitters.len() + 1];
            for _ in 0..count {
                match tree.pick(p, n, rng.next_f32()) {
                    Some((i, _)) => observed[i as usize] += 1.0,
                    None => observed[emitters.len()] += 1.0,
                }
            }
            let mut expected: Vec<f64> = (0..emitters.len() as u32)
                .map(|i| f64::from(tree.pmf(p, n, i)) * f64::from(count))
                .collect();
            expected.push(dead_mass(&tree, p, n) * f64::from(count));
            let c = chi_square(&observed, &expected, 5.0);
            assert!(
                c.passes(0.01, queries.len() as u32),
                "query {k}: chi² {} dof {} p {}",
                c.statistic,
                c.dof,
                c.p_value
            );
        }
    }

    #[test]
    fn every_emitter_that_can_light_the_point_has_positive_pmf() {
        let mut rng = Pcg32::new(3, 3);
        // Near the origin, and 1e6 away with small triangles (coordinates rounded to 1/16).
        let places = [
            (Vec3::ZERO, 10.0, 3.0),
            (Vec3::new(1e6, -1e6, 1e6), 50.0, 1.0),
        ];
        for (offset, spread, size) in places {
            for config in 0..20 {
                let emitters = random_emitters(&mut rng, 200, spread, size, offset);
                let tree = LightTree::build(&emitters).unwrap();
                for q in 0..100 {
                    let p = offset
                        + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0)
                            * spread
                            * 1.3;
                    let n = if q % 7 == 0 {
                        Vec3::ZERO
                    } else {
                        random_unit(&mut rng)
                    };
                    let mut any = false;
                    for (i, e) in emitters.iter().enumerate() {
                        let pmf = tree.pmf(p, n, i as u32);
                        assert!(pmf.is_finite() && (0.0..=1.0).contains(&pmf));
                        if can_light(e, p, n) {
                            any = true;
                            assert!(
                                pmf > 0.0,
                                "offset {offset} config {config} query {q}: emitter {i} lights p but has pmf 0"
                            );
                        }
                    }
                    if any {
                        assert!(tree.pick(p, n, 0.5).is_some() || dead_mass(&tree, p, n) > 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn grazing_and_nearly_coplanar_points_keep_their_emitters() {
        // p barely in front of a large emitter's plane, far along it; and p barely above
        // the receiver plane's horizon of an emitter.
        let quad = |y: f32, normal_up: bool| {
            let (a, b, c) = (
                Vec3::new(-1.0, y, -1.0),
                Vec3::new(1.0, y, -1.0),
                Vec3::new(-1.0, y, 1.0),
            );
            EmitterBounds::from_triangle(
                if normal_up { [a, c, b] } else { [a, b, c] },
                Vec3::splat(5.0),
            )
        };
        let up = quad(0.0, true);
        assert!(up.normal.y > 0.99);
        let tree = LightTree::build(&[up, quad(-50.0, true), quad(50.0, false)]).unwrap();
        for (p, n) in [
            (Vec3::new(1e3, 1e-3, 0.0), Vec3::ZERO),
            (Vec3::new(1e5, 1.0, 0.0), Vec3::ZERO),
            (
                Vec3::new(0.0, 10.0, 0.0),
                Vec3::new(1.0, -1e-4, 0.0).normalize(),
            ),
            (Vec3::new(0.0, 1e-4, 0.0), Vec3::X),
        ] {
            assert!(can_light(&up, p, n), "{p} {n}");
            assert!(tree.pmf(p, n, 0) > 0.0, "{p} {n}");
        }
    }

    #[test]
    fn emitters_behind_the_receiver_or_facing_away_get_zero() {
        let mut rng = Pcg32::new(4, 4);
        // A lit cluster above the receiver facing down, a cluster below it facing up, and
        // a cluster above it facing up (p is behind them).
        let cluster = |rng: &mut Pcg32, center: Vec3, down: bool| -> Vec<EmitterBounds> {
            (0..100)
                .map(|_| {
                    let a =
                        center + (Vec3::new(rng.next_f32(), 0.0, rng.next_f32()) * 2.0 - 1.0) * 4.0;
                    let (b, c) = (a + Vec3::X * 0.5, a + Vec3::Z * 0.5);
                    EmitterBounds::from_triangle(
                        if down { [a, b, c] } else { [a, c, b] },
                        Vec3::ONE * 3.0,
                    )
                })
                .collect()
        };
        let mut emitters = cluster(&mut rng, Vec3::new(0.0, 20.0, 0.0), true);
        emitters.extend(cluster(&mut rng, Vec3::new(0.0, -20.0, 0.0), false));
        emitters.extend(cluster(&mut rng, Vec3::new(40.0, 20.0, 0.0), false));
        let tree = LightTree::build(&emitters).unwrap();
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        for i in 0..100 {
            assert!(tree.pmf(p, n, i) > 0.0);
            assert_eq!(
                tree.pmf(p, n, 100 + i),
                0.0,
                "below the receiver: {}",
                100 + i
            );
            assert_eq!(tree.pmf(p, n, 200 + i), 0.0, "facing away: {}", 200 + i);
        }
        for k in 0..1000 {
            let (i, _) = tree.pick(p, n, k as f32 / 1000.0).unwrap();
            assert!(i < 100, "picked dark emitter {i}");
        }
        // Below the lit cluster's plane nothing can light a point facing down.
        assert_eq!(tree.pick(Vec3::new(0.0, -30.0, 0.0), -Vec3::Y, 0.3), None);
    }

    #[test]
    fn samplers_are_shareable_between_threads() {
        fn shareable<T: Send + Sync>() {}
        shareable::<LightTree>();
        shareable::<crate::transport::alias::AliasTable>();
    }

    #[test]
    fn a_wall_behind_its_windows_sees_none_of_them() {
        // 400 windows 2 cm in front of the wall x = 0, facing +x; p on the wall, inside
        // every sphere that holds more than a few windows.
        let mut emitters = vec![];
        for i in 0..20 {
            for j in 0..20 {
                let a = Vec3::new(0.02, 1.0 + i as f32, 1.0 + j as f32);
                let (b, c) = (a + Vec3::Y * 0.5, a + Vec3::Z * 0.5);
                emitters.push(EmitterBounds::from_triangle([a, b, c], Vec3::splat(2.0)));
            }
        }
        assert!(emitters[0].normal.x > 0.99);
        let tree = LightTree::build(&emitters).unwrap();
        let on_wall = Vec3::new(0.0, 10.2, 10.2);
        for n in [Vec3::X, Vec3::ZERO] {
            assert_eq!(tree.pick(on_wall, n, 0.4), None);
            assert!((0..400).all(|i| tree.pmf(on_wall, n, i) == 0.0));
        }
        // 1 mm in front of the windows' plane every window counts, from any direction.
        let front = Vec3::new(0.021, 10.2, 10.2);
        for n in [-Vec3::X, Vec3::ZERO, Vec3::Y] {
            let positive = (0..400).filter(|&i| tree.pmf(front, n, i) > 0.0).count();
            let lit = emitters.iter().filter(|e| can_light(e, front, n)).count();
            assert!(positive >= lit && lit > 0, "{n}: {positive} < {lit}");
        }
    }

    #[test]
    fn a_building_does_not_light_itself() {
        // Windows 2 cm out on the four walls of the box [0, 6] × [0, 20] × [0, 6].
        let mut emitters = vec![];
        for k in 0..6 {
            for f in 0..6 {
                let (s, y) = (0.5 + k as f32, 1.0 + 3.0 * f as f32);
                let quads = [
                    (Vec3::new(6.02, y, s), Vec3::Y, Vec3::Z, Vec3::X),
                    (Vec3::new(-0.02, y, s), Vec3::Z, Vec3::Y, -Vec3::X),
                    (Vec3::new(s, y, 6.02), Vec3::X, Vec3::Y, Vec3::Z),
                    (Vec3::new(s, y, -0.02), Vec3::Y, Vec3::X, -Vec3::Z),
                ];
                for (a, u, v, out) in quads {
                    let tri = [a, a + u * 0.5, a + v * 0.5];
                    emitters.push(EmitterBounds::from_triangle(tri, Vec3::splat(3.0)));
                    assert_eq!(emitters.last().unwrap().normal, out);
                }
            }
        }
        let tree = LightTree::build(&emitters).unwrap();
        assert!(!tree.planes.is_empty());
        let count = emitters.len() as u32;
        for (p, n) in [
            (Vec3::new(6.0, 7.3, 2.2), Vec3::X),
            (Vec3::new(0.0, 12.0, 5.0), -Vec3::X),
            (Vec3::new(3.0, 4.0, 6.0), Vec3::Z),
            (Vec3::new(2.0, 20.0, 3.0), Vec3::Y),
            (Vec3::new(3.0, 10.0, 3.0), Vec3::ZERO),
        ] {
            assert_eq!(tree.pick(p, n, 0.3), None, "{p}");
            assert!((0..count).all(|i| tree.pmf(p, n, i) == 0.0), "{p}");
        }
        // In front of the +x wall, its windows count and the others do not.
        let (p, n) = (Vec3::new(9.0, 7.0, 3.0), -Vec3::X);
        for (i, e) in emitters.iter().enumerate() {
            assert_eq!(
                tree.pmf(p, n, i as u32) > 0.0,
                can_light(e, p, n),
                "window {i}"
            );
        }
    }

    #[test]
    fn one_emitter_and_degenerate_inputs() {
        let e = EmitterBounds::from_triangle([Vec3::ZERO, Vec3::X, Vec3::Z], Vec3::ONE);
        assert!(e.normal.y < -0.99);
        let tree = LightTree::build(&[e]).unwrap();
        assert_eq!(tree.len(), 1);
        assert_eq!(tree.pick(-Vec3::Y, Vec3::ZERO, 0.7), Some((0, 1.0)));
        assert_eq!(tree.pmf(-Vec3::Y, Vec3::Y, 0), 1.0);
        assert_eq!(tree.pick(Vec3::Y, Vec3::ZERO, 0.7), None);
        assert_eq!(tree.pmf(Vec3::Y, Vec3::ZERO, 0), 0.0);
        assert_eq!(tree.pmf(-Vec3::Y, Vec3::ZERO, 1), 0.0);
        assert_eq!(tree.pick(Vec3::NAN, Vec3::Y, 0.5), None);
        assert_eq!(tree.pick(-Vec3::Y, Vec3::NAN, 0.5), Some((0, 1.0)));

        assert!(LightTree::build(&[]).is_none());
        let zero = EmitterBounds { power: 0.0, ..e };
        let nan = EmitterBounds {
            power: f32::NAN,
            ..e
        };
        let inf_corner = EmitterBounds {
            corners: [Vec3::INFINITY, Vec3::X, Vec3::Z],
            ..e
        };
        assert!(LightTree::build(&[zero, nan, inf_corner]).is_none());
        // Degenerate triangles with positive power (a point, a line, NaN normal), p on
        // them and everywhere: no NaN, no panic, and the point still counts.
        let point = EmitterBounds {
            corners: [Vec3::ONE; 3],
            normal: Vec3::ZERO,
            power: 1.0,
        };
        let line = EmitterBounds {
            corners: [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            normal: Vec3::NAN,
            power: 1e5,
        };
        let tree = LightTree::build(&[zero, point, line, e, nan]).unwrap();
        assert_eq!(tree.len(), 3);
        for p in [
            Vec3::ONE,
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.3, 0.0, 0.3),
            Vec3::splat(1e6),
            Vec3::splat(-3.0),
        ] {
            for n in [Vec3::ZERO, Vec3::Y, -Vec3::Y, Vec3::X] {
                let sum: f64 = (0..5).map(|i| f64::from(tree.pmf(p, n, i))).sum();
                assert!(sum.is_finite() && sum <= 1.0 + 1e-6, "{p} {n}: {sum}");
                for k in 0..64 {
                    if let Some((i, prob)) = tree.pick(p, n, k as f32 / 64.0) {
                        assert!(prob.is_finite() && prob > 0.0);
                        assert_eq!(prob.to_bits(), tree.pmf(p, n, i).to_bits());
                        assert!(i == 1 || i == 2 || i == 3);
                    }
                }
            }
        }
    }

    #[test]
    fn powers_over_nine_decades_and_far_coordinates_stay_finite() {
        let mut rng = Pcg32::new(6, 1);
        let offset = Vec3::new(-1e6, 1e6, 3e5);
        let emitters = random_emitters(&mut rng, 5000, 1e4, 1.0, offset);
        let tree = LightTree::build(&emitters).unwrap();
        for _ in 0..200 {
            let p = offset
                + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0) * 2e4;
            let n = random_unit(&mut rng);
            if let Some((i, prob)) = tree.pick(p, n, rng.next_f32()) {
                assert!(prob.is_finite() && prob > 0.0 && prob <= 1.0);
                assert_eq!(prob.to_bits(), tree.pmf(p, n, i).to_bits());
            }
        }
        assert!(tree.nodes.iter().all(|n| n.center.is_finite()
            && n.radius.is_finite()
            && n.power.is_finite()
            && n.cos_o.is_finite()));
    }

    #[test]
    fn a_million_emitters_build_in_bounded_memory() {
        let mut rng = Pcg32::new(8, 8);
        let emitters = random_emitters(&mut rng, 1_000_000, 1000.0, 1.0, Vec3::ZERO);
        let start = std::time::Instant::now();
        let tree = LightTree::build(&emitters).unwrap();
        let built = start.elapsed();
        let depth = tree
            .trails
            .iter()
            .map(|t| 63 - t.leading_zeros())
            .max()
            .unwrap();
        println!(
            "light tree: 10^6 emitters built in {:.2} s, {} nodes of {} bytes, {} planes of {} \
             bytes, depth {depth}",
            built.as_secs_f64(),
            tree.nodes.len(),
            size_of::<Node>(),
            tree.planes.len(),
            size_of::<Planes>()
        );
        assert!(size_of::<Node>() <= 64);
        assert_eq!(tree.nodes.len(), 2 * emitters.len() - 1);
        assert!(tree.planes.len() < emitters.len());
        assert!(depth <= MAX_DEPTH);
        let (p, n) = (Vec3::new(3.0, 0.5, -2.0), Vec3::Y);
        // The share of failed picks matches the dead ends' mass (4σ of a binomial).
        let mut failed = 0;
        for _ in 0..10_000 {
            match tree.pick(p, n, rng.next_f32()) {
                Some((i, prob)) => assert_eq!(prob.to_bits(), tree.pmf(p, n, i).to_bits()),
                None => failed += 1,
            }
        }
        let dead = dead_mass(&tree, p, n);
        println!(
            "light tree: 10^6 emitters, failed picks {failed} / 10^4, dead-end mass {dead:.4}"
        );
        assert!(
            (f64::from(failed) / 1e4 - dead).abs() < 0.02,
            "{failed} vs {dead}"
        );
    }

    #[test]
    fn the_depth_budget_holds_on_a_chain() {
        // Powers doubling along a line push the SAOH towards one-sided splits; the median
        // fallback keeps every trail within 63 bits.
        let emitters: Vec<EmitterBounds> = (0..5000)
            .map(|i| {
                let a = Vec3::new(i as f32 * 3.0, 0.0, 0.0);
                let mut e = EmitterBounds::from_triangle([a, a + Vec3::Z, a + Vec3::X], Vec3::ONE);
                e.power = 2f32.powi(i % 120 - 60);
                e
            })
            .collect();
        let tree = LightTree::build(&emitters).unwrap();
        assert!(
            tree.trails
                .iter()
                .all(|&t| t != 0 && 63 - t.leading_zeros() <= MAX_DEPTH)
        );
        let p = Vec3::new(7000.0, 5.0, 0.0);
        let sum: f64 = (0..5000)
            .map(|i| f64::from(tree.pmf(p, Vec3::ZERO, i)))
            .sum();
        assert!(
            (sum + dead_mass(&tree, p, Vec3::ZERO) - 1.0).abs() < 1e-4,
            "{sum}"
        );
    }

    #[test]
    fn cone_union_holds_both_cones() {
        let mut rng = Pcg32::new(9, 2);
        for _ in 0..10_000 {
            let a = Cone {
                axis: random_unit(&mut rng),
                cos: rng.next_f32() * 2.0 - 1.0,
            };
            let b = Cone {
                axis: random_unit(&mut rng),
                cos: rng.next_f32() * 2.0 - 1.0,
            };
            let u = a.union(b);
            for c in [a, b] {
                // The far edge of c, in the plane of the two axes, lies inside u.
                let angle = angle_between(u.axis, c.axis) + c.cos.acos();
                assert!(
                    angle.cos() >= u.cos - 1e-4 || u.cos <= -1.0,
                    "{a:?} {b:?} → {u:?}"
                );
            }
        }
    }
}
