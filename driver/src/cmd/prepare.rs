//! `guidebake prepare SCENE -o OUT.texels [--texels-per-unit D | --size WxH]`: rasterize a
//! scene's lightmap UVs into a texel file (see [`crate::prepare`]).

use std::path::PathBuf;

use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};
use crate::scene::Scene;

/// Arguments of `guidebake prepare`.
#[derive(Debug, clap::Args)]
pub struct PrepareArgs {
    /// Scene: .gltf, .glb, .obj or a .toml scene file.
    pub scene: PathBuf,
    /// Output texel file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Texels per world unit along an edge.
    #[arg(long, conflicts_with = "size")]
    pub texels_per_unit: Option<f32>,
    /// Page size, e.g. 1024x1024. Default when neither option is given: one 1024x1024
    /// page's worth of texels.
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Atlas layout.
    #[arg(long, value_enum, default_value_t = Layout::Auto)]
    pub layout: Layout,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Parses `WxH` (also `W×H`).
///
/// # Errors
/// A message when it is not two positive integers.
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X', '×'])
        .ok_or_else(|| format!("size '{s}' is not WxH"))?;
    let p = |v: &str| v.trim().parse::<u32>().ok().filter(|&v| v > 0);
    match (p(w), p(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("size '{s}' needs two positive integers")),
    }
}

/// Runs `guidebake prepare`.
///
/// # Errors
/// The scene cannot be loaded, the options are impossible, or writing fails.
pub fn run(args: &PrepareArgs) -> Result<(), super::CmdError> {
    let resolution = match (args.texels_per_unit, args.size) {
        (Some(d), _) if !(d.is_finite() && d > 0.0) => {
            return Err(format!("--texels-per-unit {d} must be positive and finite").into());
        }
        (Some(d), _) => Resolution::TexelsPerUnit(d),
        (None, Some((w, h))) => Resolution::Size(w, h),
        (None, None) => Resolution::Default,
    };
    let scene = Scene::load(&args.scene)?;
    let report = prepare(
        &scene,
        &args.output,
        PrepareOptions {
            resolution,
            layout: args.layout,
        },
    )?;
    // The seams beside the texel file, for `bake --seams stitch` (docs/lightmaps.md).
    crate::output::seams::prepare_seams(&scene, &args.output)?;
    for m in &report.meshes_without_lightmap_uvs {
        eprintln!(
            "guidebake: warning: mesh '{m}' has no lightmap UVs (TEXCOORD_1); it gets no texels"
        );
    }
    if scene.degenerate_triangles > 0 {
        eprintln!(
            "guidebake: {} degenerate triangles dropped",
            scene.degenerate_triangles
        );
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{}: {} texels ({} partial) in {} tiles on {} page(s) {:?}, {} layout, {:.3} texels/unit",
            args.output.display(),
            report.texels,
            report.partial_texels,
            report.tiles,
            report.pages.len(),
            report.pages,
            if report.per_mesh_layout {
                "per-mesh"
            } else {
                "shared"
            },
            report.texels_per_unit
        );
    }
    Ok(())
}
