//! `guidebake view TEXELS --scene SCENE --lightmap OUT.exr [--lightmap OTHER.exr] [-o DIR]`:
//! the baked level in a browser, in three.js ([`crate::view`]): writes the viewer's folder,
//! then serves it on 127.0.0.1 until Ctrl-C (`--no-serve`: the folder alone).

use std::path::PathBuf;

use glam::Vec3;

use crate::render::{Camera, Lightmap, Stage, ViewOptions, render};
use crate::scene::{Sky, TextureOptions};
use crate::texels::TexelFile;
use crate::view::{MAX_LIGHTMAPS, Start};

/// Arguments of `guidebake view`.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// The texel file the lightmaps were baked from.
    pub texels: PathBuf,
    /// The scene (.gltf, .glb, .obj or a .toml scene file) the texel file was prepared from.
    #[arg(long)]
    pub scene: PathBuf,
    /// The lightmap (`bake -o`; several pages are read as OUT.pageN.exr). Give it twice to see
    /// two lightmaps side by side (before and after a change).
    #[arg(long, required = true)]
    pub lightmap: Vec<PathBuf>,
    /// The folder to write (default: the first lightmap's name with `.web`, beside it). A
    /// folder an earlier `view` wrote is replaced; any other existing one is refused.
    #[arg(short, long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// The port to serve on, on 127.0.0.1 (0: a free one).
    #[arg(long, default_value_t = 8470)]
    pub port: u16,
    /// Write the folder and exit without serving it (serve it with any static server).
    #[arg(long)]
    pub no_serve: bool,
    /// Exposure before tone mapping (default: the one `render` picks for the start view).
    #[arg(long)]
    pub exposure: Option<f32>,
    /// Sun and sky, as given to `render`: the sky is the colour where no surface is seen.
    #[command(flatten)]
    pub lights: super::scene::LightFlags,
    /// Largest width or height a base-colour texture is kept at when loading the scene.
    #[arg(long, default_value_t = TextureOptions::DEFAULT_MAX_SIZE, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub max_texture_size: u32,
}

impl ViewArgs {
    /// The folder written: `-o`, else `OUT.web` beside the first lightmap.
    #[must_use]
    pub fn folder(&self) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| self.lightmap[0].with_extension("web"))
    }
}

/// What `view` reads — the scene, the texel file, each lightmap's pages and a sky map — and
/// the folder it writes.
fn view_files(args: &ViewArgs) -> Result<super::files::Files, super::CmdError> {
    let mut files = super::files::Files::new()
        .reads("the scene (--scene)", &args.scene)
        .reads("the texel file", &args.texels);
    if let Some(map) = args.lights.sky_map() {
        files = files.reads("the sky map (--sky)", map);
    }
    for lightmap in &args.lightmap {
        super::files::check_exr("--lightmap", lightmap)?;
        for (path, preview) in super::files::lightmap_files(lightmap, &args.texels) {
            files = files
                .reads("the lightmap (--lightmap)", &path)
                .reads("the lightmap's atlas preview", &preview);
        }
    }
    Ok(files.writes_dir("the viewer's folder (-o)", &args.folder()))
}

/// The size of the software view the default exposure is measured on.
const EXPOSURE_VIEW: ViewOptions = ViewOptions {
    width: 240,
    height: 135,
    cutaway: false,
};

/// Runs `guidebake view`.
///
/// # Errors
/// A wrong command line (more than two lightmaps, an exposure that is not positive, a
/// folder that is an input or not one `view` wrote); an unreadable scene, texel file or
/// lightmap, or ones that do not belong together; a folder that cannot be written; a port
/// that cannot be bound: each named.
pub fn run(args: &ViewArgs) -> Result<(), super::CmdError> {
    if args.lightmap.len() > MAX_LIGHTMAPS {
        return Err(super::usage(format!(
            "--lightmap given {} times: the viewer shows one lightmap, or two side by side",
            args.lightmap.len()
        )));
    }
    if let Some(e) = args.exposure.filter(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(super::usage(format!(
            "--exposure {e}: a positive, finite factor"
        )));
    }
    let dir = args.folder();
    let files = view_files(args)?;
    files.check()?;
    crate::view::check_folder(&dir).map_err(|e| super::usage(e.to_string()))?;
    // Bind before any work: a port in use is said at once.
    let listener = if args.no_serve {
        None
    } else {
        Some(crate::view::server::bind(args.port).map_err(|e| {
            format!(
                "cannot serve on 127.0.0.1:{}: {e} (give --port another number, 0 for a free one, or --no-serve)",
                args.port
            )
        })?)
    };
    super::interrupt::register_outputs(files.outputs());
    let (scene, _) = super::scene::load_checked(
        files,
        &args.scene,
        args.max_texture_size,
        &args.lights,
        false,
    )?;
    let texels = TexelFile::open(&args.texels)?;
    // Each lightmap checked against the texel file and the scene as `render` checks it.
    let mut lightmaps = Vec::new();
    for path in &args.lightmap {
        lightmaps.push(Lightmap::load(&texels, &scene, path)?);
    }
    let stage = Stage::new(&scene, &texels)?;
    let aspect = 16.0 / 9.0;
    let from_file = crate::render::gltf_camera(&args.scene)?;
    let inside = match from_file {
        Some(_) => None,
        None => Camera::inside(&stage, &lightmaps[0]).view(),
    };
    let camera = from_file
        .or(inside)
        .unwrap_or_else(|| Camera::framing(scene.bounds(), aspect));
    let exposure = args.exposure.unwrap_or_else(|| {
        let view = render(&stage, &lightmaps[0], &camera, EXPOSURE_VIEW);
        if inside.is_some() {
            view.key_exposure()
        } else {
            view.auto_exposure()
        }
    });
    let sky = match &scene.sky {
        Sky::None => Vec3::ZERO,
        Sky::Constant(c) => *c,
        Sky::Equirect { .. } => {
            // The mean of the map over the sphere, on a 64 × 64 grid uniform in height and angle.
            let n = 64;
            (0..n * n)
                .map(|i| {
                    let (a, b) = ((i % n) as f32 + 0.5, (i / n) as f32 + 0.5);
                    let z = 1.0 - 2.0 * b / n as f32;
                    let r = (1.0 - z * z).sqrt();
                    let phi = std::f32::consts::TAU * a / n as f32;
                    let d = Vec3::new(r * phi.cos(), z, r * phi.sin());
                    crate::transport::sky::sky_radiance(&scene.sky, d)
                })
                .sum::<Vec3>()
                / (n * n) as f32
        }
    };
    let start = Start {
        camera,
        exposure,
        sky,
    };
    crate::view::write_web(&scene, &texels, &args.lightmap, &start, &dir)?;
    eprintln!(
        "{}: the viewer's folder ({} lightmap{}, exposure {exposure:.4}, from {})",
        dir.display(),
        args.lightmap.len(),
        if args.lightmap.len() == 1 {
            ""
        } else {
            "s side by side"
        },
        if from_file.is_some() {
            "the glTF camera"
        } else if inside.is_some() {
            "inside"
        } else {
            "the overview"
        }
    );
    let Some(listener) = listener else {
        eprintln!(
            "serve it with any static server, e.g. python3 -m http.server -d {} (a page opened as a file cannot load its modules)",
            dir.display()
        );
        return Ok(());
    };
    let port = listener.local_addr().map_or(args.port, |a| a.port());
    eprintln!(
        "open http://127.0.0.1:{port}/ in a browser (Ctrl-C stops the server; the folder stays)"
    );
    crate::view::server::serve(&listener, &dir);
    Ok(())
}
