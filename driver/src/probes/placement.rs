//! Where the light probes go: an adaptive lattice over the level, fine near geometry and
//! coarse in open space, no probe inside geometry or under the ground; and probes a user
//! lists, added to those or instead of them (docs/probes.md, "Placement").
//!
//! The lattice: its finest spacing D (`--probe-spacing`, by default the level's longest side
//! over [`DEFAULT_CELLS`]) and [`LEVELS`] coarser levels, each twice the one below, so the
//! coarse cells are 2^LEVELS · D. Every coarse cell's corners are probes (the regular grid a
//! volume texture samples); a cell of any level that holds geometry — a surface within half
//! a fine cell of it — is cut into eight, down to D, and the corners of the cells cut to are
//! probes too, each with the spacing of the finest cell it is a corner of. So a probe stands
//! every D along the surfaces where light changes over short distances, and every 4D in the
//! air between them, as Unreal's volumetric lightmap puts its detail cells (its "detail cell
//! size") near geometry. Where the direct light changes across a cell in open air — a shaft
//! of sun through a window — the cell is cut too ([`LightChange`], `--refine light`).
//!
//! The lattice is offset half a fine cell below the level's bounds, so no layer of probes lies
//! in a floor or wall on them. A probe lies inside geometry where more than
//! [`INSIDE_SHARE`] of 64 rays over the sphere meet a side of a surface that faces no open
//! space (the seen sides `prepare` recorded in the texel file): inside a solid block, under
//! a level's ground (half its rays meet the ground's underside). Those are not placed, and
//! counted.
//!
//! Probes are grouped into clusters — the probes of one coarse cell, at most 4³ = 64 — that
//! share one learned guide, as a cluster of texels does (paper §2.1): clusters in Morton
//! order of their cells, probes in lattice order within them, so the probe file's order is
//! fixed by the level alone.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;
use guidebake_kernels::estimator::luminance_f32;
use guidebake_kernels::packet::{Hit8, NO_HIT, Ray8};
use guidebake_kernels::traverse::intersect8;
use rayon::prelude::*;

use super::gather::{light_axis, light_sample_at};
use crate::prepare::facing::INSIDE_SHARE;
use crate::texels::{SEEN_BACK, SEEN_FRONT};
use crate::transport::world::{World, closest_point_on_triangle};

/// The default finest spacing: the level's longest side over this many cells.
pub const DEFAULT_CELLS: f32 = 24.0;

/// Levels of cells coarser than the finest: coarse cells are 2^LEVELS = 4 fine cells wide.
pub const LEVELS: u32 = 2;

/// Rays of the inside-geometry test.
const INSIDE_RAYS: usize = 64;

/// How probes are placed.
#[derive(Clone, Debug, PartialEq)]
pub struct PlacementSettings {
    /// The finest spacing D; `None`: the level's longest side over [`DEFAULT_CELLS`].
    pub spacing: Option<f32>,
    /// Probes a user lists (`--probe-points FILE`).
    pub points: Vec<Vec3>,
    /// Whether the lattice is placed too (`false`: the listed points alone).
    pub lattice: bool,
    /// Whether lattice cells are cut where the direct light changes across them too, not only
    /// where they hold geometry (`--refine light`, the default; `--refine geometry`).
    pub refine_light: bool,
}

impl Default for PlacementSettings {
    fn default() -> Self {
        PlacementSettings {
            spacing: None,
            points: Vec::new(),
            lattice: false,
            refine_light: true,
        }
    }
}

/// One placed probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedProbe {
    /// Where it is.
    pub position: Vec3,
    /// The spacing of the finest lattice cell it is a corner of (D for a listed probe): the
    /// reach of its weight when probes are interpolated (docs/probes.md).
    pub spacing: f32,
    /// Its cluster: the coarse cell it lies in.
    pub cluster: [i32; 3],
    /// Its lattice coordinates in fine cells, for a lattice probe.
    pub lattice: Option<[i32; 3]>,
}

impl PlacedProbe {
    /// Its point of the coarse grid (a lattice probe at a coarse cell's corner), if it is one.
    #[must_use]
    pub fn coarse_point(&self) -> Option<[u32; 3]> {
        let step = 1 << LEVELS;
        let at = self.lattice?;
        at.iter()
            .all(|v| v % step == 0 && *v >= 0)
            .then(|| at.map(|v| (v / step) as u32))
    }
}

/// The regular grid of the coarse cells' corners: what a volume texture holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseGrid {
    /// The corner of lattice point (0, 0, 0).
    pub origin: Vec3,
    /// The finest spacing D.
    pub fine: f32,
    /// Points along each axis.
    pub points: [u32; 3],
}

impl CoarseGrid {
    /// The coarse spacing, 2^[`LEVELS`] · D.
    #[must_use]
    pub fn spacing(&self) -> f32 {
        self.fine * (1 << LEVELS) as f32
    }

    /// How many points it has.
    #[must_use]
    pub fn len(&self) -> usize {
        self.points.iter().map(|&n| n as usize).product()
    }

    /// Whether it has none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What placement did, for the stats.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlacementReport {
    /// Lattice points considered.
    pub lattice_candidates: u64,
    /// Listed points considered.
    pub listed_candidates: u64,
    /// Probes placed.
    pub placed: u64,
    /// Candidates not placed because they lie inside geometry.
    pub inside_geometry: u64,
    /// Lattice cells cut because the direct light changes across them ([`LIGHT_CHANGE`]).
    pub cells_cut_for_light: u64,
    /// Rays the inside-geometry test and the light's test traced.
    pub rays: u64,
}

/// The probes placed, in file order, and the grid they came from.
#[derive(Clone, Debug)]
pub struct Placement {
    /// Probes in clusters, clusters in Morton order (module docs).
    pub probes: Vec<PlacedProbe>,
    /// The coarse grid (also the listed points' clusters).
    pub grid: CoarseGrid,
    /// What was placed and skipped.
    pub report: PlacementReport,
}

impl Placement {
    /// The probes' clusters: consecutive runs of one cell.
    pub fn clusters(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        let mut start = 0;
        std::iter::from_fn(move || {
            if start >= self.probes.len() {
                return None;
            }
            let key = self.probes[start].cluster;
            let end = self.probes[start..]
                .iter()
                .position(|p| p.cluster != key)
                .map_or(self.probes.len(), |n| start + n);
            let range = start..end;
            start = end;
            Some(range)
        })
    }
}

/// Places probes over the triangles `world` traces (its `corners` given here), bounded by
/// `bounds`; `sides` holds every triangle's seen-side flags ([`SEEN_FRONT`], [`SEEN_BACK`]).
///
/// # Errors
/// A message when the spacing is not positive and finite, or would make more than
/// [`MAX_CELLS`] coarse cells.
pub fn place(
    world: &World,
    corners: &[[Vec3; 3]],
    traced: &[u32],
    sides: &[u32],
    settings: &PlacementSettings,
) -> Result<Placement, String> {
    let (lo, hi) = bounds_of(corners, traced);
    let extent = (hi - lo).max(Vec3::splat(0.0));
    let fine = match settings.spacing {
        Some(d) if d.is_finite() && d > 0.0 => d,
        Some(d) => return Err(format!("the probe spacing {d} must be positive and finite")),
        None => (extent.max_element() / DEFAULT_CELLS).max(1e-3),
    };
    let coarse = fine * (1 << LEVELS) as f32;
    let cells = ((extent + Vec3::splat(fine)) / coarse)
        .ceil()
        .max(Vec3::ONE);
    let count = f64::from(cells.x) * f64::from(cells.y) * f64::from(cells.z);
    if count > MAX_CELLS as f64 {
        return Err(format!(
            "a probe spacing of {fine} makes {count:.0} coarse cells over a level of {:.1} × \
             {:.1} × {:.1} (at most {MAX_CELLS}): give a larger --probe-spacing",
            extent.x, extent.y, extent.z
        ));
    }
    let grid = CoarseGrid {
        origin: lo - Vec3::splat(0.5 * fine),
        fine,
        points: [cells.x as u32 + 1, cells.y as u32 + 1, cells.z as u32 + 1],
    };
    let mut candidates = Vec::new();
    let mut light = LightChange::new(world, &grid, settings.refine_light);
    if settings.lattice {
        candidates = lattice_points(&grid, corners, traced, &mut light);
    }
    let lattice_candidates = candidates.len() as u64;
    for &p in &settings.points {
        let cell = ((p - grid.origin) / coarse).floor();
        candidates.push(PlacedProbe {
            position: p,
            spacing: fine,
            cluster: [cell.x as i32, cell.y as i32, cell.z as i32],
            lattice: None,
        });
    }
    let listed_candidates = settings.points.len() as u64;
    let inside: Vec<bool> = candidates
        .par_iter()
        .map(|c| inside_geometry(world, sides, c.position))
        .collect();
    let mut probes: Vec<PlacedProbe> = candidates
        .into_iter()
        .zip(&inside)
        .filter(|(_, inside)| !**inside)
        .map(|(p, _)| p)
        .collect();
    probes.sort_by_key(|p| {
        let [x, y, z] = p.lattice.unwrap_or([i32::MAX; 3]);
        (morton(p.cluster), p.cluster, x, y, z)
    });
    let inside_geometry = inside.iter().filter(|i| **i).count() as u64;
    let report = PlacementReport {
        lattice_candidates,
        listed_candidates,
        placed: probes.len() as u64,
        inside_geometry,
        cells_cut_for_light: light.cells_cut,
        rays: (inside.len() * INSIDE_RAYS) as u64 + light.rays,
    };
    Ok(Placement {
        probes,
        grid,
        report,
    })
}

/// Most coarse cells a level may have (a spacing too fine for the level is refused).
pub const MAX_CELLS: u64 = 1 << 24;

/// The bounds of the traced triangles (all of `corners` where `traced` is empty).
fn bounds_of(corners: &[[Vec3; 3]], traced: &[u32]) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    let mut grow = |c: &[Vec3; 3]| {
        for v in c {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    };
    if traced.is_empty() {
        corners.iter().for_each(&mut grow);
    } else {
        traced.iter().for_each(|&t| grow(&corners[t as usize]));
    }
    if lo.cmpgt(hi).any() {
        (Vec3::ZERO, Vec3::ZERO)
    } else {
        (lo, hi)
    }
}

/// The lattice's candidate points (module docs): every coarse corner, and the corners of
/// every cell cut to, each with the spacing of its finest cell. A cell is cut into eight where
/// it holds geometry, and where its parent was cut and the direct light changes across the
/// parent's corners ([`LightChange`]).
fn lattice_points(
    grid: &CoarseGrid,
    corners: &[[Vec3; 3]],
    traced: &[u32],
    light: &mut LightChange<'_>,
) -> Vec<PlacedProbe> {
    let fine = grid.fine;
    let limit = grid.points.map(|n| (n as i32 - 1) << LEVELS);
    let coarse_cells = grid.points.map(|n| n as i32 - 1);
    let mut levels: BTreeMap<[i32; 3], u32> = BTreeMap::new();
    for x in 0..grid.points[0] as i32 {
        for y in 0..grid.points[1] as i32 {
            for z in 0..grid.points[2] as i32 {
                levels.insert([x << LEVELS, y << LEVELS, z << LEVELS], LEVELS);
            }
        }
    }
    let held = cells_holding_geometry(grid, corners, traced);
    // The cells of the level above whose corners are probes: every coarse cell at first.
    let mut above: Vec<[i32; 3]> = Vec::new();
    if light.active() {
        for x in 0..coarse_cells[0] {
            for y in 0..coarse_cells[1] {
                for z in 0..coarse_cells[2] {
                    above.push([x, y, z]);
                }
            }
        }
    }
    for level in (0..LEVELS).rev() {
        let mut cut: Vec<[i32; 3]> = held.iter().map(|c| c.map(|v| v >> level)).collect();
        for parent in light.changing(&above, level + 1) {
            for child in 0..8 {
                cut.push([0, 1, 2].map(|a| parent[a] * 2 + ((child >> a) & 1)));
            }
        }
        cut.sort_unstable();
        cut.dedup();
        for &cell in &cut {
            for corner in 0..8 {
                let at = [0, 1, 2].map(|a| (cell[a] + ((corner >> a) & 1)) << level);
                if (0..3).all(|a| at[a] >= 0 && at[a] <= limit[a]) {
                    let l = levels.entry(at).or_insert(level);
                    *l = (*l).min(level);
                }
            }
        }
        above = cut;
    }
    levels
        .into_iter()
        .map(|(at, level)| PlacedProbe {
            position: grid.origin + Vec3::new(at[0] as f32, at[1] as f32, at[2] as f32) * fine,
            spacing: fine * (1 << level) as f32,
            cluster: at.map(|v| v >> LEVELS),
            lattice: Some(at),
        })
        .collect()
}

/// The light's part of placement: a cell is cut where the direct light changes across it —
/// where its corners' unoccluded direct light from the sun and the scene's analytic lights
/// differs by more than [`LIGHT_CHANGE`] of the brightest corner: a shaft of sun through a
/// window, a shadow's edge in open air, the steep fall-off near a lamp. Each lattice point's
/// light is one shadow ray per light towards its centre (deterministic), computed once.
/// Emissive triangles and the sky are not counted (their light changes slowly in open air,
/// and a deterministic estimate of an area light would need many rays a point).
struct LightChange<'a> {
    world: &'a World,
    grid: CoarseGrid,
    /// Off for `--refine geometry`, and where the scene has no analytic light.
    on: bool,
    /// Each evaluated lattice point's direct light (luminance), by fine lattice coordinates.
    known: BTreeMap<[i32; 3], f32>,
    /// Cells cut because the light changes across them.
    cells_cut: u64,
    /// Shadow rays traced.
    rays: u64,
}

/// A cell is cut where its darkest corner's direct light is below (1 − this) of its
/// brightest's: half.
pub const LIGHT_CHANGE: f32 = 0.5;

impl<'a> LightChange<'a> {
    fn new(world: &'a World, grid: &CoarseGrid, refine_light: bool) -> Self {
        LightChange {
            world,
            grid: *grid,
            on: refine_light && !world.lights().is_empty(),
            known: BTreeMap::new(),
            cells_cut: 0,
            rays: 0,
        }
    }

    fn active(&self) -> bool {
        self.on
    }

    /// The cells of `cells` (of level `level`: 2^level fine cells wide) across whose corners
    /// the direct light changes.
    fn changing(&mut self, cells: &[[i32; 3]], level: u32) -> Vec<[i32; 3]> {
        if !self.on || cells.is_empty() {
            return Vec::new();
        }
        let corner =
            |cell: [i32; 3], c: i32| [0, 1, 2].map(|a| (cell[a] + ((c >> a) & 1)) << level);
        let mut needed: Vec<[i32; 3]> = cells
            .iter()
            .flat_map(|&cell| (0..8).map(move |c| corner(cell, c)))
            .filter(|at| !self.known.contains_key(at))
            .collect();
        needed.sort_unstable();
        needed.dedup();
        let values: Vec<(f32, u64)> = needed
            .par_iter()
            .map(|at| {
                let p = self.grid.origin
                    + Vec3::new(at[0] as f32, at[1] as f32, at[2] as f32) * self.grid.fine;
                direct_light(self.world, p)
            })
            .collect();
        for (at, (value, rays)) in needed.into_iter().zip(values) {
            self.known.insert(at, value);
            self.rays += rays;
        }
        let out: Vec<[i32; 3]> = cells
            .iter()
            .copied()
            .filter(|&cell| {
                let (lo, hi) = (0..8).fold((f32::INFINITY, 0.0f32), |(lo, hi), c| {
                    let v = self.known[&corner(cell, c)];
                    (lo.min(v), hi.max(v))
                });
                hi > 0.0 && lo < (1.0 - LIGHT_CHANGE) * hi
            })
            .collect();
        self.cells_cut += out.len() as u64;
        out
    }
}

/// The unoccluded direct light at `p` from the world's analytic lights (luminance of each
/// light's irradiance on a plane facing it, one shadow ray to its centre), and the rays traced.
fn direct_light(world: &World, p: Vec3) -> (f32, u64) {
    let view = world.wide_bvh();
    let mut sum = 0.0;
    let mut rays = 0;
    for light in world.lights() {
        let axis = light_axis(light, p);
        if axis == Vec3::ZERO {
            continue;
        }
        let Some((_, value)) = light_sample_at(&view, light, p, axis, [0.5, 0.5]) else {
            continue;
        };
        rays += 1;
        if let Some(value) = value {
            let value = luminance_f32(value.to_array());
            if value.is_finite() {
                sum += value;
            }
        }
    }
    (sum, rays)
}

/// The fine cells within half a fine cell of a traced triangle (by the distance from the
/// cell's centre to the triangle against its half-diagonal: a few more than touch it),
/// sorted.
fn cells_holding_geometry(
    grid: &CoarseGrid,
    corners: &[[Vec3; 3]],
    traced: &[u32],
) -> Vec<[i32; 3]> {
    let fine = grid.fine;
    let reach = fine * (0.5 + 0.5 * 3f32.sqrt());
    let limit = grid.points.map(|n| ((n as i32 - 1) << LEVELS) - 1);
    let ids: Vec<u32> = if traced.is_empty() {
        (0..corners.len() as u32).collect()
    } else {
        traced.to_vec()
    };
    let mut cells: Vec<[i32; 3]> = ids
        .par_iter()
        .flat_map_iter(|&t| {
            let [a, b, c] = corners[t as usize];
            let lo = ((a.min(b).min(c) - Vec3::splat(reach) - grid.origin) / fine).floor();
            let hi = ((a.max(b).max(c) + Vec3::splat(reach) - grid.origin) / fine).floor();
            let lo = [lo.x, lo.y, lo.z].map(|v| v.max(0.0) as i32);
            let hi = [hi.x, hi.y, hi.z];
            let hi = [0, 1, 2].map(|i| (hi[i].max(0.0) as i32).min(limit[i]));
            let mut out = Vec::new();
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        let centre =
                            grid.origin + (Vec3::new(x as f32, y as f32, z as f32) + 0.5) * fine;
                        let near = closest_point_on_triangle(centre, a, b, c);
                        if near.distance(centre) <= reach {
                            out.push([x, y, z]);
                        }
                    }
                }
            }
            out
        })
        .collect();
    cells.par_sort_unstable();
    cells.dedup();
    cells
}

/// Whether `p` lies inside geometry: more than [`INSIDE_SHARE`] of 64 rays over the sphere
/// meet a side no open space faces (module docs).
#[must_use]
pub fn inside_geometry(world: &World, sides: &[u32], p: Vec3) -> bool {
    let view = world.wide_bvh();
    let mut unseen = 0;
    for packet in 0..INSIDE_RAYS / 8 {
        let dirs: [Vec3; 8] = std::array::from_fn(|l| fibonacci_sphere(packet * 8 + l));
        let rays = Ray8::from_origin(p, &dirs, 0.0, f32::INFINITY);
        let mut hits = Hit8::NONE;
        intersect8(&view, &rays, &mut hits);
        for (lane, &prim) in hits.prim.to_array().iter().enumerate() {
            if prim == NO_HIT {
                continue;
            }
            let front = world.surfaces()[prim as usize].normal.dot(dirs[lane]) < 0.0;
            let flag = if front { SEEN_FRONT } else { SEEN_BACK };
            unseen += u32::from(sides.get(prim as usize).is_none_or(|s| s & flag == 0));
        }
    }
    unseen as f32 > INSIDE_SHARE * INSIDE_RAYS as f32
}

/// Direction `i` of [`INSIDE_RAYS`] spread evenly over the sphere (a Fibonacci lattice).
fn fibonacci_sphere(i: usize) -> Vec3 {
    let z = 1.0 - 2.0 * (i as f32 + 0.5) / INSIDE_RAYS as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = i as f32 * 2.399_963;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// The Morton code of a coarse cell (its coordinates made non-negative), so neighbouring
/// clusters are baked, and written, near each other.
fn morton(c: [i32; 3]) -> u64 {
    let spread = |v: i32| {
        let mut x = u64::from((v as i64 + (1 << 20)).clamp(0, (1 << 21) - 1) as u32);
        x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
        x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
        x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
        x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
        (x | (x << 2)) & 0x1249_2492_4924_9249
    };
    spread(c[0]) | (spread(c[1]) << 1) | (spread(c[2]) << 2)
}

/// Reads a list of probe positions: one point a line, `x y z` or `x, y, z`; blank lines and
/// `#` comments are skipped.
///
/// # Errors
/// A message naming the file and the line that is not three finite numbers, or why the
/// file cannot be read.
pub fn read_points(path: &Path) -> Result<Vec<Vec3>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read the probe points: {e}", path.display()))?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let values: Vec<f32> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|_| {
                format!(
                    "{}:{}: `{line}` is not a point: three numbers, `x y z` or `x, y, z`",
                    path.display(),
                    n + 1
                )
            })?;
        match values[..] {
            [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => {
                points.push(Vec3::new(x, y, z));
            }
            _ => {
                return Err(format!(
                    "{}:{}: `{line}` is not a point: three finite numbers, `x y z` or `x, y, z`",
                    path.display(),
                    n + 1
                ));
            }
        }
    }
    if points.is_empty() {
        return Err(format!("{}: lists no probe points", path.display()));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::Preset;
    use crate::prepare::facing::seen_sides;
    use crate::scene::{Scene, Sky, Sun};
    use crate::test_support::{grey_and_lamp, outward_box_faces, quad};

    /// A 10 m floor under a constant sky with a solid 2 m block on it.
    fn yard() -> Scene {
        let mut triangles = quad(
            Vec3::new(-5.0, 0.0, 5.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -10.0),
            0,
        )
        .to_vec();
        for (o, u, v) in outward_box_faces(Vec3::new(-1.0, 0.0, -1.0), Vec3::splat(2.0)) {
            triangles.extend(quad(o, u, v, 0));
        }
        let mut scene = Scene::of_triangles("yard", triangles, grey_and_lamp(0.5, 0.0));
        scene.sky = Sky::Constant(Vec3::ONE);
        scene
    }

    fn inside_block(p: Vec3) -> bool {
        p.cmpgt(Vec3::new(-1.0, 0.0, -1.0)).all() && p.cmplt(Vec3::new(1.0, 2.0, 1.0)).all()
    }

    /// Below the floor, within its edges (a probe just beyond its edge stands in open air).
    fn under_floor(p: Vec3) -> bool {
        p.y < 0.0 && p.x.abs() < 5.0 && p.z.abs() < 5.0
    }

    /// No probe is placed inside the block or under the floor, and those candidates are
    /// counted; probes stand near the geometry at the finest spacing and farther apart
    /// above it; a listed point inside the block is skipped, one outside kept.
    #[test]
    fn probes_inside_geometry_are_not_placed() {
        let scene = yard();
        let (visibility, _) = seen_sides(&scene).unwrap();
        let world = World::new(&scene, Preset::DEFAULT).unwrap();
        let corners = scene.triangle_positions();
        let settings = PlacementSettings {
            spacing: Some(0.25),
            points: vec![Vec3::new(0.0, 1.0, 0.0), Vec3::new(3.0, 1.0, 3.0)],
            lattice: true,
            refine_light: true,
        };
        let placed = place(&world, &corners, &[], visibility.sides(), &settings).unwrap();
        let r = placed.report;
        assert_eq!(r.listed_candidates, 2);
        assert!(r.inside_geometry > 0 && r.placed > 0, "{r:?}");
        assert_eq!(r.placed + r.inside_geometry, r.lattice_candidates + 2);
        let wrong: Vec<_> = placed
            .probes
            .iter()
            .filter(|p| inside_block(p.position) || under_floor(p.position))
            .map(|p| p.position)
            .collect();
        assert!(
            wrong.is_empty(),
            "{} placed inside: {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(12)]
        );
        let listed: Vec<_> = placed
            .probes
            .iter()
            .filter(|p| p.lattice.is_none())
            .collect();
        assert_eq!(listed.len(), 1);
        assert_eq!(listed[0].position, Vec3::new(3.0, 1.0, 3.0));
        let spacing_near = |y: f32| {
            placed
                .probes
                .iter()
                .filter(|p| (p.position.y - y).abs() < 0.01)
                .map(|p| p.spacing)
                .fold(f32::INFINITY, f32::min)
        };
        assert_eq!(spacing_near(0.125), 0.25);
        assert_eq!(
            placed.probes.iter().map(|p| p.spacing).fold(0.0, f32::max),
            1.0
        );
        // Clusters: runs of one coarse cell, at most 4³ probes.
        let mut seen = std::collections::HashSet::new();
        for c in placed.clusters() {
            assert!(c.len() <= 64 + 2);
            assert!(
                seen.insert(placed.probes[c.start].cluster),
                "a cell split in two runs"
            );
        }
    }

    /// A hall 20 m square under a roof 12 m up with a 4 m hole in its middle, the sun
    /// straight above (or none).
    fn hall(sun: bool) -> Scene {
        let mut triangles = quad(
            Vec3::new(-10.0, 0.0, 10.0),
            Vec3::new(20.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -20.0),
            0,
        )
        .to_vec();
        for (o, u, v) in [
            ((-10.0, -10.0), (8.0, 0.0), (0.0, 20.0)),
            ((2.0, -10.0), (8.0, 0.0), (0.0, 20.0)),
            ((-2.0, -10.0), (4.0, 0.0), (0.0, 8.0)),
            ((-2.0, 2.0), (4.0, 0.0), (0.0, 8.0)),
        ] {
            triangles.extend(quad(
                Vec3::new(o.0, 12.0, o.1),
                Vec3::new(u.0, 0.0, u.1),
                Vec3::new(v.0, 0.0, v.1),
                0,
            ));
        }
        let mut scene = Scene::of_triangles("hall", triangles, grey_and_lamp(0.5, 0.0));
        scene.sky = Sky::Constant(Vec3::ONE);
        scene.sun = sun.then(|| Sun {
            direction: Vec3::Y,
            angular_radius: 0.00465,
            irradiance: Vec3::splat(3.0),
        });
        scene
    }

    fn place_in(scene: &Scene, refine_light: bool) -> Placement {
        let (visibility, _) = seen_sides(scene).unwrap();
        let world = World::new(scene, Preset::DEFAULT).unwrap();
        let settings = PlacementSettings {
            spacing: Some(1.0),
            lattice: true,
            refine_light,
            ..PlacementSettings::default()
        };
        place(
            &world,
            &scene.triangle_positions(),
            &[],
            visibility.sides(),
            &settings,
        )
        .unwrap()
    }

    /// The shaft of sun through the roof's hole is refined in the open air, where no geometry
    /// cuts a cell: probes at the finest spacing stand along its edges, and none where the light
    /// is the same across a cell (the shadow between the shaft and the roof's edge); without
    /// `--refine light`, or without a sun, the open air keeps the coarse spacing.
    #[test]
    fn probes_are_finer_where_the_light_changes_in_open_air() {
        // Between the coarse lattice planes y = 3.5 and 7.5 no geometry lies within reach.
        let in_air = |p: &PlacedProbe| p.position.y > 3.6 && p.position.y < 7.4;
        let refined = place_in(&hall(true), true);
        assert!(
            refined.report.cells_cut_for_light > 0,
            "{:?}",
            refined.report
        );
        let air: Vec<&PlacedProbe> = refined.probes.iter().filter(|p| in_air(p)).collect();
        assert!(
            air.iter().any(|p| p.spacing == 1.0
                && (p.position.x.abs() - 2.0).abs() < 1.0
                && p.position.z.abs() < 2.0),
            "no fine probe at the shaft's edge: {:?}",
            air.iter()
                .map(|p| (p.position, p.spacing))
                .collect::<Vec<_>>()
        );
        let shadowed = |v: f32| v > -6.5 && v < -2.5;
        assert!(
            !air.iter()
                .any(|p| shadowed(p.position.x) && shadowed(p.position.z)),
            "a probe where the light does not change"
        );
        assert!(refined.report.rays > refined.report.lattice_candidates * INSIDE_RAYS as u64);
        let one_thread = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| place_in(&hall(true), true));
        assert_eq!(
            one_thread.probes, refined.probes,
            "the same on any thread count"
        );

        let coarse = place_in(&hall(true), false);
        assert_eq!(coarse.report.cells_cut_for_light, 0);
        assert!(
            !coarse.probes.iter().any(in_air),
            "geometry alone cuts no open air"
        );
        assert!(coarse.report.placed < refined.report.placed);
        let sunless = place_in(&hall(false), true);
        assert_eq!(
            sunless.probes, coarse.probes,
            "no analytic light: nothing to refine for"
        );
        assert_eq!(sunless.report.cells_cut_for_light, 0);
    }

    /// A spacing the level cannot take is refused with a message; a points file is read
    /// line by line and a bad line named.
    #[test]
    fn bad_spacings_and_points_are_refused_with_a_message() {
        let scene = yard();
        let world = World::new(&scene, Preset::DEFAULT).unwrap();
        let corners = scene.triangle_positions();
        let sides = vec![SEEN_FRONT; corners.len()];
        for (spacing, says) in [
            (0.0, "positive and finite"),
            (1e-4, "larger --probe-spacing"),
        ] {
            let settings = PlacementSettings {
                spacing: Some(spacing),
                lattice: true,
                ..PlacementSettings::default()
            };
            let e = place(&world, &corners, &[], &sides, &settings).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
        let dir = std::env::temp_dir().join(format!("gb-points-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.txt");
        std::fs::write(&good, "# probes\n1 2 3\n\n4, 5, 6 # a comment\n").unwrap();
        assert_eq!(
            read_points(&good).unwrap(),
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)]
        );
        let bad = dir.join("bad.txt");
        std::fs::write(&bad, "1 2 3\n1 2\n").unwrap();
        let e = read_points(&bad).unwrap_err();
        assert!(e.contains("bad.txt:2") && e.contains("`1 2`"), "{e}");
        std::fs::write(&bad, "1 2 nan\n").unwrap();
        assert!(read_points(&bad).unwrap_err().contains("finite"));
        std::fs::write(&bad, "# nothing\n").unwrap();
        assert!(
            read_points(&bad)
                .unwrap_err()
                .contains("lists no probe points")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
