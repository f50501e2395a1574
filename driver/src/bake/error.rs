//! Why a bake stopped ([`BakeError`]) and the helper that names a failed file operation
//! ([`file_error`]).
//!
//! In a module of its own so that the bake's files import it without importing each other:
//! [`run`](super::run) calls [`finish`](super::finish), and both use
//! [`workdir`](super::workdir); all three return this error, and none of them needs the
//! others for it (docs/ARCHITECTURE.md, "Crates and what may depend on what").

use std::path::{Path, PathBuf};

use super::pipeline::PipelineError;
use super::settings::SettingsError;
use crate::bvh::BvhError;
use crate::output::OutputFileError;
use crate::output::exr_pages::PageWriteError;
use crate::texels::TexelFileError;

/// Why a bake stopped; every variant names what it was working on.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// Bad settings.
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// The texel file could not be opened or is invalid.
    #[error(transparent)]
    Texels(#[from] TexelFileError),
    /// The BVH could not be built from the scene.
    #[error("cannot build the BVH: {0}")]
    Bvh(#[from] BvhError),
    /// Writing, reading or syncing the result file or the journal failed.
    #[error(transparent)]
    Output(#[from] OutputFileError),
    /// The pipeline failed.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// A page could not be written.
    #[error(transparent)]
    Page(#[from] PageWriteError),
    /// A file or directory operation failed.
    #[error("{path}: {what}")]
    File {
        /// The file or directory.
        path: PathBuf,
        /// What failed.
        what: String,
    },
    /// A previous run's work exists and `--resume` was not given.
    #[error(
        "{dir}: a previous bake's work is here; pass --resume to continue it, or delete the directory to start over"
    )]
    WorkExists {
        /// The work directory.
        dir: PathBuf,
    },
    /// The scene and the texel file disagree.
    #[error("{0}")]
    Mismatch(String),
}

/// A [`BakeError::File`] for `path`, saying `what` failed.
pub(super) fn file_error(path: &Path, what: impl std::fmt::Display) -> BakeError {
    BakeError::File {
        path: path.to_owned(),
        what: what.to_string(),
    }
}
