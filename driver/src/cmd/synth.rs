//! `guidebake synth`: to be written.

/// Arguments of `guidebake synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {}

/// Runs `guidebake synth`.
///
/// # Errors
/// Always, until the subcommand exists.
pub fn run(_args: &SynthArgs) -> Result<(), super::CmdError> {
    Err("guidebake synth is not built yet".into())
}
