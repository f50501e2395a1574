//! Files that appear complete or not at all: written under a temporary name in the target's
//! own directory, synced, then renamed into place (an atomic rename on one file system); on
//! any failure the temporary file is removed. Every file the driver publishes — texel files,
//! pages, previews, stats, the bench's tables and charts — goes through here.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// `DIR/.NAME.tmp-PID`: a temporary name beside `path`, so the rename that publishes it is
/// atomic and two processes never share one.
pub fn temporary_name(path: &Path) -> PathBuf {
    with_suffix(path, "tmp")
}

/// `DIR/.NAME.SUFFIX-PID`: a scratch name beside `path` (temporary files that are not the
/// file being published).
pub fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let (prefix, pid) = scratch_affixes(path);
    path.with_file_name(format!("{prefix}{suffix}{pid}"))
}

/// What every scratch name of `path` by this process starts and ends with ([`with_suffix`]):
/// `.NAME.` and `-PID`.
fn scratch_affixes(path: &Path) -> (String, String) {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |s| s.to_string_lossy());
    (format!(".{name}."), format!("-{}", std::process::id()))
}

/// Removes every scratch file (or folder) of `path` this process made ([`with_suffix`]):
/// what an output being written leaves when the process is stopped at once (Ctrl-C).
pub fn remove_scratch(path: &Path) {
    let (prefix, pid) = scratch_affixes(path);
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        if file.starts_with(&prefix) && file.ends_with(&pid) {
            let scratch = entry.path();
            let _ = if scratch.is_dir() {
                std::fs::remove_dir_all(&scratch)
            } else {
                std::fs::remove_file(&scratch)
            };
        }
    }
}

/// Writes `path` through [`temporary_name`]: `write` fills the temporary file (given its
/// path), which is then synced and renamed into place. On failure the temporary file is
/// removed and `path` is untouched.
///
/// # Errors
/// The first I/O error of `write`, the sync or the rename.
pub fn write_with(path: &Path, write: impl FnOnce(&Path) -> io::Result<()>) -> io::Result<()> {
    let tmp = temporary_name(path);
    let result = write(&tmp)
        .and_then(|()| std::fs::File::open(&tmp)?.sync_all())
        .and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// [`write_with`] for bytes given in parts.
///
/// # Errors
/// As [`write_with`].
pub fn write_parts(path: &Path, parts: &[&[u8]]) -> io::Result<()> {
    write_with(path, |tmp| {
        let mut f = io::BufWriter::new(std::fs::File::create(tmp)?);
        for part in parts {
            f.write_all(part)?;
        }
        f.into_inner().map_err(io::IntoInnerError::into_error)?;
        Ok(())
    })
}

/// [`write_with`] for one buffer.
///
/// # Errors
/// As [`write_with`].
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    write_parts(path, &[bytes.as_ref()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_this_processs_scratch_of_the_output_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("lm.exr");
        let pid = std::process::id();
        let ours = temporary_name(&out);
        let tiles = with_suffix(&out, "tiles");
        assert_eq!(tiles, dir.path().join(format!(".lm.exr.tiles-{pid}")));
        let other_process = dir.path().join(format!(".lm.exr.tmp-{}", pid + 1));
        let other_file = dir.path().join(format!(".lm2.exr.tmp-{pid}"));
        for p in [&out, &ours, &tiles, &other_process, &other_file] {
            std::fs::write(p, b"x").unwrap();
        }
        remove_scratch(&out);
        assert!(!ours.exists() && !tiles.exists());
        assert!(out.exists() && other_process.exists() && other_file.exists());
    }

    #[test]
    fn a_file_appears_whole_and_a_failed_write_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("gb-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("out.json");
        write_parts(&path, &[b"{\"a\":", b"1}"]).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"{\"a\":1}");
        let failed = write_with(&path, |tmp| {
            std::fs::write(tmp, b"partial")?;
            Err(io::Error::other("disk full"))
        });
        assert!(failed.is_err());
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"{\"a\":1}",
            "the old file stays"
        );
        assert!(
            !temporary_name(&path).exists(),
            "the temporary file is removed"
        );
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(names.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
