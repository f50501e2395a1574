//! What a command reads and what it writes, checked before any work: no output lands on an
//! input or on another output, whatever the path's spelling (`./x`, `../dir/x`, a symbolic
//! link or a hard link to the same file).
//!
//! Each command lists its inputs and every file it derives from its outputs (a lightmap's
//! pages and their atlas previews, `OUT.exr.bake/`, a texel file's seam sidecar) and calls
//! [`Files::check`]; the message names both files and the options that gave them.

use std::path::{Path, PathBuf};

use super::{CmdError, usage};

/// The files one run of a command reads and writes, each with the option that names it.
#[derive(Debug, Default)]
pub struct Files {
    reads: Vec<(String, PathBuf)>,
    writes: Vec<Output>,
}

/// One output of a command: what it is, where, and whether it is a directory (a bake's work
/// directory) or a file.
#[derive(Debug)]
struct Output {
    what: String,
    path: PathBuf,
    directory: bool,
}

impl Files {
    /// A run that reads and writes nothing yet.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// The command reads `path`, given as `what` (e.g. "the scene (--scene)").
    #[must_use]
    pub fn reads(mut self, what: impl Into<String>, path: &Path) -> Self {
        self.reads.push((what.into(), path.to_owned()));
        self
    }

    /// The command reads every one of `paths`, each as `what`: the files a scene was read
    /// from (`LoadNotes::files_read`), checked again once the scene is loaded.
    #[must_use]
    pub fn reads_each(mut self, what: &str, paths: &[PathBuf]) -> Self {
        for p in paths {
            self.reads.push((what.to_owned(), p.clone()));
        }
        self
    }

    /// The command writes the file `path`, as `what` (e.g. "the lightmap (-o)").
    #[must_use]
    pub fn writes(mut self, what: impl Into<String>, path: &Path) -> Self {
        self.writes.push(Output {
            what: what.into(),
            path: path.to_owned(),
            directory: false,
        });
        self
    }

    /// The command writes into the directory `path` (made when missing), as `what`.
    #[must_use]
    pub fn writes_dir(mut self, what: impl Into<String>, path: &Path) -> Self {
        self.writes.push(Output {
            what: what.into(),
            path: path.to_owned(),
            directory: true,
        });
        self
    }

    /// The outputs, for [`super::interrupt::register_outputs`].
    pub fn outputs(&self) -> impl Iterator<Item = &Path> {
        self.writes.iter().map(|o| o.path.as_path())
    }

    /// Refuses an output that is an input or another output, an output whose directory does
    /// not exist, and a file output that names an existing directory.
    ///
    /// # Errors
    /// A message naming both files and what each is.
    pub fn check(&self) -> Result<(), CmdError> {
        for (i, output) in self.writes.iter().enumerate() {
            let (what, out) = (&output.what, &output.path);
            check_directory(what, out)?;
            if !output.directory && out.is_dir() {
                return Err(usage(format!("{}: {what} is a directory", out.display())));
            }
            if let Some((input, path)) = self.reads.iter().find(|(_, p)| same_file(out, p)) {
                return Err(usage(format!(
                    "{}: {what} would overwrite {input}, {}: nothing was written; give the output another name",
                    out.display(),
                    path.display()
                )));
            }
            if let Some(other) = self.writes[..i].iter().find(|o| same_file(out, &o.path)) {
                return Err(usage(format!(
                    "{}: {what} and {} ({}) are the same file: nothing was written; give them different names",
                    out.display(),
                    other.what,
                    other.path.display()
                )));
            }
        }
        Ok(())
    }
}

/// The directory an output goes into must exist.
fn check_directory(what: &str, out: &Path) -> Result<(), CmdError> {
    let dir = parent_of(out);
    if !dir.is_dir() {
        return Err(usage(format!(
            "{}: {what}: the directory {} does not exist",
            out.display(),
            dir.display()
        )));
    }
    Ok(())
}

/// `out`'s directory (`.` for a bare name).
fn parent_of(out: &Path) -> &Path {
    out.parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// Whether `a` and `b` are one file: the same device and inode where both exist (hard links,
/// symbolic links), else the same path once the directories are resolved.
#[must_use]
pub fn same_file(a: &Path, b: &Path) -> bool {
    if let (Some(a), Some(b)) = (file_id(a), file_id(b)) {
        return a == b;
    }
    resolved(a) == resolved(b)
}

#[cfg(unix)]
fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn file_id(_: &Path) -> Option<(u64, u64)> {
    None
}

/// `path` with its directory resolved (symbolic links, `.`, `..`), whether or not the file
/// itself exists.
fn resolved(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let name = path.file_name().map(PathBuf::from).unwrap_or_default();
    match parent_of(path).canonicalize() {
        Ok(dir) => dir.join(name),
        Err(_) => std::path::absolute(path).unwrap_or_else(|_| path.to_owned()),
    }
}

/// The files of the lightmap `out` baked from the texel file `texels`: each page
/// (`OUT.exr`, or `OUT.pageN.exr` for several) and its atlas preview. One page where the texel
/// file cannot be read (the command then fails on it, naming it).
#[must_use]
pub fn lightmap_files(out: &Path, texels: &Path) -> Vec<(PathBuf, PathBuf)> {
    use crate::output::exr_pages::{page_path, preview_path};
    let pages = crate::texels::TexelFile::peek_header(texels).map_or(1, |h| h.page_count);
    (0..pages.max(1))
        .map(|page| {
            let path = page_path(out, page, pages);
            let preview = preview_path(&path);
            (path, preview)
        })
        .collect()
}

/// Refuses a lightmap path that does not end in `.exr` (the pages are OpenEXR; a `.png` name
/// would put the preview on top of the lightmap).
///
/// # Errors
/// A message naming the file and the option.
pub fn check_exr(option: &str, out: &Path) -> Result<(), CmdError> {
    check_extension(
        out,
        "exr",
        &format!("{option} names the lightmap, an OpenEXR file"),
    )
}

/// Refuses `path` unless its name ends in `.ext` (any case), saying `what` it is for.
///
/// # Errors
/// `PATH: WHAT: give it a name that ends in .EXT`.
pub fn check_extension(path: &Path, ext: &str, what: &str) -> Result<(), CmdError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
    {
        return Ok(());
    }
    Err(usage(format!(
        "{}: {what}: give it a name that ends in .{ext}",
        path.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_spelling_of_one_file_is_caught() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("cb.glb");
        std::fs::write(&scene, b"scene").unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let dotted = dir.path().join("sub/../cb.glb");
        assert!(same_file(&scene, &dotted));
        let link = dir.path().join("link.glb");
        std::os::unix::fs::symlink(&scene, &link).unwrap();
        assert!(same_file(&link, &scene));
        let hard = dir.path().join("hard.glb");
        std::fs::hard_link(&scene, &hard).unwrap();
        assert!(same_file(&hard, &scene));
        let other = dir.path().join("other.glb");
        std::fs::write(&other, b"scene").unwrap();
        assert!(!same_file(&other, &scene), "same bytes, another file");
        let missing = dir.path().join("sub/../new.exr");
        assert!(same_file(&missing, &dir.path().join("new.exr")));
        assert!(!same_file(&missing, &scene));
    }

    #[test]
    fn an_output_over_an_input_or_another_output_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("cb.glb");
        std::fs::write(&scene, b"scene").unwrap();
        let out = dir.path().join("lm.exr");
        let err = Files::new()
            .reads("the scene (--scene)", &scene)
            .writes("the lightmap (-o)", &dir.path().join("./cb.glb"))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("would overwrite the scene (--scene)"), "{err}");
        assert!(err.contains("cb.glb"), "{err}");
        let err = Files::new()
            .writes("the lightmap (-o)", &out)
            .writes("the stats (--stats)", &out)
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("are the same file"), "{err}");
        let err = Files::new()
            .writes("the lightmap (-o)", &dir.path().join("nowhere/lm.exr"))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("does not exist"), "{err}");
        Files::new()
            .reads("the scene (--scene)", &scene)
            .writes("the lightmap (-o)", &out)
            .check()
            .unwrap();
    }

    #[test]
    fn a_lightmap_ends_in_exr() {
        assert!(check_exr("-o", Path::new("lm.EXR")).is_ok());
        for bad in ["lm.png", "lm", "lm.exr.png"] {
            let err = check_exr("-o", Path::new(bad)).unwrap_err().to_string();
            assert!(err.contains(".exr") && err.contains(bad), "{err}");
        }
    }
}
