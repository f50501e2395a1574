//! `--denoise` from the command line: `on` is still the À-Trous filter's name, a build without
//! the `oidn` feature refuses `--denoise oidn` before baking and says how to get it, and a
//! build with it writes the same bytes at any thread count.

use std::path::{Path, PathBuf};

mod cli;
#[cfg(not(feature = "oidn"))]
use cli::{changed, fails_with, snapshot};
use cli::{s, succeeds};

/// A small level open to the sky: a floor and two walls, an OBJ with its .mtl, prepared at
/// 32² texels. Returns (scene, texel file).
fn prepared(dir: &Path) -> (PathBuf, PathBuf) {
    let obj = dir.join("level.obj");
    std::fs::write(
        &obj,
        "mtllib level.mtl\nusemtl plaster\n\
         v 0 0 0\nv 4 0 0\nv 4 0 4\nv 0 0 4\nv 0 3 0\nv 0 3 4\nv 4 3 0\n\
         f 1 4 3\nf 1 3 2\nf 1 5 6\nf 1 6 4\nf 1 2 7\nf 1 7 5\n",
    )
    .unwrap();
    std::fs::write(dir.join("level.mtl"), "newmtl plaster\nKd 0.6 0.5 0.4\n").unwrap();
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
        "-q",
    ]);
    (obj, texels)
}

const SUN: &str = "0.4,1,0.3:3";
const SKY: &str = "0.5,0.6,0.8";

/// Bakes the level at 32 spp into `out` with `--denoise denoise` and `extra` arguments.
fn bake(obj: &Path, texels: &Path, out: &Path, denoise: &str, extra: &[&str]) {
    let mut args = vec![
        "bake",
        s(texels),
        "--scene",
        s(obj),
        "-o",
        s(out),
        "--spp",
        "32",
        "--sun",
        SUN,
        "--sky",
        SKY,
        "-q",
        "--denoise",
        denoise,
    ];
    args.extend(extra);
    succeeds(&args);
}

#[test]
fn on_is_still_the_a_trous_filter() {
    let dir = tempfile::tempdir().unwrap();
    let (obj, texels) = prepared(dir.path());
    let (on, atrous, off) = (
        dir.path().join("on.exr"),
        dir.path().join("atrous.exr"),
        dir.path().join("off.exr"),
    );
    bake(&obj, &texels, &on, "on", &[]);
    bake(&obj, &texels, &atrous, "atrous", &[]);
    bake(&obj, &texels, &off, "off", &[]);
    let read = |p: &Path| std::fs::read(p).unwrap();
    assert_eq!(read(&on), read(&atrous));
    assert_ne!(read(&on), read(&off), "the filter changed nothing");
}

#[cfg(not(feature = "oidn"))]
#[test]
fn oidn_without_the_feature_is_refused_before_baking_saying_how_to_get_it() {
    let dir = tempfile::tempdir().unwrap();
    let (obj, texels) = prepared(dir.path());
    let before = snapshot(dir.path());
    let out = dir.path().join("lm.exr");
    let err = fails_with(
        2,
        &[
            "bake",
            s(&texels),
            "--scene",
            s(&obj),
            "-o",
            s(&out),
            "--spp",
            "8",
            "--denoise",
            "oidn",
        ],
    );
    for needed in ["scripts/oidn/fetch.sh", "--features oidn"] {
        assert!(err.contains(needed), "{needed} in: {err}");
    }
    let changed = changed(&before, &snapshot(dir.path()));
    assert!(changed.is_empty(), "wrote {changed:?}");
}

#[cfg(feature = "oidn")]
#[test]
fn oidn_writes_the_same_bytes_on_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let (obj, texels) = prepared(dir.path());
    let (one, two, off) = (
        dir.path().join("one.exr"),
        dir.path().join("two.exr"),
        dir.path().join("off.exr"),
    );
    bake(&obj, &texels, &one, "oidn", &["--threads", "1"]);
    bake(&obj, &texels, &two, "oidn", &["--threads", "2"]);
    bake(&obj, &texels, &off, "off", &["--threads", "2"]);
    let read = |p: &Path| std::fs::read(p).unwrap();
    assert_eq!(read(&one), read(&two));
    assert_ne!(read(&one), read(&off), "the filter changed nothing");
}
