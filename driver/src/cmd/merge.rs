//! `guidebake merge TEXELS SHARD_DIRS... -o OUT.exr [--pass B]`: without `--pass` (or with the
//! last pass), reduces the shards' ρ sums in tile order and writes the final lightmap; with
//! `--pass B` before the last series pass, gathers pass B of every shard into the merged
//! result file the shards of pass B + 1 read. Either equals an unsharded bake's bytes.

use std::path::PathBuf;

use crate::bake::finish::{Denoise, FinishOptions, Seams, finish_with, merge_pass};
use crate::bake::workdir::read_manifest;
use crate::texels::TexelFile;

/// Arguments of `guidebake merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The texel file the shards baked.
    pub texels: PathBuf,
    /// The shards' work directories (`OUT.exr.shard-I-of-N`), every one of them.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// The lightmap to write (and, with `--pass`, beside which `OUT.exr.merged/` is made).
    #[arg(short, long = "output", alias = "out", value_name = "OUT.exr")]
    pub out: PathBuf,
    /// Merge series pass B of a pass-by-pass bake (`bake --pass B --shard I/N`); the last
    /// pass writes the pages, as without `--pass`.
    #[arg(long)]
    pub pass: Option<u32>,
    /// Denoise the lightmap as its pages are written (as `bake --denoise`; off by default).
    #[arg(long, value_enum, default_value_t = Denoise::Off)]
    pub denoise: Denoise,
    /// Stitch seams (as `bake --seams`; off by default).
    #[arg(long, value_enum, default_value_t = Seams::Off)]
    pub seams: Seams,
}

/// What `merge` reads — the texel file and the shards' work directories — and writes: the
/// lightmap's pages and atlas previews, and `OUT.exr.merged/`.
fn merge_files(args: &MergeArgs) -> Result<super::files::Files, super::CmdError> {
    super::files::check_exr("-o", &args.out)?;
    let mut files = super::files::Files::new().reads("the texel file", &args.texels);
    for shard in &args.shards {
        files = files.reads("a shard's work directory", shard);
    }
    for (path, preview) in super::files::lightmap_files(&args.out, &args.texels) {
        files = files
            .writes("the lightmap (-o)", &path)
            .writes("the lightmap's atlas preview", &preview);
    }
    Ok(files.writes_dir(
        "the merged passes' directory",
        &crate::bake::workdir::merged_dir(&args.out),
    ))
}

/// Runs `guidebake merge`.
///
/// # Errors
/// A missing or foreign shard, an unbaked tile, an unwritable page: each named.
pub fn run(args: &MergeArgs) -> Result<(), super::CmdError> {
    let files = merge_files(args)?;
    files.check()?;
    super::interrupt::register_outputs(files.outputs());
    let texels = TexelFile::open(&args.texels)?;
    if let Some(pass) = args.pass {
        let passes = read_manifest(&args.shards[0].join("manifest.json"))?.passes;
        if pass != passes {
            let merged = merge_pass(&texels, &args.shards, &args.out, pass)?;
            println!("{}", merged.display());
            return Ok(());
        }
    }
    let options = FinishOptions {
        denoise: args.denoise,
        seams: args.seams,
    };
    let written = finish_with(&texels, &args.shards, &args.out, options)?;
    if let (Some([before, after]), Some([pairs_before, pairs_after])) =
        (written.edge_jump, written.seam_jump)
    {
        let [points, skipped, _] = written.edge_points;
        eprintln!(
            "seams: mean relative jump at {points} edge points ({skipped} left out) \
             {before:.4} → {after:.4}; between the {} texel pairs {pairs_before:.4} → {pairs_after:.4}",
            written.seam_pairs
        );
    }
    for page in &written.pages {
        println!("{}", page.display());
    }
    eprintln!("ρ = {:.6}", written.rho);
    Ok(())
}
