//! Why a texel file could not be written or opened.

use super::*;

/// Why a texel file could not be written or opened. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum TexelFileError {
    /// Reading, writing, mapping or renaming failed.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is shorter than its header or than its header says.
    #[error("{path}: truncated: {what} needs {needed} bytes, the file has {actual}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Which part.
        what: &'static str,
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        actual: u64,
    },
    /// The first eight bytes are not [`MAGIC`].
    #[error("{path}: offset 0: not a texel file (magic {found:?}, expected \"GBTEXELS\")")]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The bytes found.
        found: [u8; 8],
    },
    /// A version this build does not read.
    #[error(
        "{path}: offset 8: version {found} is not supported (this build reads version {VERSION}; run `guidebake prepare` again to rewrite the file)"
    )]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The version found.
        found: u32,
    },
    /// A header field is inconsistent.
    #[error("{path}: header: {message}")]
    BadHeader {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A section lies (partly) past the end of the file, or its size overflows.
    #[error(
        "{path}: {section} section at offset {offset} with {len} bytes ends past the end of the {file_len}-byte file"
    )]
    SectionOutOfBounds {
        /// The file.
        path: PathBuf,
        /// Section name.
        section: &'static str,
        /// Its offset.
        offset: u64,
        /// Its length (saturated at `u64::MAX` when it overflows).
        len: u64,
        /// File length.
        file_len: u64,
    },
    /// A section does not start at a multiple of [`SECTION_ALIGN`].
    #[error("{path}: {section} section offset {offset} is not a multiple of {SECTION_ALIGN}")]
    Misaligned {
        /// The file.
        path: PathBuf,
        /// Section name.
        section: &'static str,
        /// Its offset.
        offset: u64,
    },
    /// Two sections overlap.
    #[error("{path}: sections {a} and {b} overlap")]
    Overlap {
        /// The file.
        path: PathBuf,
        /// One section.
        a: &'static str,
        /// The other.
        b: &'static str,
    },
    /// A page record is invalid.
    #[error("{path}: page {page} (offset {offset}): {message}")]
    BadPage {
        /// The file.
        path: PathBuf,
        /// Page index.
        page: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// A triangle record is invalid.
    #[error("{path}: triangle {triangle} (offset {offset}): {message}")]
    BadTriangle {
        /// The file.
        path: PathBuf,
        /// Triangle index.
        triangle: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// A tile record is invalid.
    #[error("{path}: tile {tile} (offset {offset}): {message}")]
    BadTile {
        /// The file.
        path: PathBuf,
        /// Tile index.
        tile: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// A texel record is invalid.
    #[error("{path}: texel {texel} (offset {offset}): {message}")]
    BadTexel {
        /// The file.
        path: PathBuf,
        /// Texel index.
        texel: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// The writer was used out of order (a caller bug, reported instead of panicking).
    #[error("{path}: writer misuse: {message}")]
    Usage {
        /// The file being written.
        path: PathBuf,
        /// What happened.
        message: String,
    },
}
