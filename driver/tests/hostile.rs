//! Commands a new user types that must not lose their work (docs/RELIABILITY.md, "Hostile
//! commands"): an output over an input under any spelling, a lightmap that is not an EXR, two
//! outputs of one command on one file, Ctrl-C; and what the commands say while they work —
//! progress lines in a log, a summary, `--quiet`, `--help` for people, one exit code per
//! outcome. Each case checks the exit code, the message, every input's bytes and that no
//! output (nor a scratch file) is left behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod cli;
use cli::{BIN, changed, fails_with, s, snapshot, succeeds, text};

/// A refused command: exit code `code`, stderr holding each of `expect`, and the folder
/// exactly as before (every input's bytes, nothing new, no scratch file).
fn refused(dir: &Path, code: i32, args: &[&str], expect: &[&str]) -> String {
    let before = snapshot(dir);
    let err = fails_with(code, args);
    for e in expect {
        assert!(err.contains(e), "{args:?}: expected {e:?} in: {err}");
    }
    let changed = changed(&before, &snapshot(dir));
    assert!(changed.is_empty(), "{args:?} changed {changed:?}: {err}");
    err
}

const SUN: &str = "0.4,1,0.3:3";
const SKY: &str = "0.5,0.6,0.8";

/// A small level: a floor and two walls, open to the sky, an OBJ with its .mtl.
fn level(dir: &Path) -> PathBuf {
    let obj = "mtllib level.mtl\nusemtl plaster\n\
               v 0 0 0\nv 4 0 0\nv 4 0 4\nv 0 0 4\n\
               v 0 3 0\nv 0 3 4\nv 4 3 0\n\
               f 1 4 3\nf 1 3 2\nf 1 5 6\nf 1 6 4\nf 1 2 7\nf 1 7 5\n";
    let path = dir.join("level.obj");
    std::fs::write(&path, obj).unwrap();
    std::fs::write(dir.join("level.mtl"), "newmtl plaster\nKd 0.6 0.5 0.4\n").unwrap();
    path
}

/// The level prepared at 32² texels: (scene, texel file).
fn prepared(dir: &Path) -> (PathBuf, PathBuf) {
    let obj = level(dir);
    let texels = dir.join("level.texels");
    succeeds(&[
        "prepare",
        s(&obj),
        "-o",
        s(&texels),
        "--size",
        "32x32",
        "--sun",
        SUN,
        "--sky",
        SKY,
    ]);
    (obj, texels)
}

/// `bake` of the prepared level with `extra` arguments, cheap.
fn bake_args<'a>(texels: &'a Path, obj: &'a Path, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "bake",
        s(texels),
        "--scene",
        s(obj),
        "-o",
        out,
        "--spp",
        "8",
        "--iterations",
        "1",
        "--bounces",
        "1",
        "--threads",
        "1",
        "--sun",
        SUN,
        "--sky",
        SKY,
    ];
    args.extend_from_slice(extra);
    args
}

#[test]
fn bake_refuses_an_output_over_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (obj, texels) = prepared(d);
    // The scene, the texel file: neither is a lightmap's name.
    for out in [s(&obj), s(&texels)] {
        refused(
            d,
            2,
            &bake_args(&texels, &obj, out, &[]),
            &[out, "ends in .exr"],
        );
    }
    // A PNG would put the atlas preview on the lightmap.
    let png = d.join("lm2.png");
    refused(
        d,
        2,
        &bake_args(&texels, &obj, s(&png), &[]),
        &["lm2.png", ".exr"],
    );
    // The stats over the scene, spelt through a dot-dot path.
    std::fs::create_dir(d.join("sub")).unwrap();
    let dotted = d.join("sub/../level.obj");
    let lm = d.join("lm.exr");
    refused(
        d,
        2,
        &bake_args(&texels, &obj, s(&lm), &["--stats", s(&dotted)]),
        &["would overwrite the scene (--scene)", "level.obj"],
    );
    // A symbolic link named like a lightmap, pointing at the texel file.
    let link = d.join("link.exr");
    std::os::unix::fs::symlink(&texels, &link).unwrap();
    refused(
        d,
        2,
        &bake_args(&texels, &obj, s(&link), &[]),
        &["would overwrite the texel file", "link.exr"],
    );
    // A hard link of the scene named like the stats.
    let hard = d.join("stats.json");
    std::fs::hard_link(&obj, &hard).unwrap();
    refused(
        d,
        2,
        &bake_args(&texels, &obj, s(&lm), &["--stats", s(&hard)]),
        &["would overwrite the scene"],
    );
    // Two outputs of one bake on one file: the stats over the lightmap's preview.
    let preview = d.join("lm.atlas.png");
    refused(
        d,
        2,
        &bake_args(&texels, &obj, s(&lm), &["--stats", s(&preview)]),
        &["are the same file", "atlas preview"],
    );
}

#[test]
fn render_refuses_an_output_over_an_input_and_the_recipe_keeps_both_pictures() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (obj, texels) = prepared(d);
    let lm = d.join("level.exr");
    let (_, err) = succeeds(&bake_args(&texels, &obj, s(&lm), &[]));
    let atlas = d.join("level.atlas.png");
    assert!(lm.exists() && atlas.exists(), "{err}");
    let render = |out: &Path| {
        vec![
            "render".to_owned(),
            s(&obj).to_owned(),
            "--texels".to_owned(),
            s(&texels).to_owned(),
            "--lightmap".to_owned(),
            s(&lm).to_owned(),
            "-o".to_owned(),
            s(out).to_owned(),
            "--width".to_owned(),
            "64".to_owned(),
            "--sun".to_owned(),
            SUN.to_owned(),
            "--sky".to_owned(),
            SKY.to_owned(),
        ]
    };
    let run = |out: &Path, expect: &[&str]| {
        let args = render(out);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(d, 2, &args, expect);
    };
    run(&obj, &["level.obj", ".png"]);
    run(&lm, &["level.exr", ".png"]);
    run(&texels, &[".png"]);
    run(&atlas, &["would overwrite the lightmap's atlas preview"]);
    let hard = d.join("view.png");
    std::fs::hard_link(&texels, &hard).unwrap();
    run(&hard, &["would overwrite the texel file (--texels)"]);
    std::fs::remove_file(&hard).unwrap();
    // README's recipe: the view has a name of its own beside the atlas preview.
    let view = d.join("level.png");
    let atlas_bytes = std::fs::read(&atlas).unwrap();
    let args = render(&view);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    succeeds(&args);
    assert!(view.exists());
    assert_eq!(
        std::fs::read(&atlas).unwrap(),
        atlas_bytes,
        "the atlas preview is kept"
    );
}

#[test]
fn prepare_synth_and_merge_refuse_outputs_over_inputs_and_each_other() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = level(d);
    let glb = d.join("level.glb");
    let texels = d.join("level.texels");
    let prepare = |out: &Path, extra: &[&str]| {
        let mut args = vec!["prepare", s(&obj), "-o", s(out)];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--sun", SUN]);
        args.iter().map(|a| (*a).to_owned()).collect::<Vec<_>>()
    };
    let refuse = |args: Vec<String>, expect: &[&str]| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(d, 2, &args, expect);
    };
    refuse(prepare(&obj, &[]), &["would overwrite the scene"]);
    // The files the scene is read from are inputs too: its material library.
    refuse(
        prepare(&d.join("level.mtl"), &[]),
        &["would overwrite a file of the scene", "level.mtl"],
    );
    refuse(
        prepare(&d.join("./level.obj"), &[]),
        &["would overwrite the scene"],
    );
    refuse(prepare(&texels, &["--write-gltf", s(&texels)]), &[".glb"]);
    let texels_glb = d.join("both.glb");
    refuse(
        prepare(&texels_glb, &["--write-gltf", s(&texels_glb)]),
        &["are the same file"],
    );
    refuse(
        prepare(&texels, &["--write-gltf", s(&d.join("nowhere/x.glb"))]),
        &["does not exist"],
    );
    // synth writes the texel file and its scene, OUT.glb and OUT.toml, beside each other.
    refused(
        d,
        2,
        &["synth", "--texels", "2048", "-o", s(&glb)],
        &["are the same file"],
    );
    // merge: a lightmap that is not an EXR, a lightmap over the texel file.
    succeeds(
        &prepare(&texels, &[])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    let shard = d.join("lm.exr.bake");
    refused(
        d,
        2,
        &["merge", s(&texels), s(&shard), "-o", s(&d.join("lm.png"))],
        &[".exr"],
    );
    let link = d.join("lm.exr");
    std::os::unix::fs::symlink(&texels, &link).unwrap();
    refused(
        d,
        2,
        &["merge", s(&texels), s(&shard), "-o", s(&link)],
        &["would overwrite the texel file"],
    );
}

#[test]
fn a_bake_in_a_log_says_how_far_it_is_and_quiet_says_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (obj, texels) = prepared(d);
    let lm = d.join("lm.exr");
    // stderr is a pipe here, as in a log or a Slurm job.
    let (_, err) = succeeds(&bake_args(&texels, &obj, s(&lm), &[]));
    assert!(err.contains("bake: pass 1/2 done"), "{err}");
    assert!(err.contains("bake: pass 2/2 done"), "{err}");
    assert!(err.contains("Mrays/s") && err.contains("ETA"), "{err}");
    assert!(
        err.contains("guidebake: baked") && err.contains(s(&lm)),
        "a summary naming the lightmap: {err}"
    );
    let quiet = d.join("quiet.exr");
    let (out, err) = succeeds(&bake_args(&texels, &obj, s(&quiet), &["--quiet"]));
    assert!(quiet.exists());
    assert_eq!((out.as_str(), err.as_str()), ("", ""), "--quiet");
}

#[test]
fn help_is_for_people_and_the_output_option_has_one_name() {
    for command in [
        "bake", "prepare", "render", "merge", "synth", "demo", "bench", "samples",
    ] {
        let (out, _) = succeeds(&[command, "--help"]);
        assert!(
            !out.contains("[`") && !out.contains("`]"),
            "{command} --help shows Rust doc syntax:\n{out}"
        );
        assert!(out.contains("--output"), "{command} --help: {out}");
    }
    let (bake, _) = succeeds(&["bake", "--help"]);
    let at = |option: &str| {
        bake.find(option)
            .unwrap_or_else(|| panic!("{option} in bake --help"))
    };
    for first in [
        "--spp",
        "--bounces",
        "--sun",
        "--sky",
        "--denoise",
        "--directional",
    ] {
        for lever in [
            "--guide-target",
            "--min-split",
            "--smooth",
            "--combine",
            "--mix",
        ] {
            assert!(at(first) < at(lever), "{first} before {lever}:\n{bake}");
        }
    }
    assert!(bake.contains("Research levers"), "{bake}");
    // The other spelling still works.
    let dir = tempfile::tempdir().unwrap();
    let (obj, texels) = prepared(dir.path());
    let lm = dir.path().join("lm.exr");
    let mut args = bake_args(&texels, &obj, s(&lm), &[]);
    let o = args.iter().position(|a| *a == "-o").unwrap();
    args[o] = "--out";
    succeeds(&args);
    assert!(lm.exists());
}

#[test]
fn one_exit_code_per_outcome() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (obj, texels) = prepared(d);
    let lm = d.join("lm.exr");
    // The command line is wrong: 2.
    fails_with(2, &["bake", "--no-such-option"]);
    fails_with(2, &bake_args(&texels, &obj, s(&lm), &["--spp", "0"]));
    fails_with(
        2,
        &[
            "prepare",
            s(&obj),
            "-o",
            s(&texels),
            "--texels-per-unit",
            "-1",
        ],
    );
    // An input that is missing or wrong: 1, naming the file.
    let missing = d.join("missing.texels");
    let err = fails_with(1, &bake_args(&missing, &obj, s(&lm), &[]));
    assert!(err.contains("missing.texels"), "{err}");
    assert!(!lm.exists());
}

/// Waits (at most `limit`) until `ready` holds; false when it never did.
fn wait_for(limit: Duration, ready: impl Fn() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if ready() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

fn interrupt(child: &std::process::Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

#[test]
fn ctrl_c_exits_130_everywhere_and_leaves_nothing_half_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (obj, texels) = prepared(d);
    // A bake keeps its work and says how to resume.
    let lm = d.join("lm.exr");
    let mut args = bake_args(&texels, &obj, s(&lm), &[]);
    let spp = args.iter().position(|a| *a == "8").unwrap();
    args[spp] = "65536";
    let child = Command::new(BIN)
        .args(&args)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let work = d.join("lm.exr.bake");
    assert!(wait_for(Duration::from_secs(60), || work
        .join("manifest.json")
        .exists()));
    interrupt(&child);
    let o = child.wait_with_output().unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("--resume") && work.exists(), "{err}");
    assert!(!lm.exists(), "no lightmap from an interrupted bake");

    // prepare stops at once: no texel file, no scratch file beside it.
    let big = d.join("big.texels");
    let before = snapshot(d);
    let child = Command::new(BIN)
        .args([
            "prepare",
            s(&obj),
            "-o",
            s(&big),
            "--size",
            "4096x4096",
            "--sun",
            SUN,
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let scratch = |d: &Path| {
        std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().starts_with(".big.texels."))
    };
    assert!(
        wait_for(Duration::from_secs(120), || scratch(d)),
        "prepare writes its texel file under a scratch name"
    );
    interrupt(&child);
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", text(&o.stderr));
    assert!(!big.exists() && !scratch(d), "{:?}", snapshot(d).keys());
    assert_eq!(snapshot(d), before);
}
