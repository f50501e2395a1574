//! The `guidebake` subcommands, one module each. Every `run` returns a typed error that
//! `main` prints with its context; no subcommand panics on user input.

pub mod bake;
pub mod bench;
pub mod demo;
pub mod inspect;
pub mod merge;
pub mod prepare;
pub mod samples;
pub mod synth;

/// What a subcommand failed with: printed by `main` as `guidebake: <message>`, exit code 1.
pub type CmdError = Box<dyn std::error::Error + Send + Sync + 'static>;
