//! The command line as the CLI tests run it, written once: run `guidebake`, check its exit
//! code and that it did not panic, and take a folder's snapshot to show a refused command
//! changed nothing. Each test file that runs the binary says `mod cli;`.

#![allow(dead_code)] // each test file uses its part

use std::collections::BTreeMap;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_guidebake");

/// A `guidebake` command to add arguments, a directory or pipes to before running it.
pub fn command() -> Command {
    Command::new(BIN)
}

/// `guidebake` with `args`, run to its end.
pub fn run<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// The exit code (`None`: killed by a signal) and stderr of `guidebake args`.
pub fn outcome<S: AsRef<OsStr>>(args: &[S]) -> (Option<i32>, String) {
    let o = run(args);
    (o.status.code(), text(&o.stderr))
}

/// Runs a command that must succeed; returns (stdout, stderr).
pub fn succeeds<S: AsRef<OsStr> + std::fmt::Debug>(args: &[S]) -> (String, String) {
    let o = run(args);
    let (out, err) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{args:?} failed: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    (out, err)
}

/// Runs a command that must fail with exit code `code` (1: an input or the work failed; 2: a
/// wrong command line); returns its stderr.
pub fn fails_with<S: AsRef<OsStr> + std::fmt::Debug>(code: i32, args: &[S]) -> String {
    let (got, err) = outcome(args);
    assert_eq!(got, Some(code), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    err
}

/// Runs a command that must fail, with any exit code but a signal; returns (code, stderr).
pub fn fails<S: AsRef<OsStr> + std::fmt::Debug>(args: &[S]) -> (i32, String) {
    let (code, err) = outcome(args);
    let code = code.unwrap_or_else(|| panic!("{args:?} was killed by a signal: {err}"));
    assert_ne!(code, 0, "{args:?} succeeded");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    (code, err)
}

/// Bytes as text, lossily.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A path as the `&str` an argument list takes.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every file and folder under `dir`, by path below it: a file's bytes, `<dir>` for a folder,
/// `<link>` for a symbolic link.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap().flatten() {
            let path = entry.path();
            let name = path.strip_prefix(dir).unwrap().to_owned();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            if meta.is_dir() {
                files.insert(name, b"<dir>".to_vec());
                stack.push(path);
            } else if meta.file_type().is_symlink() {
                files.insert(name, b"<link>".to_vec());
            } else {
                files.insert(name, std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// The paths whose entries differ between two snapshots (changed, made or removed).
pub fn changed(
    before: &BTreeMap<PathBuf, Vec<u8>>,
    after: &BTreeMap<PathBuf, Vec<u8>>,
) -> Vec<PathBuf> {
    before
        .keys()
        .chain(after.keys().filter(|k| !before.contains_key(*k)))
        .filter(|k| before.get(*k) != after.get(*k))
        .cloned()
        .collect()
}
