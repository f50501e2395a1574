//! Why a level is dark: a shell that keeps the sun and sky out (docs/levels.md, "Roles: sky
//! shells, clip brushes and caulk").
//!
//! Cube 2, Quake-family and many other engines wrap the playable space in a world-sized shell
//! they draw as sky. Baked as it comes, that shell is a wall: no sun or sky reaches inside,
//! the level bakes black, and the shell's outside — which no player sees — takes the atlas.
//! [`find_shell`] tells that case from a level that is simply dark, from the light the
//! facing analysis already traced ([`Visibility::side_light`]):
//!
//! 1. **Who sees the sky.** The surfaces the sun or the sky above reach directly, by area,
//!    grouped by material and by mesh. The fewest groups (at most [`MAX_GROUPS`]) that hold
//!    [`SKY_COVER`] of that area are the candidate, in the grouping that names fewer
//!    triangles.
//! 2. **The rest is dark.** Of the other surfaces with texels, less than [`REST_LIT`] of the
//!    area gets any light at all. (Their share of the area does not matter: a level's shell
//!    may well be larger than the level.)
//! 3. **Opened, light comes in.** Rays from the rest ([`PROBES`] triangles at most, both
//!    sides, one packet each) traced with the candidate left out reach the sky above at
//!    least [`OPENED_SKY`] of the time.
//!
//! Then the candidate closes the level, and `prepare` names it, says what its outside costs in
//! texels, and suggests the role that opens it (`--role sky=…`, `scene::roles`).

use glam::Vec3;
use guidebake_kernels::packet::{NO_HIT, offset_origin, triangle_extent};

use super::facing::{Visibility, trace_cosine};
use crate::bvh::{Bvh, BvhError, Preset};
use crate::scene::{Scene, ids_where};

/// Share of the directly lit area the candidate groups must hold.
pub const SKY_COVER: f64 = 0.99;
/// Most groups a candidate shell is made of (a box of six meshes fits).
pub const MAX_GROUPS: usize = 8;
/// The rest is dark when less than this share of its area gets any light.
pub const REST_LIT: f64 = 0.02;
/// The candidate closes the level when, left out, this share of the rest's rays reach the
/// sky above.
pub const OPENED_SKY: f64 = 0.02;
/// Triangles of the rest the opening test traces from, at most.
pub const PROBES: usize = 4096;

/// How a shell is named: by its materials or by its meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ShellBy {
    /// Material names.
    Material,
    /// Mesh names.
    Mesh,
}

/// A shell found around a level ([`find_shell`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Shell {
    /// Whether [`Shell::names`] are materials or meshes.
    pub by: ShellBy,
    /// The materials or meshes that close the level.
    pub names: Vec<String>,
    /// Their triangles.
    pub triangles: u64,
    /// The share of the rest of the level's area (the surfaces with texels not in the shell)
    /// that receives no light at all.
    pub dark_share: f64,
    /// The share of the rest's rays that reach the sky above with the shell left out.
    pub opened_sky_share: f64,
    /// Texels on the shell, and in all (filled in once the atlas is rasterised).
    pub texels: u64,
    /// Texels of the whole atlas.
    pub atlas_texels: u64,
    /// Per triangle of the scene: part of the shell.
    #[serde(skip)]
    pub mask: Vec<bool>,
}

impl Shell {
    /// The `--role` that opens it, to print: `sky=material:NAME` (one name), else a rule per
    /// name.
    #[must_use]
    pub fn suggested_roles(&self) -> Vec<String> {
        let kind = match self.by {
            ShellBy::Material => "material",
            ShellBy::Mesh => "mesh",
        };
        self.names
            .iter()
            .map(|n| format!("--role 'sky={kind}:{n}'"))
            .collect()
    }
}

/// The shell that closes `scene` (module docs), if one does; `visibility` is what
/// [`super::facing::seen_sides`] decided for it.
///
/// # Errors
/// [`BvhError`] when the tree without the candidate cannot be built.
pub fn find_shell(scene: &Scene, visibility: &Visibility) -> Result<Option<Shell>, BvhError> {
    if !scene.lit_from_outside() {
        return Ok(None);
    }
    let n = scene.triangles.len();
    let area: Vec<f64> = scene
        .triangles
        .iter()
        .map(|t| f64::from(t.area()))
        .collect();
    let sky_lit = |t: usize| {
        let [f, b] = visibility.side_light(t);
        scene.role(t).traced() && f.direct.max(b.direct) > 0.0
    };
    let by_material = candidate(scene, &area, &sky_lit, |t| {
        scene.triangles[t].material as usize
    });
    let by_mesh = candidate(scene, &area, &sky_lit, |t| scene.triangles[t].mesh as usize);
    let count = |m: &Option<Vec<bool>>| {
        m.as_ref()
            .map_or(usize::MAX, |m| m.iter().filter(|&&x| x).count())
    };
    let (by, mask) = if count(&by_material) <= count(&by_mesh) {
        (ShellBy::Material, by_material)
    } else {
        (ShellBy::Mesh, by_mesh)
    };
    let Some(mask) = mask else {
        return Ok(None);
    };
    let rest: Vec<usize> = (0..n)
        .filter(|&t| !mask[t] && scene.role(t).has_texels() && area[t] > 0.0)
        .collect();
    let rest_area: f64 = rest.iter().map(|&t| area[t]).sum();
    let rest_lit: f64 = rest
        .iter()
        .filter(|&&t| {
            let [f, b] = visibility.side_light(t);
            f.total.max(b.total) > 0.0
        })
        .map(|&t| area[t])
        .sum();
    if rest_area <= 0.0 || rest_lit >= REST_LIT * rest_area {
        return Ok(None);
    }
    let opened = opened_sky_share(scene, &mask, &rest)?;
    if opened < OPENED_SKY {
        return Ok(None);
    }
    let names = names_of(scene, &mask, by);
    Ok(Some(Shell {
        by,
        names,
        triangles: mask.iter().filter(|&&m| m).count() as u64,
        dark_share: 1.0 - rest_lit / rest_area,
        opened_sky_share: opened,
        texels: 0,
        atlas_texels: 0,
        mask,
    }))
}

/// The triangles of the fewest groups (`group` of a triangle) that hold [`SKY_COVER`] of the
/// directly lit area, at most [`MAX_GROUPS`] of them; `None` when nothing is lit directly or
/// more groups are needed.
fn candidate(
    scene: &Scene,
    area: &[f64],
    sky_lit: &dyn Fn(usize) -> bool,
    group: impl Fn(usize) -> usize,
) -> Option<Vec<bool>> {
    let n = scene.triangles.len();
    let groups = (0..n).map(&group).max()? + 1;
    let mut lit = vec![0.0f64; groups];
    for t in (0..n).filter(|&t| sky_lit(t)) {
        lit[group(t)] += area[t];
    }
    let all: f64 = lit.iter().sum();
    if all <= 0.0 {
        return None;
    }
    let mut order: Vec<usize> = (0..groups).filter(|&g| lit[g] > 0.0).collect();
    order.sort_by(|&a, &b| lit[b].total_cmp(&lit[a]).then(a.cmp(&b)));
    let mut chosen = vec![false; groups];
    let mut covered = 0.0;
    for &g in order.iter().take(MAX_GROUPS) {
        chosen[g] = true;
        covered += lit[g];
        if covered >= SKY_COVER * all {
            return Some((0..n).map(|t| chosen[group(t)]).collect());
        }
    }
    None
}

/// The share of rays from the `rest` triangles (both sides of up to [`PROBES`] of them, one
/// cosine packet each from the centroid) that reach the sky above once the `shell` is left
/// out of the tree.
fn opened_sky_share(scene: &Scene, shell: &[bool], rest: &[usize]) -> Result<f64, BvhError> {
    let corners = scene.triangle_positions();
    let kept = ids_where(corners.len(), |t| !shell[t] && scene.role(t).traced());
    let bvh = Bvh::build_over(&corners, kept.as_deref(), Preset::FastBuild)?;
    let view = bvh.wide();
    let step = rest.len().div_ceil(PROBES).max(1);
    let (mut sky, mut rays) = (0u64, 0u64);
    for (k, &t) in rest.iter().step_by(step).enumerate() {
        let c = &corners[t];
        let g = scene.triangles[t].geometric_normal();
        let p = (c[0] + c[1] + c[2]) / 3.0;
        for n in [g, -g] {
            let origin = offset_origin(p, n, triangle_extent(p, c));
            let (dirs, hits) = trace_cosine(&view, origin, n, k);
            for (lane, &u) in hits.prim.to_array().iter().enumerate() {
                sky += u64::from(u == NO_HIT && dirs[lane].dot(Vec3::Y) > 0.0);
            }
            rays += dirs.len() as u64;
        }
    }
    Ok(sky as f64 / rays.max(1) as f64)
}

/// The names of the materials or meshes (`by`) of the `shell` triangles, in file order.
fn names_of(scene: &Scene, shell: &[bool], by: ShellBy) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for (_, tri) in scene
        .triangles
        .iter()
        .enumerate()
        .filter(|&(t, _)| shell[t])
    {
        let name = match by {
            ShellBy::Material => &scene.materials[tri.material as usize].name,
            ShellBy::Mesh => &scene.meshes[tri.mesh as usize].name,
        };
        if !names.contains(name) {
            names.push(name.clone());
        }
    }
    names
}
