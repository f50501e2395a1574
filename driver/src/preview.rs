//! `preview`: PNG figures and previews — an 8-bit RGB canvas with a few drawing primitives,
//! linear-to-sRGB encoding and tone mapping for radiance previews, and an atomic PNG writer.
//!
//! Every PNG guidebake writes goes through [`write_png`]: the parent directory is created,
//! the image is written to a temporary name beside the target and renamed over it at the end,
//! so an interrupted or failed write never leaves a partial file under the final name.

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
    /// The canvas is empty or larger than a PNG allows.
    #[error("image size {width}x{height} cannot be written")]
    Size {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
}

/// An 8-bit sRGB image in row-major order, origin at the top left.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Canvas {
    width: u32,
    height: u32,
    pixels: Vec<[u8; 3]>,
}

impl Canvas {
    /// A `width` × `height` canvas filled with `background`.
    pub fn new(width: u32, height: u32, background: [u8; 3]) -> Self {
        Canvas {
            width,
            height,
            pixels: vec![background; width as usize * height as usize],
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The pixel at (x, y), or `None` outside the canvas.
    pub fn get(&self, x: i64, y: i64) -> Option<[u8; 3]> {
        self.index(x, y).map(|i| self.pixels[i])
    }

    fn index(&self, x: i64, y: i64) -> Option<usize> {
        let inside =
            (0..i64::from(self.width)).contains(&x) && (0..i64::from(self.height)).contains(&y);
        inside.then(|| y as usize * self.width as usize + x as usize)
    }

    /// Sets the pixel at (x, y); pixels outside the canvas are ignored (clipping).
    pub fn set(&mut self, x: i64, y: i64, color: [u8; 3]) {
        if let Some(i) = self.index(x, y) {
            self.pixels[i] = color;
        }
    }

    /// Fills the rectangle [x0, x1) × [y0, y1), clipped.
    pub fn fill_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, color: [u8; 3]) {
        for y in y0.max(0)..y1.min(i64::from(self.height)) {
            for x in x0.max(0)..x1.min(i64::from(self.width)) {
                self.set(x, y, color);
            }
        }
    }

    /// A filled disk of `radius` pixels centred at (cx, cy) in pixel coordinates.
    pub fn dot(&mut self, cx: f32, cy: f32, radius: f32, color: [u8; 3]) {
        let r2 = radius * radius;
        let (x0, x1) = ((cx - radius).floor() as i64, (cx + radius).ceil() as i64);
        let (y0, y1) = ((cy - radius).floor() as i64, (cy + radius).ceil() as i64);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                if dx * dx + dy * dy <= r2 {
                    self.set(x, y, color);
                }
            }
        }
    }

    /// A one-pixel line from (x0, y0) to (x1, y1) (DDA), clipped.
    pub fn line(&mut self, x0: f32, y0: f32, x1: f32, y1: f32, color: [u8; 3]) {
        let steps = (x1 - x0).abs().max((y1 - y0).abs()).ceil().max(1.0) as usize;
        for s in 0..=steps {
            let t = s as f32 / steps as f32;
            let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
            self.set(x.floor() as i64, y.floor() as i64, color);
        }
    }

    /// A one-pixel circle outline.
    pub fn circle(&mut self, cx: f32, cy: f32, radius: f32, color: [u8; 3]) {
        let steps = (radius * 8.0).ceil().max(16.0) as usize;
        for s in 0..steps {
            let phi = std::f32::consts::TAU * s as f32 / steps as f32;
            self.set(
                (cx + radius * phi.cos()).floor() as i64,
                (cy + radius * phi.sin()).floor() as i64,
                color,
            );
        }
    }

    /// The pixels as packed RGB bytes, row by row.
    pub fn as_bytes(&self) -> &[u8] {
        bytemuck::cast_slice(&self.pixels)
    }
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

/// Writes `canvas` as a PNG at `path`, atomically: creates the parent directory, writes
/// `.<name>.tmp-<pid>` beside the target, renames it over `path`.
///
/// # Errors
/// [`PreviewError`] naming the file when the directory cannot be created, the canvas is empty,
/// encoding or writing fails, or the rename fails. The temporary file is removed on failure.
pub fn write_png(path: &Path, canvas: &Canvas) -> Result<(), PreviewError> {
    write_png_rgb8(path, canvas.width, canvas.height, canvas.as_bytes())
}

/// [`write_png`] for packed 8-bit RGB rows (`width * height * 3` bytes).
///
/// # Errors
/// As [`write_png`]; also [`PreviewError::Size`] when the byte count does not match.
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

    #[test]
    fn png_round_trips_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nested/deeper/figure.png");
        let mut canvas = Canvas::new(7, 5, [10, 20, 30]);
        canvas.dot(3.5, 2.5, 1.0, [255, 0, 0]);
        canvas.set(6, 4, [1, 2, 3]);
        canvas.set(-1, 99, [9, 9, 9]); // clipped, no panic
        write_png(&path, &canvas).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (7, 5));
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
        let err = write_png(&blocker.join("a.png"), &Canvas::new(2, 2, [0; 3])).unwrap_err();
        assert!(matches!(err, PreviewError::CreateDir { .. }), "{err}");
        let err = write_png(&dir.path().join("e.png"), &Canvas::new(0, 3, [0; 3])).unwrap_err();
        assert!(matches!(err, PreviewError::Size { .. }));
        let err = write_png_rgb8(&dir.path().join("s.png"), 2, 2, &[0; 11]).unwrap_err();
        assert!(matches!(err, PreviewError::Size { .. }));
        // A directory in the way of the final name: the rename fails, the temp file is gone.
        std::fs::create_dir(dir.path().join("taken.png")).unwrap();
        std::fs::write(dir.path().join("taken.png/inner"), b"x").unwrap();
        let err = write_png(&dir.path().join("taken.png"), &Canvas::new(2, 2, [0; 3])).unwrap_err();
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
