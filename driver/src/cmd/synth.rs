//! `guidebake synth --texels N -o OUT [--lit-windows W] [--night]`: write a procedural city
//! of about N texels (see [`crate::synth`]) as a texel file plus its scene (`OUT` with
//! `.glb` and `.toml`), optionally with W emissive windows and by night.

use std::path::PathBuf;

/// Arguments of `guidebake synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Number of texels (rounded to whole 32x32 tiles, within about 1%).
    #[arg(long)]
    pub texels: u64,
    /// Lit windows: this many small emissive quads on the box sides (2 triangles each),
    /// radiance 1.5 to 1000.
    #[arg(long, default_value_t = 0)]
    pub lit_windows: u32,
    /// Night: no sun, a dim sky; the windows light the city.
    #[arg(long)]
    pub night: bool,
    /// The texel file to write; the scene (OUT.glb and OUT.toml) is written beside it.
    #[arg(short, long, alias = "out", value_name = "OUT.texels")]
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
    let options = crate::synth::SynthOptions {
        lit_windows: args.lit_windows,
        night: args.night,
    };
    let files = super::files::Files::new()
        .writes("the texel file (-o)", &args.output)
        .writes("the scene's geometry", &args.output.with_extension("glb"))
        .writes("the scene file", &args.output.with_extension("toml"));
    files.check()?;
    super::interrupt::register_outputs(files.outputs());
    let r = crate::synth::synth_with(args.texels, &args.output, &options)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {} texels in {} tiles on {} page(s); {}x{} cells, {} triangles ({} emissive); scene {}",
            args.output.display(),
            r.texels,
            r.tiles,
            r.pages,
            r.grid,
            r.grid,
            r.triangles,
            r.emissive_triangles,
            r.scene.display()
        );
    }
    Ok(())
}
