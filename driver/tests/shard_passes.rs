//! Pass-by-pass sharding of a series bake through the command line: `bake --pass B
//! --shard I/N` for every pass and shard, `merge --pass B` after each pass, and a shard
//! SIGKILLed in the middle of its pass and run again with `--resume`; the lightmap must equal
//! the single-process bake's bytes. The Slurm variant runs the same chain through a real
//! scheduler with `scripts/slurm/` (ignored by default; see [`slurm_bake_equals_one_bake`]).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod cli;
use cli::{BIN, s};

const SHARDS: u32 = 3;
const PASSES: u32 = 3;
/// The bake's settings, the same for every command (the default transport: series).
const SETTINGS: [&str; 8] = [
    "--spp",
    "32",
    "--iterations",
    "2",
    "--bounces",
    "3",
    "--seed",
    "5",
];

fn run(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "{c:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A synthesised city of about 10^5 texels (96 tiles, 32 per shard) and its scene.
struct City {
    dir: tempfile::TempDir,
    texels: PathBuf,
    scene: PathBuf,
}

impl City {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let texels = dir.path().join("city.texels");
        run(Command::new(BIN).args(["synth", "--texels", "100000", "-o", s(&texels)]));
        let scene = texels.with_extension("toml");
        City { dir, texels, scene }
    }

    /// `guidebake bake` of this city to `out` with `extra` arguments.
    fn bake(&self, out: &Path, extra: &[&str]) -> Command {
        let mut c = Command::new(BIN);
        c.args([
            "bake",
            s(&self.texels),
            "--scene",
            s(&self.scene),
            "-o",
            s(out),
        ])
        .args(SETTINGS)
        .args(["--threads", "1"])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
        c
    }

    /// `guidebake merge` of every shard of `out`, of pass `pass`.
    fn merge(&self, out: &Path, pass: u32) -> Command {
        let mut c = Command::new(BIN);
        c.arg("merge").arg(&self.texels);
        for i in 0..SHARDS {
            c.arg(shard_dir(out, i));
        }
        c.args(["-o", s(out), "--pass", &pass.to_string()]);
        c
    }
}

fn shard_dir(out: &Path, index: u32) -> PathBuf {
    let name = out.file_name().unwrap().to_str().unwrap();
    out.with_file_name(format!("{name}.shard-{index}-of-{SHARDS}"))
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Starts `command` and waits until `started` exists (the pass has begun), the child has
/// exited, or 120 s have passed.
fn spawn_until_started(command: &mut Command, started: &Path) -> Child {
    let mut child = command.spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    while !started.exists() && child.try_wait().unwrap().is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
    child
}

/// Runs `command` to success; returns how long it ran after `started` appeared: the pass's
/// own work, without the set-up before it (loading the scene, building the BVH, reading the
/// previous pass), which a debug build spends most of a shard's time on.
fn run_after(mut command: Command, started: &Path) -> Duration {
    let child = spawn_until_started(&mut command, started);
    let start = Instant::now();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{command:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    start.elapsed()
}

/// Starts `command`, waits until `started` exists (the pass has begun), then `after` more,
/// and SIGKILLs it. Returns whether it was still running (killed mid-pass).
fn kill_mid_pass(mut command: Command, started: &Path, after: Duration) -> bool {
    let mut child = spawn_until_started(&mut command, started);
    std::thread::sleep(after);
    let running = child.try_wait().unwrap().is_none();
    child.kill().unwrap(); // SIGKILL
    let status = child.wait().unwrap();
    running && !status.success()
}

#[test]
fn three_shards_by_three_passes_with_a_killed_shard_equal_one_bake() {
    let city = City::new();
    let whole = city.dir.path().join("whole.exr");
    run(&mut city.bake(&whole, &[]));

    let out = city.dir.path().join("sharded.exr");
    for pass in 0..=PASSES {
        // The slowest shard of this pass so far, from its journal's creation on (passes
        // differ: pass 0 is the direct light alone, later passes gather, reading most of it
        // from the pass before; the set-up before the journal varies with the build).
        let mut shard_time = Duration::ZERO;
        for index in 0..SHARDS {
            let args = [
                "--pass".to_owned(),
                pass.to_string(),
                "--shard".into(),
                format!("{index}/{SHARDS}"),
                "--resume".into(),
            ];
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let journal = shard_dir(&out, index).join(format!("journal.{pass}.bin"));
            if pass == 2 && index == 1 {
                // Killed early in its pass, then run again: a scheduler's retry.
                assert!(
                    kill_mid_pass(city.bake(&out, &args), &journal, shard_time / 4),
                    "the shard finished before the kill: make the world bigger"
                );
                let journal_bytes = bytes(&journal).len();
                assert!(
                    journal_bytes < 64 + 48 * 32,
                    "killed before its last commit"
                );
            }
            shard_time = shard_time.max(run_after(city.bake(&out, &args), &journal));
        }
        run(&mut city.merge(&out, pass));
    }
    assert_eq!(bytes(&whole), bytes(&out));
    assert_eq!(
        bytes(&whole.with_extension("atlas.png")),
        bytes(&out.with_extension("atlas.png"))
    );
}

/// The pid of a running `guidebake bake` whose command line holds every one of `words`
/// (found through /proc, as an operator or the kernel's OOM killer would pick it).
fn find_bake(words: &[&str]) -> Option<i32> {
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let pid: i32 = e.file_name().to_str()?.parse().ok()?;
        let cmdline = std::fs::read(e.path().join("cmdline")).ok()?;
        let args: Vec<&str> = cmdline
            .split(|&b| b == 0)
            .filter_map(|a| std::str::from_utf8(a).ok())
            .collect();
        let is_bake = args.first()?.ends_with("guidebake") && args.get(1) == Some(&"bake");
        (is_bake && words.iter().all(|w| args.contains(w))).then_some(pid)
    })
}

/// The same chain through Slurm with `scripts/slurm/bake.sh` (one array job per pass, each
/// merge a dependent job): needs a running Slurm whose nodes share this file system, e.g. the
/// single-node one `scripts/slurm/local-cluster.sh` starts (what `.ci/run` does). Shard 1's
/// bake of pass 2 is SIGKILLed mid-pass from outside; its job script runs it again with
/// `--resume`, and the lightmap is still the single-process bake's bytes.
///
/// `scripts/slurm/local-cluster.sh && cargo test -p guidebake --test shard_passes -- --ignored`
#[test]
#[ignore = "needs a running Slurm (scripts/slurm/local-cluster.sh)"]
fn slurm_bake_equals_one_bake() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let city = City::new();
    let whole = city.dir.path().join("whole.exr");
    run(&mut city.bake(&whole, &[]));
    let out = city.dir.path().join("slurm.exr");
    let mut submit = Command::new("bash");
    submit
        .arg(root.join("scripts/slurm/bake.sh"))
        .args([
            s(&city.texels),
            s(&city.scene),
            s(&out),
            &SHARDS.to_string(),
        ])
        .args(SETTINGS)
        .env("GUIDEBAKE", BIN)
        .env("GUIDEBAKE_SLURM_WAIT", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let chain = submit.spawn().unwrap();
    // Kill shard 1 of pass 2 as soon as its pass has begun (its journal exists).
    let journal = shard_dir(&out, 1).join("journal.2.bin");
    let deadline = Instant::now() + Duration::from_secs(600);
    let pid = loop {
        assert!(Instant::now() < deadline, "shard 1 of pass 2 never ran");
        if journal.exists()
            && let Some(pid) = find_bake(&["--pass", "2", "--shard", "1/3"])
        {
            break pid;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    // At once: once its journal exists the pass itself takes a fraction of a second (most of
    // a shard's time is the set-up before it), and a later kill can find it gone.
    let killed = Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .unwrap();
    assert!(killed.success(), "kill -KILL {pid}");
    let done = chain.wait_with_output().unwrap();
    let log =
        String::from_utf8_lossy(&done.stdout).into_owned() + &String::from_utf8_lossy(&done.stderr);
    assert!(done.status.success(), "{log}");
    assert_eq!(bytes(&whole), bytes(&out), "{log}");
    assert_eq!(
        bytes(&whole.with_extension("atlas.png")),
        bytes(&out.with_extension("atlas.png"))
    );
    let shard_log =
        std::fs::read_to_string(city.dir.path().join("slurm.exr.slurm").join("bake-2-1.log"))
            .unwrap();
    assert!(
        shard_log.contains("status 137") && shard_log.contains("attempt 2"),
        "the killed shard was run again: {shard_log}"
    );
}
