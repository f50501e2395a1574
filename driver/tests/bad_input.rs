//! Bad input: each a typed error naming the file and what is wrong, a non-zero exit from
//! the command line, no panic, and no output file left behind.

use std::path::{Path, PathBuf};

use guidebake::prepare::{Layout, PrepareError, PrepareOptions, Resolution, prepare};
use guidebake::scene::{Scene, SceneError};
use guidebake::test_support::floor_texel;
use guidebake::texels::{PageRecord, TexelFile, TexelFileError, TexelWriter, TileRect};

mod cli;
use cli::fails as cli_fails;

/// A command that fails on its input (exit 1) with `expect` in its message.
fn assert_cli_fails(args: &[&str], expect: &str) {
    let err = cli::fails_with(1, args);
    assert!(
        err.contains(expect),
        "{args:?}: expected '{expect}' in: {err}"
    );
}

/// A valid file: one 8x8 page, two tiles, 12 texels.
fn valid_file(dir: &Path) -> PathBuf {
    let path = dir.join("good.texels");
    let mut w = TexelWriter::create(
        &path,
        &[PageRecord {
            width: 8,
            height: 8,
        }],
        &[],
        1.0,
    )
    .unwrap();
    let texel = floor_texel;
    let a: Vec<_> = (0..8).map(|x| texel(x, 0)).collect();
    let b: Vec<_> = (0..4).map(|x| texel(x, 5)).collect();
    w.push_tile(
        TileRect {
            page: 0,
            x: 0,
            y: 0,
            width: 8,
            height: 4,
        },
        &a,
    )
    .unwrap();
    w.push_tile(
        TileRect {
            page: 0,
            x: 0,
            y: 4,
            width: 8,
            height: 4,
        },
        &b,
    )
    .unwrap();
    w.finish().unwrap();
    TexelFile::open(&path).unwrap();
    path
}

/// Copies the valid file with `edit` applied to its bytes.
fn corrupt(dir: &Path, name: &str, edit: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
    let mut bytes = std::fs::read(valid_file(dir)).unwrap();
    edit(&mut bytes);
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn put_u64(b: &mut [u8], at: usize, v: u64) {
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

/// Header offsets (docs/texel-format.md).
const TILE_COUNT: usize = 32;
const PAGES_OFFSET: usize = 56;
const TEXELS_OFFSET: usize = 72;
const TILES_OFFSET: usize = 80;

#[test]
fn bad_texel_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    type Check = fn(&TexelFileError) -> bool;
    type Edit = Box<dyn FnOnce(&mut Vec<u8>)>;
    let cases: Vec<(&str, Edit, Check, &str)> = vec![
        (
            "truncated",
            Box::new(|b| b.truncate(b.len() - 10)),
            |e| matches!(e, TexelFileError::Truncated { .. }),
            "truncated",
        ),
        (
            "tiny",
            Box::new(|b| b.truncate(50)),
            |e| {
                matches!(
                    e,
                    TexelFileError::Truncated {
                        needed: 192,
                        actual: 50,
                        ..
                    }
                )
            },
            "truncated",
        ),
        (
            "magic",
            Box::new(|b| b[0] = b'X'),
            |e| matches!(e, TexelFileError::BadMagic { .. }),
            "not a texel file",
        ),
        (
            "version",
            Box::new(|b| b[8] = 1),
            |e| matches!(e, TexelFileError::UnsupportedVersion { found: 1, .. }),
            "run `guidebake prepare` again",
        ),
        (
            "past_end",
            Box::new(|b| {
                let n = b.len() as u64;
                put_u64(b, TILES_OFFSET, n + 64);
            }),
            |e| {
                matches!(
                    e,
                    TexelFileError::SectionOutOfBounds {
                        section: "tile",
                        ..
                    }
                )
            },
            "past the end",
        ),
        (
            "misaligned",
            Box::new(|b| {
                let o = u64_at(b, PAGES_OFFSET);
                put_u64(b, PAGES_OFFSET, o + 4);
            }),
            |e| {
                matches!(
                    e,
                    TexelFileError::Misaligned {
                        section: "page",
                        ..
                    }
                )
            },
            "not a multiple of 64",
        ),
        (
            "nan",
            Box::new(|b| {
                let at = u64_at(b, TEXELS_OFFSET) as usize + 3 * 64;
                b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
            }),
            |e| matches!(e, TexelFileError::BadTexel { texel: 3, .. }),
            "texel 3",
        ),
        (
            "zero_normal",
            Box::new(|b| {
                let at = u64_at(b, TEXELS_OFFSET) as usize + 9 * 64 + 12;
                b[at..at + 12].fill(0);
            }),
            |e| matches!(e, TexelFileError::BadTexel { texel: 9, .. }),
            "not unit length",
        ),
        (
            "tile_overflow",
            Box::new(|b| put_u64(b, TILE_COUNT, u64::MAX / 16)),
            |e| {
                matches!(
                    e,
                    TexelFileError::SectionOutOfBounds {
                        section: "tile",
                        len: u64::MAX,
                        ..
                    }
                )
            },
            "tile section",
        ),
    ];
    for (name, edit, check, message) in cases {
        let p = corrupt(d, &format!("{name}.texels"), edit);
        let e = TexelFile::open(&p).unwrap_err();
        assert!(check(&e), "{name}: wrong error {e:?}");
        let text = e.to_string();
        assert!(
            text.contains(&format!("{name}.texels")),
            "{name}: error does not name the file: {text}"
        );
        assert!(text.contains(message), "{name}: {text}");
        assert_cli_fails(&["inspect", p.to_str().unwrap()], message);
    }
}

fn write_gltf(dir: &Path, name: &str, json: &str, bin: Option<&[u8]>) -> PathBuf {
    if let Some(bin) = bin {
        std::fs::write(dir.join(format!("{name}.bin")), bin).unwrap();
    }
    let p = dir.join(format!("{name}.gltf"));
    std::fs::write(&p, json).unwrap();
    p
}

/// One triangle: 3 positions (36 bytes), 3 UVs (24 bytes), 3 u32 indices (12 bytes).
fn triangle_gltf(name: &str, with_uv: bool, indices: [u32; 3]) -> (String, Vec<u8>) {
    let mut bin = Vec::new();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]] {
        bin.extend(v.iter().flat_map(|c| c.to_le_bytes()));
    }
    for v in [[0.1f32, 0.1], [0.9, 0.1], [0.1, 0.9]] {
        bin.extend(v.iter().flat_map(|c| c.to_le_bytes()));
    }
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    let uv = if with_uv { r#", "TEXCOORD_1": 1"# } else { "" };
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
        "nodes": [{{"name": "tri", "mesh": 0}}],
        "meshes": [{{"name": "tri", "primitives": [{{"attributes": {{"POSITION": 0{uv}}}, "indices": 2}}]}}],
        "accessors": [
          {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,-1], "max": [1,0,0]}},
          {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}},
          {{"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}}],
        "bufferViews": [
          {{"buffer": 0, "byteOffset": 0, "byteLength": 36}},
          {{"buffer": 0, "byteOffset": 36, "byteLength": 24}},
          {{"buffer": 0, "byteOffset": 60, "byteLength": 12}}],
        "buffers": [{{"byteLength": 72, "uri": "{name}.bin"}}]}}"#
    );
    (json, bin)
}

#[test]
fn good_triangle_gltf_prepares() {
    let dir = tempfile::tempdir().unwrap();
    let (json, bin) = triangle_gltf("ok", true, [0, 1, 2]);
    let p = write_gltf(dir.path(), "ok", &json, Some(&bin));
    let out = dir.path().join("ok.texels");
    let (code, err) = cli::outcome(&[
        "prepare",
        p.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--size",
        "64x64",
        "--sky",
        "1",
    ]);
    assert_eq!(code, Some(0), "{err}");
    // UV area 0.32 of a 64² page = 1310.72 centre texels, plus the border's partial texels.
    let f = TexelFile::open(&out).unwrap();
    let n = f.header().texel_count;
    assert!((1280..1500).contains(&n), "{n}");
}

#[test]
fn bad_scenes_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out.texels");
    let out_s = out.to_str().unwrap();

    // Missing buffer file.
    let (json, _) = triangle_gltf("nobuf", true, [0, 1, 2]);
    let p = write_gltf(d, "nobuf", &json, None);
    let e = Scene::load(&p).unwrap_err();
    assert!(
        matches!(&e, SceneError::GltfResource { item, .. } if item == "buffers[0]"),
        "{e}"
    );
    assert_cli_fails(&["prepare", p.to_str().unwrap(), "-o", out_s], "nobuf.gltf");

    // Out-of-range index.
    let (json, bin) = triangle_gltf("badidx", true, [0, 1, 7]);
    let p = write_gltf(d, "badidx", &json, Some(&bin));
    let e = Scene::load(&p).unwrap_err();
    assert!(
        matches!(e, SceneError::BadMesh { .. }) && e.to_string().contains("index 7"),
        "{e}"
    );
    assert_cli_fails(
        &["prepare", p.to_str().unwrap(), "-o", out_s],
        "index 7 at position 2 is out of range",
    );

    // No TEXCOORD_1: loads, but prepare without the unwrapper names the mesh.
    let (json, bin) = triangle_gltf("nouv", false, [0, 1, 2]);
    let p = write_gltf(d, "nouv", &json, Some(&bin));
    let scene = Scene::load(&p).unwrap();
    assert_eq!(scene.meshes_without_lightmap_uvs(), ["tri"]);
    let opts = PrepareOptions {
        resolution: Resolution::Default,
        layout: Layout::Auto,
    };
    assert!(matches!(
        prepare(&scene, &out, opts),
        Err(PrepareError::NoLightmapUvs { .. })
    ));
    // (`--unwrap missing`, the default, gives it UVs: driver/tests/unwrap.rs.)
    assert_cli_fails(
        &[
            "prepare",
            p.to_str().unwrap(),
            "-o",
            out_s,
            "--unwrap",
            "never",
            "--sky",
            "1",
        ],
        "no mesh has lightmap UVs (TEXCOORD_1); meshes without: tri",
    );

    // Empty scene.
    let p = write_gltf(
        d,
        "empty",
        r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": []}], "scene": 0}"#,
        None,
    );
    assert!(matches!(Scene::load(&p), Err(SceneError::Empty { .. })));
    assert_cli_fails(
        &["prepare", p.to_str().unwrap(), "-o", out_s],
        "the scene has no triangles",
    );

    // Only degenerate triangles: empty too, and counted.
    let (json, bin) = triangle_gltf("degen", true, [0, 1, 1]);
    let p = write_gltf(d, "degen", &json, Some(&bin));
    assert!(matches!(
        Scene::load(&p),
        Err(SceneError::Empty { degenerate: 1, .. })
    ));

    // Not JSON at all, and an unknown extension.
    let p = write_gltf(d, "junk", "this is not json", None);
    assert_cli_fails(&["prepare", p.to_str().unwrap(), "-o", out_s], "junk.gltf");
    assert_cli_fails(
        &["prepare", "scene.fbx", "-o", out_s],
        "unknown scene format",
    );

    // A scene file with a bad sun.
    std::fs::write(d.join("s.toml"), "geometry = \"badidx.gltf\"\n[sun]\ndirection = [0, 0, 0]\nangular_radius_deg = 0.3\nirradiance = [1, 1, 1]\n").unwrap();
    let (json, bin) = triangle_gltf("badidx", true, [0, 1, 2]);
    write_gltf(d, "badidx", &json, Some(&bin));
    assert_cli_fails(
        &["prepare", d.join("s.toml").to_str().unwrap(), "-o", out_s],
        "sun direction",
    );

    assert!(!out.exists(), "no output may be left behind");
    let leftovers: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().contains("tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A prepared one-triangle scene in `dir`: (scene, texel file).
fn prepared_triangle(dir: &Path) -> (PathBuf, PathBuf) {
    let (json, bin) = triangle_gltf("tri", true, [0, 1, 2]);
    write_gltf(dir, "tri", &json, Some(&bin));
    let texels = dir.join("tri.texels");
    // Lit by a sky from a scene file: a scene nothing lights is refused.
    let toml = dir.join("tri.toml");
    std::fs::write(
        &toml,
        "geometry = \"tri.gltf\"\n[sky]\nconstant = [1, 1, 1]\n",
    )
    .unwrap();
    let (code, err) = cli::outcome(&[
        "prepare",
        toml.to_str().unwrap(),
        "-o",
        texels.to_str().unwrap(),
        "--size",
        "32x32",
    ]);
    assert_eq!(code, Some(0), "{err}");
    (toml, texels)
}

/// Nothing named like the output or its work directory exists in `dir`.
fn assert_no_output(dir: &Path, stem: &str) {
    let left: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(stem))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Bad `guidebake bake` values: each a clear message naming the option or file, a non-zero
/// exit, no panic, and neither a lightmap nor a work directory left behind.
#[test]
fn bad_bake_arguments_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, texels) = prepared_triangle(d);
    let out = d.join("lm.exr");
    let (scene, texels, out_s) = (
        scene.to_str().unwrap(),
        texels.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let bake = |extra: &[&'static str]| -> Vec<String> {
        let mut args = vec!["bake", texels, "--scene", scene, "-o", out_s];
        args.extend_from_slice(extra);
        args.into_iter().map(String::from).collect()
    };
    let fails = |args: Vec<String>| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cli_fails(&args)
    };

    // Sample counts and iterations the bake cannot split into packets.
    for (extra, expect) in [
        (&["--spp", "0"][..], "--spp 0"),
        (
            &["--spp", "8", "--iterations", "2"],
            "--spp 8 over 2 iterations",
        ),
        (&["--spp", "32", "--iterations", "0"], "--iterations 0"),
        (&["--spp", "1024", "--iterations", "17"], "--iterations 17"),
    ] {
        let (_, err) = fails(bake(extra));
        assert!(
            err.contains(expect),
            "{extra:?}: expected '{expect}' in: {err}"
        );
    }
    // Shards that do not exist, and values clap refuses (exit 2, usage message).
    for shard in ["3/2", "2/2", "0/0", "1", "a/b", "1/2/3"] {
        let (_, err) = fails(bake(&["--spp", "32", "--shard", shard]));
        assert!(err.contains("--shard"), "--shard {shard}: {err}");
    }
    for (extra, expect) in [
        (&["--guiding", "sometimes"][..], "--guiding"),
        (&["--spp", "many"], "--spp"),
        (&["--spp", "32", "--seed", "-3"], "-3"),
        (&["--spp", "32", "--threads", "0"], "--threads"),
    ] {
        let (_, err) = fails(bake(extra));
        assert!(err.contains(expect), "{extra:?}: {err}");
    }
    assert_no_output(d, "lm.");

    // A missing scene and a missing texel file are named.
    let missing_scene = d.join("nowhere.gltf");
    let (_, err) = cli_fails(&[
        "bake",
        texels,
        "--scene",
        missing_scene.to_str().unwrap(),
        "-o",
        out_s,
        "--spp",
        "32",
    ]);
    assert!(err.contains("nowhere.gltf"), "{err}");
    let missing_texels = d.join("nothing.texels");
    let (_, err) = cli_fails(&[
        "bake",
        missing_texels.to_str().unwrap(),
        "--scene",
        scene,
        "-o",
        out_s,
        "--spp",
        "32",
    ]);
    assert!(err.contains("nothing.texels"), "{err}");
    assert_no_output(d, "lm.");

    // A texture cap of 0 is refused. (A missing texture image is a warning:
    // tests/levels.rs.)
    let (_, err) = fails(bake(&["--spp", "32", "--max-texture-size", "0"]));
    assert!(err.contains("--max-texture-size"), "{err}");
    assert_no_output(d, "lm.");
}

/// A texel file prepared from another scene is refused, naming both files.
#[test]
fn a_texel_file_of_another_scene_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, texels) = prepared_triangle(d);
    // The same triangle twice (a second node): another scene.
    let (json, bin) = triangle_gltf("two", true, [0, 1, 2]);
    let json = json
        .replace(r#""nodes": [0]"#, r#""nodes": [0, 1]"#)
        .replace(
            r#""nodes": [{"name": "tri", "mesh": 0}]"#,
            r#""nodes": [{"name": "tri", "mesh": 0}, {"name": "copy", "mesh": 0, "translation": [0, 1, 0]}]"#,
        );
    let other = write_gltf(d, "two", &json, Some(&bin));
    let out = d.join("lm.exr");
    let (_, err) = cli_fails(&[
        "bake",
        texels.to_str().unwrap(),
        "--scene",
        other.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--spp",
        "32",
        "--sky",
        "1",
    ]);
    assert!(
        err.contains("tri.texels") && err.contains("two.gltf") && err.contains("1 triangles"),
        "{err}"
    );
    assert_no_output(d, "lm.");
}

/// An output directory that does not exist, is a file, or cannot be written: a clear
/// message naming it, before any work, and nothing left behind.
#[test]
fn an_unwritable_output_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, texels) = prepared_triangle(d);
    let bake_to = |out: &Path| {
        cli_fails(&[
            "bake",
            texels.to_str().unwrap(),
            "--scene",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--spp",
            "32",
        ])
        .1
    };
    let err = bake_to(&d.join("no/such/dir/lm.exr"));
    assert!(
        err.contains("no/such/dir") && err.contains("does not exist"),
        "{err}"
    );
    let file = d.join("plain-file");
    std::fs::write(&file, b"not a directory").unwrap();
    let err = bake_to(&file.join("lm.exr"));
    assert!(err.contains("plain-file"), "{err}");

    // A directory nobody may write: read-only permissions (as a normal user), or a
    // read-only file system (/proc, which refuses even root).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let locked = d.join("locked");
        std::fs::create_dir(&locked).unwrap();
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o555)).unwrap();
        let writable = std::fs::write(locked.join("probe"), b"").is_ok();
        let target = if writable {
            PathBuf::from("/proc/guidebake-lm.exr") // root ignores permissions
        } else {
            locked.join("lm.exr")
        };
        let err = bake_to(&target);
        let parent = target.parent().unwrap().to_str().unwrap();
        assert!(err.contains(parent), "{err}");
        assert!(!target.exists());
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o755)).unwrap();
        assert_no_output(&locked, "lm.");
    }
    assert_no_output(d, "lm.");
}
