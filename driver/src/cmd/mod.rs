//! The `guidebake` subcommands, one module each. Every `run` returns a typed error that
//! `main` prints with its context; no subcommand panics on user input.

pub mod bake;
pub mod bench;
pub mod demo;
pub mod inspect;
pub mod merge;
pub mod prepare;
pub mod render;
pub mod samples;
pub mod synth;

/// What a subcommand failed with: printed by `main` as `guidebake: <message>`, exit code 1.
pub type CmdError = Box<dyn std::error::Error + Send + Sync + 'static>;

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
