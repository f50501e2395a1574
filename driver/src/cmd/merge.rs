//! `guidebake merge TEXELS SHARD_DIRS... -o OUT.exr`: reduces the shards' ρ sums in tile order
//! and writes the final lightmap. The result equals an unsharded bake's bit for bit.

use std::path::PathBuf;

use crate::bake::run::finish;
use crate::texels::TexelFile;

/// Arguments of `guidebake merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The texel file the shards baked.
    pub texels: PathBuf,
    /// The shards' work directories (`OUT.exr.shard-I-of-N`), every one of them.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// The lightmap to write.
    #[arg(short, long)]
    pub out: PathBuf,
}

/// Runs `guidebake merge`.
///
/// # Errors
/// A missing or foreign shard, an unbaked tile, an unwritable page: each named.
pub fn run(args: &MergeArgs) -> Result<(), super::CmdError> {
    let texels = TexelFile::open(&args.texels)?;
    let written = finish(&texels, &args.shards, &args.out)?;
    for page in &written.pages {
        println!("{}", page.display());
    }
    eprintln!("ρ = {:.6}", written.rho);
    Ok(())
}
