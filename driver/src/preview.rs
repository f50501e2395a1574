//! `preview`: what turns pixels into PNG files — linear-to-sRGB encoding, tone mapping for
//! radiance previews, colour helpers, and an atomic PNG writer. It draws nothing: the figures
//! (`guidebake samples`, the bench's charts) are drawn with plotters on an RGB buffer that
//! [`write_png_rgb8`] then writes.
//!
//! A PNG written whole goes through [`write_png_rgb8`]: the parent directory is created, the
//! image is written to a temporary name beside the target and renamed over it at the end, so
//! an interrupted or failed write never leaves a partial file under the final name. (The page
//! writer streams its previews row by row through the same kind of temporary name,
//! `output/exr_pages`.)

use std::path::{Path, PathBuf};

/// What writing a PNG failed with; each variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    /// The output's directory could not be created.
    #[error("cannot create directory {path}")]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Encoding or writing the temporary file failed.
    #[error("cannot write PNG {path}")]
    Write {
        /// The temporary file being written.
        path: PathBuf,
        /// Why.
        #[source]
        source: image::ImageError,
    },
    /// Moving the finished temporary file to its final name failed.
    #[error("cannot rename {from} to {to}")]
    Rename {
        /// The temporary file.
        from: PathBuf,
        /// The requested output.
        to: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The path names no file (empty, or ends in `..` or `/`).
    #[error("output path {0} does not name a file")]
    NotAFile(PathBuf),
    /// The image is empty, or its size does not match its bytes.
    #[error("image size {width}x{height} cannot be written")]
    Size {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
}

/// Linear [0, 1] to 8-bit sRGB (IEC 61966-2-1 transfer curve); NaN and negatives give 0,
/// values above 1 give 255.
pub fn linear_to_srgb8(v: f32) -> u8 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Tone maps linear radiance to 8-bit sRGB: exposure, then Reinhard's x / (1 + x) per
/// channel. Non-finite or negative input gives black, so no NaN reaches a preview.
pub fn tonemap_reinhard(rgb: [f32; 3], exposure: f32) -> [u8; 3] {
    rgb.map(|c| {
        let x = if c.is_finite() {
            (c * exposure).max(0.0)
        } else {
            0.0
        };
        linear_to_srgb8(x / (1.0 + x))
    })
}

/// A well-separated colour for item `i` of a sequence: hue steps by the golden ratio, so
/// neighbours (consecutive packets) never get similar colours.
pub fn categorical_color(i: usize) -> [u8; 3] {
    let hue = (i as f64 * 0.618_033_988_749_895).fract();
    let value = if i.is_multiple_of(2) { 0.95 } else { 0.75 };
    hsv_to_rgb8(hue as f32, 0.85, value)
}

/// HSV (all in [0, 1]) to 8-bit RGB.
pub fn hsv_to_rgb8(h: f32, s: f32, v: f32) -> [u8; 3] {
    let h6 = h.rem_euclid(1.0) * 6.0;
    let sector = h6.floor();
    let f = h6 - sector;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match sector as u32 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r, g, b].map(|c| (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
}

/// Writes packed 8-bit RGB rows (`width * height * 3` bytes) as a PNG at `path`, atomically:
/// creates the parent directory, writes `.<name>.tmp-<pid>` beside the target, renames it
/// over `path`.
///
/// # Errors
/// [`PreviewError`] naming the file when the directory cannot be created, the size is zero
/// or does not match the byte count ([`PreviewError::Size`]), encoding or writing fails, or
/// the rename fails. The temporary file is removed on failure.
pub fn write_png_rgb8(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[u8],
) -> Result<(), PreviewError> {
    if width == 0 || height == 0 || rgb.len() as u64 != u64::from(width) * u64::from(height) * 3 {
        return Err(PreviewError::Size { width, height });
    }
    let name = path
        .file_name()
        .ok_or_else(|| PreviewError::NotAFile(path.to_owned()))?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|source| PreviewError::CreateDir {
        path: dir.to_owned(),
        source,
    })?;
    let tmp = crate::atomic::temporary_name(&dir.join(name));
    let written = image::save_buffer_with_format(
        &tmp,
        rgb,
        width,
        height,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    );
    if let Err(source) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(PreviewError::Write { path: tmp, source });
    }
    std::fs::rename(&tmp, path).map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        PreviewError::Rename {
            from: tmp.clone(),
            to: path.to_owned(),
            source,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `width` × `height` image of `background` with the given pixels set, as packed RGB.
    fn image(width: u32, height: u32, background: [u8; 3], set: &[(u32, u32, [u8; 3])]) -> Vec<u8> {
        let mut rgb = background.repeat(width as usize * height as usize);
        for &(x, y, c) in set {
            let i = 3 * (y * width + x) as usize;
            rgb[i..i + 3].copy_from_slice(&c);
        }
        rgb
    }

    #[test]
    fn png_round_trips_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nested/deeper/figure.png");
        let rgb = image(
            7,
            5,
            [10, 20, 30],
            &[(3, 2, [255, 0, 0]), (6, 4, [1, 2, 3])],
        );
        write_png_rgb8(&path, 7, 5, &rgb).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (7, 5));
        assert_eq!(back.as_raw(), &rgb);
        assert_eq!(back.get_pixel(3, 2).0, [255, 0, 0]);
        assert_eq!(back.get_pixel(6, 4).0, [1, 2, 3]);
        assert_eq!(back.get_pixel(0, 0).0, [10, 20, 30]);
        let leftovers: Vec<_> = std::fs::read_dir(path.parent().unwrap()).unwrap().collect();
        assert_eq!(leftovers.len(), 1, "only figure.png should remain");
    }

    #[test]
    fn bad_outputs_are_typed_errors() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("file");
        std::fs::write(&blocker, b"x").unwrap();
        let black = [0u8; 12];
        let err = write_png_rgb8(&blocker.join("a.png"), 2, 2, &black).unwrap_err();
        assert!(matches!(err, PreviewError::CreateDir { .. }), "{err}");
        let err = write_png_rgb8(&dir.path().join("e.png"), 0, 3, &[]).unwrap_err();
        assert!(matches!(err, PreviewError::Size { .. }));
        let err = write_png_rgb8(&dir.path().join("s.png"), 2, 2, &[0; 11]).unwrap_err();
        assert!(matches!(err, PreviewError::Size { .. }));
        // A directory in the way of the final name: the rename fails, the temp file is gone.
        std::fs::create_dir(dir.path().join("taken.png")).unwrap();
        std::fs::write(dir.path().join("taken.png/inner"), b"x").unwrap();
        let err = write_png_rgb8(&dir.path().join("taken.png"), 2, 2, &black).unwrap_err();
        assert!(matches!(err, PreviewError::Rename { .. }), "{err}");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert!(
            names.iter().all(|n| !n.to_string_lossy().contains(".tmp-")),
            "{names:?}"
        );
    }

    #[test]
    fn colour_helpers() {
        assert_eq!(linear_to_srgb8(0.0), 0);
        assert_eq!(linear_to_srgb8(1.0), 255);
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb8(0.214_041_14), 128); // sRGB mid-grey
        assert_eq!(
            tonemap_reinhard([f32::INFINITY, -1.0, f32::NAN], 1.0),
            [0, 0, 0]
        );
        assert_eq!(
            tonemap_reinhard([1.0, 0.0, 1e30], 1.0)[0],
            linear_to_srgb8(0.5)
        );
        assert_eq!(hsv_to_rgb8(0.0, 1.0, 1.0), [255, 0, 0]);
        assert_eq!(hsv_to_rgb8(1.0 / 3.0, 1.0, 1.0), [0, 255, 0]);
        for i in 0..64 {
            let (a, b) = (categorical_color(i), categorical_color(i + 1));
            let d: u32 = a
                .iter()
                .zip(&b)
                .map(|(x, y)| u32::from(x.abs_diff(*y)))
                .sum();
            assert!(d > 60, "packets {i} and {} look alike: {a:?} {b:?}", i + 1);
        }
    }
}
