//! Every file knows what made it: a texel file the geometry of its scene, a lightmap the texel
//! file it was baked for, a work directory everything that changes a bake's bits. A command
//! given files that do not belong together refuses them, names them and what differs, and
//! leaves every file as it was.

use std::path::{Path, PathBuf};

use guidebake::output::exr_pages::{PageImage, read_identity};
use guidebake::scene::Scene;
use guidebake::texels::{TexelFile, TexelFileError};

mod cli;
use cli::{s, snapshot};

fn cli_ok(args: &[&str]) -> String {
    cli::succeeds(args).1
}

fn cli_fails(args: &[&str]) -> String {
    cli::fails_with(1, args)
}

/// A one-triangle glTF `NAME.gltf` (+ `NAME.bin`) whose third corner is at depth `depth`, and
/// a scene file `NAME.toml` lighting it with a sun of `sun` irradiance and a sky.
fn write_scene(dir: &Path, name: &str, depth: f32, sun: f32) -> PathBuf {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -depth] {
        bin.extend(v.to_le_bytes());
    }
    for v in [0.1f32, 0.1, 0.9, 0.1, 0.1, 0.9] {
        bin.extend(v.to_le_bytes());
    }
    for i in [0u32, 1, 2] {
        bin.extend(i.to_le_bytes());
    }
    std::fs::write(dir.join(format!("{name}.bin")), bin).unwrap();
    let gltf = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
    "nodes": [{{"name": "tri", "mesh": 0}}],
    "meshes": [{{"name": "tri", "primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_1": 1}}, "indices": 2}}]}}],
    "accessors": [
      {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,-{depth}], "max": [1,0,0]}},
      {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}},
      {{"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}}],
    "bufferViews": [
      {{"buffer": 0, "byteOffset": 0, "byteLength": 36}},
      {{"buffer": 0, "byteOffset": 36, "byteLength": 24}},
      {{"buffer": 0, "byteOffset": 60, "byteLength": 12}}],
    "buffers": [{{"byteLength": 72, "uri": "{name}.bin"}}]}}"#
    );
    std::fs::write(dir.join(format!("{name}.gltf")), gltf).unwrap();
    let toml = format!(
        "geometry = \"{name}.gltf\"\n[sky]\nconstant = [0.5, 0.6, 0.8]\n\
         [sun]\ndirection = [0.3, 1.0, 0.2]\nangular_radius_deg = 0.267\nirradiance = [{sun}, {sun}, {sun}]\n"
    );
    let scene = dir.join(format!("{name}.toml"));
    std::fs::write(&scene, toml).unwrap();
    scene
}

fn prepare(scene: &Path, texels: &Path, size: &str) {
    cli_ok(&["prepare", s(scene), "-o", s(texels), "--size", size]);
}

/// The cheapest bake: few samples, one iteration, one thread.
const QUICK: [&str; 6] = ["--spp", "8", "--iterations", "1", "--threads", "1"];

fn bake_args<'a>(texels: &'a Path, scene: &'a Path, out: &'a Path) -> Vec<&'a str> {
    let mut a = vec!["bake", s(texels), "--scene", s(scene), "-o", s(out)];
    a.extend(QUICK);
    a
}

#[test]
fn a_scene_of_other_geometry_is_refused_by_bake_and_render() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write_scene(d, "tri", 1.0, 3.0);
    // The same one triangle, one corner moved.
    let moved = write_scene(d, "moved", 1.5, 3.0);
    let texels = d.join("tri.texels");
    prepare(&scene, &texels, "64x64");
    let before = snapshot(d);

    let out = d.join("out.exr");
    let err = cli_fails(&bake_args(&texels, &moved, &out));
    assert!(
        err.contains("same 1 triangles but other positions"),
        "{err}"
    );
    assert!(err.contains(s(&texels)) && err.contains("moved."), "{err}");
    assert!(err.contains("guidebake prepare"), "{err}");
    assert_eq!(snapshot(d), before, "the bake changed or left files");

    let view = d.join("view.png");
    let args = [
        "render",
        s(&moved),
        "--texels",
        s(&texels),
        "--lightmap",
        s(&out),
        "-o",
        s(&view),
        "--width",
        "32",
    ];
    let err = cli_fails(&args);
    assert!(
        err.contains("same 1 triangles but other positions"),
        "{err}"
    );
    assert!(err.contains(s(&texels)) && err.contains("moved."), "{err}");
    assert_eq!(snapshot(d), before, "render changed or left files");

    // The scene it was prepared from passes, and so does the scene written back with its UVs.
    let header = *TexelFile::open(&texels).unwrap().header();
    assert_eq!(
        header.geometry,
        Scene::load(&scene).unwrap().geometry_fingerprint()
    );
    let glb = d.join("written.glb");
    cli_ok(&[
        "prepare",
        s(&scene),
        "-o",
        s(&d.join("again.texels")),
        "--size",
        "64x64",
        "--write-gltf",
        s(&glb),
    ]);
    assert_eq!(
        header.geometry,
        Scene::load(&glb).unwrap().geometry_fingerprint()
    );
}

#[test]
fn synth_records_the_geometry_of_the_scene_it_writes() {
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("city.texels");
    cli_ok(&["synth", "--texels", "8000", "-o", s(&texels)]);
    let header = *TexelFile::open(&texels).unwrap().header();
    let scene = Scene::load(&texels.with_extension("toml")).unwrap();
    assert_ne!(header.geometry, 0);
    assert_eq!(header.geometry, scene.geometry_fingerprint());
}

#[test]
fn a_lightmap_of_another_texel_file_is_not_rendered_or_merged() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write_scene(d, "tri", 1.0, 3.0);
    let (first, second) = (d.join("first.texels"), d.join("second.texels"));
    prepare(&scene, &first, "64x64");
    prepare(&scene, &second, "32x32");
    let lightmap = d.join("first.exr");
    cli_ok(&bake_args(&first, &scene, &lightmap));
    let identity = read_identity(&lightmap)
        .unwrap()
        .expect("the page says what made it");
    assert_eq!(
        identity.texels(),
        Some(TexelFile::open(&first).unwrap().identity())
    );
    assert_eq!(identity.get("texel file"), Some("first.texels"));
    assert!(identity.get("settings").unwrap().contains("--spp 8"));
    assert!(
        identity
            .get("lights")
            .unwrap()
            .contains("--sun 0.3,1,0.2:3")
    );

    let view = d.join("view.png");
    let render = |texels: &Path, lightmap: &Path| {
        [
            "render".to_owned(),
            s(&scene).to_owned(),
            "--texels".into(),
            s(texels).into(),
            "--lightmap".into(),
            s(lightmap).into(),
            "-o".into(),
            s(&view).into(),
            "--width".into(),
            "32".into(),
        ]
    };
    let args = render(&second, &lightmap);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let err = cli_fails(&args);
    assert!(
        err.contains(s(&lightmap))
            && err.contains("baked for the texel file first.texels")
            && err.contains(s(&second)),
        "{err}"
    );
    assert!(!view.exists(), "a view was written");
    // Its own texel file renders it.
    let args = render(&first, &lightmap);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let err = cli_ok(&args);
    assert!(!err.contains("warning"), "{err}");
    assert!(view.exists());
    std::fs::remove_file(&view).unwrap();
    // A page an older guidebake wrote (no identity) is rendered, with a warning.
    let page = TexelFile::open(&first).unwrap().pages()[0];
    let old = d.join("old.exr");
    PageImage::new(page.width, page.height)
        .write_exr(&old)
        .unwrap();
    assert_eq!(read_identity(&old).unwrap(), None);
    // (Its pixels are black: `--exposure` writes the picture all the same.)
    let args = render(&first, &old);
    let mut args: Vec<&str> = args.iter().map(String::as_str).collect();
    args.extend(["--exposure", "1"]);
    let err = cli_ok(&args);
    assert!(
        err.contains("warning") && err.contains("does not record the texel file"),
        "{err}"
    );
    assert!(view.exists());

    // Shards of the first texel file are not merged with the second.
    let sharded = d.join("sharded.exr");
    let mut shards = Vec::new();
    for shard in ["0/2", "1/2"] {
        let mut args = bake_args(&first, &scene, &sharded);
        args.extend(["--shard", shard, "--transport", "path"]);
        cli_ok(&args);
    }
    for i in 0..2 {
        shards.push(d.join(format!("sharded.exr.shard-{i}-of-2")));
    }
    let before = snapshot(d);
    let err = cli_fails(&[
        "merge",
        s(&second),
        s(&shards[0]),
        s(&shards[1]),
        "-o",
        s(&sharded),
    ]);
    assert!(
        err.contains(s(&shards[0]))
            && err.contains("baked for the texel file")
            && err.contains(s(&first))
            && err.contains(s(&second)),
        "{err}"
    );
    assert_eq!(snapshot(d), before, "merge changed or left files");
    assert!(!sharded.exists());
    // With their own texel file they merge.
    cli_ok(&[
        "merge",
        s(&first),
        s(&shards[0]),
        s(&shards[1]),
        "-o",
        s(&sharded),
    ]);
    assert!(sharded.exists());
}

#[test]
fn resume_of_a_different_bake_names_each_difference() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write_scene(d, "tri", 1.0, 3.0);
    let texels = d.join("tri.texels");
    prepare(&scene, &texels, "64x64");
    let out = d.join("out.exr");
    let work = d.join("out.exr.bake");
    // The direct pass alone: the work directory is left as an interrupted bake leaves it.
    let mut args = bake_args(&texels, &scene, &out);
    args.extend(["--pass", "0"]);
    cli_ok(&args);
    assert!(work.is_dir() && !out.exists());
    let before = snapshot(d);

    // Another sun and other samples on the command line.
    let mut args = bake_args(&texels, &scene, &out);
    args.retain(|a| *a != "8");
    args.insert(args.iter().position(|a| *a == "--spp").unwrap() + 1, "64");
    args.extend(["--sun", "-0.8,1,-0.2:40", "--resume"]);
    let err = cli_fails(&args);
    assert!(err.contains("--resume of a different bake"), "{err}");
    assert!(err.contains("--spp was 8, now 64"), "{err}");
    assert!(
        err.contains("--sun was 0.3,1,0.2:3, now -0.8,1,-0.2:40"),
        "{err}"
    );
    assert!(
        err.contains(&format!("delete {} to start over", s(&work))),
        "{err}"
    );
    assert!(!err.contains("--seed"), "only what differs is named: {err}");
    assert_eq!(snapshot(d), before, "the refused resume changed files");

    // Another seed.
    let mut args = bake_args(&texels, &scene, &out);
    args.extend(["--seed", "5", "--resume"]);
    let err = cli_fails(&args);
    assert!(err.contains("--seed was 0, now 5"), "{err}");
    assert_eq!(snapshot(d), before);

    // The scene file's sun changed.
    let brighter = write_scene(d, "brighter", 1.0, 5.0);
    let before = snapshot(d);
    let mut args = bake_args(&texels, &brighter, &out);
    args.push("--resume");
    let err = cli_fails(&args);
    assert!(
        err.contains("--sun was 0.3,1,0.2:3, now 0.3,1,0.2:5"),
        "{err}"
    );
    assert!(!err.contains("--spp"), "{err}");
    assert_eq!(snapshot(d), before);

    // Another texel file of the same scene.
    let other = d.join("other.texels");
    prepare(&scene, &other, "32x32");
    let before = snapshot(d);
    let mut args = bake_args(&other, &scene, &out);
    args.push("--resume");
    let err = cli_fails(&args);
    assert!(
        err.contains("the texel file was") && err.contains(s(&other)),
        "{err}"
    );
    assert_eq!(snapshot(d), before);

    // A manifest an older guidebake wrote records nothing to compare: a generic refusal.
    let manifest = work.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json.as_object_mut().unwrap().remove("record").unwrap();
    json["bake_id"] = serde_json::json!(1);
    std::fs::write(&manifest, serde_json::to_string(&json).unwrap()).unwrap();
    let mut args = bake_args(&texels, &scene, &out);
    args.push("--resume");
    let err = cli_fails(&args);
    assert!(
        err.contains("--resume of a different bake (an older guidebake made it"),
        "{err}"
    );
    std::fs::write(&manifest, text).unwrap();

    // The same everything resumes and finishes.
    let mut args = bake_args(&texels, &scene, &out);
    args.push("--resume");
    cli_ok(&args);
    assert!(out.exists() && !work.exists());
}

#[test]
fn files_that_are_no_texel_files_say_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let exr = d.join("lightmap.exr");
    PageImage::new(4, 4).write_exr(&exr).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "empty.texels",
            vec![],
            "this is an empty file, not a texel file",
        ),
        (
            "scene.glb",
            b"glTF\x02\0\0\0\x40\0\0\0".to_vec(),
            "this is a glTF file (binary), not a texel file: make one from it with `guidebake prepare",
        ),
        (
            "scene.gltf",
            br#"{"asset": {"version": "2.0"}}"#.to_vec(),
            "this is a glTF file (JSON text), not a texel file",
        ),
        (
            "level.obj",
            b"# a level\nmtllib level.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
            "this is an OBJ file, not a texel file",
        ),
        (
            "scene.toml",
            b"geometry = \"tri.gltf\"\n[sky]\nconstant = [0.5, 0.6, 0.8]\n".to_vec(),
            "this is a TOML scene file, not a texel file",
        ),
        (
            "lightmap.texels",
            std::fs::read(&exr).unwrap(),
            "this is an OpenEXR image (a lightmap?), not a texel file",
        ),
        (
            "image.texels",
            b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec(),
            "this is a PNG image, not a texel file",
        ),
    ];
    for (name, bytes, expect) in cases {
        let p = d.join(name);
        std::fs::write(&p, &bytes).unwrap();
        let e = TexelFile::open(&p).unwrap_err();
        assert!(
            matches!(e, TexelFileError::BadMagic { .. }),
            "{name}: {e:?}"
        );
        let text = e.to_string();
        assert!(text.contains(expect), "{name}: {text}");
        assert!(text.contains(s(&p)), "{name}: {text}");
        let err = cli_fails(&["inspect", s(&p)]);
        assert!(err.contains(expect), "{name}: {err}");
        assert_eq!(std::fs::read(&p).unwrap(), bytes, "{name} was changed");
    }

    // A texel file of the version before: made by an older guidebake, prepare it again.
    let scene = write_scene(d, "tri", 1.0, 3.0);
    let texels = d.join("tri.texels");
    prepare(&scene, &texels, "32x32");
    let mut bytes = std::fs::read(&texels).unwrap();
    bytes[8..12].copy_from_slice(&2u32.to_le_bytes());
    bytes.truncate(128);
    let old = d.join("old.texels");
    std::fs::write(&old, &bytes).unwrap();
    let e = TexelFile::open(&old).unwrap_err();
    assert!(
        matches!(e, TexelFileError::UnsupportedVersion { found: 2, .. }),
        "{e:?}"
    );
    let text = e.to_string();
    assert!(
        text.contains("made by an older guidebake")
            && text.contains("run `guidebake prepare` again"),
        "{text}"
    );
    let out = d.join("out.exr");
    let err = cli_fails(&bake_args(&old, &scene, &out));
    assert!(err.contains("made by an older guidebake"), "{err}");
    assert!(!out.exists() && !d.join("out.exr.bake").exists());
}
