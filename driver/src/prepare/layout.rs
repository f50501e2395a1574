//! Where every mesh's texels go (step 1 of [`super`]'s list): the shared layout of one
//! atlas, the per-mesh layout of UV squares packed onto pages at a texel density, and the
//! layout of meshes xatlas unwrapped ([`super::unwrap`]), their atlas packed onto pages with
//! the other meshes' squares; one packer places all of them ([`super::pack`]). And the
//! density or page size that would fit when nothing does.

use glam::Vec2;

use crate::scene::Scene;
use crate::texels::{PageRecord, TILE_SIZE};

use super::pack::{Place, pack_rects};
use super::*;

/// Where a mesh's lightmap UVs land on the atlas: `pixel = uv · uv_scale + uv_offset` on
/// `page` (continuous pixel coordinates). Each triangle's result is what the texel file's
/// triangle table holds ([`TriangleRecord`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct MeshLayout {
    /// Atlas page.
    pub(super) page: u32,
    /// 1 when the mesh has lightmap UVs (and texels), else 0.
    pub(super) flags: u32,
    /// UV → pixel scale.
    pub(super) uv_scale: [f32; 2],
    /// UV → pixel offset.
    pub(super) uv_offset: [f32; 2],
}

/// Per-mesh UV statistics.
#[derive(Clone, Copy, Debug)]
pub(super) struct MeshUv {
    world_area: f64,
    uv_area: f64,
    lo: Vec2,
    hi: Vec2,
}

pub(super) fn uv_area(uv: &[Vec2; 3]) -> f32 {
    0.5 * (uv[1] - uv[0]).perp_dot(uv[2] - uv[0])
}

pub(super) fn mesh_uv_stats(scene: &Scene) -> Vec<Option<MeshUv>> {
    let mut out: Vec<Option<MeshUv>> = vec![None; scene.meshes.len()];
    for (i, t) in scene.triangles.iter().enumerate() {
        let Some(uv) = t.lightmap_uv.filter(|_| scene.role(i).has_texels()) else {
            continue;
        };
        let s = out[t.mesh as usize].get_or_insert(MeshUv {
            world_area: 0.0,
            uv_area: 0.0,
            lo: Vec2::splat(f32::INFINITY),
            hi: Vec2::splat(f32::NEG_INFINITY),
        });
        s.world_area += f64::from(t.area());
        s.uv_area += f64::from(uv_area(&uv).abs());
        for v in uv {
            s.lo = s.lo.min(v);
            s.hi = s.hi.max(v);
        }
    }
    out
}

pub(super) fn shared_layout(
    scene: &Scene,
    stats: &[Option<MeshUv>],
    res: Resolution,
) -> Result<(Vec<PageRecord>, Vec<MeshLayout>, f32), PrepareError> {
    let (wa, ua) = stats
        .iter()
        .flatten()
        .fold((0.0, 0.0), |a, s| (a.0 + s.world_area, a.1 + s.uv_area));
    let density = (wa / ua.max(1e-30)).sqrt(); // world units per UV unit
    let (w, h) = match res {
        Resolution::Size(w, h) => (w, h),
        Resolution::Default => (DEFAULT_PAGE, DEFAULT_PAGE),
        Resolution::TexelsPerUnit(d) => {
            let side = (f64::from(d) * density).ceil();
            check_side(scene, side)?;
            (side as u32, side as u32)
        }
    };
    check_side(scene, f64::from(w.max(h)))?;
    let tpu = (f64::from(w).min(f64::from(h)) / density) as f32;
    let page = PageRecord {
        width: w,
        height: h,
    };
    let meshes = stats
        .iter()
        .map(|s| MeshLayout {
            page: 0,
            flags: u32::from(s.is_some()),
            uv_scale: [w as f32, h as f32],
            uv_offset: [0.0; 2],
        })
        .collect();
    Ok((vec![page], meshes, tpu))
}

pub(super) fn check_side(scene: &Scene, side: f64) -> Result<(), PrepareError> {
    if !(1.0..=f64::from(MAX_PAGE)).contains(&side) {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!(
                "a page of {side} texels is outside 1..={MAX_PAGE}; choose a smaller --texels-per-unit or --size"
            ),
        });
    }
    Ok(())
}

/// Edge in texels of the square that holds mesh `s`'s own UVs at density `d`.
pub(super) fn cell_side(s: &MeshUv, d: f64) -> f64 {
    let ext = f64::from((s.hi - s.lo).max_element().max(1e-12));
    // The UV bounding square scaled to `side` texels holds uv_area·side²/ext² texels.
    d * (s.world_area / s.uv_area.max(1e-30)).sqrt() * ext
}

/// Cell edge of each mesh at density `d`, `None` for meshes without UVs; clamped to what a
/// page of edge `max` holds (an asked-for density is checked first, by [`check_cells`]).
pub(super) fn cells(stats: &[Option<MeshUv>], d: f64, max: u32) -> Vec<Option<u32>> {
    stats
        .iter()
        .map(|s| s.map(|s| (cell_side(&s, d).ceil() as u32).clamp(2, max - 2 * GUTTER)))
        .collect()
}

/// Refuses an asked-for density at which a mesh's own UVs need a square larger than a page of
/// edge `max`: [`cells`] would clamp it and bake that mesh at a lower density than asked,
/// silently — and at `--texels-per-unit 1e30` fill a 4096² page per mesh.
pub(super) fn check_cells(
    scene: &Scene,
    stats: &[Option<MeshUv>],
    d: f64,
    max: u32,
) -> Result<(), PrepareError> {
    if !(d.is_finite() && d > 0.0) {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!("{d} texels/unit is not a positive density"),
        });
    }
    let room = f64::from(max - 2 * GUTTER);
    for (mesh, s) in scene.meshes.iter().zip(stats) {
        let Some(s) = s else { continue };
        let side = cell_side(s, d);
        if side.is_nan() || side > room {
            return Err(PrepareError::Resolution {
                path: scene.path.clone(),
                message: format!(
                    "mesh '{}' needs a square of {side:.4e} texels at {d:.4e} texels/unit, more than a page of {max}x{max}; --texels-per-unit {:.4} or less fits",
                    mesh.name,
                    0.95 * d * room / side
                ),
            });
        }
    }
    Ok(())
}

pub(super) fn per_mesh_layout(
    scene: &Scene,
    stats: &[Option<MeshUv>],
    res: Resolution,
) -> Result<(Vec<PageRecord>, Vec<MeshLayout>, f32), PrepareError> {
    let sum_ratio: f64 = stats
        .iter()
        .flatten()
        .map(|s| s.world_area / s.uv_area.max(1e-30))
        .sum();
    let (mut d, page, one_page) = match res {
        Resolution::TexelsPerUnit(d) => (f64::from(d), (PACK_PAGE, PACK_PAGE), false),
        Resolution::Default => (
            f64::from(DEFAULT_PAGE) / sum_ratio.sqrt(),
            (PACK_PAGE, PACK_PAGE),
            false,
        ),
        Resolution::Size(w, h) => (f64::from(w.min(h)) / sum_ratio.sqrt(), (w, h), true),
    };
    check_side(scene, f64::from(page.0.max(page.1)))?;
    if page.0.min(page.1) <= 2 * GUTTER + 2 {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!("page {}x{} is too small to pack meshes", page.0, page.1),
        });
    }
    let max = page.0.min(page.1);
    if let Resolution::TexelsPerUnit(_) = res {
        check_cells(scene, stats, d, max)?;
    }
    let (places, cs, n) = loop {
        let cs = cells(stats, d, max);
        let squares: Vec<_> = cs.iter().map(|c| c.map(|c| (c, c))).collect();
        let (places, n) = pack_rects(&squares, GUTTER, page, !one_page);
        if !one_page || n == 1 || d < 1e-9 {
            break (places, cs, n);
        }
        d *= 0.95;
    };
    if n > 4096 {
        return Err(PrepareError::Resolution {
            path: scene.path.clone(),
            message: format!(
                "{n} pages needed at {d:.4} texels/unit; --texels-per-unit {:.4} or less fits 4096",
                fitting_density(d, n)
            ),
        });
    }
    let meshes = (0..scene.meshes.len())
        .map(|i| {
            let (page, scale, offset) = match (places[i], cs[i], stats[i]) {
                (Some((p, x, y)), Some(c), Some(s)) => {
                    let k = c as f32 / (s.hi - s.lo).max_element().max(1e-12);
                    (p, [k, k], [x as f32 - s.lo.x * k, y as f32 - s.lo.y * k])
                }
                _ => (0, [0.0; 2], [0.0; 2]),
            };
            MeshLayout {
                page,
                flags: u32::from(stats[i].is_some()),
                uv_scale: scale,
                uv_offset: offset,
            }
        })
        .collect();
    // Without --size, a single page shrinks to what the packing used (32-texel multiples).
    let used = if one_page || n > 1 {
        page
    } else {
        let extent = |f: fn(&(u32, u32, u32), u32) -> u32| {
            places
                .iter()
                .zip(&cs)
                .filter_map(|(p, c)| Some(f(&(*p)?, (*c)?)))
                .max()
                .unwrap_or(1)
        };
        let w = extent(|p, c| p.1 + c + GUTTER)
            .next_multiple_of(TILE_SIZE)
            .min(page.0);
        let h = extent(|p, c| p.2 + c + GUTTER)
            .next_multiple_of(TILE_SIZE)
            .min(page.1);
        (w, h)
    };
    let pages = vec![
        PageRecord {
            width: used.0,
            height: used.1
        };
        n as usize
    ];
    Ok((pages, meshes, d as f32))
}

/// Share of a page the charts are taken to fill when `prepare` derives the density of an
/// unwrap from a page budget (xatlas's own estimate takes 0.75; the padding of many small
/// charts costs more).
pub(super) const UNWRAP_FILL: f64 = 0.6;

/// The scene with page UVs on every triangle that gets texels, its layout records, the
/// density, and what the unwrapper did.
pub(super) type Unwrapped = (Scene, Vec<PageRecord>, Vec<MeshLayout>, f32, UnwrapReport);

/// Unwraps the `selected` meshes with xatlas into one atlas (one per mesh when one would
/// not fit a page), packs it with the other meshes' UV squares ([`cells`]) onto pages, and
/// returns the scene with every triangle's UVs rewritten as page UVs.
pub(super) fn unwrap_layout(
    scene: &Scene,
    res: Resolution,
    selected: &[bool],
) -> Result<Unwrapped, PrepareError> {
    let stats = mesh_uv_stats(scene);
    let kept: Vec<Option<MeshUv>> = stats
        .iter()
        .zip(selected)
        .map(|(s, &u)| if u { None } else { *s })
        .collect();
    let to_unwrap: Vec<usize> = (0..selected.len()).filter(|&i| selected[i]).collect();
    let area: f64 = scene
        .triangles
        .iter()
        .enumerate()
        .filter(|&(i, t)| {
            (selected[t.mesh as usize] || kept[t.mesh as usize].is_some())
                && scene.role(i).has_texels()
        })
        .map(|(_, t)| f64::from(t.area()))
        .sum();
    let resolution_error = |message: String| PrepareError::Resolution {
        path: scene.path.clone(),
        message,
    };
    let (page, one_page) = match res {
        Resolution::Size(w, h) => ((w, h), true),
        _ => ((PACK_PAGE, PACK_PAGE), false),
    };
    check_side(scene, f64::from(page.0.max(page.1)))?;
    if page.0.min(page.1) <= 2 * GUTTER + 2 * unwrap::PADDING + 2 {
        return Err(resolution_error(format!(
            "page {}x{} is too small to pack charts",
            page.0, page.1
        )));
    }
    let mut d = match res {
        Resolution::TexelsPerUnit(d) => f64::from(d),
        Resolution::Default => f64::from(DEFAULT_PAGE) * (UNWRAP_FILL / area).sqrt(),
        Resolution::Size(w, h) => (f64::from(w) * f64::from(h) * UNWRAP_FILL / area).sqrt(),
    };
    let max_texels = 4096.0 * f64::from(PACK_PAGE) * f64::from(PACK_PAGE);
    if !(d.is_finite() && d > 0.0) || area * d * d / UNWRAP_FILL > max_texels {
        return Err(resolution_error(format!(
            "{:.3e} m² at {d} texels/unit needs more than 4096 pages of {PACK_PAGE}²; --texels-per-unit {:.4} or less fits",
            area,
            0.95 * (max_texels * UNWRAP_FILL / area).sqrt()
        )));
    }
    let max = page.0.min(page.1) - 2 * GUTTER;
    let fits =
        |a: &unwrap::Packed| a.width + 2 * GUTTER <= page.0 && a.height + 2 * GUTTER <= page.1;
    if let Resolution::TexelsPerUnit(_) = res {
        check_cells(scene, &kept, d, max)?;
    }
    let mut charted = unwrap::Charted::new(scene, &to_unwrap)?;
    let mut per_mesh_seconds = 0.0;
    let mut tries = 0;
    // The smallest atlas packed so far (area, width, height, density, charts) and the tries
    // since it last shrank by 3 %: past a point the charts' padding, not their area, sets the
    // atlas's size, and the density drops faster to find that floor.
    let mut smallest: Option<(u64, u32, u32, f64, u32)> = None;
    let mut stalled = 0;
    let lowest = d * 1e-4;
    // The error when the charts fit no page of the size: the smallest atlas seen (`w`×`h` at
    // density `at`) names the page that would hold them.
    let no_fit = |w: u32, h: u32, at: f64, charts: u32| {
        // 5 % spare: the packer's placement varies with the density.
        let fit =
            |v: u32| ((f64::from(v) * 1.05).ceil() as u32 + 2 * GUTTER).next_multiple_of(TILE_SIZE);
        resolution_error(format!(
            "the {} charts do not fit one {}x{} page at any density tried: at {at:.4e} texels/unit they pack into {w}x{h} texels, so the smallest page that holds them is about {}x{} (--size {}x{}); or leave out --size and prepare picks pages for --texels-per-unit",
            charts,
            page.0,
            page.1,
            fit(w),
            fit(h),
            fit(w),
            fit(h)
        ))
    };
    let (atlases, cs, places, n) = loop {
        tries += 1;
        if tries > 100 || d < lowest {
            let (_, w, h, at, charts) = smallest.unwrap_or((0, page.0, page.1, d, 0));
            return Err(no_fit(w, h, at, charts));
        }
        let one = charted.pack(scene, d as f32, max)?;
        if one_page && tries == 1 && !fits(&one) {
            // Before shrinking step by step: at the lowest density tried every chart is a
            // texel or two and the padding alone sets the atlas's size. When even that atlas
            // does not fit, no density will (a million-triangle level's charts at 1024²
            // took 12 minutes of tries to say so).
            let floor = charted.pack(scene, lowest as f32, max)?;
            if !fits(&floor) {
                return Err(no_fit(floor.width, floor.height, lowest, floor.charts));
            }
        }
        let area = u64::from(one.width) * u64::from(one.height);
        match smallest {
            Some((best, ..)) if area as f64 > 0.97 * best as f64 => stalled += 1,
            _ => stalled = 0,
        }
        if smallest.is_none_or(|(best, ..)| area < best) {
            smallest = Some((area, one.width, one.height, d, one.charts));
        }
        let atlases = if fits(&one) {
            vec![one]
        } else if one_page {
            d *= 0.98
                * (f64::from(page.0) / f64::from(one.width + 2 * GUTTER))
                    .min(f64::from(page.1) / f64::from(one.height + 2 * GUTTER));
            if stalled >= 3 {
                d *= 0.5;
            }
            continue;
        } else {
            // Too big for one page: an atlas per mesh, each on one page.
            atlas_per_mesh(scene, &to_unwrap, d, (page, max), &mut per_mesh_seconds)?
        };
        let cs = cells(&kept, d, max);
        let rects: Vec<Option<(u32, u32)>> = atlases
            .iter()
            .map(|a| Some((a.width, a.height)))
            .chain(cs.iter().map(|c| c.map(|c| (c, c))))
            .collect();
        let (places, n) = pack_rects(&rects, GUTTER, page, !one_page);
        if one_page && n > 1 {
            d *= 0.95;
            continue;
        }
        if n > 4096 {
            return Err(resolution_error(format!(
                "{n} pages needed at {d:.4} texels/unit; --texels-per-unit {:.4} or less fits 4096",
                fitting_density(d, n)
            )));
        }
        break (atlases, cs, places, n);
    };
    let rect_sizes: Vec<(u32, u32)> = atlases
        .iter()
        .map(|a| (a.width, a.height))
        .chain(cs.iter().map(|c| c.map_or((0, 0), |c| (c, c))))
        .collect();
    // Without --size, a single page shrinks to what the packing used (32-texel multiples).
    let used = if one_page || n > 1 {
        page
    } else {
        let extent = |f: &dyn Fn(Place, (u32, u32)) -> u32| {
            places
                .iter()
                .zip(&rect_sizes)
                .filter_map(|(p, &r)| Some(f((*p)?, r)))
                .max()
                .unwrap_or(1)
        };
        let w = extent(&|p, r| p.1 + r.0 + GUTTER);
        let h = extent(&|p, r| p.2 + r.1 + GUTTER);
        (
            w.next_multiple_of(TILE_SIZE).min(page.0),
            h.next_multiple_of(TILE_SIZE).min(page.1),
        )
    };
    let mut out = scene.clone();
    let mut mesh_page = vec![0u32; scene.meshes.len()];
    let mut pixels: Vec<Option<[Vec2; 3]>> = vec![None; scene.triangles.len()];
    for (a, place) in atlases.iter().zip(&places) {
        let (p, x, y) = place.unwrap_or((0, 0, 0));
        let at = Vec2::new(x as f32, y as f32);
        for (m, uvs) in &a.meshes {
            mesh_page[*m] = p;
            let first = scene.meshes[*m].first_triangle as usize;
            for (k, q) in uvs.iter().enumerate() {
                pixels[first + k] = q.map(|q| q.map(|v| v + at));
            }
        }
    }
    for (i, ((c, s), place)) in cs
        .iter()
        .zip(&kept)
        .zip(&places[atlases.len()..])
        .enumerate()
    {
        let (Some(c), Some(s), Some((p, x, y))) = (c, s, place) else {
            continue;
        };
        mesh_page[i] = *p;
        let k = *c as f32 / (s.hi - s.lo).max_element().max(1e-12);
        let offset = Vec2::new(*x as f32 - s.lo.x * k, *y as f32 - s.lo.y * k);
        let m = &scene.meshes[i];
        let range = m.first_triangle as usize..(m.first_triangle + m.triangle_count) as usize;
        for (px, t) in pixels[range.clone()]
            .iter_mut()
            .zip(&scene.triangles[range])
        {
            *px = t.lightmap_uv.map(|q| q.map(|v| v * k + offset));
        }
    }
    let size = Vec2::new(used.0 as f32, used.1 as f32);
    for (t, px) in out.triangles.iter_mut().zip(&pixels) {
        t.lightmap_uv = px.map(|q| q.map(|v| v / size));
    }
    let mut records = Vec::with_capacity(out.meshes.len());
    let mut ignored = 0;
    for (i, m) in out.meshes.iter_mut().enumerate() {
        let range = m.first_triangle as usize..(m.first_triangle + m.triangle_count) as usize;
        let uvs = &pixels[range];
        ignored += if selected[i] {
            uvs.iter().filter(|q| q.is_none()).count() as u64
        } else {
            0
        };
        m.has_lightmap_uvs = selected[i] || uvs.iter().all(Option::is_some);
        records.push(MeshLayout {
            page: mesh_page[i],
            flags: u32::from(selected[i] || kept[i].is_some()),
            uv_scale: [size.x, size.y],
            uv_offset: [0.0; 2],
        });
    }
    let pages = vec![
        PageRecord {
            width: used.0,
            height: used.1
        };
        n as usize
    ];
    let report = UnwrapReport {
        meshes: to_unwrap
            .iter()
            .map(|&m| scene.meshes[m].name.clone())
            .collect(),
        charts: atlases.iter().map(|a| a.charts).sum(),
        atlases: atlases.iter().map(|a| (a.width, a.height)).collect(),
        seconds: charted.seconds() + per_mesh_seconds,
        tiny_triangles: ignored,
        utilisation: 0.0,
    };
    Ok((out, pages, records, d as f32, report))
}

/// Each of the meshes `to_unwrap` unwrapped into an atlas of its own at density `d`, for pages
/// of `page` (`max`: the longest chart). When some do not fit a page, the error names the one
/// that needs the lowest density, how many more do not fit, and a density at which all of
/// them were packed again and fit: charts longer than a page are scaled down to it, so an
/// atlas's size at one density under-states what a lower one needs, and the density is
/// lowered until they do fit (or ten tries say only where the last one stood).
fn atlas_per_mesh(
    scene: &Scene,
    to_unwrap: &[usize],
    d: f64,
    (page, max): ((u32, u32), u32),
    seconds: &mut f64,
) -> Result<Vec<unwrap::Packed>, PrepareError> {
    let shrink = |a: &unwrap::Packed| {
        (f64::from(page.0) / f64::from(a.width + 2 * GUTTER))
            .min(f64::from(page.1) / f64::from(a.height + 2 * GUTTER))
    };
    let mut atlases = Vec::with_capacity(to_unwrap.len());
    let mut too_big = Vec::new();
    for &m in to_unwrap {
        let mut c = unwrap::Charted::new(scene, &[m])?;
        let a = c.pack(scene, d as f32, max)?;
        *seconds += c.seconds();
        if shrink(&a) < 1.0 {
            too_big.push((m, c, a.width, a.height, shrink(&a)));
        }
        atlases.push(a);
    }
    let Some(&(m, _, w, h, _)) = too_big.iter().min_by(|x, y| x.4.total_cmp(&y.4)) else {
        return Ok(atlases);
    };
    let mut fit = d * too_big.iter().map(|t| t.4).fold(1.0, f64::min);
    for _ in 0..10 {
        fit *= 0.95;
        let mut least = 1.0f64;
        for (_, c, ..) in &mut too_big {
            least = least.min(shrink(&c.pack(scene, fit as f32, max)?));
        }
        if least >= 1.0 {
            break;
        }
        fit *= least;
    }
    let fit = (fit * 1e4).floor() / 1e4; // printed to four decimals, never above what fit
    let others = match too_big.len() - 1 {
        0 => String::new(),
        1 => " (and 1 other mesh)".into(),
        n => format!(" (and {n} other meshes)"),
    };
    Err(PrepareError::Resolution {
        path: scene.path.clone(),
        message: format!(
            "mesh '{}'{others} unwraps to {w}x{h} texels at {d:.4} texels/unit, more than a page of {}x{}; --texels-per-unit {fit:.4} or less fits",
            scene.meshes[m].name, page.0, page.1
        ),
    })
}

/// A density at which what needed `n` pages at density `d` needs at most 4096 (pages hold
/// area, which goes with the square of the density; 5 % spare for the packing).
pub(super) fn fitting_density(d: f64, n: u32) -> f64 {
    0.95 * d * (4096.0 / f64::from(n)).sqrt()
}

/// `true` when texel centres of a 512² test grid are covered by triangles of two meshes.
pub(super) fn meshes_overlap(scene: &Scene, stats: &[Option<MeshUv>]) -> bool {
    const N: u32 = 512;
    let outside = stats
        .iter()
        .flatten()
        .any(|s| s.lo.min_element() < -1e-3 || s.hi.max_element() > 1.0 + 1e-3);
    if outside {
        return true;
    }
    let mut owner = vec![u32::MAX; (N * N) as usize];
    let (mut covered, mut conflicts) = (0u64, 0u64);
    for t in &scene.triangles {
        let Some(uv) = t.lightmap_uv else { continue };
        let q = uv.map(|v| v * N as f32);
        for_each_centre(&q, (N, N), |x, y| {
            let o = &mut owner[(y * N + x) as usize];
            if *o == u32::MAX {
                *o = t.mesh;
                covered += 1;
            } else if *o != t.mesh {
                conflicts += 1;
            }
        });
    }
    conflicts * 100 > covered
}
