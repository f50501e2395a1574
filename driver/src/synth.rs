//! `synth`: procedural worlds of any size for scaling tests (a city of boxes;
//! docs/ARCHITECTURE.md), written straight to a texel file and a scene, streaming.
//!
//! Not from the paper: the paper's scenes are production levels. This is the "huge world"
//! the bake must stream in bounded memory.
//!
//! The city is a g×g grid of 10 m cells (g = round(√(N / 24576)), from 1 to 2048): the
//! world grows with N at a fixed texel density (it used to stop growing at 64²
//! cells, so larger N made texels denser instead). Every cell has a ground quad and one box
//! (6 m × 6 m, height 5–40 m from an integer hash of the cell, so the world is
//! deterministic). Every quad (ground, box top, four sides) becomes a texel rectangle whose
//! sides are multiples of 32, so every tile is one full 32×32 block of one quad: positions
//! are exact texel centres on the quad, no partial texels. The texel density is bisected so
//! the total is within about 1% of N (the count is a multiple of 1024); with g rounded, it
//! stays within a few percent of 5.6 texels/m. Each quad's geometry is a grid of cells of
//! [`CELL_TEXELS`]² texels, two triangles each, so a huge world has huge geometry: one
//! triangle per 32 texels, 3 M triangles at 10^8 texels. Rectangles are shelf-packed onto
//! 4096×4096 pages; every page is one glTF mesh whose `TEXCOORD_1` maps onto that page.
//!
//! Memory: the geometry is built in memory while the .glb is written (measured: 20 MB peak
//! RSS, 15 MB anonymous, for 10^7 texels and 312 k triangles — about 50 bytes per triangle),
//! and texels are produced one tile at a time into [`TexelWriter`].
//!
//! Files: `OUT` (texel file), `OUT` with extension `.glb` (geometry), and `.toml` (scene file
//! naming the .glb, with a sun and a constant sky) — load the scene with
//! [`crate::scene::Scene::load`] on the `.toml`.
//!
//! **Lit windows** ([`SynthOptions::lit_windows`], `--lit-windows N`): a many-emitter world
//! for comparing emitter samplers (the light tree against the power alias table). The box sides get a grid of window slots, 4·s columns
//! by ⌊h / 3 m⌋·s floors per side, s the smallest integer that makes at least N slots in
//! the whole city; exactly N of them, evenly spread over the slot order, become lit
//! windows: quads of 60% × 50% of their slot, 2 cm in front of the wall, emitting outward
//! (winding normal = the wall's). Their radiance spans 1.5..1000 (`emissiveFactor` ×
//! `KHR_materials_emissive_strength`): of every 1000 lit windows one has strength 1000,
//! nine 100, ninety 12, the rest 1.5, by their rank — deterministic, no random stream. The
//! windows are one glTF mesh `lit_windows` after the pages, without lightmap UVs (no
//! texels; its mesh record has flag 0), 2N emissive triangles. [`SynthOptions::night`]
//! drops the sun and dims the sky to [`NIGHT_SKY`], so the windows carry the lighting.
//! Windows cost about 150 bytes each while the geometry is written (up to
//! [`MAX_LIT_WINDOWS`]); the texels still stream.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::scene::fingerprint::GeometryFingerprint;
use crate::texels::{
    FLAG_VALID, PageRecord, SEEN_FRONT, TILE_SIZE, TexelFileError, TexelRecord, TexelWriter,
    TileRect, TriangleRecord,
};

/// Page edge for synthesized worlds.
pub const PAGE: u32 = 4096;
/// Texels per city cell: the texel density is fixed (about 24 576 texels on a cell's ground,
/// box top and sides, ≈ 5.6 texels/m), and N sets the number of cells.
pub const TEXELS_PER_CELL: u64 = 24_576;
/// Largest grid edge: 2048² cells hold 1.03 · 10^11 texels and 3.2 · 10^9 triangles, within
/// the texel file's 32-bit triangle indices.
const MAX_GRID: u32 = 2048;
/// Edge, in texels, of the geometry's cells: every quad is a grid of cells of this many
/// texels a side, two triangles each, so a huge world has huge geometry (one triangle per 32
/// texels: 3 M triangles at 10^8 texels). Divides the tile size.
pub const CELL_TEXELS: u32 = 8;
/// Smallest world: one cell, 6 quads of one tile each.
pub const MIN_TEXELS: u64 = 6 * (TILE_SIZE as u64 * TILE_SIZE as u64);
const CELL: f32 = 10.0;
const BOX: f32 = 6.0;
/// Most lit windows a city takes (its geometry is built in memory).
pub const MAX_LIT_WINDOWS: u32 = 1 << 20;
/// The constant sky of a night city (no sun).
pub const NIGHT_SKY: [f32; 3] = [0.004, 0.005, 0.01];
/// Window radiance classes: emissive colour (max 1) and `emissiveStrength`.
const WINDOW_CLASSES: [([f32; 3], f32); 4] = [
    ([1.0, 0.85, 0.6], 1.5),
    ([0.8, 0.9, 1.0], 12.0),
    ([1.0, 0.7, 0.4], 100.0),
    ([1.0, 1.0, 1.0], 1000.0),
];
/// Floor height of the window grid.
const FLOOR: f32 = 3.0;

/// What to add to the city besides boxes and ground.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SynthOptions {
    /// Lit windows (emissive quads) on the box sides; 0 for none.
    pub lit_windows: u32,
    /// Night: no sun and a dim sky ([`NIGHT_SKY`]).
    pub night: bool,
}

/// Why `synth` failed.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// N is outside what a city can hold.
    #[error("--texels {n} is outside {MIN_TEXELS}..={max}")]
    Count {
        /// Requested.
        n: u64,
        /// Largest supported.
        max: u64,
    },
    /// More lit windows than a city takes.
    #[error("--lit-windows {n} is above {max}")]
    Windows {
        /// Requested.
        n: u32,
        /// Largest supported.
        max: u32,
    },
    /// Writing the texel file failed.
    #[error(transparent)]
    Texels(#[from] TexelFileError),
    /// Writing the scene failed.
    #[error("{path}: cannot write: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// What `synth` wrote.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SynthReport {
    /// Texels written.
    pub texels: u64,
    /// Tiles written.
    pub tiles: u64,
    /// Pages.
    pub pages: u32,
    /// Grid edge in cells.
    pub grid: u32,
    /// Triangles in the scene.
    pub triangles: u32,
    /// Emissive triangles among them (two per lit window).
    pub emissive_triangles: u32,
    /// Texels per world unit.
    pub texels_per_unit: f32,
    /// The glTF geometry.
    pub geometry: PathBuf,
    /// The TOML scene file.
    pub scene: PathBuf,
}

/// One planar quad `origin + s·eu + t·ev`, s, t ∈ [0, 1], normal eu × ev.
#[derive(Clone, Copy, Debug)]
struct Quad {
    origin: Vec3,
    eu: Vec3,
    ev: Vec3,
}

/// A quad placed on a page: texel rectangle (multiples of 32) and its first triangle.
#[derive(Clone, Copy, Debug)]
struct Placed {
    quad: Quad,
    page: u32,
    x: u32,
    y: u32,
    w: u32,
    h: u32,
    first_triangle: u32,
}

impl Placed {
    /// Triangles of its geometry: two per cell of [`CELL_TEXELS`]² texels.
    fn triangle_count(&self) -> u32 {
        2 * (self.w / CELL_TEXELS) * (self.h / CELL_TEXELS)
    }
}

/// Grid edge of a city of about `n` texels: every cell holds about [`TEXELS_PER_CELL`], so the
/// world grows with N at a fixed texel density.
fn city_grid(n: u64) -> u32 {
    ((n as f64 / TEXELS_PER_CELL as f64).sqrt().round() as u32).clamp(1, MAX_GRID)
}

/// A lit window: its quad and its radiance class (index into [`WINDOW_CLASSES`]).
#[derive(Clone, Copy, Debug)]
struct Window {
    quad: Quad,
    class: usize,
}

/// Integer hash (Wang/splitmix finalizer) of a cell → [0, 1); not a random stream.
fn hash01(i: u32, j: u32) -> f32 {
    let mut x = (u64::from(i) << 32 | u64::from(j)).wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    (x >> 40) as f32 / (1u64 << 24) as f32
}

fn city(grid: u32) -> Vec<Quad> {
    let mut q = Vec::with_capacity((grid * grid * 6) as usize);
    for j in 0..grid {
        for i in 0..grid {
            let (cx, cz) = (i as f32 * CELL, j as f32 * CELL);
            q.push(Quad {
                origin: Vec3::new(cx, 0.0, cz + CELL),
                eu: Vec3::X * CELL,
                ev: -Vec3::Z * CELL,
            });
            let h = 5.0 + 35.0 * hash01(i, j);
            let m = (CELL - BOX) / 2.0;
            let (x0, x1, z0, z1) = (cx + m, cx + m + BOX, cz + m, cz + m + BOX);
            q.push(Quad {
                origin: Vec3::new(x0, h, z1),
                eu: Vec3::X * BOX,
                ev: -Vec3::Z * BOX,
            });
            q.push(Quad {
                origin: Vec3::new(x1, 0.0, z1),
                eu: -Vec3::Z * BOX,
                ev: Vec3::Y * h,
            });
            q.push(Quad {
                origin: Vec3::new(x0, 0.0, z0),
                eu: Vec3::Z * BOX,
                ev: Vec3::Y * h,
            });
            q.push(Quad {
                origin: Vec3::new(x0, 0.0, z1),
                eu: Vec3::X * BOX,
                ev: Vec3::Y * h,
            });
            q.push(Quad {
                origin: Vec3::new(x1, 0.0, z0),
                eu: -Vec3::X * BOX,
                ev: Vec3::Y * h,
            });
        }
    }
    q
}

/// Whether a city quad is a box side (see [`city`]: ground, top, then four sides).
fn is_side(k: usize) -> bool {
    k % 6 >= 2
}

/// Window columns and floors of a side quad at grid scale `s`.
fn window_grid(side: &Quad, s: u32) -> (u32, u32) {
    let floors = ((side.ev.length() / FLOOR).floor() as u32).max(1);
    (4 * s, floors * s)
}

/// Exactly `count` lit windows on the sides of `quads`, spread evenly over the slots of the
/// smallest grid scale with at least `count` slots.
fn windows(quads: &[Quad], count: u32) -> Vec<Window> {
    if count == 0 {
        return Vec::new();
    }
    let slots = |s: u32| -> u64 {
        let sides = quads.iter().enumerate().filter(|(k, _)| is_side(*k));
        sides
            .map(|(_, q)| {
                let (c, f) = window_grid(q, s);
                u64::from(c) * u64::from(f)
            })
            .sum()
    };
    let base = slots(1);
    let mut s = ((f64::from(count) / base as f64).sqrt().ceil() as u32).max(1);
    while slots(s) < u64::from(count) {
        s += 1;
    }
    let total = slots(s);
    let (count, mut slot, mut out) = (u64::from(count), 0u64, Vec::with_capacity(count as usize));
    for (_, q) in quads.iter().enumerate().filter(|(k, _)| is_side(*k)) {
        let (cols, floors) = window_grid(q, s);
        let normal = q.eu.cross(q.ev).normalize();
        let (du, dv) = (q.eu / cols as f32, q.ev / floors as f32);
        for f in 0..floors {
            for c in 0..cols {
                // Slot j is lit when ⌊(j + 1)·N / T⌋ steps past ⌊j·N / T⌋.
                let lit = (slot + 1) * count / total > slot * count / total;
                slot += 1;
                if !lit {
                    continue;
                }
                let rank = out.len() % 1000;
                let class = match rank {
                    0 => 3,
                    r if r % 100 == 50 => 2,
                    r if r % 10 == 5 => 1,
                    _ => 0,
                };
                out.push(Window {
                    quad: Quad {
                        origin: q.origin
                            + du * (c as f32 + 0.2)
                            + dv * (f as f32 + 0.25)
                            + normal * 0.02,
                        eu: du * 0.6,
                        ev: dv * 0.5,
                    },
                    class,
                });
            }
        }
    }
    debug_assert_eq!(out.len() as u64, count);
    out
}

fn rect_side(len: f32, d: f64) -> u32 {
    let tiles = (f64::from(len) * d / f64::from(TILE_SIZE)).round().max(1.0);
    (tiles as u32).min(PAGE / TILE_SIZE) * TILE_SIZE
}

fn total(quads: &[Quad], d: f64) -> u64 {
    quads
        .iter()
        .map(|q| u64::from(rect_side(q.eu.length(), d)) * u64::from(rect_side(q.ev.length(), d)))
        .sum()
}

/// Texel density whose total is closest to `n` (bisection on the monotone total).
fn density_for(quads: &[Quad], n: u64) -> f64 {
    let area: f64 = quads
        .iter()
        .map(|q| f64::from(q.eu.cross(q.ev).length()))
        .sum();
    let (mut lo, mut hi) = (1e-6, (n as f64 / area).sqrt() * 4.0 + 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if total(quads, mid) < n {
            lo = mid
        } else {
            hi = mid
        }
    }
    if total(quads, hi).abs_diff(n) < total(quads, lo).abs_diff(n) {
        hi
    } else {
        lo
    }
}

/// Shelf-packs the quads' rectangles onto pages, in quad order (which keeps a cell's quads
/// together and neighbouring cells near each other). Not `prepare`'s packer
/// ([`crate::prepare::pack`]): that one orders by size, for density, and costs a pass over
/// the skyline per rectangle; a synthetic world wants the file in world order, and 3 M
/// rectangles at 10^8 texels in constant time each.
fn pack(quads: &[Quad], d: f64) -> (Vec<Placed>, u32) {
    let (mut page, mut x, mut y, mut shelf) = (0u32, 0u32, 0u32, 0u32);
    let mut out = Vec::with_capacity(quads.len());
    for (k, q) in quads.iter().enumerate() {
        let (w, h) = (rect_side(q.eu.length(), d), rect_side(q.ev.length(), d));
        if x + w > PAGE {
            (x, y, shelf) = (0, y + shelf, 0);
        }
        if y + h > PAGE {
            (page, x, y, shelf) = (page + 1, 0, 0, 0);
        }
        out.push(Placed {
            quad: *q,
            page,
            x,
            y,
            w,
            h,
            first_triangle: 2 * k as u32,
        });
        x += w;
        shelf = shelf.max(h);
    }
    (out, page + 1)
}

/// Writes a city of about `n` texels to `out` (+ `.glb` and `.toml` beside it), by day and
/// without lit windows.
///
/// # Errors
/// As [`synth_with`].
pub fn synth(n: u64, out: &Path) -> Result<SynthReport, SynthError> {
    synth_with(n, out, &SynthOptions::default())
}

/// Writes a city of about `n` texels to `out` (+ `.glb` and `.toml` beside it) with the
/// lit windows and the time of day of `options`.
///
/// # Errors
/// [`SynthError::Count`] when `n` is too small or too large, [`SynthError::Windows`] when
/// `options.lit_windows` exceeds [`MAX_LIT_WINDOWS`]; I/O errors naming the file.
pub fn synth_with(n: u64, out: &Path, options: &SynthOptions) -> Result<SynthReport, SynthError> {
    let max = u64::from(MAX_GRID * MAX_GRID) * TEXELS_PER_CELL;
    if !(MIN_TEXELS..=max).contains(&n) {
        return Err(SynthError::Count { n, max });
    }
    if options.lit_windows > MAX_LIT_WINDOWS {
        return Err(SynthError::Windows {
            n: options.lit_windows,
            max: MAX_LIT_WINDOWS,
        });
    }
    let grid = city_grid(n);
    let quads = city(grid);
    let lit = windows(&quads, options.lit_windows);
    let d = density_for(&quads, n);
    let (placed, pages) = pack(&quads, d);
    // Triangles are ordered by page (one glTF mesh per page), then quad order.
    let mut placed = placed;
    placed.sort_by_key(|p| p.page);
    let mut first = 0;
    for p in &mut placed {
        p.first_triangle = first;
        first += p.triangle_count();
    }
    let city_triangles = first;
    let geometry = out.with_extension("glb");
    let scene = out.with_extension("toml");
    let (triangles, geometry_fingerprint) = write_city_glb(&geometry, &placed, pages, &lit)?;
    debug_assert_eq!(
        triangles.len(),
        (city_triangles + 2 * lit.len() as u32) as usize
    );
    write_scene_file(&scene, &geometry, options.night)?;
    let page_records = vec![
        PageRecord {
            width: PAGE,
            height: PAGE
        };
        pages as usize
    ];
    let mut w = TexelWriter::create(out, &page_records, &triangles, d as f32)?;
    w.set_geometry(geometry_fingerprint);
    let mut buf = Vec::with_capacity((TILE_SIZE * TILE_SIZE) as usize);
    let mut tiles = 0u64;
    for p in &placed {
        for ty in 0..p.h / TILE_SIZE {
            for tx in 0..p.w / TILE_SIZE {
                buf.clear();
                fill_tile(p, tx * TILE_SIZE, ty * TILE_SIZE, &mut buf);
                let rect = TileRect {
                    page: p.page,
                    x: p.x + tx * TILE_SIZE,
                    y: p.y + ty * TILE_SIZE,
                    width: TILE_SIZE,
                    height: TILE_SIZE,
                };
                w.push_tile(rect, &buf)?;
                tiles += 1;
            }
        }
    }
    let texels = w.texel_count();
    w.finish()?;
    Ok(SynthReport {
        texels,
        tiles,
        pages,
        grid,
        triangles: triangles.len() as u32,
        emissive_triangles: 2 * lit.len() as u32,
        texels_per_unit: d as f32,
        geometry,
        scene,
    })
}

/// The 32×32 texels of a quad's rectangle starting at local texel (lx, ly), row-major.
fn fill_tile(p: &Placed, lx: u32, ly: u32, buf: &mut Vec<TexelRecord>) {
    let q = p.quad;
    let normal = q.eu.cross(q.ev).normalize().to_array();
    let (dpdu, dpdv) = (q.eu / p.w as f32, q.ev / p.h as f32);
    for y in ly..ly + TILE_SIZE {
        for x in lx..lx + TILE_SIZE {
            let s = (x as f32 + 0.5) / p.w as f32;
            let t = (y as f32 + 0.5) / p.h as f32;
            // The quad's cell (i, j) of CELL_TEXELS²; in it, triangle 0 is (v0, v1, v2) = the
            // half with local s ≥ t, triangle 1 is (v0, v2, v3).
            let (i, j) = (x / CELL_TEXELS, y / CELL_TEXELS);
            let (ls, lt) = (x % CELL_TEXELS, y % CELL_TEXELS);
            let tri = p.first_triangle + 2 * (j * (p.w / CELL_TEXELS) + i) + u32::from(ls < lt);
            buf.push(TexelRecord {
                position: (q.origin + q.eu * s + q.ev * t).to_array(),
                normal,
                dpdu: dpdu.to_array(),
                dpdv: dpdv.to_array(),
                page: p.page,
                pixel: [(p.x + x) as u16, (p.y + y) as u16],
                triangle: tri,
                flags: FLAG_VALID,
            });
        }
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SynthError + '_ {
    move |source| SynthError::Io {
        path: path.to_owned(),
        source,
    }
}

/// Writes `bytes` to `path` through a temporary name.
fn write_atomically(path: &Path, bytes: &[&[u8]]) -> Result<(), SynthError> {
    crate::atomic::write_parts(path, bytes).map_err(io_err(path))
}

/// Writes the city as a glb ([`crate::scene::glb`]), one glTF mesh per page; returns the
/// triangle table of the texel file (every face is seen from its front, where its texels face).
fn write_city_glb(
    path: &Path,
    placed: &[Placed],
    pages: u32,
    windows: &[Window],
) -> Result<(Vec<TriangleRecord>, u64), SynthError> {
    use crate::scene::glb::{
        self, ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, GlbBuffer, UNSIGNED_INT,
    };
    use bytemuck::cast_slice;
    use serde_json::json;
    // The scene's geometry fingerprint, as `Scene::load` of the file will compute it: the
    // triangles in primitive order, each by its corners.
    let mut fingerprint = GeometryFingerprint::default();
    let mut buffer = GlbBuffer::default();
    let (mut accessors, mut meshes, mut nodes, mut records) = (vec![], vec![], vec![], vec![]);
    // Positions, normals, optional lightmap UVs and indices as buffer views and accessors;
    // returns the index of the first accessor (POSITION, NORMAL, [TEXCOORD_1,] indices).
    let mut push_geometry =
        |buffer: &mut GlbBuffer, pos: &[Vec3], nrm: &[Vec3], uv: Option<&[Vec2]>, idx: &[u32]| {
            let (lo, hi) = pos.iter().fold(
                (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |(a, b), p| (a.min(*p), b.max(*p)),
            );
            let a0 = accessors.len();
            // Vertex data is f32; the indices, the one SCALAR accessor here, are u32.
            let mut push = |data: &[u8], count: usize, kind: &str, bounds| {
                let (target, component) = match kind {
                    "SCALAR" => (ELEMENT_ARRAY_BUFFER, UNSIGNED_INT),
                    _ => (ARRAY_BUFFER, FLOAT),
                };
                let v = buffer.push_view(data, None, Some(target));
                accessors.push(glb::accessor(v, component, count, kind, bounds));
            };
            push(
                cast_slice(pos),
                pos.len(),
                "VEC3",
                Some((lo.to_array(), hi.to_array())),
            );
            push(cast_slice(nrm), nrm.len(), "VEC3", None);
            if let Some(uv) = uv {
                push(cast_slice(uv), uv.len(), "VEC2", None);
            }
            push(cast_slice(idx), idx.len(), "SCALAR", None);
            a0
        };
    for page in 0..pages {
        let quads: Vec<&Placed> = placed.iter().filter(|p| p.page == page).collect();
        let (mut pos, mut nrm, mut uv, mut idx) = (vec![], vec![], vec![], vec![]);
        for p in &quads {
            let q = p.quad;
            let n = q.eu.cross(q.ev).normalize();
            let base = pos.len() as u32;
            // A grid of (cu + 1) × (cv + 1) vertices; two triangles per cell.
            let (cu, cv) = (p.w / CELL_TEXELS, p.h / CELL_TEXELS);
            for j in 0..=cv {
                for i in 0..=cu {
                    let (x, y) = (i * CELL_TEXELS, j * CELL_TEXELS);
                    let (s, t) = (x as f32 / p.w as f32, y as f32 / p.h as f32);
                    pos.push(q.origin + q.eu * s + q.ev * t);
                    nrm.push(n);
                    uv.push(Vec2::new((p.x + x) as f32, (p.y + y) as f32) / PAGE as f32);
                }
            }
            for j in 0..cv {
                for i in 0..cu {
                    let v0 = base + j * (cu + 1) + i;
                    let (v1, v2, v3) = (v0 + 1, v0 + cu + 2, v0 + cu + 1);
                    idx.extend_from_slice(&[v0, v1, v2, v0, v2, v3]);
                }
            }
        }
        for t in idx.chunks_exact(3) {
            fingerprint.push(&[pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]]);
        }
        let a0 = push_geometry(&mut buffer, &pos, &nrm, Some(&uv), &idx);
        meshes.push(json!({"name": format!("city_page{page}"), "primitives": [{
            "attributes": {"POSITION": a0, "NORMAL": a0 + 1, "TEXCOORD_1": a0 + 2},
            "indices": a0 + 3, "material": 0, "mode": 4}]}));
        nodes.push(json!({"name": format!("city_page{page}"), "mesh": page}));
        records.extend(idx.chunks_exact(3).map(|t| {
            let corner = |v: u32| uv[v as usize] * PAGE as f32;
            TriangleRecord::lightmapped(
                page,
                [corner(t[0]), corner(t[1]), corner(t[2])],
                SEEN_FRONT,
            )
        }));
    }
    let mut materials = vec![
        json!({"name": "concrete", "doubleSided": true, "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.58, 0.55, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}}),
    ];
    if !windows.is_empty() {
        // One primitive per radiance class; the scene numbers triangles in primitive order.
        let mut primitives = vec![];
        for (class, (color, strength)) in WINDOW_CLASSES.iter().enumerate() {
            materials.push(json!({"name": format!("window_{strength}"),
                "pbrMetallicRoughness": {"baseColorFactor": [0.05, 0.05, 0.05, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
                "emissiveFactor": color,
                "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}}));
            let (mut pos, mut nrm, mut idx) = (vec![], vec![], vec![]);
            for w in windows.iter().filter(|w| w.class == class) {
                let q = w.quad;
                let base = pos.len() as u32;
                let n = q.eu.cross(q.ev).normalize();
                for (s, t) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                    pos.push(q.origin + q.eu * s + q.ev * t);
                    nrm.push(n);
                }
                idx.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
            }
            if pos.is_empty() {
                continue;
            }
            for t in idx.chunks_exact(3) {
                fingerprint.push(&[pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]]);
            }
            let a0 = push_geometry(&mut buffer, &pos, &nrm, None, &idx);
            primitives.push(json!({"attributes": {"POSITION": a0, "NORMAL": a0 + 1},
                "indices": a0 + 2, "material": 1 + class, "mode": 4}));
        }
        meshes.push(json!({"name": "lit_windows", "primitives": primitives}));
        nodes.push(json!({"name": "lit_windows", "mesh": pages}));
        let window_triangles = 2 * windows.len();
        records.extend(std::iter::repeat_n(
            TriangleRecord::unmapped(SEEN_FRONT),
            window_triangles,
        ));
    }
    let (bin, views) = buffer.finish();
    let doc = json!({
        "asset": {"version": "2.0", "generator": "guidebake synth"},
        "scene": 0,
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    let json = serde_json::to_vec(&doc).map_err(|e| io_err(path)(std::io::Error::other(e)))?;
    glb::write(path, json, &bin).map_err(io_err(path))?;
    Ok((records, fingerprint.finish()))
}

fn write_scene_file(path: &Path, geometry: &Path, night: bool) -> Result<(), SynthError> {
    let name = geometry
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let text = if night {
        format!(
            "# Written by guidebake synth: a city of boxes at night, lit by its windows.\n\
             geometry = {name:?}\n\n[sky]\nconstant = {NIGHT_SKY:?}\n"
        )
    } else {
        format!(
            "# Written by guidebake synth: a city of boxes under a sun and a blue sky.\n\
             geometry = {name:?}\n\n[sky]\nconstant = [0.25, 0.35, 0.6]\n\n\
             [sun]\ndirection = [0.4, 1.0, 0.25]\nangular_radius_deg = 0.267\nirradiance = [3.0, 2.85, 2.6]\n"
        )
    };
    write_atomically(path, &[text.as_bytes()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_face_outward_and_density_hits_the_target() {
        let quads = city(3);
        for (k, q) in quads.iter().enumerate() {
            let n = q.eu.cross(q.ev).normalize();
            if k % 6 == 0 || k % 6 == 1 {
                assert_eq!(n, Vec3::Y);
            } else {
                // A side's normal points away from its box's axis.
                let mid = q.origin + 0.5 * (q.eu + q.ev);
                let cell = Vec3::new(
                    (mid.x / CELL).floor() * CELL + CELL / 2.0,
                    0.0,
                    (mid.z / CELL).floor() * CELL + CELL / 2.0,
                );
                assert!(n.dot(mid - cell) > 0.0, "quad {k}");
            }
        }
        for n in [100_000u64, 1_000_000, 7_777_777] {
            let d = density_for(&quads, n);
            let t = total(&quads, d) as f64;
            assert!((t / n as f64 - 1.0).abs() < 0.02, "{n}: {t}");
        }
    }

    /// The box whose side a window is on: the cell of its centre, box centre at mid height.
    fn cell_center(p: Vec3) -> Vec3 {
        Vec3::new(
            (p.x / CELL).floor() * CELL + CELL / 2.0,
            p.y,
            (p.z / CELL).floor() * CELL + CELL / 2.0,
        )
    }

    #[test]
    fn windows_are_exactly_n_outside_their_walls_facing_out() {
        for (grid, n) in [(1, 1), (1, 999), (2, 10_000), (3, 12_345), (1, 100_000)] {
            let quads = city(grid);
            let w = windows(&quads, n);
            assert_eq!(w.len(), n as usize, "grid {grid}");
            for (k, win) in w.iter().enumerate() {
                let q = win.quad;
                let normal = q.eu.cross(q.ev).normalize();
                let mid = q.origin + 0.5 * (q.eu + q.ev);
                let c = cell_center(mid);
                assert!(normal.dot(mid - c) > 0.0, "window {k} faces inward");
                assert!(normal.y.abs() < 1e-6, "window {k} not on a side");
                // 2 cm in front of its wall: the box half-width plus 0.02 along the normal.
                let out = normal.dot(mid - c);
                assert!((out - (BOX / 2.0 + 0.02)).abs() < 1e-3, "window {k}: {out}");
                assert!(q.eu.cross(q.ev).length() > 0.0);
            }
            if n >= 1000 {
                for class in 0..WINDOW_CLASSES.len() {
                    assert!(w.iter().any(|x| x.class == class), "class {class} missing");
                }
            }
        }
    }

    #[test]
    fn lit_window_night_city_loads_with_its_emitters() {
        use crate::scene::{Scene, Sky};
        use crate::texels::TexelFile;
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("night.texels");
        let n = 10_000;
        let options = SynthOptions {
            lit_windows: n,
            night: true,
        };
        let r = synth_with(100_000, &out, &options).unwrap();
        assert_eq!(r.emissive_triangles, 2 * n);
        let scene = Scene::load(&r.scene).unwrap();
        assert!(scene.sun.is_none());
        assert!(matches!(scene.sky, Sky::Constant(c) if c == Vec3::from(NIGHT_SKY)));
        let f = TexelFile::open(&out).unwrap();
        assert_eq!(scene.triangles.len() as u32, r.triangles);
        assert_eq!(f.header().triangle_count, r.triangles);
        let emissive: Vec<usize> = (0..scene.triangles.len())
            .filter(|&i| scene.triangle_material(i).emission != Vec3::ZERO)
            .collect();
        assert!(emissive.len() >= 2 * n as usize, "{}", emissive.len());
        let lum = |i: usize| {
            guidebake_kernels::estimator::luminance_f32(
                scene.triangle_material(i).emission.to_array(),
            )
        };
        let (lo, hi) = emissive.iter().fold((f32::MAX, 0f32), |(a, b), &i| {
            (a.min(lum(i)), b.max(lum(i)))
        });
        assert!(lo < 2.0 && hi > 900.0, "radiance spans {lo}..{hi}");
        let unmapped = f
            .triangles()
            .iter()
            .filter(|t| t.pixel_uv().is_none())
            .count();
        assert_eq!(unmapped, 2 * n as usize, "the windows have no lightmap UVs");
        for &i in &emissive {
            let t = &scene.triangles[i];
            assert!(t.lightmap_uv.is_none());
            assert_eq!(t.mesh as usize, scene.meshes.len() - 1);
            let mid = (t.positions[0] + t.positions[1] + t.positions[2]) / 3.0;
            assert!(
                t.geometric_normal().dot(mid - cell_center(mid)) > 0.0,
                "emitter {i} faces its wall"
            );
        }
        // Deterministic: the same options write the same geometry.
        let again = synth_with(100_000, &dir.path().join("again.texels"), &options).unwrap();
        assert_eq!(
            std::fs::read(&r.geometry).unwrap(),
            std::fs::read(&again.geometry).unwrap()
        );
        // The day city is unchanged by the option's existence.
        let day = synth(100_000, &dir.path().join("day.texels")).unwrap();
        assert_eq!(day.emissive_triangles, 0);
        assert!(Scene::load(&day.scene).unwrap().sun.is_some());
        assert!(matches!(
            synth_with(
                100_000,
                &out,
                &SynthOptions {
                    lit_windows: MAX_LIT_WINDOWS + 1,
                    night: false
                }
            ),
            Err(SynthError::Windows { .. })
        ));
    }
}
