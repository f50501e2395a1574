//! Game levels as they come (docs/levels.md): missing textures, tiling texture UVs, no
//! lights, an OBJ written back as glTF, and the Cube 2 level zdm2 (from `../shared/scenes`,
//! skipped with a message when absent) prepared, baked and rendered from the command line.

use std::path::{Path, PathBuf};

use guidebake::scene::Scene;
use guidebake::texels::TexelFile;

mod cli;
use cli::{s, succeeds};

/// Runs a command that must fail on its input (exit 1); returns its stderr.
fn fails(args: &[&str]) -> String {
    cli::fails_with(1, args)
}

/// A named plane of the small level: name, material, corner, two edges.
type Plane<'a> = (&'a str, &'a str, [f32; 3], [f32; 3], [f32; 3]);

/// A small level as an OBJ: a 4 × 4 floor and two walls (a corner open to the sky), each a
/// grid of 2 × 2 quads whose UV set is `uv(quad, corner)`, the floor textured with
/// `floor.png` (which may not exist), the walls of `Kd 0.6 0.5 0.4`.
fn corner_obj(dir: &Path, uv: impl Fn(usize, [f32; 2]) -> [f32; 2]) -> PathBuf {
    let mut obj = String::from("mtllib level.mtl\n");
    let (mut v, mut vt) = (0, 0);
    let mut faces = String::new();
    let planes: [Plane; 3] = [
        ("floor", "stone", [0.0; 3], [0.0, 0.0, 4.0], [4.0, 0.0, 0.0]),
        (
            "west",
            "plaster",
            [0.0; 3],
            [0.0, 3.0, 0.0],
            [0.0, 0.0, 4.0],
        ),
        (
            "north",
            "plaster",
            [0.0; 3],
            [4.0, 0.0, 0.0],
            [0.0, 3.0, 0.0],
        ),
    ];
    for (name, material, o, a, b) in planes {
        faces += &format!("o {name}\nusemtl {material}\n");
        let mut quad = 0;
        for j in 0..2 {
            for i in 0..2 {
                let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
                for c in corners {
                    let (s, t) = ((i as f32 + c[0]) / 2.0, (j as f32 + c[1]) / 2.0);
                    let p: Vec<f32> = (0..3).map(|k| o[k] + a[k] * s + b[k] * t).collect();
                    obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
                    let q = uv(quad, c);
                    obj += &format!("vt {} {}\n", q[0], q[1]);
                }
                faces += &format!(
                    "f {}/{} {}/{} {}/{} {}/{}\n",
                    v + 1,
                    vt + 1,
                    v + 2,
                    vt + 2,
                    v + 3,
                    vt + 3,
                    v + 4,
                    vt + 4
                );
                (v, vt, quad) = (v + 4, vt + 4, quad + 1);
            }
        }
    }
    let path = dir.join("level.obj");
    std::fs::write(&path, obj + &faces).unwrap();
    std::fs::write(
        dir.join("level.mtl"),
        "newmtl stone\nmap_Kd textures/floor.png\n\nnewmtl plaster\nKd 0.6 0.5 0.4\n",
    )
    .unwrap();
    path
}

/// UVs that tile a texture: every quad repeats it, offset by its index.
fn tiling(quad: usize, c: [f32; 2]) -> [f32; 2] {
    [c[0] * 2.0 + quad as f32, c[1] * 2.0 - 1.0]
}

const SUN: &str = "0.4,1,0.3:3";
const SKY: &str = "0.5,0.6,0.8";

#[test]
fn a_missing_texture_warns_and_bakes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = corner_obj(d, tiling);
    let texels = d.join("level.texels");
    let (out, err) = succeeds(&[
        "prepare",
        s(&obj),
        "-o",
        s(&texels),
        "--size",
        "64x64",
        "--sun",
        SUN,
        "--sky",
        SKY,
        "--json",
    ]);
    assert!(
        err.contains("warning")
            && err.contains("texture textures/floor.png cannot be read")
            && err.contains("material 'stone'"),
        "{err}"
    );
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    let missing = report["missing_textures"].as_array().unwrap();
    assert_eq!(missing.len(), 1, "{report}");
    assert_eq!(missing[0]["material"], "stone");
    assert_eq!(missing[0]["fallback"], serde_json::json!([0.5, 0.5, 0.5]));

    let lightmap = d.join("level.exr");
    let stats = d.join("stats.json");
    let (_, err) = succeeds(&[
        "bake",
        s(&texels),
        "--scene",
        s(&obj),
        "-o",
        s(&lightmap),
        "--spp",
        "32",
        "--iterations",
        "1",
        "--bounces",
        "1",
        "--sun",
        SUN,
        "--sky",
        SKY,
        "--stats",
        s(&stats),
    ]);
    assert!(err.contains("textures/floor.png"), "{err}");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(stats["missing_textures"], 1, "{stats}");
    assert_eq!(stats["missing_texture_files"][0]["material"], "stone");
    // The floor, in the sun and under the sky, is lit.
    let f = TexelFile::open(&texels).unwrap();
    let values = guidebake::output::readback::read_lightmap(&f, &lightmap).unwrap();
    let brightest = values.iter().flatten().map(|v| v[1]).fold(0.0f32, f32::max);
    assert!(brightest > 1.0, "{brightest}");
}

#[test]
fn uv_sets_that_are_not_lightmap_atlases_are_unwrapped_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // (UV set, what the note says, unwrapped): tiling outside [0, 1]; every quad on the
    // whole square (overlapping itself inside [0, 1]); a true atlas, each quad in its cell.
    type Uv = fn(usize, [f32; 2]) -> [f32; 2];
    let cases: [(Uv, Option<&str>); 3] = [
        (tiling, Some("leaves [0, 1]")),
        (|_, c| c, Some("overlaps itself (100.0 %")),
        (
            |q, c| {
                let (x, y) = ((q % 2) as f32, (q / 2) as f32);
                [(x + 0.1 + 0.8 * c[0]) / 2.0, (y + 0.1 + 0.8 * c[1]) / 2.0]
            },
            None,
        ),
    ];
    for (uv, note) in cases {
        let obj = corner_obj(d, uv);
        let texels = d.join("level.texels");
        let (out, err) = succeeds(&[
            "prepare",
            s(&obj),
            "-o",
            s(&texels),
            "--size",
            "64x64",
            "--sky",
            SKY,
            "--json",
        ]);
        let report: serde_json::Value = serde_json::from_str(&out).unwrap();
        let not_atlas = report["not_atlas"].as_array().unwrap();
        match note {
            Some(note) => {
                let meshes: Vec<&str> = not_atlas
                    .iter()
                    .map(|n| n["mesh"].as_str().unwrap())
                    .collect();
                assert_eq!(meshes, ["floor", "west", "north"], "{report}");
                for n in not_atlas {
                    let reason = n["reason"].as_str().unwrap();
                    assert!(reason.starts_with(note), "{reason}");
                    assert_eq!(n["unwrapped"], true);
                    assert!(
                        err.contains(&format!(
                            "note: mesh '{}': its UV set {reason}",
                            n["mesh"].as_str().unwrap()
                        )),
                        "{err}"
                    );
                }
                assert_eq!(
                    report["unwrap"]["meshes"],
                    serde_json::json!(["floor", "west", "north"])
                );
                // Unwrapped: no texel centre is covered twice, every texel on its triangle.
                let scene = Scene::load(&obj).unwrap();
                let f = TexelFile::open(&texels).unwrap();
                guidebake::test_support::assert_texels_on_triangles(&scene, &f);
            }
            None => {
                assert!(not_atlas.is_empty(), "{report}");
                assert!(report.get("unwrap").is_none(), "{report}");
            }
        }
        // `--unwrap never` keeps the UV set as it is, and still says why it is no atlas.
        let (out, _) = succeeds(&[
            "prepare",
            s(&obj),
            "-o",
            s(&texels),
            "--size",
            "64x64",
            "--sky",
            SKY,
            "--unwrap",
            "never",
            "--json",
        ]);
        let report: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert!(report.get("unwrap").is_none(), "{report}");
        assert_eq!(
            report["not_atlas"].as_array().unwrap().len(),
            if note.is_some() { 3 } else { 0 }
        );
    }
}

#[test]
fn an_obj_writes_a_gltf_back_whose_texcoord_1_reprepares_to_the_same_texels() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = corner_obj(d, tiling);
    std::fs::create_dir(d.join("textures")).unwrap();
    image::RgbImage::from_fn(4, 4, |x, y| image::Rgb([60 * x as u8, 60 * y as u8, 128]))
        .save(d.join("textures/floor.png"))
        .unwrap();
    // Wrapped in a scene file with the sky, as a level usually is.
    let toml = d.join("level.toml");
    std::fs::write(
        &toml,
        "geometry = \"level.obj\"\n[sky]\nconstant = [0.5, 0.6, 0.8]\n",
    )
    .unwrap();
    let (texels, glb) = (d.join("a.texels"), d.join("level.glb"));
    let (_, err) = succeeds(&[
        "prepare",
        s(&toml),
        "-o",
        s(&texels),
        "--size",
        "64x64",
        "--sun",
        SUN,
        "--write-gltf",
        s(&glb),
    ]);
    assert!(!err.contains("warning"), "{err}");
    let source = Scene::load(&obj).unwrap();
    let written = Scene::load(&glb).unwrap();
    assert_eq!(written.meshes.len(), source.meshes.len());
    assert_eq!(written.triangles.len(), source.triangles.len());
    for (a, b) in source.triangles.iter().zip(&written.triangles) {
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.texture_uv, b.texture_uv, "TEXCOORD_0 is the texture's");
        assert!(b.lightmap_uv.is_some());
    }
    let textured = written
        .materials
        .iter()
        .find(|m| m.name == "stone")
        .unwrap();
    assert_eq!(
        textured.base_color_texture.as_ref().unwrap().image.size(),
        (4, 4)
    );
    // Re-prepared from its TEXCOORD_1 (the same sun and sky), the same texels.
    let again = d.join("b.texels");
    succeeds(&[
        "prepare",
        s(&glb),
        "-o",
        s(&again),
        "--size",
        "64x64",
        "--unwrap",
        "never",
        "--layout",
        "shared",
        "--sun",
        SUN,
        "--sky",
        SKY,
    ]);
    let (a, b) = (
        TexelFile::open(&texels).unwrap(),
        TexelFile::open(&again).unwrap(),
    );
    assert_eq!(a.pages(), b.pages());
    assert_eq!(a.triangles(), b.triangles());
    assert_eq!(a.tiles(), b.tiles());
    assert_eq!(a.texels(), b.texels());
}

#[test]
fn a_scene_without_lights_names_the_flags() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = corner_obj(d, tiling);
    let texels = d.join("level.texels");
    let err = fails(&["prepare", s(&obj), "-o", s(&texels), "--size", "64x64"]);
    assert!(
        err.contains(s(&obj))
            && err.contains("nothing lights this scene")
            && err.contains("--sun")
            && err.contains("--sky"),
        "{err}"
    );
    assert!(!texels.exists(), "no partial output");
    // Lit for prepare, not for the bake: the bake says the same.
    succeeds(&[
        "prepare",
        s(&obj),
        "-o",
        s(&texels),
        "--size",
        "64x64",
        "--sky",
        SKY,
    ]);
    let lightmap = d.join("level.exr");
    let err = fails(&[
        "bake",
        s(&texels),
        "--scene",
        s(&obj),
        "-o",
        s(&lightmap),
        "--spp",
        "32",
    ]);
    assert!(err.contains("--sun") && err.contains("--sky"), "{err}");
    assert!(!lightmap.exists());
    // Bad flags are usage errors naming them.
    for (flag, value) in [("--sun", "0,0,0"), ("--sun", "1,2"), ("--sky", "-1")] {
        let err = cli::fails_with(2, &["prepare", s(&obj), "-o", s(&texels), flag, value]);
        assert!(err.contains(flag) && err.contains(value), "{err}");
    }
}

/// `prepare` records the lights it decided the seen sides under (the texel header's
/// `lighting`); a bake under other lights says so, naming the texel file, and bakes; a bake
/// under the same lights does not.
#[test]
fn a_bake_under_other_lights_than_prepare_is_told() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = corner_obj(d, tiling);
    let texels = d.join("level.texels");
    let sun = ["--sun", "0.3,1,0.2:3"];
    succeeds(
        &[
            &["prepare", s(&obj), "-o", s(&texels), "--size", "64x64"][..],
            &sun,
            &["--sky", SKY],
        ]
        .concat(),
    );
    let header = TexelFile::open(&texels).unwrap().header().lighting;
    assert_ne!(header, 0, "prepare records its lights");
    let bake = |lights: &[&str]| {
        let lightmap = d.join("level.exr");
        let (_, err) = succeeds(
            &[
                &[
                    "bake",
                    s(&texels),
                    "--scene",
                    s(&obj),
                    "-o",
                    s(&lightmap),
                    "--spp",
                    "8",
                    "--iterations",
                    "1",
                ][..],
                lights,
            ]
            .concat(),
        );
        assert!(lightmap.exists());
        err
    };
    let same = bake(&[&sun[..], &["--sky", SKY]].concat());
    assert!(!same.contains("other lights"), "{same}");
    for other in [
        vec!["--sun", "0.3,1,0.2:4", "--sky", SKY],
        vec!["--sun", "-0.3,1,0.2:3", "--sky", SKY],
        vec!["--sun", "0.3,1,0.2:3"],
    ] {
        let err = bake(&other);
        assert!(
            err.contains("prepared under other lights") && err.contains(s(&texels)),
            "{other:?}: {err}"
        );
    }
}

/// The Cube 2 level zdm2 as it comes — an OBJ with tiling texture UVs, its textures missing,
/// no lights — prepared with the default options, baked cheaply and rendered from inside,
/// with a sun and a sky from the command line.
#[test]
fn zdm2_bakes_with_a_sun_and_a_sky_from_the_command_line() {
    let Some(scenes) = guidebake::test_support::shared_scenes_dir() else {
        return;
    };
    let obj = scenes.join("calinou_zdm2/zdm2.obj");
    if !obj.exists() {
        eprintln!("skipping: {} is absent", obj.display());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (texels, lightmap, view) = (
        d.join("zdm2.texels"),
        d.join("zdm2.exr"),
        d.join("zdm2.png"),
    );
    let (sun, sky) = ("0.3,1,0.45:4", "0.45,0.55,0.7");
    let (out, err) = succeeds(&[
        "prepare",
        s(&obj),
        "-o",
        s(&texels),
        "--sun",
        sun,
        "--sky",
        sky,
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(
        report["missing_textures"].as_array().unwrap().len() > 10,
        "{err}"
    );
    assert!(
        err.contains("warning: ") && err.contains("packages/"),
        "{err}"
    );
    let meshes = report["unwrap"]["meshes"].as_array().unwrap().len();
    assert_eq!(report["not_atlas"].as_array().unwrap().len(), meshes);
    assert!(report["texels"].as_u64().unwrap() > 100_000, "{report}");
    succeeds(&[
        "bake",
        s(&texels),
        "--scene",
        s(&obj),
        "-o",
        s(&lightmap),
        "--spp",
        "8",
        "--iterations",
        "1",
        "--bounces",
        "1",
        "--sun",
        sun,
        "--sky",
        sky,
    ]);
    let (_, err) = succeeds(&[
        "render",
        s(&obj),
        "--texels",
        s(&texels),
        "--lightmap",
        s(&lightmap),
        "-o",
        s(&view),
        "--width",
        "96",
        "--sun",
        sun,
        "--sky",
        sky,
    ]);
    assert!(err.contains("inside, at"), "{err}");
    let png = image::open(&view).unwrap().to_rgb8();
    let mean = png.pixels().map(|p| u32::from(p[1])).sum::<u32>() / (png.width() * png.height());
    assert!(
        (20..235).contains(&mean),
        "a lit view, not black or white: {mean}"
    );
}

/// Many small charts on a page too small for their padding: the error names a page size, and
/// that size holds them.
#[test]
fn an_atlas_that_cannot_fit_names_the_page_size_that_would() {
    use glam::Vec3;
    use guidebake::prepare::{Layout, PrepareOptions, Resolution, Unwrap, prepare_with};
    use guidebake::scene::{Material, Triangle};
    let dir = tempfile::tempdir().unwrap();
    // 400 separate triangles in a row: 400 charts.
    let triangles: Vec<Triangle> = (0..400)
        .map(|i| {
            let o = Vec3::new(i as f32 * 2.0, 0.0, 0.0);
            Triangle {
                positions: [o, o + Vec3::X, o + Vec3::Z],
                normals: [Vec3::Y; 3],
                lightmap_uv: None,
                texture_uv: None,
                colour: None,
                mesh: 0,
                material: 0,
            }
        })
        .collect();
    let mut scene = Scene::of_triangles("chips", triangles, vec![Material::default_grey()]);
    scene.sky = guidebake::scene::Sky::Constant(Vec3::ONE);
    let out = dir.path().join("chips.texels");
    let options = |w, h| PrepareOptions {
        resolution: Resolution::Size(w, h),
        layout: Layout::Auto,
    };
    let e = prepare_with(&scene, &out, options(16, 16), Unwrap::Missing)
        .expect_err("400 charts do not fit 16x16")
        .to_string();
    assert!(e.contains("400 charts do not fit one 16x16 page"), "{e}");
    assert!(!out.exists());
    let size = e
        .split("(--size ")
        .nth(1)
        .and_then(|r| r.split(')').next())
        .unwrap();
    let (w, h) = size.split_once('x').unwrap();
    let (w, h): (u32, u32) = (w.parse().unwrap(), h.parse().unwrap());
    assert!(w > 16 && h > 16 && w <= 1024, "{size}");
    let (report, _) = prepare_with(&scene, &out, options(w, h), Unwrap::Missing)
        .unwrap_or_else(|e| panic!("the size it named, {size}, holds them: {e}"));
    assert_eq!(report.pages, [(w, h)]);
}

/// A room the bake leaves black: prepared open to a sky (its sides are baked), then baked and
/// rendered under a black sky and a sun below the horizon. Every surface `render`'s view sees
/// is black, so it names the picture and the lightmap, says what to try, writes nothing and
/// exits 1 — and writes the picture when `--exposure` asks for it anyway. (The automatic
/// view's fallback from a dark enclosed space is `render.rs`'s unit test.)
#[test]
fn a_black_lightmap_renders_no_black_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = d.join("room.obj");
    // A 4 × 4 floor and four 2 m walls, no roof: quads (corner, edge, edge).
    let quads: [([f32; 3], [f32; 3], [f32; 3]); 5] = [
        ([0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 0.0, 4.0]),
        ([0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
        ([0.0, 0.0, 4.0], [4.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
        ([0.0, 0.0, 0.0], [0.0, 0.0, 4.0], [0.0, 2.0, 0.0]),
        ([4.0, 0.0, 0.0], [0.0, 0.0, 4.0], [0.0, 2.0, 0.0]),
    ];
    let mut text = String::new();
    for (i, (o, u, v)) in quads.iter().enumerate() {
        for (a, b) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            let p: Vec<f32> = (0..3).map(|k| o[k] + a * u[k] + b * v[k]).collect();
            text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        let f = 4 * i + 1;
        text += &format!("f {} {} {}\nf {} {} {}\n", f, f + 1, f + 2, f, f + 2, f + 3);
    }
    std::fs::write(&obj, text).unwrap();
    let texels = d.join("room.texels");
    let lights = ["--sun", "0.4,-1,0.3:3", "--sky", "0,0,0"];
    succeeds(&[
        "prepare",
        s(&obj),
        "-o",
        s(&texels),
        "--size",
        "64x64",
        "--sky",
        SKY,
    ]);
    let lightmap = d.join("room.exr");
    let bake = [
        &[
            "bake",
            s(&texels),
            "--scene",
            s(&obj),
            "-o",
            s(&lightmap),
            "--spp",
            "24",
            "-q",
        ][..],
        &lights,
    ]
    .concat();
    succeeds(&bake);
    let view = d.join("view.png");
    let render = [
        &[
            "render",
            s(&obj),
            "--texels",
            s(&texels),
            "--lightmap",
            s(&lightmap),
            "-o",
            s(&view),
            "--width",
            "64",
        ][..],
        &lights,
    ]
    .concat();
    let err = fails(&render);
    assert!(
        err.contains(s(&lightmap))
            && err.contains("every surface this view sees is black")
            && err.contains("--exposure"),
        "{err}"
    );
    assert!(!view.exists(), "nothing written");
    succeeds(&[&render[..], &["--exposure", "1"]].concat());
    assert!(view.is_file());
}
