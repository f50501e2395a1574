//! `guidebake synth --texels N -o OUT`: write a procedural city of about N texels (see
//! [`crate::synth`]) as a texel file plus its scene (`OUT` with `.glb` and `.toml`).

use std::path::PathBuf;

/// Arguments of `guidebake synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Number of texels (rounded to whole 32x32 tiles, within about 1%).
    #[arg(long)]
    pub texels: u64,
    /// Output texel file; the .glb and .toml scene are written beside it.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `guidebake synth`.
///
/// # Errors
/// N out of range or a write failure.
pub fn run(args: &SynthArgs) -> Result<(), super::CmdError> {
    let r = crate::synth::synth(args.texels, &args.output)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {} texels in {} tiles on {} page(s); {}x{} cells, {} triangles; scene {}",
            args.output.display(),
            r.texels,
            r.tiles,
            r.pages,
            r.grid,
            r.grid,
            r.triangles,
            r.scene.display()
        );
    }
    Ok(())
}
