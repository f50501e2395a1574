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
    /// The first eight bytes are not [`MAGIC`]; the message says what the file is instead
    /// when it can tell ([`what_file_is`]): a scene, an image, an empty file.
    #[error("{path}: {}", not_a_texel_file(path, found, *kind))]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The bytes found (zero past the end of a shorter file).
        found: [u8; 8],
        /// What the file is instead, when its first bytes tell ([`what_file_is`]).
        kind: Option<FileKind>,
    },
    /// A version this build does not read.
    #[error("{path}: offset 8: {}", version_message(*found))]
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

/// What a file given as a texel file is instead, as its first bytes tell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// No bytes at all.
    Empty,
    /// A binary glTF (`glTF` magic).
    Glb,
    /// JSON text (a `.gltf`, most likely).
    GltfJson,
    /// Wavefront OBJ text.
    Obj,
    /// A TOML scene file (`geometry = …`, `[sun]`, `[sky]`).
    TomlScene,
    /// An OpenEXR image (a lightmap, most likely).
    Exr,
    /// A PNG image.
    Png,
    /// A JPEG image.
    Jpeg,
    /// Some other text.
    Text,
}

impl FileKind {
    fn name(self) -> &'static str {
        match self {
            FileKind::Empty => "an empty file",
            FileKind::Glb => "a glTF file (binary)",
            FileKind::GltfJson => "a glTF file (JSON text)",
            FileKind::Obj => "an OBJ file",
            FileKind::TomlScene => "a TOML scene file",
            FileKind::Exr => "an OpenEXR image",
            FileKind::Png => "a PNG image",
            FileKind::Jpeg => "a JPEG image",
            FileKind::Text => "a text file",
        }
    }

    /// Whether `guidebake prepare` reads it.
    fn is_scene(self) -> bool {
        matches!(
            self,
            FileKind::Glb | FileKind::GltfJson | FileKind::Obj | FileKind::TomlScene
        )
    }
}

/// What the file whose first bytes are `head` (up to a few hundred) is, when they tell.
#[must_use]
pub fn what_file_is(head: &[u8]) -> Option<FileKind> {
    if head.is_empty() {
        return Some(FileKind::Empty);
    }
    if head.starts_with(b"glTF") {
        return Some(FileKind::Glb);
    }
    if head.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return Some(FileKind::Exr);
    }
    if head.starts_with(b"\x89PNG\r\n\x1a\n") {
        return Some(FileKind::Png);
    }
    if head.starts_with(&[0xff, 0xd8, 0xff]) {
        return Some(FileKind::Jpeg);
    }
    // Text: valid UTF-8 (but for a character the cut split) without control bytes.
    let text = match std::str::from_utf8(head) {
        Ok(t) => t,
        Err(e) if e.error_len().is_none() => std::str::from_utf8(&head[..e.valid_up_to()]).ok()?,
        Err(_) => return None,
    };
    if text
        .chars()
        .any(|c| c.is_control() && !matches!(c, '\n' | '\r' | '\t'))
    {
        return None;
    }
    let text = text.trim_start_matches('\u{feff}');
    if text.trim_start().starts_with('{') {
        return Some(FileKind::GltfJson);
    }
    let lines = || {
        text.lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
    };
    let obj = [
        "v ", "vt ", "vn ", "f ", "o ", "g ", "s ", "mtllib ", "usemtl ",
    ];
    if lines().next().is_some()
        && lines()
            .take(8)
            .all(|l| obj.iter().any(|k| l.starts_with(k)) || l == "v" || l == "f")
    {
        return Some(FileKind::Obj);
    }
    let toml = |l: &str| {
        (l.starts_with('[') && l.ends_with(']'))
            || l.split_once('=').is_some_and(|(k, _)| {
                let k = k.trim();
                !k.is_empty()
                    && k.chars()
                        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
            })
    };
    if lines().next().is_some() && lines().take(8).all(toml) {
        return Some(FileKind::TomlScene);
    }
    Some(FileKind::Text)
}

fn not_a_texel_file(path: &Path, found: &[u8; 8], kind: Option<FileKind>) -> String {
    let make = "make one with `guidebake prepare SCENE -o OUT.texels`";
    match kind {
        Some(k) if k.is_scene() => format!(
            "this is {}, not a texel file: make one from it with `guidebake prepare {} -o OUT.texels`",
            k.name(),
            path.display()
        ),
        Some(FileKind::Exr) => format!(
            "this is an OpenEXR image (a lightmap?), not a texel file: give the texel file it was \
             baked from, or {make}"
        ),
        Some(k) => format!("this is {}, not a texel file: {make}", k.name()),
        None => {
            format!("offset 0: not a texel file (magic {found:?}, expected \"GBTEXELS\"): {make}")
        }
    }
}

fn version_message(found: u32) -> String {
    if found < VERSION {
        format!(
            "texel file version {found}, made by an older guidebake; this one reads version \
             {VERSION} (which records the scene's geometry): run `guidebake prepare` again to \
             make it anew"
        )
    } else {
        format!(
            "texel file version {found}, made by a newer guidebake; this one reads version \
             {VERSION}: use that guidebake, or run `guidebake prepare` again with this one"
        )
    }
}
