//! Scene-loading messages a person can act on, as `guidebake prepare` prints them: the file
//! that is missing named (as resolved, and the line naming it), a parse error placed at its
//! file, line and column, a path that is not a scene said as what it is, each said once (no
//! "caused by" line repeating it); and on an error a non-zero exit, the input untouched and
//! no output (nor a temporary beside it) left behind.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod cli;

/// Runs `guidebake prepare SCENE -o DIR/out.texels EXTRA...`; returns (exit code, stderr).
fn prepare(dir: &Path, scene: &Path, extra: &[&str]) -> (i32, String) {
    let out = dir.join("out.texels");
    let result = cli::command()
        .arg("prepare")
        .arg(scene)
        .arg("-o")
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&result.stderr).into_owned();
    let code = result
        .status
        .code()
        .unwrap_or_else(|| panic!("killed by a signal: {err}"));
    assert!(!err.contains("panicked"), "panicked: {err}");
    (code, err)
}

/// Every file in `dir` (not below) with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect()
}

/// No line of stderr is said twice, and no "caused by" line repeats what the message says.
fn assert_said_once(err: &str) {
    let lines: Vec<&str> = err.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        assert!(!lines[..i].contains(l), "said twice: {l:?} in:\n{err}");
        if let Some(cause) = l.trim_start().strip_prefix("caused by: ") {
            assert!(
                !lines[..i].iter().any(|m| m.contains(cause)),
                "the cause {cause:?} repeats the message:\n{err}"
            );
        }
    }
}

/// `prepare` of `scene` fails with `expected` as its message (`guidebake: ` before it), said
/// once; the files in `dir` are as they were and no output is left.
fn assert_fails(dir: &Path, scene: &Path, expected: &str) {
    let before = snapshot(dir);
    let (code, err) = prepare(dir, scene, &["--sky", "1"]);
    assert_ne!(code, 0, "{scene:?} succeeded: {err}");
    let first = err.lines().next().unwrap_or_default();
    assert_eq!(first, format!("guidebake: {expected}"), "stderr:\n{err}");
    assert_said_once(&err);
    assert_eq!(
        snapshot(dir),
        before,
        "the input changed or output was left"
    );
}

/// `prepare` of `scene` succeeds, printing `warning` (after `guidebake: warning: `) once;
/// the inputs are unchanged.
fn assert_warns(dir: &Path, scene: &Path, warning: &str) -> String {
    let before = snapshot(dir);
    let (code, err) = prepare(dir, scene, &["--sky", "1"]);
    assert_eq!(code, 0, "{err}");
    let line = format!("guidebake: warning: {warning}");
    assert_eq!(
        err.lines().filter(|l| *l == line).count(),
        1,
        "expected once: {line}\nin:\n{err}"
    );
    assert_said_once(&err);
    let mut after = snapshot(dir);
    assert!(after.contains_key("out.texels"), "no output: {err}");
    // The texel file and its sidecars.
    after.retain(|name, _| {
        let output = name.starts_with("out.texels");
        if output {
            std::fs::remove_file(dir.join(name)).unwrap();
        }
        !output
    });
    assert_eq!(after, before, "an input changed");
    err
}

/// `path` made absolute as the messages show it.
fn abs(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap()
}

const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
                    f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n";

fn write(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn a_missing_mtl_is_a_warning_naming_it_and_its_mtllib_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = write(
        d,
        "level.obj",
        format!("# exported\nmtllib level.mtl\n{QUAD}"),
    );
    let mtl = abs(&d.join("level.mtl"));
    let err = assert_warns(
        d,
        &obj,
        &format!(
            "{}:2: material library \"level.mtl\" cannot be read ({}: No such file or directory (os error 2)); its materials are the default grey (0.8)",
            obj.display(),
            mtl.display()
        ),
    );
    assert!(!err.contains("open file failed"), "{err}");
}

#[test]
fn a_malformed_mtl_is_a_warning_naming_its_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = write(d, "m.obj", format!("mtllib m.mtl\nusemtl wall\n{QUAD}"));
    write(d, "m.mtl", "newmtl wall\nKd 0.5 abc 1\n");
    let mtl = abs(&d.join("m.mtl"));
    assert_warns(
        d,
        &obj,
        &format!(
            "{}:2:8: Kd \"abc\" is not a number (material library named on {}:1); its materials are the default grey (0.8)",
            mtl.display(),
            obj.display()
        ),
    );
    // Two numbers made tobj 4.0.5 panic; said as malformed. One is a grey and loads.
    write(d, "m.mtl", "newmtl wall\n\nKd 0.5 0.5\n");
    assert_warns(
        d,
        &obj,
        &format!(
            "{}:3:11: Kd has 2 numbers; it needs 3 (r g b) or 1 (a grey) (material library named on {}:1); its materials are the default grey (0.8)",
            mtl.display(),
            obj.display()
        ),
    );
    write(d, "m.mtl", "newmtl wall\nKd 0.5\n");
    let (code, err) = prepare(d, &obj, &["--sky", "1"]);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("warning"), "{err}");
    for e in std::fs::read_dir(d).unwrap().filter_map(Result::ok) {
        if e.file_name().to_string_lossy().starts_with("out.texels") {
            std::fs::remove_file(e.path()).unwrap();
        }
    }
    // A material the library does not define.
    write(d, "m.mtl", "newmtl wal\nKd 0.5\n");
    assert_warns(
        d,
        &obj,
        &format!(
            "{}:2: usemtl \"wall\": no material library of the file defines it; its faces are the default grey (0.8)",
            obj.display()
        ),
    );
}

#[test]
fn obj_parse_errors_name_the_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (body, at, message) in [
        (
            "v 0 0 0\nv 1.0e 0 0\n",
            "2:3",
            "vertex position \"1.0e\" is not a number",
        ),
        (
            "v 0 0 0\nv 1 2\n",
            "2:6",
            "vertex position has 2 numbers; it needs 3 (x y z)",
        ),
        (
            "vt 0 x\n",
            "1:6",
            "texture coordinate \"x\" is not a number",
        ),
        (
            "vn 0 0\n",
            "1:7",
            "normal has 2 numbers; it needs 3 (x y z)",
        ),
        (
            "v 0 0 0 0\n",
            "1:9",
            "vertex weight is 0 (x y z are divided by it)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            "4:7",
            "vertex index 9 names no vertex (the file has 3, 3 before this line)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n",
            "4:7",
            "vertex index 0 names no vertex (the file has 3, 3 before this line)",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x3\n",
            "4:7",
            "vertex index \"x3\" is not a whole number",
        ),
        ("v 0 0 0\nf\n", "2:2", "\"f\" lists no vertices"),
        ("usemtl \n", "1:7", "usemtl names no material"),
        (
            "v 0 0 0\nv \u{e9}\u{e9} 0 0\n",
            "2:3",
            "vertex position \"\u{e9}\u{e9}\" is not a number",
        ),
    ] {
        let obj = write(d, "level.obj", body);
        assert_fails(d, &obj, &format!("{}:{at}: {message}", obj.display()));
    }
    // Bytes that are not UTF-8 on line 2, column 3.
    let obj = write(d, "level.obj", b"v 0 0 0\nv \xff 0 0\n");
    assert_fails(
        d,
        &obj,
        &format!(
            "{}:2:3: not UTF-8 text (an OBJ file is text; tobj reads it as UTF-8)",
            obj.display()
        ),
    );
}

#[test]
fn non_finite_obj_positions_are_a_warning_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = write(
        d,
        "level.obj",
        format!("{QUAD}v nan 0 0\nv 0 inf 1\nv 1e39 0 0\nf 5 6 7\n"),
    );
    assert_warns(
        d,
        &obj,
        &format!(
            "{}:11:3: vertex position \"nan\" is not a finite number (2 more such coordinates after it); the triangles using it are dropped",
            obj.display()
        ),
    );
}

#[test]
fn toml_scene_file_errors_name_the_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "level.obj", QUAD);
    let cases = [
        (
            "# the level\ngeometry = level.obj\n",
            "2:12",
            "string values must be quoted, expected literal string",
        ),
        (
            "geomtry = \"level.obj\"\n",
            "1:1",
            "unknown field `geomtry`, expected one of `geometry`, `sky`, `sun`, `sphere_light`",
        ),
        (
            "geometry = \"level.obj\"\n\n[sun]\ndirection = [0, 0, 0]\nangular_radius_deg = 0.3\nirradiance = [1, 1, 1]\n",
            "3:1",
            "sun direction must be finite and non-zero",
        ),
        (
            "geometry = \"level.obj\"\n[sky]\nconstant = [1, 1, 1]\nequirect = \"sky.exr\"\n",
            "2:1",
            "[sky] needs exactly one of `constant` or `equirect`",
        ),
    ];
    for (text, at, message) in cases {
        let toml = write(d, "scene.toml", text);
        let (code, err) = prepare(d, &toml, &[]);
        assert_ne!(code, 0, "{err}");
        // toml's messages may run over lines: the place is on the first.
        let first = message.lines().next().unwrap();
        assert!(
            err.starts_with(&format!("guidebake: {}:{at}: {first}", toml.display())),
            "{err}"
        );
        assert!(err.contains(message), "{err}");
        assert_said_once(&err);
        assert!(!d.join("out.texels").exists());
    }
}

#[test]
fn a_scene_files_missing_geometry_is_named_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let toml = write(
        d,
        "scene.toml",
        "# the level\ngeometry = \"levels/missing.glb\"\n[sky]\nconstant = [1, 1, 1]\n",
    );
    assert_fails(
        d,
        &toml,
        &format!(
            "{}:2:12: geometry \"levels/missing.glb\" cannot be read: {}: No such file or directory (os error 2)",
            toml.display(),
            abs(&d.join("levels/missing.glb")).display()
        ),
    );
}

/// A one-triangle glTF whose buffer is the file `bin` names.
fn gltf_json(bin: &str) -> String {
    format!(
        r#"{{"asset": {{"version": "2.0"}},
"scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
"meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
  "min": [0, 0, 0], "max": [1, 1, 0]}}],
"bufferViews": [{{"buffer": 0, "byteLength": 36}}],
"buffers": [{{"byteLength": 36, "uri": "{bin}"}}]}}"#
    )
}

#[test]
fn gltf_errors_name_the_line_column_and_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gltf = write(
        d,
        "level.gltf",
        "{\"asset\": {\"version\": \"2.0\"},\n \"scenes\": [}\n",
    );
    assert_fails(
        d,
        &gltf,
        &format!(
            "{}:2:13: not valid glTF JSON: expected value",
            gltf.display()
        ),
    );
    let gltf = write(d, "level.gltf", gltf_json("data/level%20a.bin"));
    assert_fails(
        d,
        &gltf,
        &format!(
            "{}: buffers[0]: cannot read \"data/level%20a.bin\" ({}): No such file or directory (os error 2)",
            gltf.display(),
            abs(&d.join("data/level a.bin")).display()
        ),
    );
}

#[test]
fn paths_that_are_not_scenes_say_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let accepted = "guidebake reads .gltf, .glb, .obj and .toml scene files";
    let sub = d.join("level.obj");
    std::fs::create_dir(&sub).unwrap();
    assert_fails(
        d,
        &sub,
        &format!(
            "{}: is a directory, not a scene file; {accepted}",
            sub.display()
        ),
    );
    std::fs::remove_dir(&sub).unwrap();
    let empty = write(d, "level.gltf", "");
    assert_fails(
        d,
        &empty,
        &format!("{}: is empty (0 bytes); {accepted}", empty.display()),
    );
    std::fs::remove_file(&empty).unwrap();
    let fbx = write(d, "level.fbx", "; FBX 7.4.0 project file\n");
    assert_fails(
        d,
        &fbx,
        &format!(
            "{}: unknown scene format \".fbx\"; {accepted}",
            fbx.display()
        ),
    );
    let glb = write(d, "level.dat", b"glTF\x02\0\0\0\x0c\0\0\0");
    assert_fails(
        d,
        &glb,
        &format!(
            "{}: unknown scene format \".dat\" (it looks like a binary glTF (.glb); rename it to match); {accepted}",
            glb.display()
        ),
    );
    let bare = write(d, "level", QUAD);
    assert_fails(
        d,
        &bare,
        &format!(
            "{}: unknown scene format (the file name has no extension) (it looks like a Wavefront OBJ file; rename it to match); {accepted}",
            bare.display()
        ),
    );
}

#[test]
fn files_of_another_kind_than_their_extension_say_what_they_look_like() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut exr = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    exr.extend_from_slice(&[0xff; 64]);
    for (name, bytes, expected) in [
        (
            "level.obj",
            exr.clone(),
            "looks like an OpenEXR image, not a Wavefront OBJ file",
        ),
        (
            "level.obj",
            [&b"GBTEXELS"[..], &[0; 56]].concat(),
            "looks like a guidebake texel file (.texels), not a Wavefront OBJ file",
        ),
        (
            "level.gltf",
            QUAD.as_bytes().to_vec(),
            "looks like a Wavefront OBJ file, not a glTF file (.gltf JSON or .glb)",
        ),
        (
            "level.glb",
            exr.clone(),
            "looks like an OpenEXR image, not a glTF file (.gltf JSON or .glb)",
        ),
        (
            "scene.toml",
            gltf_json("x.bin").into_bytes(),
            "looks like glTF JSON (.gltf), not a TOML scene file (a scene file names its geometry: geometry = \"level.glb\"; docs/levels.md)",
        ),
    ] {
        let p = write(d, name, bytes);
        assert_fails(d, &p, &format!("{}: {expected}", p.display()));
        std::fs::remove_file(p).unwrap();
    }
}

#[test]
fn a_missing_texture_is_a_warning_naming_the_file_as_resolved_and_the_material() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = write(d, "m.obj", format!("mtllib m.mtl\nusemtl wood\n{QUAD}"));
    write(
        d,
        "m.mtl",
        "newmtl wood\nKd 0.5 0.5 0.5\nmap_Kd tex/wood.png\n",
    );
    assert_warns(
        d,
        &obj,
        &format!(
            "{}: texture tex/wood.png cannot be read ({}: No such file or directory (os error 2)); material 'wood' uses its colour 0.500,0.500,0.500 instead",
            obj.display(),
            abs(&d.join("tex/wood.png")).display()
        ),
    );
}

#[test]
fn a_glb_named_gltf_loads() {
    // A .glb renamed .gltf (and the other way round) is read by its first bytes, not
    // refused by its name.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = write(d, "level.obj", QUAD);
    let glb = d.join("level.glb");
    let (code, err) = prepare(
        d,
        &obj,
        &["--sky", "1", "--write-gltf", glb.to_str().unwrap()],
    );
    assert_eq!(code, 0, "{err}");
    assert!(std::fs::read(&glb).unwrap().starts_with(b"glTF"));
    let renamed = d.join("renamed.gltf");
    std::fs::rename(&glb, &renamed).unwrap();
    std::fs::remove_file(&obj).unwrap();
    let (code, err) = prepare(d, &renamed, &["--sky", "1"]);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("warning"), "{err}");
}
