//! Why a scene could not be loaded ([`SceneError`]), where in its text ([`TextPos`]), and
//! what a file that is not what its extension says looks like.

use std::path::{Path, PathBuf};

/// Why a scene could not be loaded. Every variant names the file, and where a parser knows
/// it the line and column (`level.obj:1234:7: ...`, as compilers write it).
///
/// No variant's [`std::error::Error::source`] repeats what its message already says: the
/// messages carry their cause's text, and `source()` is `None` (the command line prints the
/// message and then each source as a "caused by" line).
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read (missing, unreadable).
    #[error("{path}: cannot read: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error (its text is in the message, so it is not the `source()`).
        error: std::io::Error,
    },
    /// The path is not a scene file guidebake can read: a directory, an empty file, or a
    /// file whose contents are another kind than its extension says.
    #[error("{path}: {message}")]
    NotAScene {
        /// The path.
        path: PathBuf,
        /// What it is instead, and what is accepted.
        message: String,
    },
    /// The glTF importer rejected the file (a bad GLB chunk, a failed validation, ...).
    #[error("{path}: not a loadable glTF file: {error}")]
    Gltf {
        /// The file.
        path: PathBuf,
        /// The importer's error (its text is in the message, so it is not the `source()`).
        error: ::gltf::Error,
    },
    /// One of a glTF file's buffers or images could not be loaded: a data URI that is not
    /// base64, a relative URI whose percent-escapes do not decode to UTF-8, a file that
    /// cannot be read, a buffer shorter than its `byteLength`, an image that does not decode.
    #[error("{path}: {item}: {message}")]
    GltfResource {
        /// The glTF file.
        path: PathBuf,
        /// Which one, e.g. `buffers[0]` or `images[2]`.
        item: String,
        /// What is wrong.
        message: String,
    },
    /// A text file (OBJ, glTF JSON) is malformed at a place: a number that is not one, too
    /// few components, a face index naming no element, a JSON syntax error.
    #[error("{path}:{at}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// Where.
        at: TextPos,
        /// What is wrong.
        message: String,
    },
    /// tobj rejected the OBJ for a reason the loader could not place on a line.
    #[error("{path}: not a loadable OBJ file: {error}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// tobj's error (its text is in the message, so it is not the `source()`).
        error: tobj::LoadError,
    },
    /// The TOML scene file is malformed (at `at`, where known), or a `--sun`/`--sky` value
    /// given for the scene is invalid.
    #[error("{path}{}: {message}", at.map(|a| format!(":{a}")).unwrap_or_default())]
    SceneFile {
        /// The file.
        path: PathBuf,
        /// Where in it, when the error is about one place.
        at: Option<TextPos>,
        /// What is wrong.
        message: String,
    },
    /// A mesh's data is inconsistent (index out of range, attribute count mismatch, ...).
    #[error("{path}: mesh '{mesh}': {message}")]
    BadMesh {
        /// The file.
        path: PathBuf,
        /// The mesh name.
        mesh: String,
        /// What is wrong.
        message: String,
    },
    /// The file extension is none we read.
    #[error(
        "{path}: unknown scene format{detail}; guidebake reads .gltf, .glb, .obj and .toml scene files"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// The extension it has and, where the contents are recognised, what it looks like
        /// (e.g. ` ".fbx"` or ` ".dat" (it looks like a binary glTF (.glb): rename it)`).
        detail: String,
    },
    /// After dropping degenerate triangles nothing is left.
    #[error("{path}: the scene has no triangles ({degenerate} degenerate triangles dropped)")]
    Empty {
        /// The file.
        path: PathBuf,
        /// How many degenerate triangles were dropped.
        degenerate: usize,
    },
    /// A texture image (OBJ `map_Kd`) is missing or cannot be decoded: the OBJ loader notes
    /// it as a [`MissingTexture`] and goes on (module docs), so [`Scene::load`] does not
    /// return it.
    #[error("{path}: texture {image}: {message}")]
    Texture {
        /// The scene (or MTL) file naming it.
        path: PathBuf,
        /// The image file as named.
        image: String,
        /// What is wrong.
        message: String,
    },
    /// Nothing lights the scene: no sun, no sky, no punctual light, no emissive triangle.
    #[error(
        "{path}: nothing lights this scene (no lights, no emissive materials, no sky); add a sun and a sky on the command line, the same on prepare, bake and render, e.g. `--sun 0.3,1,0.2:3 --sky 0.5,0.6,0.8` (--sun X,Y,Z[:IRRADIANCE], towards the sun, +Y up; --sky R,G,B or an equirect .exr), or [sun] and [sky] in a TOML scene file (docs/levels.md)"
    )]
    Unlit {
        /// The scene file.
        path: PathBuf,
    },
    /// The equirectangular sky image could not be read.
    #[error("{path}: cannot read sky image: {message}")]
    Sky {
        /// The EXR file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A place in a text file: a line and, where the parser knows it, a column, both counted
/// from 1 (the column in characters). Displays as `LINE` or `LINE:COLUMN`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextPos {
    /// The line, from 1.
    pub line: usize,
    /// The column, from 1, in characters.
    pub column: Option<usize>,
}

impl TextPos {
    /// The place of byte `offset` of `text` (clamped to its length).
    #[must_use]
    pub fn of_offset(text: &str, offset: usize) -> Self {
        let mut offset = offset.min(text.len());
        while !text.is_char_boundary(offset) {
            offset -= 1;
        }
        let before = &text[..offset];
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        Self {
            line: before.matches('\n').count() + 1,
            column: Some(before[line_start..].chars().count() + 1),
        }
    }
}

impl std::fmt::Display for TextPos {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.column {
            Some(c) => write!(f, "{}:{c}", self.line),
            None => write!(f, "{}", self.line),
        }
    }
}

/// What a file's first bytes say it is, for a message about a file whose contents are
/// another kind than its extension; `None` for text nothing here recognises.
pub(crate) fn looks_like(bytes: &[u8]) -> Option<&'static str> {
    const MAGIC: [(&[u8], &str); 9] = [
        (b"glTF", "a binary glTF (.glb)"),
        (&[0x76, 0x2f, 0x31, 0x01], "an OpenEXR image"),
        (b"GBTEXELS", "a guidebake texel file (.texels)"),
        (b"\x89PNG", "a PNG image"),
        (&[0xff, 0xd8, 0xff], "a JPEG image"),
        (b"PK\x03\x04", "a zip archive"),
        (&[0x1f, 0x8b], "a gzip file"),
        (b"Kaydara FBX Binary", "a binary FBX file"),
        (b"#?RADIANCE", "a Radiance HDR image"),
    ];
    if let Some((_, kind)) = MAGIC.iter().find(|(m, _)| bytes.starts_with(m)) {
        return Some(kind);
    }
    let head = &bytes[..bytes.len().min(4096)];
    let text = String::from_utf8_lossy(head);
    let text = text.trim_start_matches('\u{feff}').trim_start();
    if text.starts_with('{') {
        return Some("glTF JSON (.gltf)");
    }
    let words = |w: &str| text.lines().any(|l| l.split_whitespace().next() == Some(w));
    if words("v") && (words("f") || words("vt") || words("vn")) {
        return Some("a Wavefront OBJ file");
    }
    if head.contains(&0) {
        return Some("binary data");
    }
    None
}

/// The first 4 KiB of a file, if it can be read.
pub(super) fn read_head(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(4096).read_to_end(&mut head))
        .ok()?;
    Some(head)
}

/// The absolute form of `path` for a message (the path as given where that fails).
pub(crate) fn shown_absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_owned())
}
