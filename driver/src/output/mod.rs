//! What a bake leaves on disk, and how it survives a crash (docs/ARCHITECTURE.md,
//! "Invariants"; docs/bake.md).
//!
//! A bake never holds the lightmap in memory. Workers hand finished tiles to one writer,
//! which writes them **in place** into a preallocated [`result_file`] (one fixed-size record
//! per texel, indexed by global texel id), syncs it, and only then appends the tiles to a
//! synced [`journal`]. An interrupted bake therefore resumes from the journal with every
//! journalled tile's results on disk, and a torn journal record is detected by its checksum
//! and dropped (its tile is baked again, which gives the same bits).
//!
//! The world-wide bias correction ρ = L̂ / L̂_GD of the paper (§2.5) needs every tile's sums:
//! the journal keeps them per tile and [`journal::rho_sums`] adds them exactly (the kernels'
//! `RhoAccumulator`), so ρ is bit-identical whatever the thread count, the order tiles finished in, or the shard
//! split. A final streaming pass ([`exr_pages`]) applies ρ and writes the EXR pages, each to
//! a temporary name renamed into place, so an output that looks complete is complete.

use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

pub mod denoise;
pub mod exr_pages;
pub mod journal;
pub mod readback;
pub mod result_file;
pub mod seams;

/// What went wrong with a result file or a journal; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum OutputFileError {
    /// The operating system refused an operation.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The OS error.
        source: io::Error,
    },
    /// The file is not of this kind or version, or belongs to another bake.
    #[error("{path}: {what}")]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// What does not match.
        what: String,
    },
    /// A texel range past the end of a result file.
    #[error("{path}: texels {first}..{end} lie past the {count} texels of the file")]
    OutOfRange {
        /// The file.
        path: PathBuf,
        /// First texel asked for.
        first: u64,
        /// One past the last texel asked for.
        end: u64,
        /// Texels in the file.
        count: u64,
    },
    /// Records to read or write that are not whole texels of the file's layout.
    #[error("{path}: {records} records are not whole texels of {per_texel} records each")]
    PartialTexel {
        /// The file.
        path: PathBuf,
        /// Records asked for.
        records: u64,
        /// Records per texel in the file.
        per_texel: u64,
    },
}

/// An [`OutputFileError::Io`] for `path`.
fn io_error(path: &Path, what: &'static str, source: io::Error) -> OutputFileError {
    OutputFileError::Io {
        path: path.to_owned(),
        what,
        source,
    }
}

/// Bytes of the header every output file starts with: magic (8), version (4), the rest.
const HEADER_BYTES: usize = 64;

/// Creates (or truncates) `path`, sizes it to `len` bytes (sparse), writes `header` at offset
/// 0 and syncs: the common start of a result file and a journal.
fn create_with_header(
    path: &Path,
    header: &[u8; HEADER_BYTES],
    len: u64,
) -> Result<File, OutputFileError> {
    let io = |what| move |source| io_error(path, what, source);
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(path)
        .map_err(io("create"))?;
    file.set_len(len).map_err(io("preallocate"))?;
    file.write_all_at(header, 0).map_err(io("write header"))?;
    file.sync_all().map_err(io("sync"))?;
    Ok(file)
}

/// Opens `path` and returns it with its length and header, after checking the header's magic
/// (first 8 bytes) and version (next 4, little-endian); `kind` names the file in messages.
fn open_with_header(
    path: &Path,
    writable: bool,
    kind: &str,
    magic: [u8; 8],
    version: u32,
) -> Result<(File, u64, [u8; HEADER_BYTES]), OutputFileError> {
    let io = |what| move |source| io_error(path, what, source);
    let mismatch = |what: String| OutputFileError::Mismatch {
        path: path.to_owned(),
        what,
    };
    let file = OpenOptions::new()
        .read(true)
        .write(writable)
        .open(path)
        .map_err(io("open"))?;
    let len = file.metadata().map_err(io("stat"))?.len();
    if len < HEADER_BYTES as u64 {
        return Err(mismatch(format!("{len} bytes is too short for a {kind}")));
    }
    let mut header = [0u8; HEADER_BYTES];
    file.read_exact_at(&mut header, 0)
        .map_err(io("read header"))?;
    if header[..8] != magic {
        return Err(mismatch(format!(
            "not a guidebake {kind} (bad magic at offset 0)"
        )));
    }
    let found = u32::from_le_bytes(header[8..12].try_into().expect("4 bytes"));
    if found != version {
        return Err(mismatch(format!(
            "{kind} version {found} (this build reads {version})"
        )));
    }
    Ok((file, len, header))
}
