//! `guidebake inspect`: to be written.

/// Arguments of `guidebake inspect`.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {}

/// Runs `guidebake inspect`.
///
/// # Errors
/// Always, until the subcommand exists.
pub fn run(_args: &InspectArgs) -> Result<(), super::CmdError> {
    Err("guidebake inspect is not built yet".into())
}
