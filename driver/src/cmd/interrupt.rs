//! Ctrl-C, the same in every command: exit code 130 and nothing half-written left behind.
//!
//! One handler for the whole process ([`install`]). While a bake runs it is *cooperative*
//! ([`Cooperate`]): the first Ctrl-C sets [`cancel_flag`], the tiles in flight finish and
//! are journalled, and the command returns [`super::Interrupted`] saying how to resume. Any
//! other time — loading a scene, preparing, rendering, merging, or a second Ctrl-C — the
//! process stops at once after removing the scratch files of the outputs it registered
//! (`atomic::remove_scratch`: the `.NAME.*-PID` files `atomic` writes before renaming),
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
            "\nguidebake: Ctrl-C: finishing the work in flight (tiles, or a batch of probes) and keeping it (Ctrl-C again stops at once)"
        );
        return;
    }
    let outputs = OUTPUTS.lock().map(|o| o.clone()).unwrap_or_default();
    for out in &outputs {
        crate::atomic::remove_scratch(out);
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
