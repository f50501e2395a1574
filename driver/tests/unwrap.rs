//! `prepare --unwrap`: lightmap UVs from xatlas for a glTF made here without `TEXCOORD_1` (a
//! closed room with a box in it). The texels lie on their triangles, charts neither overlap
//! nor come closer than the padding, the bake gives the closed-form irradiance, the output
//! is the same bytes on every run, and the scene written back with `--write-gltf` keeps its
//! other attributes and round-trips to the same texels.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use glam::{Vec2, Vec3};
use guidebake::bake::finish::FinishOptions;
use guidebake::bake::run::{BakeJob, bake};
use guidebake::bake::settings::{BakeSettings, EmitterSampling, Guiding, Transport};
use guidebake::bake::shard::Shard;
use guidebake::prepare::unwrap::PADDING;
use guidebake::prepare::{
    Layout, Lightmap, PrepareError, PrepareOptions, Resolution, Unwrap, prepare_with,
};
use guidebake::scene::Scene;
use guidebake::scene::gltf_write::write_glb;
use guidebake::test_support::{assert_texels_on_triangles, inward_box_faces};
use guidebake::texels::{FLAG_PARTIAL, TexelFile};

mod cli;

const ALBEDO: f32 = 0.5;
const LE: f32 = 1.5;

/// One glTF mesh: positions, normals, optional TEXCOORD_0, 32-bit indices.
struct MeshData {
    name: &'static str,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uv0: Option<Vec<Vec2>>,
    indices: Vec<u32>,
}

/// Quads (corner, edge u, edge v; normal u × v) as a mesh of 4 vertices and 2 triangles each.
fn quads(name: &'static str, faces: &[(Vec3, Vec3, Vec3)], uv0: bool) -> MeshData {
    let mut m = MeshData {
        name,
        positions: Vec::new(),
        normals: Vec::new(),
        uv0: uv0.then(Vec::new),
        indices: Vec::new(),
    };
    for &(c, u, v) in faces {
        let base = m.positions.len() as u32;
        let n = u.cross(v).normalize();
        for (a, b) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            m.positions.push(c + u * a + v * b);
            m.normals.push(n);
            if let Some(t) = &mut m.uv0 {
                t.push(Vec2::new(a, b));
            }
        }
        m.indices.extend([0, 1, 2, 0, 2, 3].map(|i: u32| base + i));
    }
    m
}

/// A closed 4 m room (faces inwards) and a 1 m box in it (faces outwards, with TEXCOORD_0,
/// moved and mirrored by its node), all of albedo 0.5 emitting 1.5: no TEXCOORD_1 anywhere.
/// Written as `room.gltf` + `room.bin` in `dir`.
fn room_with_box(dir: &Path) -> PathBuf {
    let room = quads("room", &inward_box_faces(Vec3::splat(-2.0), 4.0), false);
    let outward: Vec<_> = inward_box_faces(Vec3::splat(-0.5), 1.0)
        .iter()
        .map(|&(c, u, v)| (c, v, u))
        .collect();
    let cube = quads("box", &outward, true);
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut push = |bytes: Vec<u8>,
                    count: usize,
                    kind: &str,
                    component: u32,
                    bounds: Option<(Vec3, Vec3)>| {
        views.push(
            serde_json::json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len() }),
        );
        bin.extend(bytes);
        let mut a = serde_json::json!({
            "bufferView": views.len() - 1, "componentType": component, "count": count, "type": kind,
        });
        if let Some((lo, hi)) = bounds {
            a["min"] = serde_json::json!(lo.to_array());
            a["max"] = serde_json::json!(hi.to_array());
        }
        accessors.push(a);
        accessors.len() - 1
    };
    let f32s = |v: &mut dyn Iterator<Item = f32>| v.flat_map(f32::to_le_bytes).collect::<Vec<u8>>();
    let mut meshes = Vec::new();
    for m in [&room, &cube] {
        let lo = m.positions.iter().fold(Vec3::INFINITY, |a, &b| a.min(b));
        let hi = m
            .positions
            .iter()
            .fold(Vec3::NEG_INFINITY, |a, &b| a.max(b));
        let n = m.positions.len();
        let p = push(
            f32s(&mut m.positions.iter().flat_map(|v| v.to_array())),
            n,
            "VEC3",
            5126,
            Some((lo, hi)),
        );
        let nm = push(
            f32s(&mut m.normals.iter().flat_map(|v| v.to_array())),
            n,
            "VEC3",
            5126,
            None,
        );
        let mut attributes = serde_json::json!({ "POSITION": p, "NORMAL": nm });
        if let Some(t) = &m.uv0 {
            let t = push(
                f32s(&mut t.iter().flat_map(|v| v.to_array())),
                n,
                "VEC2",
                5126,
                None,
            );
            attributes["TEXCOORD_0"] = t.into();
        }
        let idx: Vec<u8> = m.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let i = push(idx, m.indices.len(), "SCALAR", 5125, None);
        meshes.push(serde_json::json!({
            "name": m.name,
            "primitives": [{ "attributes": attributes, "indices": i, "material": 0 }],
        }));
    }
    let json = serde_json::json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{ "nodes": [0, 1] }],
        "nodes": [
            { "name": "room", "mesh": 0 },
            { "name": "box", "mesh": 1, "translation": [0.3, -1.2, 0.2], "scale": [-1.0, 1.0, 1.0] },
        ],
        "meshes": meshes,
        "materials": [{
            "name": "glow",
            "pbrMetallicRoughness": { "baseColorFactor": [ALBEDO, ALBEDO, ALBEDO, 1.0] },
            "emissiveFactor": [1.0, 1.0, 1.0],
            "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": LE } },
        }],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{ "byteLength": bin.len(), "uri": "room.bin" }],
    });
    std::fs::write(dir.join("room.bin"), &bin).unwrap();
    let path = dir.join("room.gltf");
    std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    path
}

fn options(resolution: Resolution) -> PrepareOptions {
    PrepareOptions {
        resolution,
        layout: Layout::Auto,
    }
}

/// Texel centres strictly inside more than one UV triangle of the page: charts overlap.
fn centres_covered_twice(lightmap: &Lightmap, scene: &Scene) -> usize {
    let mut covered: HashMap<(u32, u32, u32), u32> = HashMap::new();
    for (t, uv) in scene.triangles.iter().zip(&lightmap.uv) {
        let Some(uv) = uv else { continue };
        let page = lightmap.mesh_page[t.mesh as usize];
        let (w, h) = lightmap.pages[page as usize];
        let q = uv.map(|v| v * Vec2::new(w as f32, h as f32));
        let area = (q[1] - q[0]).perp_dot(q[2] - q[0]);
        let lo = q[0].min(q[1]).min(q[2]).floor();
        let hi = q[0].max(q[1]).max(q[2]).ceil();
        for y in lo.y.max(0.0) as u32..(hi.y as u32).min(h) {
            for x in lo.x.max(0.0) as u32..(hi.x as u32).min(w) {
                let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let l0 = (q[1] - c).perp_dot(q[2] - c) / area;
                let l1 = (q[2] - c).perp_dot(q[0] - c) / area;
                if l0 > 1e-4 && l1 > 1e-4 && 1.0 - l0 - l1 > 1e-4 {
                    *covered.entry((page, x, y)).or_default() += 1;
                }
            }
        }
    }
    covered.values().filter(|&&n| n > 1).count()
}

/// Charts as connected sets of triangles sharing a UV vertex (same mesh, same bits).
fn chart_of_triangle(lightmap: &Lightmap, scene: &Scene) -> Vec<usize> {
    let n = scene.triangles.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    let mut first: HashMap<(u32, [u32; 2]), usize> = HashMap::new();
    for (i, (t, uv)) in scene.triangles.iter().zip(&lightmap.uv).enumerate() {
        for v in uv.iter().flatten() {
            let key = (t.mesh, v.to_array().map(f32::to_bits));
            let j = *first.entry(key).or_insert(i);
            let (a, b) = (root(&mut parent, i), root(&mut parent, j));
            parent[a] = b;
        }
    }
    (0..n).map(|i| root(&mut parent, i)).collect()
}

/// The smallest Chebyshev distance (up to `PADDING + 2`) between texels of two different
/// charts.
fn closest_charts(f: &TexelFile, chart: &[usize]) -> u32 {
    let mut owners: Vec<Vec<usize>> = f
        .pages()
        .iter()
        .map(|p| vec![usize::MAX; p.width as usize * p.height as usize])
        .collect();
    for x in f.texels() {
        let w = f.pages()[x.page as usize].width as usize;
        owners[x.page as usize][x.pixel[1] as usize * w + x.pixel[0] as usize] =
            chart[x.triangle as usize];
    }
    let r = PADDING as i64 + 2;
    let mut best = r as u32 + 1;
    for x in f.texels() {
        let page = f.pages()[x.page as usize];
        let (w, h) = (i64::from(page.width), i64::from(page.height));
        let owner = &owners[x.page as usize];
        let c = chart[x.triangle as usize];
        let (px, py) = (i64::from(x.pixel[0]), i64::from(x.pixel[1]));
        for y in (py - r).max(0)..=(py + r).min(h - 1) {
            for xx in (px - r).max(0)..=(px + r).min(w - 1) {
                let o = owner[(y * w + xx) as usize];
                if o != usize::MAX && o != c {
                    best = best.min((xx - px).unsigned_abs().max((y - py).unsigned_abs()) as u32);
                }
            }
        }
    }
    best
}

#[test]
fn a_room_without_lightmap_uvs_unwraps_bakes_and_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = room_with_box(dir.path());
    let scene = Scene::load(&gltf).unwrap();
    assert_eq!(scene.meshes_without_lightmap_uvs(), ["room", "box"]);
    let texels = dir.path().join("room.texels");
    let (report, lightmap) = prepare_with(
        &scene,
        &texels,
        options(Resolution::TexelsPerUnit(6.0)),
        Unwrap::Missing,
    )
    .unwrap();
    let unwrap = report.unwrap.as_ref().expect("the unwrapper ran");
    assert_eq!(unwrap.meshes, ["room", "box"]);
    assert!(report.meshes_without_lightmap_uvs.is_empty());
    assert!(unwrap.charts >= 12, "{} charts for 12 faces", unwrap.charts);
    let f = TexelFile::open(&texels).unwrap();
    // 6·16 m² + 6·1 m² at 6 texels per unit: ≈ 3672 texels covered, plus chart borders.
    let area_texels = 102.0 * 36.0;
    let covered = (report.texels - report.partial_texels) as f64;
    assert!(
        (covered / area_texels - 1.0).abs() < 0.1,
        "{covered} centre-covered texels for {area_texels} texels of area"
    );
    assert_texels_on_triangles(&scene, &f);
    assert_eq!(
        centres_covered_twice(&lightmap, &scene),
        0,
        "charts overlap"
    );
    let charts = chart_of_triangle(&lightmap, &scene);
    let gap = closest_charts(&f, &charts);
    assert!(
        gap > PADDING,
        "texels of two charts {gap} apart: fewer than {PADDING} empty texels between"
    );

    // Written back: the same triangles, TEXCOORD_0 kept, and the same texels again.
    let glb = dir.path().join("room.glb");
    write_glb(&scene, &lightmap, &glb).unwrap();
    let back = Scene::load(&glb).unwrap();
    assert!(back.meshes_without_lightmap_uvs().is_empty());
    assert_eq!(back.triangles.len(), scene.triangles.len());
    for (a, b) in scene.triangles.iter().zip(&back.triangles) {
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.normals, b.normals);
    }
    assert_box_keeps_texcoord_0(&glb);
    // The bake, of the written scene: the series transport looks bounced light up through
    // the scene's lightmap UVs, which only the written file has. A closed room of one
    // emitting material has E = π Le (1 + ρ + … + ρ^(B−1))
    // at every point, and every sample of the series transport without guiding is the same.
    let bounces = 3;
    let out = dir.path().join("room.exr");
    let job = BakeJob {
        texels: texels.clone(),
        out: out.clone(),
        settings: BakeSettings {
            spp: 16,
            iterations: 1,
            transport: Transport::Series,
            bounces,
            guiding: Guiding::Off,
            emitters: EmitterSampling::Hits,
            ..Default::default()
        },
        threads: 2,
        shard: Shard::WHOLE,
        resume: false,
        aux: false,
        finish: FinishOptions::default(),
    };
    // The texel file carries the lightmap UVs its series passes read bounces through, so the
    // original scene, which has none, bakes to the same bits as the one written back with
    // them.
    let original = dir.path().join("original.exr");
    let job_original = BakeJob {
        out: original.clone(),
        ..job.clone()
    };
    bake(
        &job_original,
        &scene,
        &AtomicBool::new(false),
        &mut |_, _| {},
    )
    .unwrap();
    // So does one whose TEXCOORD_1 is some other layout (every triangle squeezed onto the
    // page's corner).
    let mut other = back.clone();
    for t in &mut other.triangles {
        t.lightmap_uv = t.lightmap_uv.map(|q| q.map(|v| v * 0.01));
    }
    let squeezed = dir.path().join("squeezed.exr");
    let job_squeezed = BakeJob {
        out: squeezed.clone(),
        ..job.clone()
    };
    bake(
        &job_squeezed,
        &other,
        &AtomicBool::new(false),
        &mut |_, _| {},
    )
    .unwrap();
    bake(&job, &back, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    for (what, path) in [("without UVs", &original), ("with other UVs", &squeezed)] {
        assert_eq!(
            std::fs::read(path).unwrap(),
            std::fs::read(&out).unwrap(),
            "the scene {what} bakes other bits than the one with the atlas"
        );
    }
    let rho = f64::from(ALBEDO);
    let want =
        std::f64::consts::PI * f64::from(LE) * (1.0 - rho.powi(bounces as i32)) / (1.0 - rho);
    let red = red_channel(&out);
    let (w, _) = report.pages[0];
    let mut worst = (0.0f64, 0u32, 0u32, false);
    for x in f.texels() {
        let v = red[x.pixel[1] as usize * w as usize + x.pixel[0] as usize];
        let err = (v - want).abs() / want;
        if err > worst.0 {
            worst = (
                err,
                u32::from(x.pixel[0]),
                u32::from(x.pixel[1]),
                x.flags & FLAG_PARTIAL != 0,
            );
        }
    }
    assert!(
        worst.0 < 1e-4,
        "texel {:?} (partial: {}) is {:.2e} off the closed form {want}",
        (worst.1, worst.2),
        worst.3,
        worst.0
    );

    let again = dir.path().join("again.texels");
    let (w, h) = report.pages[0];
    let opts = PrepareOptions {
        resolution: Resolution::Size(w, h),
        layout: Layout::Shared,
    };
    let (report2, _) = prepare_with(&back, &again, opts, Unwrap::Never).unwrap();
    assert_eq!(report2.pages, report.pages);
    let g = TexelFile::open(&again).unwrap();
    assert_eq!(g.pages(), f.pages());
    assert_eq!(g.triangles(), f.triangles());
    assert_eq!(g.tiles(), f.tiles());
    assert!(
        g.texels() == f.texels(),
        "the written glTF gives other texels"
    );
}

/// Every vertex of the written box has the TEXCOORD_0 of the source vertex at its place.
fn assert_box_keeps_texcoord_0(glb: &Path) {
    let (doc, buffers, _) = gltf::import(glb).unwrap();
    let mesh = doc.meshes().find(|m| m.name() == Some("box")).unwrap();
    let prim = mesh.primitives().next().unwrap();
    let r = prim.reader(|b| Some(&buffers[b.index()].0[..]));
    let p: Vec<[f32; 3]> = r.read_positions().unwrap().collect();
    let n: Vec<[f32; 3]> = r.read_normals().unwrap().collect();
    let t0: Vec<[f32; 2]> = r.read_tex_coords(0).unwrap().into_f32().collect();
    let t1: Vec<[f32; 2]> = r.read_tex_coords(1).unwrap().into_f32().collect();
    assert_eq!(t1.len(), p.len());
    assert!(p.len() >= 24, "{} vertices: split, never merged", p.len());
    let faces: Vec<_> = inward_box_faces(Vec3::splat(-0.5), 1.0)
        .iter()
        .map(|&(c, u, v)| (c, v, u))
        .collect();
    let source = quads("box", &faces, true);
    for ((p, n), t) in p.iter().zip(&n).zip(&t0) {
        let i = source
            .positions
            .iter()
            .zip(&source.normals)
            .position(|(sp, sn)| sp.to_array() == *p && sn.to_array() == *n)
            .expect("a source vertex");
        assert_eq!(source.uv0.as_ref().unwrap()[i].to_array(), *t);
    }
}

fn red_channel(path: &Path) -> Vec<f64> {
    let image = exr::prelude::read_first_flat_layer_from_file(path).unwrap();
    image
        .layer_data
        .channel_data
        .list
        .iter()
        .find(|c| c.name == *"R")
        .unwrap()
        .sample_data
        .values_as_f32()
        .map(f64::from)
        .collect()
}

#[test]
fn the_same_scene_gives_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load(&room_with_box(dir.path())).unwrap();
    let run = |name: &str| {
        let texels = dir.path().join(format!("{name}.texels"));
        let glb = dir.path().join(format!("{name}.glb"));
        let (_, lightmap) = prepare_with(
            &scene,
            &texels,
            options(Resolution::Default),
            Unwrap::Always,
        )
        .unwrap();
        write_glb(&scene, &lightmap, &glb).unwrap();
        (std::fs::read(texels).unwrap(), std::fs::read(glb).unwrap())
    };
    assert!(run("a") == run("b"));
}

/// `--size` is met on one page; a world too big for one page spills onto more (the unit
/// test `prepare::tests::a_world_too_big_for_a_page_spills_onto_more` checks that without
/// writing gigabytes).
#[test]
fn a_size_is_met_on_one_page() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load(&room_with_box(dir.path())).unwrap();
    let out = dir.path().join("s.texels");
    let (r, lightmap) = prepare_with(
        &scene,
        &out,
        options(Resolution::Size(128, 96)),
        Unwrap::Always,
    )
    .unwrap();
    assert_eq!(r.pages, [(128, 96)]);
    assert_eq!(centres_covered_twice(&lightmap, &scene), 0);
    let f = TexelFile::open(&out).unwrap();
    assert_texels_on_triangles(&scene, &f);
}

#[test]
fn a_mesh_xatlas_cannot_unwrap_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = room_with_box(dir.path());
    let mut scene = Scene::load(&gltf).unwrap();
    // The box shrunk to 1e-4 m: every triangle's area (5e-9 m²) is below what xatlas takes.
    let b = &scene.meshes[1];
    let range = b.first_triangle as usize..(b.first_triangle + b.triangle_count) as usize;
    for t in &mut scene.triangles[range] {
        t.positions = t.positions.map(|p| p * 1e-4);
    }
    let out = dir.path().join("x.texels");
    let e = prepare_with(&scene, &out, options(Resolution::Default), Unwrap::Missing)
        .expect_err("a mesh left without UVs is an error");
    assert!(matches!(e, PrepareError::Unwrap(_)), "{e}");
    let message = e.to_string();
    assert!(
        message.contains(&*gltf.to_string_lossy()) && message.contains("mesh 'box'"),
        "{message}"
    );
    assert!(!out.exists(), "no partial output");
}

#[test]
fn the_cli_unwraps_and_writes_the_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = room_with_box(dir.path());
    let texels = dir.path().join("cli.texels");
    let glb = dir.path().join("cli.glb");
    let run = |args: &[&str]| cli::run(args);
    let o = run(&[
        "prepare",
        gltf.to_str().unwrap(),
        "-o",
        texels.to_str().unwrap(),
        "--write-gltf",
        glb.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        report["unwrap"]["meshes"],
        serde_json::json!(["room", "box"])
    );
    assert!(glb.exists() && texels.exists());
    // `--unwrap never` on the same scene: nothing has lightmap UVs, an error naming the file.
    let none = dir.path().join("none.texels");
    let o = run(&[
        "prepare",
        gltf.to_str().unwrap(),
        "-o",
        none.to_str().unwrap(),
        "--unwrap",
        "never",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no mesh has lightmap UVs") && err.contains("room.gltf"),
        "{err}"
    );
    assert!(!none.exists());
    // `--write-gltf` is checked before any work: a name that is not .glb, or a directory
    // that does not exist, is an error naming it, and no texel file is written. (An OBJ scene
    // is written back too: tests/levels.rs.)
    for (bad, says) in [
        (dir.path().join("quad.gltf"), "give it a .glb name"),
        (dir.path().join("nowhere/quad.glb"), "does not exist"),
    ] {
        let quad = dir.path().join("quad.texels");
        let o = run(&[
            "prepare",
            gltf.to_str().unwrap(),
            "-o",
            quad.to_str().unwrap(),
            "--write-gltf",
            bad.to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&*bad.to_string_lossy()) && err.contains(says),
            "{err}"
        );
        assert!(!quad.exists());
    }
}

/// The shared scenes re-unwrapped: every mesh gets texels, on its triangles, without
/// overlap (the vinc3r box's meshes without TEXCOORD_1 too).
#[test]
fn shared_scenes_unwrap_without_overlap() {
    let Some(dir) = guidebake::test_support::shared_scenes_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let vinc3r = "vinc3r_cornellbox/BJS-2.80-Eevee-gltf/assets/cornellBox-2.80-Eevee-gltf.gltf";
    for (file, unwrap) in [
        ("converted/bitterli_cornell_box.glb", Unwrap::Always),
        (
            "converted/bitterli_veach_ajar_no_teapots.glb",
            Unwrap::Always,
        ),
        (vinc3r, Unwrap::Missing),
        (vinc3r, Unwrap::Always),
    ] {
        let scene = Scene::load(&dir.join(file)).unwrap();
        let out = tmp.path().join("s.texels");
        let (r, lightmap) =
            prepare_with(&scene, &out, options(Resolution::Default), unwrap).unwrap();
        assert!(r.meshes_without_lightmap_uvs.is_empty(), "{file}");
        let u = r.unwrap.as_ref().unwrap();
        println!(
            "{file} {unwrap:?}: {} meshes, {} charts, pages {:?}, utilisation {:.3}, {:.2} s",
            u.meshes.len(),
            u.charts,
            r.pages,
            u.utilisation,
            u.seconds
        );
        assert!(u.utilisation > 0.4, "{file}: {}", u.utilisation);
        assert_eq!(centres_covered_twice(&lightmap, &scene), 0, "{file}");
        let f = TexelFile::open(&out).unwrap();
        assert_texels_on_triangles(&scene, &f);
        if unwrap == Unwrap::Always {
            let gap = closest_charts(&f, &chart_of_triangle(&lightmap, &scene));
            assert!(gap > PADDING, "{file}: texels of two charts {gap} apart");
        }
    }
}
