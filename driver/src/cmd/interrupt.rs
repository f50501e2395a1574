//! Ctrl-C, the same in every command: exit code 130 and nothing half-written left behind.
//!
//! One handler for the whole process ([`install`]). While a bake runs it is *cooperative*
//! ([`Cooperate`]): the first Ctrl-C sets [`cancel_flag`], the tiles in flight finish and
//! are journalled, and the command returns [`super::Interrupted`] saying how to resume. Any
//! other time — loading a scene, preparing, rendering, merging, or a second Ctrl-C — the
//! process stops at once after removing the scratch files of the outputs it registered
//! ([`remove_scratch_of`]: the `.NAME.*-PID` files `atomic` writes before renaming),
//! so an output either exists whole, as before the command, or not at all.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// The exit code of a command stopped by Ctrl-C (128 + SIGINT, as shells report it).
pub const EXIT_INTERRUPTED: u8 = 130;

static CANCEL: AtomicBool = AtomicBool::new(false);
static COOPERATIVE: AtomicBool = AtomicBool::new(false);
static OUTPUTS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Installs the process's Ctrl-C handler (once, from `main`).
pub fn install() {
    // Fails only when a handler exists already: the first one keeps working.
    let _ = ctrlc::set_handler(handle);
}

fn handle() {
    if COOPERATIVE.load(Ordering::SeqCst) && !CANCEL.swap(true, Ordering::SeqCst) {
        eprintln!(
            "\nguidebake: Ctrl-C: finishing the tiles in flight and keeping the work (Ctrl-C again stops at once)"
        );
        return;
    }
    let outputs = OUTPUTS.lock().map(|o| o.clone()).unwrap_or_default();
    for out in &outputs {
        remove_scratch_of(out);
    }
    eprintln!("\nguidebake: interrupted (Ctrl-C)");
    std::process::exit(i32::from(EXIT_INTERRUPTED));
}

/// The flag a cooperative bake polls between tiles.
#[must_use]
pub fn cancel_flag() -> &'static AtomicBool {
    &CANCEL
}

/// While alive, Ctrl-C asks the running bake to stop (it polls [`cancel_flag`]) instead of
/// stopping the process.
pub struct Cooperate(());

impl Cooperate {
    /// Makes Ctrl-C cooperative until the value is dropped.
    #[must_use]
    pub fn begin() -> Self {
        COOPERATIVE.store(true, Ordering::SeqCst);
        Self(())
    }
}

impl Drop for Cooperate {
    fn drop(&mut self) {
        COOPERATIVE.store(false, Ordering::SeqCst);
    }
}

/// Registers outputs whose scratch files a hard stop removes.
pub fn register_outputs<'a>(outputs: impl IntoIterator<Item = &'a Path>) {
    if let Ok(mut o) = OUTPUTS.lock() {
        o.extend(outputs.into_iter().map(Path::to_owned));
    }
}

/// Removes this process's scratch files of `out` (`DIR/.NAME.SUFFIX-PID`, as
/// `atomic::with_suffix` names them).
pub fn remove_scratch_of(out: &Path) {
    let Some(name) = out.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let (prefix, suffix) = (format!(".{name}."), format!("-{}", std::process::id()));
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        if file.starts_with(&prefix) && file.ends_with(&suffix) {
            let path = entry.path();
            let _ = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_this_processs_scratch_of_the_output_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("lm.exr");
        let pid = std::process::id();
        let ours = dir.path().join(format!(".lm.exr.tmp-{pid}"));
        let tiles = dir.path().join(format!(".lm.exr.tiles-{pid}"));
        let other_process = dir.path().join(format!(".lm.exr.tmp-{}", pid + 1));
        let other_file = dir.path().join(format!(".lm2.exr.tmp-{pid}"));
        for p in [&out, &ours, &tiles, &other_process, &other_file] {
            std::fs::write(p, b"x").unwrap();
        }
        remove_scratch_of(&out);
        assert!(!ours.exists() && !tiles.exists());
        assert!(out.exists() && other_process.exists() && other_file.exists());
    }
}
