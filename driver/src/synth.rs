//! `synth`: procedural worlds of any size for scaling tests (DESIGN.md, "prepare" — "a city
//! of boxes"), written straight to a texel file and a scene, streaming.
//!
//! Not from the paper: the paper's scenes are production levels. This is the "huge world"
//! the bake must stream in bounded memory.
//!
//! The city is a g×g grid of 10 m cells (g = clamp(⌊√(N / 24576)⌋, 1, 64)); every cell has
//! a ground quad and one box (6 m × 6 m, height 5–40 m from an integer hash of the cell, so
//! the world is deterministic). Every quad (ground, box top, four sides) becomes a texel
//! rectangle whose sides are multiples of 32, so every tile is one full 32×32 block of one
//! quad: positions are exact texel centres on the quad, no partial texels. The texel density
//! is bisected so the total is within about 1% of N (the count is a multiple of 1024).
//! Rectangles are shelf-packed onto 4096×4096 pages; every page is one glTF mesh whose
//! `TEXCOORD_1` maps onto that page.
//!
//! Memory: the geometry is capped at 64² cells (≈ 25 k quads, a few MB), and texels are
//! produced one tile at a time into [`TexelWriter`]; peak memory does not grow with N.
//!
//! Files: `OUT` (texel file), `OUT` with extension `.glb` (geometry), and `.toml` (scene file
//! naming the .glb, with a sun and a constant sky) — load the scene with
//! [`crate::scene::Scene::load`] on the `.toml`.

use std::io::Write;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::texels::{
    FLAG_VALID, MeshRecord, PageRecord, TILE_SIZE, TexelFileError, TexelRecord, TexelWriter,
    TileRect,
};

/// Page edge for synthesized worlds.
pub const PAGE: u32 = 4096;
/// Smallest world: one cell, 6 quads of one tile each.
pub const MIN_TEXELS: u64 = 6 * (TILE_SIZE as u64 * TILE_SIZE as u64);
const CELL: f32 = 10.0;
const BOX: f32 = 6.0;

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
/// together and neighbouring cells near each other).
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

/// Writes a city of about `n` texels to `out` (+ `.glb` and `.toml` beside it).
///
/// # Errors
/// [`SynthError::Count`] when `n` is too small or too large; I/O errors naming the file.
pub fn synth(n: u64, out: &Path) -> Result<SynthReport, SynthError> {
    let max = 64 * 64 * 6 * u64::from(PAGE / 2) * u64::from(PAGE / 2);
    if !(MIN_TEXELS..=max).contains(&n) {
        return Err(SynthError::Count { n, max });
    }
    let grid = ((n as f64 / 24576.0).sqrt().floor() as u32).clamp(1, 64);
    let quads = city(grid);
    let d = density_for(&quads, n);
    let (placed, pages) = pack(&quads, d);
    // Triangles are ordered by page (one glTF mesh per page), then quad order.
    let mut placed = placed;
    placed.sort_by_key(|p| p.page);
    for (k, p) in placed.iter_mut().enumerate() {
        p.first_triangle = 2 * k as u32;
    }
    let geometry = out.with_extension("glb");
    let scene = out.with_extension("toml");
    let meshes = write_glb(&geometry, &placed, pages)?;
    write_scene_file(&scene, &geometry)?;
    let page_records = vec![
        PageRecord {
            width: PAGE,
            height: PAGE
        };
        pages as usize
    ];
    let mut w = TexelWriter::create(
        out,
        &page_records,
        &meshes,
        2 * placed.len() as u32,
        d as f32,
    )?;
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
        triangles: 2 * placed.len() as u32,
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
            // Triangle 0 is (v0, v1, v2) = the half with s ≥ t; triangle 1 is (v0, v2, v3).
            let tri = p.first_triangle + u32::from(s < t);
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
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        for b in bytes {
            f.write_all(b)?;
        }
        f.into_inner()
            .map_err(std::io::IntoInnerError::into_error)?
            .sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io_err(path))
}

/// Writes one glTF mesh per page; returns the mesh records of the texel file.
fn write_glb(path: &Path, placed: &[Placed], pages: u32) -> Result<Vec<MeshRecord>, SynthError> {
    use serde_json::json;
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut nodes, mut records) =
        (vec![], vec![], vec![], vec![], vec![]);
    let mut push_view = |bin: &mut Vec<u8>, data: &[u8], target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(data);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(
            json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len(), "target": target}),
        );
        views.len() - 1
    };
    for page in 0..pages {
        let quads: Vec<&Placed> = placed.iter().filter(|p| p.page == page).collect();
        let (mut pos, mut nrm, mut uv, mut idx) = (vec![], vec![], vec![], vec![]);
        for p in &quads {
            let q = p.quad;
            let n = q.eu.cross(q.ev).normalize();
            let base = pos.len() as u32;
            let corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
            for (s, t) in corners {
                pos.push(q.origin + q.eu * s + q.ev * t);
                nrm.push(n);
                let px = Vec2::new(p.x as f32 + s * p.w as f32, p.y as f32 + t * p.h as f32);
                uv.push(px / PAGE as f32);
            }
            idx.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        let (lo, hi) = pos.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(a, b), p| (a.min(*p), b.max(*p)),
        );
        let a0 = accessors.len();
        let v = push_view(&mut bin, bytemuck::cast_slice(&pos), 34962);
        accessors.push(json!({"bufferView": v, "componentType": 5126, "count": pos.len(), "type": "VEC3", "min": lo.to_array(), "max": hi.to_array()}));
        let v = push_view(&mut bin, bytemuck::cast_slice(&nrm), 34962);
        accessors.push(
            json!({"bufferView": v, "componentType": 5126, "count": nrm.len(), "type": "VEC3"}),
        );
        let v = push_view(&mut bin, bytemuck::cast_slice(&uv), 34962);
        accessors.push(
            json!({"bufferView": v, "componentType": 5126, "count": uv.len(), "type": "VEC2"}),
        );
        let v = push_view(&mut bin, bytemuck::cast_slice(&idx), 34963);
        accessors.push(
            json!({"bufferView": v, "componentType": 5125, "count": idx.len(), "type": "SCALAR"}),
        );
        meshes.push(json!({"name": format!("city_page{page}"), "primitives": [{
            "attributes": {"POSITION": a0, "NORMAL": a0 + 1, "TEXCOORD_1": a0 + 2},
            "indices": a0 + 3, "material": 0, "mode": 4}]}));
        nodes.push(json!({"name": format!("city_page{page}"), "mesh": page}));
        records.push(MeshRecord {
            first_triangle: quads.first().map_or(0, |p| p.first_triangle),
            triangle_count: 2 * quads.len() as u32,
            page,
            flags: 1,
            uv_scale: [PAGE as f32; 2],
            uv_offset: [0.0; 2],
        });
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "guidebake synth"},
        "scene": 0,
        "scenes": [{"nodes": (0..pages).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": [{"name": "concrete", "doubleSided": true, "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.58, 0.55, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    let mut json = serde_json::to_vec(&doc).map_err(|e| io_err(path)(std::io::Error::other(e)))?;
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let header = [
        &b"glTF"[..],
        &2u32.to_le_bytes(),
        &(total as u32).to_le_bytes(),
    ]
    .concat();
    let jh = [(json.len() as u32).to_le_bytes(), *b"JSON"].concat();
    let bh = [(bin.len() as u32).to_le_bytes(), *b"BIN\0"].concat();
    write_atomically(path, &[&header, &jh, &json, &bh, &bin])?;
    Ok(records)
}

fn write_scene_file(path: &Path, geometry: &Path) -> Result<(), SynthError> {
    let name = geometry
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let text = format!(
        "# Written by guidebake synth: a city of boxes under a sun and a blue sky.\n\
         geometry = {name:?}\n\n[sky]\nconstant = [0.25, 0.35, 0.6]\n\n\
         [sun]\ndirection = [0.4, 1.0, 0.25]\nangular_radius_deg = 0.267\nirradiance = [3.0, 2.85, 2.6]\n"
    );
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
}
