//! Roles of a level's surfaces, from the command line to the lightmap (docs/levels.md,
//! "Roles: sky shells, clip brushes and caulk"): a plane under a constant sky, closed in by a
//! shell or shaded by a blocker, baked under each role. Under a constant sky L with nothing
//! above it, a plane's irradiance is πL exactly (every ray escapes: each sample is L), so the
//! roles that let rays through must give exactly that, and the others a shadow.

use std::path::{Path, PathBuf};

use guidebake::scene::Role;
use guidebake::texels::TexelFile;

mod cli;
use cli::{s, succeeds};

/// The sky's radiance, one value for grey.
const SKY: f32 = 0.5;

/// An OBJ: a 4 × 4 plane at y = 0 facing up (object `plane`, material `stone`, lightmap UVs
/// on the left half of the atlas) and `extra`: OBJ lines of further objects, whose vertices
/// are numbered from 5 and UVs from 5.
fn level(dir: &Path, extra: &str) -> PathBuf {
    let mut obj = String::from("mtllib level.mtl\no plane\nusemtl stone\n");
    for (x, z) in [(0.0, 0.0), (0.0, 4.0), (4.0, 4.0), (4.0, 0.0)] {
        obj += &format!("v {x} 0 {z}\n");
    }
    for (u, v) in [(0.02, 0.02), (0.02, 0.98), (0.48, 0.98), (0.48, 0.02)] {
        obj += &format!("vt {u} {v}\n");
    }
    obj += "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n";
    obj += extra;
    let path = dir.join("level.obj");
    std::fs::write(&path, obj).unwrap();
    std::fs::write(
        dir.join("level.mtl"),
        "newmtl stone\nKd 0.5 0.5 0.5\nnewmtl shell\nKd 0.5 0.5 0.5\nnewmtl board\nKd 0.5 0.5 0.5\n",
    )
    .unwrap();
    path
}

/// A closed box from (−10, −1, −10) to (10, 10, 10) around the plane, wound inwards
/// (object `box`, material `shell`, no UVs).
fn shell() -> String {
    closed_box("box", "shell", [-10.0, -1.0, -10.0], [10.0, 10.0, 10.0], 4)
}

/// OBJ lines of a closed box from `a` to `b` wound inwards, object `object`, material
/// `material`, no UVs; the file has `vertices` vertices before it.
fn closed_box(object: &str, material: &str, a: [f32; 3], b: [f32; 3], vertices: usize) -> String {
    let mut out = format!("o {object}\nusemtl {material}\n");
    for i in 0..8 {
        let pick = |k: usize| if i >> k & 1 == 1 { b[k] } else { a[k] };
        out += &format!("v {} {} {}\n", pick(0), pick(1), pick(2));
    }
    // Quads of corner indices (bit 0 x, bit 1 y, bit 2 z), each wound to face the inside.
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    for q in quads {
        let [a, b, c, d] = q.map(|k| k + 1 + vertices);
        out += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
    }
    out
}

/// A 2 × 2 board 1 m above the plane's centre, facing down, its UVs on the right half of
/// the atlas (object `blocker`, material `board`).
fn blocker() -> String {
    let mut out = String::from("o blocker\nusemtl board\n");
    for (x, z) in [(1.0, 1.0), (3.0, 1.0), (3.0, 3.0), (1.0, 3.0)] {
        out += &format!("v {x} 1 {z}\n");
    }
    for (u, v) in [(0.52, 0.02), (0.98, 0.02), (0.98, 0.98), (0.52, 0.98)] {
        out += &format!("vt {u} {v}\n");
    }
    out + "f 5/5 6/6 7/7\nf 5/5 7/7 8/8\n"
}

/// What a bake gave: per valid texel, its triangle and its irradiance's luminance.
struct Baked {
    texels: Vec<(u32, f32)>,
    prepare_err: String,
    report: serde_json::Value,
}

impl Baked {
    /// Texels of the triangles `tris`.
    fn on(&self, tris: std::ops::Range<u32>) -> Vec<f32> {
        self.texels
            .iter()
            .filter(|(t, _)| tris.contains(t))
            .map(|&(_, e)| e)
            .collect()
    }
}

/// Prepares (with `roles`, each a `--role` value) and bakes `obj` under the constant sky.
fn bake(obj: &Path, roles: &[&str]) -> Baked {
    let d = obj.parent().unwrap();
    let texels = d.join("level.texels");
    let sky = SKY.to_string();
    let mut args = vec![
        "prepare",
        s(obj),
        "-o",
        s(&texels),
        "--size",
        "32x32",
        "--sky",
        &sky,
        "--json",
    ];
    for r in roles {
        args.extend(["--role", r]);
    }
    let (out, prepare_err) = succeeds(&args);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    let lightmap = d.join("level.exr");
    succeeds(&[
        "bake",
        s(&texels),
        "--scene",
        s(obj),
        "-o",
        s(&lightmap),
        "--spp",
        "64",
        "--sky",
        &sky,
        "--quiet",
    ]);
    let f = TexelFile::open(&texels).unwrap();
    let values = guidebake::output::readback::read_lightmap(&f, &lightmap).unwrap();
    let texels = f
        .texels()
        .iter()
        .zip(values)
        .filter_map(|(t, v)| v.map(|rgb| (t.triangle, rgb[1])))
        .collect();
    Baked {
        texels,
        prepare_err,
        report,
    }
}

/// Every value is πL to a part in 10⁴.
fn all_pi_l(values: &[f32]) -> bool {
    let want = std::f32::consts::PI * SKY;
    !values.is_empty() && values.iter().all(|e| (e - want).abs() <= 1e-4 * want)
}

#[test]
fn a_sky_shell_darkens_the_level_until_it_gets_the_sky_role() {
    let dir = tempfile::tempdir().unwrap();
    let obj = level(dir.path(), &shell());
    // As it comes: the shell keeps the sky out; prepare names it and the role that opens it.
    let closed = bake(&obj, &[]);
    let err = &closed.prepare_err;
    assert!(
        err.contains("no sun or sky reaches inside the level: material 'shell' (12 triangles)")
            && err.contains("--role 'sky=material:shell'"),
        "{err}"
    );
    assert_eq!(closed.report["shell"]["names"][0], "shell");
    let inside = closed.on(0..2);
    assert!(inside.iter().all(|&e| e == 0.0), "{inside:?}");
    // With the role the shell is an opening: the plane sees the sky and gets πL.
    let open = bake(&obj, &["sky=material:shell"]);
    assert!(
        !open.prepare_err.contains("no sun or sky"),
        "{}",
        open.prepare_err
    );
    assert!(all_pi_l(&open.on(0..2)), "{:?}", open.on(0..2));
    assert!(open.on(2..14).is_empty(), "a sky shell has no texels");
    assert_eq!(open.report["roles"]["roles"][0]["role"], "sky");
    assert_eq!(open.report["roles"]["roles"][0]["triangles"], 12);
    // Written back for the engine, the level keeps the role in its nodes' extras.
    let glb = dir.path().join("level.glb");
    let texels = dir.path().join("again.texels");
    succeeds(&[
        "prepare",
        s(&obj),
        "-o",
        s(&texels),
        "--sky",
        "0.5",
        "--role",
        "sky=material:shell",
        "--write-gltf",
        s(&glb),
    ]);
    let scene = guidebake::scene::Scene::load(&glb).unwrap();
    let roles: Vec<_> = (0..scene.triangles.len()).map(|t| scene.role(t)).collect();
    assert_eq!(roles.iter().filter(|&&r| r == Role::Sky).count(), 12);
    assert_eq!(roles.iter().filter(|&&r| r == Role::Baked).count(), 2);
}

#[test]
fn each_role_of_a_blocker_decides_its_texels_and_its_shadow() {
    let dir = tempfile::tempdir().unwrap();
    let obj = level(dir.path(), &blocker());
    // (role, the blocker has texels, it shades the plane)
    let cases = [
        ("baked", true, true),
        ("skip", false, false),
        ("no-shadow", true, false),
        ("occluder", false, true),
    ];
    for (role, texels, shades) in cases {
        let rule = format!("{role}=mesh:blocker");
        let baked = bake(&obj, &[&rule]);
        let plane = baked.on(0..2);
        assert_eq!(!baked.on(2..4).is_empty(), texels, "{role}");
        if shades {
            let least = plane.iter().copied().fold(f32::INFINITY, f32::min);
            assert!(
                least < 0.7 * std::f32::consts::PI * SKY,
                "{role}: the plane under the blocker is in its shadow: {least}"
            );
        } else {
            assert!(all_pi_l(&plane), "{role}: {plane:?}");
        }
    }
}

#[test]
fn names_that_say_clip_or_sky_take_their_role_without_a_flag_and_a_rule_that_names_nothing_is_said()
{
    let dir = tempfile::tempdir().unwrap();
    // The blocker renamed as a clip brush, the shell's material as the sky.
    let extra =
        blocker().replace("o blocker", "o playerclip") + &shell().replace("o box", "o dome");
    let mtl_sky = |obj: &Path| {
        let mtl = obj.with_file_name("level.mtl");
        let text = std::fs::read_to_string(&mtl)
            .unwrap()
            .replace("newmtl shell", "newmtl sky");
        std::fs::write(&mtl, text).unwrap();
        let o = std::fs::read_to_string(obj)
            .unwrap()
            .replace("usemtl shell", "usemtl sky");
        std::fs::write(obj, o).unwrap();
    };
    let obj = level(dir.path(), &extra);
    mtl_sky(&obj);
    let baked = bake(&obj, &["skip=mesh:no-such-mesh"]);
    assert!(all_pi_l(&baked.on(0..2)), "{:?}", baked.on(0..2));
    assert!(baked.on(2..16).is_empty());
    let err = &baked.prepare_err;
    assert!(
        err.contains("--role skip=mesh:no-such-mesh matches no mesh or material name"),
        "{err}"
    );
    let roles: Vec<&str> = baked.report["roles"]["roles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["role"].as_str().unwrap())
        .collect();
    assert_eq!(roles, ["sky", "skip"]);
    // A role no one knows, or a rule without a pattern: a clear error, exit 2, nothing written.
    let texels = dir.path().join("typo.texels");
    for (rule, says) in [
        (
            "skyy=dome",
            "\"skyy\" is not a role; the roles are baked, sky, skip",
        ),
        ("dome", "is not ROLE=PATTERN"),
    ] {
        let err = cli::fails_with(
            2,
            &[
                "prepare",
                s(&obj),
                "-o",
                s(&texels),
                "--sky",
                "0.5",
                "--role",
                rule,
            ],
        );
        assert!(err.contains(says), "{rule}: {err}");
        assert!(!texels.exists(), "{rule}: nothing written");
    }
}

/// The Cube 2 level zdm2 (from `../shared/scenes`) closed in a box spanning its bounds, as
/// engines wrap a level in a sky shell: as it comes the inside bakes black and `prepare`
/// names the box; with `--role sky=…` the level's texels are the open level's and bake to the
/// same bytes.
#[test]
fn zdm2_in_a_shell_bakes_as_the_open_level_once_the_shell_is_sky() {
    let Some(scenes) = guidebake::test_support::shared_scenes_dir() else {
        eprintln!("skipping: ../shared/scenes is absent");
        return;
    };
    let src = scenes.join("calinou_zdm2");
    if !src.join("zdm2.obj").is_file() {
        eprintln!("skipping: {} is absent", src.join("zdm2.obj").display());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = std::fs::read_to_string(src.join("zdm2.obj")).unwrap();
    std::fs::write(d.join("zdm2.obj"), &text).unwrap();
    let mtl = std::fs::read_to_string(src.join("zdm2.mtl")).unwrap();
    std::fs::write(d.join("zdm2.mtl"), &mtl).unwrap();
    // The box: 5 % larger than the level's bounds on every side, wound inwards.
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let mut vertices = 0;
    for line in text.lines().filter(|l| l.starts_with("v ")) {
        vertices += 1;
        for (k, w) in line.split_whitespace().skip(1).take(3).enumerate() {
            let x: f32 = w.parse().unwrap();
            (lo[k], hi[k]) = (lo[k].min(x), hi[k].max(x));
        }
    }
    let pad: Vec<f32> = (0..3).map(|k| 0.05 * (hi[k] - lo[k])).collect();
    let a = [0, 1, 2].map(|k| lo[k] - pad[k]);
    let b = [0, 1, 2].map(|k| hi[k] + pad[k]);
    let shell = "\n".to_owned() + &closed_box("shell", "shellwall", a, b, vertices);
    let boxed = d.join("boxed.obj");
    std::fs::write(
        &boxed,
        text.replace("mtllib zdm2.mtl", "mtllib boxed.mtl") + &shell,
    )
    .unwrap();
    std::fs::write(
        d.join("boxed.mtl"),
        mtl + "\nnewmtl shellwall\nKd 0.5 0.5 0.5\n",
    )
    .unwrap();

    let light = ["--sun", "0.4,1,0.3:3", "--sky", "0.4,0.5,0.7"];
    let prepare = |obj: &Path, out: &Path, role: Option<&str>| {
        let mut args = vec![
            "prepare",
            s(obj),
            "-o",
            s(out),
            "--size",
            "640x640",
            "--quiet",
        ];
        args.extend(light);
        if let Some(r) = role {
            args.extend(["--role", r]);
        }
        succeeds(&args).1
    };
    let bake = |texels: &Path, obj: &Path, out: &Path| {
        let mut args = vec![
            "bake",
            s(texels),
            "--scene",
            s(obj),
            "-o",
            s(out),
            "--quiet",
        ];
        args.extend(["--spp", "8", "--iterations", "1", "--bounces", "1"]);
        args.extend(light);
        succeeds(&args);
        let f = TexelFile::open(texels).unwrap();
        let values = guidebake::output::readback::read_lightmap(&f, out).unwrap();
        (f.texels().to_vec(), values)
    };
    let err = prepare(&boxed, &d.join("closed.texels"), None);
    assert!(
        err.contains("material 'shellwall' (12 triangles) closes it like a shell")
            && err.contains("--role 'sky=material:shellwall'"),
        "{err}"
    );
    let (texels, closed) = bake(&d.join("closed.texels"), &boxed, &d.join("closed.exr"));
    let level = 0..texels.iter().map(|t| t.triangle).max().unwrap() - 11;
    let inside: Vec<f32> = texels
        .iter()
        .zip(&closed)
        .filter(|(t, _)| level.contains(&t.triangle))
        .filter_map(|(_, v)| v.map(|rgb| rgb[1]))
        .collect();
    assert!(
        !inside.is_empty() && inside.iter().all(|&e| e == 0.0),
        "the inside is black"
    );

    prepare(
        &boxed,
        &d.join("sky.texels"),
        Some("sky=material:shellwall"),
    );
    prepare(&d.join("zdm2.obj"), &d.join("open.texels"), None);
    let (sky_texels, sky) = bake(&d.join("sky.texels"), &boxed, &d.join("sky.exr"));
    let (open_texels, open) = bake(
        &d.join("open.texels"),
        &d.join("zdm2.obj"),
        &d.join("open.exr"),
    );
    assert_eq!(
        sky_texels, open_texels,
        "the same texels: the shell's outside takes none"
    );
    assert_eq!(sky, open, "the same light, bit for bit");
}
