//! `guidebake samples`: to be written.

/// Arguments of `guidebake samples`.
#[derive(Debug, clap::Args)]
pub struct SamplesArgs {}

/// Runs `guidebake samples`.
///
/// # Errors
/// Always, until the subcommand exists.
pub fn run(_args: &SamplesArgs) -> Result<(), super::CmdError> {
    Err("guidebake samples is not built yet".into())
}
