//! Light probes from the command line (docs/probes.md): a small open-topped room under a
//! constant sky, with a solid block on its floor, prepared, baked, and its probes placed and
//! baked; a probe just above the floor against the floor's own baked texel; probes inside
//! the block not placed; the same bytes on one thread and two; bad input named, nothing
//! written; `render` drawing the probes and a sphere they light; a bake stopped part-way
//! (twice, by Ctrl-C, or killed) and resumed writing the same bytes as one never stopped, and a resume
//! of other settings, lights or lightmap refused with the work kept; shards merged into the
//! bytes of one bake.

use std::path::{Path, PathBuf};

use glam::Vec3;
use guidebake::probes::file::{ProbeFile, volume_path};
use guidebake::render::Lightmap;
use guidebake::scene::Scene;
use guidebake::texels::TexelFile;

mod cli;
use cli::{BIN, fails, fails_with, outcome, s, snapshot, succeeds};

/// The sky's radiance.
const SKY: f32 = 1.0;

/// A 4 × 4 room, 3 high, open to the sky above, walls wound inwards, and a closed 1 m block
/// at x 2.5–3.5, z 0.5–1.5 on its floor, all of albedo 0.5; a TOML scene file with the sky.
fn room(dir: &Path) -> PathBuf {
    let mut obj = String::from("mtllib room.mtl\nusemtl plaster\n");
    let mut v = 0;
    let mut quad = |obj: &mut String, c: [[f32; 3]; 4]| {
        for p in c {
            *obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        *obj += &format!(
            "f {} {} {}\nf {} {} {}\n",
            v + 1,
            v + 2,
            v + 3,
            v + 1,
            v + 3,
            v + 4
        );
        v += 4;
    };
    obj += "o room\n";
    quad(
        &mut obj,
        [[0., 0., 0.], [0., 0., 4.], [4., 0., 4.], [4., 0., 0.]],
    );
    quad(
        &mut obj,
        [[0., 0., 0.], [4., 0., 0.], [4., 3., 0.], [0., 3., 0.]],
    );
    quad(
        &mut obj,
        [[0., 0., 4.], [0., 3., 4.], [4., 3., 4.], [4., 0., 4.]],
    );
    quad(
        &mut obj,
        [[0., 0., 0.], [0., 3., 0.], [0., 3., 4.], [0., 0., 4.]],
    );
    quad(
        &mut obj,
        [[4., 0., 0.], [4., 0., 4.], [4., 3., 4.], [4., 3., 0.]],
    );
    obj += "o block\n";
    let (a, b) = ([2.5f32, 0.0, 0.5], [3.5f32, 1.0, 1.5]);
    let p = |i: u32| [0, 1, 2].map(|k| if i >> k & 1 == 1 { b[k] } else { a[k] });
    // Corner bits: 1 x, 2 y, 4 z; each face wound to face out of the block.
    for face in [
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ] {
        quad(&mut obj, face.map(p));
    }
    std::fs::write(dir.join("room.obj"), obj).unwrap();
    std::fs::write(dir.join("room.mtl"), "newmtl plaster\nKd 0.5 0.5 0.5\n").unwrap();
    let scene = dir.join("room.toml");
    std::fs::write(
        &scene,
        format!("geometry = \"room.obj\"\n[sky]\nconstant = [{SKY}, {SKY}, {SKY}]\n"),
    )
    .unwrap();
    scene
}

/// The room prepared and baked: (scene, texels, lightmap).
fn baked(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let scene = room(dir);
    let texels = dir.join("room.texels");
    let lightmap = dir.join("room.exr");
    succeeds(&[
        "prepare",
        s(&scene),
        "-o",
        s(&texels),
        "--texels-per-unit",
        "16",
    ]);
    succeeds(&[
        "bake",
        s(&texels),
        "--scene",
        s(&scene),
        "-o",
        s(&lightmap),
        "--spp",
        "256",
        "--quiet",
    ]);
    (scene, texels, lightmap)
}

/// The irradiance the lightmap holds at floor point (x, 0, z).
fn floor_irradiance(scene: &Path, texels: &Path, lightmap: &Path, x: f32, z: f32) -> Vec3 {
    let scene = Scene::load(scene).unwrap();
    let texels = TexelFile::open(texels).unwrap();
    let map = Lightmap::load(&texels, &scene, lightmap).unwrap();
    let p = Vec3::new(x, 0.0, z);
    for (i, t) in scene.triangles.iter().enumerate() {
        let [a, b, c] = t.positions;
        if t.geometric_normal().y < 0.99 || a.y.abs() > 1e-6 {
            continue;
        }
        // Barycentrics in the x–z plane.
        let (e1, e2, d) = (b - a, c - a, p - a);
        let det = e1.x * e2.z - e1.z * e2.x;
        let b1 = (d.x * e2.z - d.z * e2.x) / det;
        let b2 = (e1.x * d.z - e1.z * d.x) / det;
        if b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0 {
            return map.irradiance(i as u32, b1, b2);
        }
    }
    panic!("no floor triangle under ({x}, {z})");
}

/// A probe 2 cm above the floor reads the floor's own baked irradiance towards +Y (what
/// the floor texel gathers over its hemisphere, the probe gathers over its upper one), within
/// 10 %: the two bakes' noise and the L2 truncation (measured 2026-12-07: the probe 1.488,
/// the texel 1.398 at 256 spp; against 2048-spp path references, 1.505 and 1.456); the point
/// inside the block is skipped and counted; the volume textures are written.
#[test]
fn a_probe_above_the_floor_reads_the_floors_baked_irradiance() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let points = dir.join("points.txt");
    std::fs::write(
        &points,
        "# above the floor, inside the block\n1.5 0.02 2.5\n3.0 0.5 1.0\n",
    )
    .unwrap();
    let out = dir.join("room.probes");
    let (_, err) = succeeds(&[
        "probes",
        s(&texels),
        "--scene",
        s(&scene),
        "--lightmap",
        s(&lightmap),
        "-o",
        s(&out),
        "--points",
        s(&points),
        "--placement",
        "points",
        "--spp",
        "4096",
    ]);
    assert!(
        err.contains("1 probes") && err.contains("1 inside geometry skipped"),
        "{err}"
    );
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("room.probes.json")).unwrap())
            .unwrap();
    assert_eq!(stats["probes"], 1);
    assert_eq!(stats["skipped_inside_geometry"], 1);
    assert!(stats["lightmap_reads"].as_u64().unwrap() > 500);
    for band in 0..3 {
        assert!(volume_path(&out, band).is_file());
    }
    let file = ProbeFile::open(&out).unwrap();
    assert_eq!(file.probes.len(), 1);
    let probe = file.probes[0].sh.irradiance(Vec3::Y);
    let floor = floor_irradiance(&scene, &texels, &lightmap, 1.5, 2.5);
    let ratio = probe.x / floor.x;
    assert!(
        (ratio - 1.0).abs() < 0.1,
        "probe {probe} vs floor texel {floor}"
    );
}

/// The lattice places probes over the room and none inside the block or under the floor;
/// one thread and two write the same bytes; `render --probes --sphere` draws them.
#[test]
fn lattice_probes_are_the_same_bytes_on_any_thread_count_and_render() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let mut files = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.join(format!("t{threads}.probes"));
        succeeds(&[
            "probes",
            s(&texels),
            "--scene",
            s(&scene),
            "--lightmap",
            s(&lightmap),
            "-o",
            s(&out),
            "--spacing",
            "0.25",
            "--spp",
            "64",
            "--threads",
            threads,
            "--quiet",
        ]);
        files.push(out);
    }
    let bytes: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    assert_eq!(bytes[0], bytes[1], "one thread and two differ");
    let probes = ProbeFile::open(&files[0]).unwrap().probes;
    assert!(probes.len() > 100, "{}", probes.len());
    let block = |p: Vec3| {
        p.cmpgt(Vec3::new(2.5, 0.0, 0.5)).all() && p.cmplt(Vec3::new(3.5, 1.0, 1.5)).all()
    };
    let inside_room_under_floor =
        |p: Vec3| p.y < 0.0 && p.x > 0.0 && p.x < 4.0 && p.z > 0.0 && p.z < 4.0;
    assert!(
        !probes
            .iter()
            .any(|p| block(p.position) || inside_room_under_floor(p.position))
    );
    assert!(probes.iter().all(|p| p.sh.irradiance(Vec3::Y).x >= 0.0));
    let view = dir.join("view.png");
    succeeds(&[
        "render",
        s(&scene),
        "--texels",
        s(&texels),
        "--lightmap",
        s(&lightmap),
        "-o",
        s(&view),
        "--probes",
        s(&files[0]),
        "--sphere",
        "1.5,1.2,2.5,0.3",
        "--width",
        "160",
    ]);
    assert!(std::fs::metadata(&view).unwrap().len() > 1000);
}

/// Bad input is named, exits 1 or 2, and writes nothing: a points file with a bad line, a
/// probe file named .exr, `--placement points` without points, a lightmap that is not there,
/// and `render --probes` of a damaged probe file.
#[test]
fn bad_input_is_named_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let before = snapshot(dir);
    let out = dir.join("x.probes");
    let points = dir.join("bad-points.txt");
    std::fs::write(&points, "1 2 3\n1 two 3\n").unwrap();
    let before_points = snapshot(dir);
    let common = [
        "probes",
        s(&texels),
        "--scene",
        s(&scene),
        "--lightmap",
        s(&lightmap),
    ];
    let with = |extra: &[&str]| -> Vec<String> {
        common
            .iter()
            .chain(extra)
            .map(|s| (*s).to_owned())
            .collect()
    };
    let e = fails_with(1, &with(&["-o", s(&out), "--points", s(&points)]));
    assert!(
        e.contains("bad-points.txt:2") && e.contains("`1 two 3`"),
        "{e}"
    );
    assert_eq!(snapshot(dir), before_points);
    std::fs::remove_file(&points).unwrap();
    let e = fails_with(2, &with(&["-o", s(&dir.join("x.exr"))]));
    assert!(e.contains("not an EXR"), "{e}");
    let e = fails_with(2, &with(&["-o", s(&out), "--placement", "points"]));
    assert!(e.contains("--placement points needs --points"), "{e}");
    let missing = dir.join("nothing.exr");
    let (_, e) = fails(&[
        "probes",
        s(&texels),
        "--scene",
        s(&scene),
        "--lightmap",
        s(&missing),
        "-o",
        s(&out),
    ]);
    assert!(e.contains("nothing.exr"), "{e}");
    assert_eq!(snapshot(dir), before);
    let damaged = dir.join("damaged.probes");
    std::fs::write(
        &damaged,
        b"GBPROBES but not really a probe file at all, sixty-four bytes or more",
    )
    .unwrap();
    let e = fails_with(
        1,
        &[
            "render",
            s(&scene),
            "--texels",
            s(&texels),
            "--lightmap",
            s(&lightmap),
            "-o",
            s(&dir.join("v.png")),
            "--probes",
            s(&damaged),
        ],
    );
    assert!(
        e.contains("damaged.probes") && e.contains("not a usable probe file"),
        "{e}"
    );
    assert!(!dir.join("v.png").exists());
}

/// Starts `guidebake` with `args` and waits until `file` (a batch of its work) exists, the
/// command ends, or two minutes pass; `true` while it is still running.
fn start_until(
    args: &[String],
    stderr: std::process::Stdio,
    file: &Path,
) -> (std::process::Child, bool) {
    let mut child = std::process::Command::new(BIN)
        .args(args)
        .stderr(stderr)
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !file.exists() && start.elapsed().as_secs() < 120 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let running = child.try_wait().unwrap().is_none();
    (child, running)
}

/// `probes` of the room into `out` at `--spacing 0.25 --spp 64`, one cluster a batch (many
/// batches), with `extra` options (which replace those).
fn probe_args(
    scene: &Path,
    texels: &Path,
    lightmap: &Path,
    out: &Path,
    extra: &[&str],
) -> Vec<String> {
    let mut args: Vec<String> = [
        "probes",
        s(texels),
        "--scene",
        s(scene),
        "--lightmap",
        s(lightmap),
        "-o",
        s(out),
        "--quiet",
    ]
    .iter()
    .map(|a| (*a).to_owned())
    .collect();
    for [flag, value] in [
        ["--spacing", "0.25"],
        ["--spp", "64"],
        ["--batch-clusters", "1"],
    ] {
        if !extra.contains(&flag) {
            args.extend([flag.to_owned(), value.to_owned()]);
        }
    }
    args.extend(extra.iter().map(|a| (*a).to_owned()));
    args
}

/// The files a probe bake into `out` publishes, by name: the probe file, the volume's three
/// images, and the stats without their timings (and the files they list, by name).
fn published(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<PathBuf> = vec![out.to_owned()];
    files.extend((0..3).map(|band| volume_path(out, band)));
    let mut got: Vec<(String, Vec<u8>)> = files
        .iter()
        .map(|f| {
            let name = f.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(f).unwrap())
        })
        .collect();
    let stats = PathBuf::from(format!("{}.json", out.display()));
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(stats).unwrap()).unwrap();
    json.as_object_mut().unwrap().remove("seconds");
    let names: Vec<String> = json["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            Path::new(f.as_str().unwrap())
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    json["files"] = serde_json::json!(names);
    got.push(("stats".into(), json.to_string().into_bytes()));
    got
}

/// The work directory of the probe file `out`.
fn work_dir(out: &Path) -> PathBuf {
    PathBuf::from(format!("{}.bake", out.display()))
}

/// A bake of one cluster a batch, stopped after 3 batches; a resume under other settings,
/// other lights, another lightmap, and a rerun without `--resume`, refused (exit 1, the
/// message naming the work directory and what differs, no file changed); stopped again after
/// 2 more on one thread, then resumed to the end on two: it writes the same probe file,
/// volume and stats (timings apart) as a bake never stopped of 256 clusters a batch. Nothing
/// is published at the final paths while it is stopped; the work directory is gone at the end.
#[test]
fn a_stopped_probe_bake_resumes_to_the_same_bytes_and_other_settings_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let (whole_dir, cut_dir) = (dir.join("whole"), dir.join("cut"));
    std::fs::create_dir_all(&whole_dir).unwrap();
    std::fs::create_dir_all(&cut_dir).unwrap();
    let whole = whole_dir.join("room.probes");
    succeeds(&probe_args(
        &scene,
        &texels,
        &lightmap,
        &whole,
        &["--batch-clusters", "256"],
    ));
    assert!(
        !work_dir(&whole).exists(),
        "a finished bake left its work directory"
    );
    let clusters = published(&whole);

    let out = cut_dir.join("room.probes");
    let work = work_dir(&out);
    let e = fails_with(
        130,
        &probe_args(
            &scene,
            &texels,
            &lightmap,
            &out,
            &["--stop-after-batches", "3"],
        ),
    );
    assert!(
        e.contains("interrupted after 3 of") && e.contains(s(&work)) && e.contains("--resume"),
        "{e}"
    );
    assert_eq!(
        std::fs::read_dir(&cut_dir).unwrap().count(),
        1,
        "a stopped bake published something beside its work directory"
    );
    let kept = snapshot(dir);
    let refused = |extra: &[&str], says: &str| {
        let mut with = vec!["--resume"];
        with.extend(extra);
        let e = fails_with(1, &probe_args(&scene, &texels, &lightmap, &out, &with));
        assert!(e.contains(s(&work)) && e.contains(says), "{e}");
        assert_eq!(snapshot(dir), kept, "a refused resume changed files");
    };
    refused(&["--spp", "32"], "--spp was 64, now 32");
    refused(&["--sun", "-0.8,1,-0.2:40"], "--sun was none, now");
    refused(&["--dering"], "--dering was off, now on");
    let e = fails_with(1, &probe_args(&scene, &texels, &lightmap, &out, &[]));
    assert!(e.contains(s(&work)) && e.contains("pass --resume"), "{e}");
    assert_eq!(snapshot(dir), kept);
    let other_map = dir.join("other.exr");
    succeeds(&[
        "bake",
        s(&texels),
        "--scene",
        s(&scene),
        "-o",
        s(&other_map),
        "--spp",
        "64",
        "--seed",
        "1",
        "--quiet",
    ]);
    let kept = snapshot(dir);
    let e = fails_with(
        1,
        &probe_args(&scene, &texels, &other_map, &out, &["--resume"]),
    );
    assert!(e.contains(s(&work)) && e.contains("--lightmap was"), "{e}");
    assert_eq!(snapshot(dir), kept);

    let e = fails_with(
        130,
        &probe_args(
            &scene,
            &texels,
            &lightmap,
            &out,
            &["--resume", "--threads", "1", "--stop-after-batches", "2"],
        ),
    );
    assert!(e.contains("interrupted after 5 of"), "{e}");
    assert!(!out.exists());
    let (_, err) = succeeds(&probe_args(
        &scene,
        &texels,
        &lightmap,
        &out,
        &["--resume", "--threads", "2"],
    ));
    assert!(!err.contains("warning"), "{err}");
    assert!(!work.exists(), "a finished resume left its work directory");
    assert_eq!(published(&out), clusters, "the resumed bake differs");
}

/// A bake killed (SIGKILL) while it runs leaves nothing at its final paths; `--resume` then
/// ends with the same bytes as a bake never stopped.
#[test]
fn a_killed_probe_bake_resumes_to_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let whole = dir.join("whole.probes");
    succeeds(&probe_args(
        &scene,
        &texels,
        &lightmap,
        &whole,
        &["--threads", "1"],
    ));
    let out = dir.join("killed.probes");
    let args = probe_args(&scene, &texels, &lightmap, &out, &["--threads", "1"]);
    let second = work_dir(&out).join("batch-000002.bin");
    let (mut child, killed) = start_until(&args, std::process::Stdio::null(), &second);
    child.kill().unwrap();
    child.wait().unwrap();
    if killed {
        assert!(
            !out.exists() && !volume_path(&out, 0).exists(),
            "a killed bake published its file"
        );
        let (code, e) = outcome(&probe_args(&scene, &texels, &lightmap, &out, &[]));
        assert_eq!(code, Some(1), "{e}");
        assert!(e.contains("pass --resume"), "{e}");
    } else {
        eprintln!("the bake finished before it could be killed: only its bytes are compared");
    }
    succeeds(&probe_args(&scene, &texels, &lightmap, &out, &["--resume"]));
    let renamed = |(n, b): (String, Vec<u8>)| {
        let b = if n == "stats" {
            String::from_utf8(b)
                .unwrap()
                .replace("whole", "killed")
                .into_bytes()
        } else {
            b
        };
        (n.replace("whole", "killed"), b)
    };
    let a: Vec<_> = published(&whole).into_iter().map(renamed).collect();
    let b = published(&out);
    assert_eq!(a.len(), b.len());
    for ((na, ba), (nb, bb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        assert!(ba == bb, "{na} differs");
    }
}

/// Shards K/N of N = 1, 2, 3, each baked by its own process (publishing nothing at the final
/// paths), merged, write the same probe file, volume and stats (timings apart) as one process;
/// a merge missing a shard, with a shard of other settings or with a directory that is not a
/// shard's is refused (exit 1, the message naming the shard or its directory), `--shard 3/3`
/// too (exit 2), and nothing is published.
#[test]
fn shards_merge_to_the_bytes_of_one_bake() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let whole_dir = dir.join("whole");
    std::fs::create_dir_all(&whole_dir).unwrap();
    let whole = whole_dir.join("room.probes");
    succeeds(&probe_args(&scene, &texels, &lightmap, &whole, &[]));
    let one = published(&whole);
    for n in 1..=3 {
        let sub = dir.join(format!("n{n}"));
        std::fs::create_dir_all(&sub).unwrap();
        let out = sub.join("room.probes");
        let mut shards = Vec::new();
        for k in 0..n {
            let shard = format!("{k}/{n}");
            succeeds(&probe_args(
                &scene,
                &texels,
                &lightmap,
                &out,
                &["--shard", &shard],
            ));
            shards.push(PathBuf::from(format!("{}.shard-{k}-of-{n}", out.display())));
            assert!(shards[k].is_dir());
        }
        assert_eq!(
            std::fs::read_dir(&sub).unwrap().count(),
            n,
            "a shard published a file"
        );
        let merge = |dirs: &[PathBuf]| {
            let mut extra = vec!["--merge"];
            extra.extend(dirs.iter().map(|d| s(d)));
            probe_args(&scene, &texels, &lightmap, &out, &extra)
        };
        if n == 3 {
            let e = fails_with(1, &merge(&shards[..2]));
            assert!(e.contains("shard 2/3 is missing"), "{e}");
            let other = sub.join("other.probes");
            succeeds(&probe_args(
                &scene,
                &texels,
                &lightmap,
                &other,
                &["--shard", "2/3", "--spp", "32"],
            ));
            let other_dir = PathBuf::from(format!("{}.shard-2-of-3", other.display()));
            let e = fails_with(
                1,
                &merge(&[shards[0].clone(), shards[1].clone(), other_dir.clone()]),
            );
            assert!(
                e.contains(s(&other_dir)) && e.contains("--spp was 32, now 64"),
                "{e}"
            );
            let nowhere = sub.join("nowhere");
            let e = fails_with(1, &merge(std::slice::from_ref(&nowhere)));
            assert!(
                e.contains(s(&nowhere)) && e.contains("no such shard work directory"),
                "{e}"
            );
            let e = fails_with(
                2,
                &probe_args(&scene, &texels, &lightmap, &out, &["--shard", "3/3"]),
            );
            assert!(e.contains("3/3"), "{e}");
            assert!(!out.exists() && !volume_path(&out, 0).exists());
        }
        succeeds(&merge(&shards));
        assert_eq!(
            published(&out),
            one,
            "{n} shards merged differ from one bake"
        );
    }
}

/// Ctrl-C (SIGINT) while the batches are baked: the batch in flight finishes, the command
/// exits 130 saying how to resume, nothing is published at the final paths, and `--resume`
/// ends with the same bytes as a bake never stopped.
#[test]
fn a_probe_bake_stopped_by_ctrl_c_resumes_to_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let (whole_dir, cut_dir) = (dir.join("whole"), dir.join("cut"));
    std::fs::create_dir_all(&whole_dir).unwrap();
    std::fs::create_dir_all(&cut_dir).unwrap();
    let whole = whole_dir.join("room.probes");
    succeeds(&probe_args(&scene, &texels, &lightmap, &whole, &[]));
    let out = cut_dir.join("room.probes");
    let args = probe_args(&scene, &texels, &lightmap, &out, &["--threads", "1"]);
    let first = work_dir(&out).join("batch-000001.bin");
    let (child, running) = start_until(&args, std::process::Stdio::piped(), &first);
    if running {
        let sent = std::process::Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
    }
    let done = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&done.stderr);
    if done.status.success() {
        eprintln!("the bake finished before Ctrl-C reached it: only its bytes are compared");
    } else {
        assert_eq!(done.status.code(), Some(130), "{err}");
        assert!(
            err.contains("interrupted after") && err.contains("--resume"),
            "{err}"
        );
        assert_eq!(std::fs::read_dir(&cut_dir).unwrap().count(), 1, "{err}");
        succeeds(&probe_args(&scene, &texels, &lightmap, &out, &["--resume"]));
    }
    assert_eq!(published(&out), published(&whole));
}

/// `bake --probes` bakes the lightmap, then the probes from it: the same probe file and
/// volume as `probes --lightmap` run after the bake. What it cannot do it refuses before
/// baking anything: a probe file named as the lightmap, an EXR, the texel file or a file of
/// the scene, or probes from a shard.
#[test]
fn bake_bakes_probes_from_the_lightmap_it_writes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (scene, texels, lightmap) = baked(dir);
    let both = dir.join("both.exr");
    let probes = dir.join("both.probes");
    let room_mtl = dir.join("room.mtl");
    let bake = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = ["bake", s(&texels), "--scene", s(&scene), "-o", s(&both)]
            .iter()
            .map(|x| (*x).to_owned())
            .collect();
        a.extend(["--spp", "256", "--quiet"].map(str::to_owned));
        a.extend(extra.iter().map(|x| (*x).to_owned()));
        a
    };
    let before = snapshot(dir);
    for (extra, says) in [
        (vec!["--probes", s(&both)], "would overwrite the lightmap"),
        (vec!["--probes", "x.exr"], "not an EXR"),
        (
            vec!["--probes", s(&texels)],
            "would overwrite the texel file",
        ),
        (
            vec!["--probes", s(&room_mtl)],
            "would overwrite a file of the scene",
        ),
        (vec!["--probes", "x.EXR"], "not an EXR"),
        (
            vec!["--probes", s(&probes), "--shard", "0/2"],
            "after `guidebake merge`",
        ),
    ] {
        let a = bake(&extra);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let err = fails_with(2, &a);
        assert!(err.contains(says), "{err}");
    }
    assert_eq!(snapshot(dir), before, "refused bakes wrote nothing");
    let a = bake(&["--probes", s(&probes)]);
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    succeeds(&a);
    assert_eq!(
        std::fs::read(&both).unwrap(),
        std::fs::read(&lightmap).unwrap(),
        "the lightmap as a bake without probes writes it"
    );
    // The default probes of `bake --probes` against `probes` with its defaults.
    let default = dir.join("default.probes");
    succeeds(&[
        "probes",
        s(&texels),
        "--scene",
        s(&scene),
        "--lightmap",
        s(&lightmap),
        "-o",
        s(&default),
        "--quiet",
    ]);
    assert_eq!(
        std::fs::read(&probes).unwrap(),
        std::fs::read(&default).unwrap()
    );
    for band in 0..3 {
        assert_eq!(
            std::fs::read(volume_path(&probes, band)).unwrap(),
            std::fs::read(volume_path(&default, band)).unwrap()
        );
    }
}
