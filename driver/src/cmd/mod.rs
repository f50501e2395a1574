//! The `guidebake` subcommands, one module each. Every `run` returns a typed error that
//! `main` prints with its context; no subcommand panics on user input.
//!
//! One exit code per outcome, in every command ([`exit_code`]): 0 done; 1 an input or the
//! work failed (a file unreadable, invalid or made for another file, an I/O error); 2 the
//! command line is wrong (an unknown option, a value out of range, an output that would
//! overwrite an input); 130 stopped by Ctrl-C ([`interrupt`]).

pub mod bake;
pub mod bench;
pub mod demo;
pub mod files;
pub mod inspect;
pub mod interrupt;
pub mod merge;
pub mod prepare;
pub mod probes;
pub mod render;
pub mod samples;
pub mod scene;
pub mod synth;
pub mod view;

/// What a subcommand failed with: printed by `main` as `guidebake: <message>`.
pub type CmdError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Exit code of a command that failed on an input or in its work.
pub const EXIT_FAILED: u8 = 1;
/// Exit code of a command line that is wrong (clap's own usage errors exit 2 too).
pub const EXIT_USAGE: u8 = 2;

/// A command line that cannot be run as given: exit code [`EXIT_USAGE`].
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Usage(pub String);

/// A command that Ctrl-C stopped with its work kept: exit code
/// [`interrupt::EXIT_INTERRUPTED`].
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Interrupted(pub String);

/// `on` or `off`: an option's value where a bare flag would not do (it has a default of
/// `on`, or reads better spelled out).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// A [`Usage`] error, boxed.
pub fn usage(message: impl Into<String>) -> CmdError {
    Box::new(Usage(message.into()))
}

/// The exit code for `e`: [`EXIT_USAGE`] for a wrong command line (an option out of range
/// included), [`interrupt::EXIT_INTERRUPTED`] for Ctrl-C, else [`EXIT_FAILED`].
#[must_use]
pub fn exit_code(e: &CmdError) -> u8 {
    if e.is::<Usage>() || e.is::<crate::bake::settings::SettingsError>() {
        EXIT_USAGE
    } else if e.is::<Interrupted>() {
        interrupt::EXIT_INTERRUPTED
    } else {
        EXIT_FAILED
    }
}

/// `e` and its causes as lines, each said once: a cause whose text its error already shows
/// is left out.
#[must_use]
pub fn error_lines(e: &(dyn std::error::Error + 'static)) -> Vec<String> {
    let mut lines = vec![e.to_string()];
    let mut source = e.source();
    while let Some(s) = source {
        let text = s.to_string();
        if !lines.iter().any(|l| l.contains(text.trim())) {
            lines.push(text);
        }
        source = s.source();
    }
    lines
}

/// `--threads N`: a worker count of at least 1 (0 used to be taken silently as 1).
///
/// # Errors
/// A message for clap's usage error when `s` is not a positive integer.
pub fn parse_threads(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err(
            "0 workers cannot bake: give at least 1 (or leave --threads out for every core)".into(),
        ),
        Ok(n) => Ok(n),
        Err(e) => Err(format!("{s:?} is not a worker count: {e}")),
    }
}

/// Worker threads where `--threads` is left out: every core.
pub fn every_core() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
