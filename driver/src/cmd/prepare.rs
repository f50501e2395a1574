//! `guidebake prepare`: to be written.

/// Arguments of `guidebake prepare`.
#[derive(Debug, clap::Args)]
pub struct PrepareArgs {}

/// Runs `guidebake prepare`.
///
/// # Errors
/// Always, until the subcommand exists.
pub fn run(_args: &PrepareArgs) -> Result<(), super::CmdError> {
    Err("guidebake prepare is not built yet".into())
}
