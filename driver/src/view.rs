//! `view`: the baked level in a browser, through a real engine's lightmap path — three.js
//! (r180, checked in under `driver/viewer/three/`) loading the level as a glb whose
//! `TEXCOORD_1` are the lightmap UVs, with each lightmap page an HDR texture bound as the
//! materials' `lightMap` (docs/engines.md, "three.js").
//!
//! [`write_web`] writes a folder a static server can serve as it is:
//! - `index.html`, `viewer.js` (`driver/viewer/`) and `three/` (the module, its licence and
//!   the addons it uses), built into the binary, so nothing is fetched at run time;
//! - `level.glb`: the scene with the texel file's lightmap UVs (`prepare --write-gltf`'s
//!   writer, [`crate::scene::gltf_write`]; the UVs come from the texel file's triangle table,
//!   [`Lightmap::of_texel_file`]): a glTF scene keeps its document (materials, textures,
//!   cameras), any other gets a new one;
//! - `lightmaps/K-pageP.exr`: page P of lightmap K (one or two lightmaps, shown side by side),
//!   its irradiance E as half-float RGBA, ZIP-compressed scanlines (what three.js's
//!   `EXRLoader` reads; values above half's largest, 65 504, are clamped to it);
//! - `view.json`: the pages of each lightmap, the start camera, the exposure, the sky's
//!   colour and a walking speed (the viewer's only input besides the glb).
//!
//! The folder is written under a scratch name beside it and renamed into place: it exists
//! whole or not at all. A folder that is already there is replaced only when an earlier
//! `view` wrote it (its `view.json` says so, [`GENERATOR`]); anything else is refused.
//! [`server`] serves it on the loopback interface.

pub mod server;

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::output::exr_pages::page_path;
use crate::output::readback::read_page;
use crate::prepare::Lightmap;
use crate::render::{Camera, Projection};
use crate::scene::Scene;
use crate::scene::gltf_write::{WriteError, write_glb, write_new};
use crate::texels::TexelFile;

/// What `view.json`'s `generator` says: the mark of a folder `view` may replace.
pub const GENERATOR: &str = "guidebake view";
/// The level's file in the folder.
pub const LEVEL: &str = "level.glb";
/// The viewer's description in the folder.
pub const VIEW_JSON: &str = "view.json";
/// Lightmaps shown side by side at most.
pub const MAX_LIGHTMAPS: usize = 2;

/// The viewer's static files, built into the binary: (path in the folder, bytes).
const STATIC_FILES: &[(&str, &[u8])] = &[
    ("index.html", include_bytes!("../viewer/index.html")),
    ("viewer.js", include_bytes!("../viewer/viewer.js")),
    ("three/LICENSE", include_bytes!("../viewer/three/LICENSE")),
    ("three/VERSION", include_bytes!("../viewer/three/VERSION")),
    (
        "three/three.module.min.js",
        include_bytes!("../viewer/three/three.module.min.js"),
    ),
    (
        "three/three.core.min.js",
        include_bytes!("../viewer/three/three.core.min.js"),
    ),
    (
        "three/addons/loaders/GLTFLoader.js",
        include_bytes!("../viewer/three/addons/loaders/GLTFLoader.js"),
    ),
    (
        "three/addons/loaders/EXRLoader.js",
        include_bytes!("../viewer/three/addons/loaders/EXRLoader.js"),
    ),
    (
        "three/addons/controls/OrbitControls.js",
        include_bytes!("../viewer/three/addons/controls/OrbitControls.js"),
    ),
    (
        "three/addons/utils/BufferGeometryUtils.js",
        include_bytes!("../viewer/three/addons/utils/BufferGeometryUtils.js"),
    ),
    (
        "three/addons/libs/fflate.module.js",
        include_bytes!("../viewer/three/addons/libs/fflate.module.js"),
    ),
];

/// Why the folder could not be written; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// A lightmap page could not be read.
    #[error("{path}: {what}")]
    Lightmap {
        /// The page.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The level could not be written as a glb.
    #[error(transparent)]
    Glb(#[from] WriteError),
    /// Writing the folder failed.
    #[error("{path}: cannot write: {message}")]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// The folder exists and is not one `view` wrote.
    #[error(
        "{path}: the folder exists and is not one guidebake view wrote (it has no {VIEW_JSON} of \
         ours): nothing was written; give -o another folder"
    )]
    NotOurs {
        /// The folder.
        path: PathBuf,
    },
}

/// What the viewer starts from.
#[derive(Clone, Debug)]
pub struct Start {
    /// The camera (`render`'s for the same scene: its glTF camera, else the inside view, else
    /// the overview).
    pub camera: Camera,
    /// Exposure before Reinhard's tone map.
    pub exposure: f32,
    /// The sky's radiance (the colour where no surface is seen): the scene's constant sky,
    /// the mean of a sky map, black without one.
    pub sky: Vec3,
}

/// Whether `dir` may be written by `view`: it does not exist, or an earlier `view` wrote it.
///
/// # Errors
/// [`ViewError::NotOurs`] naming the folder.
pub fn check_folder(dir: &Path) -> Result<(), ViewError> {
    if !dir.exists() {
        return Ok(());
    }
    let ours = std::fs::read(dir.join(VIEW_JSON))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .is_some_and(|v| v["generator"] == GENERATOR);
    if ours {
        Ok(())
    } else {
        Err(ViewError::NotOurs {
            path: dir.to_owned(),
        })
    }
}

/// Writes the viewer's folder `dir` for `scene`, prepared as `texels`, lit by `lightmaps`
/// (each `bake -o`, its pages beside it), starting from `start` (module docs). The scene,
/// texel file and lightmaps are the caller's to check against each other first (`render`'s
/// `Lightmap::load` does).
///
/// # Errors
/// [`ViewError`] naming the file: a page unreadable, the glb or a file of the folder not
/// written, or a folder there already that `view` did not write. Nothing is left at `dir`
/// (nor in its scratch folder) on failure.
pub fn write_web(
    scene: &Scene,
    texels: &TexelFile,
    lightmaps: &[PathBuf],
    start: &Start,
    dir: &Path,
) -> Result<(), ViewError> {
    check_folder(dir)?;
    let scratch = crate::atomic::with_suffix(dir, "tmp");
    let _ = std::fs::remove_dir_all(&scratch);
    let result =
        fill(scene, texels, lightmaps, start, &scratch).and_then(|()| publish(&scratch, dir));
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&scratch);
    }
    result
}

fn write_error(path: &Path) -> impl Fn(std::io::Error) -> ViewError + '_ {
    move |e| ViewError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// Writes every file of the folder into `folder`.
fn fill(
    scene: &Scene,
    texels: &TexelFile,
    lightmaps: &[PathBuf],
    start: &Start,
    folder: &Path,
) -> Result<(), ViewError> {
    for (name, bytes) in STATIC_FILES {
        let path = folder.join(name);
        let parent = path.parent().unwrap_or(folder);
        std::fs::create_dir_all(parent).map_err(write_error(parent))?;
        std::fs::write(&path, bytes).map_err(write_error(&path))?;
    }
    let layout = Lightmap::of_texel_file(texels, scene);
    let glb = folder.join(LEVEL);
    let gltf = scene
        .path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"));
    if gltf {
        write_glb(scene, &layout, &glb)?;
    } else {
        write_new(scene, &layout, &glb)?;
    }
    let pages_dir = folder.join("lightmaps");
    std::fs::create_dir_all(&pages_dir).map_err(write_error(&pages_dir))?;
    let count = layout.pages.len() as u32;
    let mut described = Vec::new();
    for (k, lightmap) in lightmaps.iter().enumerate() {
        let mut pages = Vec::new();
        for p in 0..count {
            let source = page_path(lightmap, p, count);
            let name = format!("lightmaps/{k}-page{p}.exr");
            write_half_exr(&source, &folder.join(&name))?;
            pages.push(name);
        }
        let name = lightmap.file_name().map_or_else(
            || lightmap.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        described.push(serde_json::json!({ "name": name, "pages": pages }));
    }
    let json = view_json(scene, start, described);
    let path = folder.join(VIEW_JSON);
    std::fs::write(
        &path,
        serde_json::to_vec_pretty(&json).expect("JSON of numbers and strings"),
    )
    .map_err(write_error(&path))
}

/// `view.json`: what the viewer reads besides the glb and the pages.
fn view_json(scene: &Scene, start: &Start, lightmaps: Vec<serde_json::Value>) -> serde_json::Value {
    let (lo, hi) = scene.bounds();
    let size = (hi - lo).length().max(1e-3);
    let c = &start.camera;
    let fov = match c.projection {
        Projection::Perspective { tan_half_fov } => 2.0 * tan_half_fov.atan(),
        // The viewer's camera is perspective: an orthographic one is shown at 50°.
        Projection::Orthographic { .. } => 50f32.to_radians(),
    };
    // The orbit's centre: the bounds' centre for a view from outside them, else a short way
    // ahead (turning about it is looking around).
    let centre = (lo + hi) / 2.0;
    let inside = c.eye.cmpge(lo).all() && c.eye.cmple(hi).all();
    let target = if inside {
        c.eye + c.forward * (0.05 * size)
    } else {
        c.eye + c.forward * (centre - c.eye).dot(c.forward).max(0.05 * size)
    };
    serde_json::json!({
        "generator": GENERATOR,
        "scene": LEVEL,
        "lightmaps": lightmaps,
        "intensity": 1.0,
        "camera": {
            "eye": c.eye.to_array(),
            "target": target.to_array(),
            "fov": fov.to_degrees(),
            "near": size * 1e-4,
            "far": size * 4.0,
        },
        "exposure": start.exposure,
        "sky": start.sky.to_array(),
        "walk_speed": size / 20.0,
    })
}

/// Page `source` (irradiance RGB) as a half-float RGBA EXR at `out` (module docs).
fn write_half_exr(source: &Path, out: &Path) -> Result<(), ViewError> {
    use exr::prelude::*;
    let page = read_page(source).map_err(|e| ViewError::Lightmap {
        path: e.path,
        what: e.what,
    })?;
    let width = page.width;
    let half = |v: f32| {
        f16::from_f32(if v.is_finite() {
            v.clamp(0.0, 65504.0)
        } else {
            0.0
        })
    };
    let channels = SpecificChannels::rgba(|Vec2(x, y): Vec2<usize>| {
        let [r, g, b] = page.rgb[y * width + x];
        (half(r), half(g), half(b), f16::ONE)
    });
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        (page.width, page.height),
        LayerAttributes::default(),
        encoding,
        channels,
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| ViewError::Write {
            path: out.to_owned(),
            message: e.to_string(),
        })?;
    std::fs::write(out, bytes.into_inner()).map_err(write_error(out))
}

/// Renames the finished `scratch` folder to `dir`, replacing an earlier `view`'s folder.
fn publish(scratch: &Path, dir: &Path) -> Result<(), ViewError> {
    if dir.exists() {
        let old = crate::atomic::with_suffix(dir, "old");
        std::fs::rename(dir, &old).map_err(write_error(dir))?;
        if let Err(e) = std::fs::rename(scratch, dir) {
            let _ = std::fs::rename(&old, dir);
            return Err(write_error(dir)(e));
        }
        let _ = std::fs::remove_dir_all(&old);
        return Ok(());
    }
    std::fs::rename(scratch, dir).map_err(write_error(dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every file the page asks for by a relative path is one the folder has: the import
    /// map's two roots, the module the page loads, and each addon's imports.
    #[test]
    fn the_static_files_hold_everything_the_page_imports() {
        let has = |p: &str| STATIC_FILES.iter().any(|(name, _)| *name == p);
        let text = |p: &str| {
            let bytes = STATIC_FILES.iter().find(|(n, _)| *n == p).unwrap().1;
            String::from_utf8_lossy(bytes).into_owned()
        };
        let index = text("index.html");
        assert!(index.contains(r#""three": "./three/three.module.min.js""#));
        assert!(index.contains(r#""three/addons/": "./three/addons/""#));
        assert!(index.contains(r#"src="./viewer.js""#));
        assert!(has("three/three.module.min.js") && has("three/three.core.min.js"));
        assert!(text("three/three.module.min.js").contains(r#"from"./three.core.min.js""#));
        for import in text("viewer.js")
            .lines()
            .filter_map(|l| l.strip_prefix("import "))
            .filter_map(|l| l.split("'three/addons/").nth(1))
        {
            let file = import.trim_end_matches("';");
            assert!(has(&format!("three/addons/{file}")), "{file}");
        }
        // The addons' own relative imports.
        for (name, _) in STATIC_FILES
            .iter()
            .filter(|(n, _)| n.starts_with("three/addons/"))
        {
            let dir = Path::new(name).parent().unwrap();
            for line in text(name).lines().filter(|l| l.contains("from '../")) {
                let rel = line.split("from '").nth(1).unwrap().trim_end_matches("';");
                let joined = dir.join(rel);
                let mut parts: Vec<&str> = Vec::new();
                for c in joined.iter() {
                    match c.to_str().unwrap() {
                        ".." => {
                            parts.pop();
                        }
                        s => parts.push(s),
                    }
                }
                assert!(has(&parts.join("/")), "{name} imports {rel}");
            }
        }
        assert!(text("three/LICENSE").contains("MIT"));
    }

    #[test]
    fn a_folder_view_did_not_write_is_refused_and_one_it_wrote_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let web = dir.path().join("web");
        assert!(check_folder(&web).is_ok(), "a folder that is not there");
        std::fs::create_dir(&web).unwrap();
        std::fs::write(web.join("notes.txt"), "mine").unwrap();
        let e = check_folder(&web).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("{}: the folder exists", web.display())),
            "{e}"
        );
        std::fs::write(web.join(VIEW_JSON), r#"{"generator": "someone else"}"#).unwrap();
        assert!(check_folder(&web).is_err());
        std::fs::write(
            web.join(VIEW_JSON),
            format!(r#"{{"generator": "{GENERATOR}"}}"#),
        )
        .unwrap();
        assert!(check_folder(&web).is_ok());
    }

    #[test]
    fn a_page_is_written_as_half_floats_that_read_back_within_half_precision() {
        let dir = tempfile::tempdir().unwrap();
        let mut page = crate::output::exr_pages::PageImage::new(3, 2);
        page.set(0, 0, [0.25, 1.5, 3.0]);
        page.set(2, 1, [1e6, 0.001, 7.0]);
        let source = dir.path().join("lm.exr");
        page.write_exr(&source).unwrap();
        let out = dir.path().join("half.exr");
        write_half_exr(&source, &out).unwrap();
        let back = read_page(&out).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        let want = read_page(&source).unwrap();
        for (b, w) in back.rgb.iter().zip(&want.rgb) {
            for (b, w) in b.iter().zip(w) {
                let w = w.min(65504.0);
                assert!((b - w).abs() <= w.abs() * 1e-3 + 1e-6, "{b} {w}");
            }
        }
        assert_eq!(back.rgb[5][0], 65504.0, "clamped to half's largest");
        let e = write_half_exr(&dir.path().join("none.exr"), &out).unwrap_err();
        assert!(e.to_string().contains("none.exr"), "{e}");
    }
}
