//! `guidebake render SCENE --texels T --lightmap OUT.exr -o view.png`: a picture of the lit
//! scene ([`crate::render`]), from the glTF file's camera or an automatic view.

use std::path::PathBuf;

use crate::probes::field::ProbeField;
use crate::probes::file::ProbeFile;
use crate::probes::view::ProbeOverlay;
use crate::render::{Camera, Inside, Lightmap, Stage, View, ViewOptions, render_with};
use crate::scene::TextureOptions;
use crate::texels::TexelFile;

use super::OnOff;

/// Arguments of `guidebake render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The scene (.gltf, .glb, .obj or a .toml scene file) the lightmap was baked for.
    pub scene: PathBuf,
    /// The texel file the lightmap was baked from.
    #[arg(long)]
    pub texels: PathBuf,
    /// The lightmap (`bake -o`; several pages are read as OUT.pageN.exr).
    #[arg(long)]
    pub lightmap: PathBuf,
    /// The PNG to write (a name of its own: not the lightmap's atlas preview, NAME.atlas.png).
    #[arg(short, long = "output", alias = "out", value_name = "VIEW.png")]
    pub out: PathBuf,
    /// Width in pixels.
    #[arg(long, default_value_t = 960)]
    pub width: u32,
    /// Height in pixels (default: from the glTF camera's aspect ratio, else 540).
    #[arg(long)]
    pub height: Option<u32>,
    /// `gltf`: the file's first camera (an error if it has none); `auto`: from inside the
    /// open space the scene encloses (a level, a room), else the overview; `overview`: the
    /// scene's bounds framed from above a corner. Default: the glTF camera where there is
    /// one, else auto.
    #[arg(long, value_enum)]
    pub camera: Option<CameraChoice>,
    /// Pass through lightmapped surfaces seen from their unlit side (a dollhouse view of a
    /// closed room). Default: on for the overview, off for a glTF camera and the inside
    /// view.
    #[arg(long, value_enum)]
    pub cutaway: Option<OnOff>,
    /// Exposure before tone mapping (default: the mean surface luminance maps to ½; for the
    /// inside view, the log-average luminance maps to an 18 % grey).
    #[arg(long)]
    pub exposure: Option<f32>,
    /// Sun and sky, replacing the scene file's (the sky is what rays that leave the scene
    /// see): give the same as to `prepare` and `bake`.
    #[command(flatten)]
    pub lights: super::scene::LightFlags,
    /// Largest width or height a base-colour texture is kept at (as `bake`'s).
    #[arg(long, default_value_t = TextureOptions::DEFAULT_MAX_SIZE, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub max_texture_size: u32,
    /// Draw the light probes of this probe file (`guidebake probes -o`) as small spheres
    /// shaded by their SH.
    #[arg(long, value_name = "LEVEL.probes")]
    pub probes: Option<PathBuf>,
    /// Radius of the drawn probes (default: a tenth of the finest probe spacing; 0: none
    /// drawn, only --sphere).
    #[arg(long, requires = "probes")]
    pub probe_radius: Option<f32>,
    /// A grey test sphere (albedo 0.5) at X,Y,Z of radius R, lit from the probes
    /// interpolated at its centre as an engine lights a dynamic object.
    #[arg(long, value_name = "X,Y,Z,R", requires = "probes", value_parser = parse_sphere, allow_hyphen_values = true)]
    pub sphere: Option<[f32; 4]>,
}

/// `--sphere X,Y,Z,R`: four finite numbers, the radius positive.
fn parse_sphere(s: &str) -> Result<[f32; 4], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}` is not X,Y,Z,R (four numbers)"))?;
    match v[..] {
        [x, y, z, r] if [x, y, z, r].iter().all(|v| v.is_finite()) && r > 0.0 => Ok([x, y, z, r]),
        _ => Err(format!("`{s}` is not X,Y,Z,R: four finite numbers, R > 0")),
    }
}

/// What `render` reads — the scene, the texel file, a sky map, the lightmap's pages and their
/// atlas previews (kept, though not read) — and the one PNG it writes.
fn render_files(args: &RenderArgs) -> Result<super::files::Files, super::CmdError> {
    super::files::check_exr("--lightmap", &args.lightmap)?;
    super::files::check_extension(&args.out, "png", "-o writes a PNG picture")?;
    let mut files = super::files::Files::new()
        .reads("the scene", &args.scene)
        .reads("the texel file (--texels)", &args.texels);
    if let Some(map) = args.lights.sky_map() {
        files = files.reads("the sky map (--sky)", map);
    }
    for (path, preview) in super::files::lightmap_files(&args.lightmap, &args.texels) {
        files = files
            .reads("the lightmap (--lightmap)", &path)
            .reads("the lightmap's atlas preview", &preview);
    }
    if let Some(probes) = &args.probes {
        files = files.reads("the probe file (--probes)", probes);
    }
    Ok(files.writes("the picture (-o)", &args.out))
}

/// The probes and test sphere to draw, read from `--probes`.
fn probe_overlay(args: &RenderArgs) -> Result<Option<ProbeOverlay>, super::CmdError> {
    let Some(path) = &args.probes else {
        return Ok(None);
    };
    if let Some(r) = args.probe_radius.filter(|r| !(r.is_finite() && *r >= 0.0)) {
        return Err(super::usage(format!(
            "--probe-radius {r}: a finite distance ≥ 0"
        )));
    }
    let file = ProbeFile::open(path)?;
    let radius = args.probe_radius.unwrap_or(0.1 * file.header.fine_spacing);
    let field = ProbeField::new(file.probes);
    let sphere = args
        .sphere
        .map(|[x, y, z, r]| (glam::Vec3::new(x, y, z), r));
    Ok(Some(ProbeOverlay::new(&field, radius, sphere)))
}

/// Which camera `render` looks through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CameraChoice {
    /// The glTF file's first camera.
    Gltf,
    /// From inside the open space the scene encloses, else the overview.
    Auto,
    /// The scene's bounds framed from above a corner, cut away.
    Overview,
}

/// A view whose every surface is black has no exposure to set: an error saying what to try,
/// before anything is written (a view of the sky alone keeps exposure 1).
fn exposable(view: &View, args: &RenderArgs) -> Result<(), super::CmdError> {
    if view.sees_surfaces() && !view.sees_light() {
        return Err(format!(
            "{}: every surface this view sees is black in {}: there is no exposure to set, and nothing was written. Try --camera overview (or another --camera), check that the bake's --sun and --sky reach the surfaces (a level inside a closed shell receives neither: docs/levels.md), or give --exposure to write the picture anyway",
            args.out.display(),
            args.lightmap.display()
        )
        .into());
    }
    Ok(())
}

/// Runs `guidebake render`.
///
/// # Errors
/// An unreadable scene, texel file or lightmap, a scene that does not match them, a missing
/// glTF camera when `--camera gltf` asks for one, an unwritable PNG: each named.
pub fn run(args: &RenderArgs) -> Result<(), super::CmdError> {
    if args.width == 0 || args.height == Some(0) || args.width > 16384 || args.height > Some(16384)
    {
        return Err(super::usage(
            "--width and --height must be between 1 and 16384 pixels",
        ));
    }
    if let Some(e) = args.exposure.filter(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(super::usage(format!(
            "--exposure {e}: a positive, finite factor"
        )));
    }
    let files = render_files(args)?;
    files.check()?;
    super::interrupt::register_outputs(files.outputs());
    let (scene, _) = super::scene::load_checked(
        files,
        &args.scene,
        args.max_texture_size,
        &args.lights,
        false,
    )?;
    let texels = TexelFile::open(&args.texels)?;
    let lightmap = Lightmap::load(&texels, &scene, &args.lightmap)?;
    let from_file = match args.camera {
        Some(CameraChoice::Auto | CameraChoice::Overview) => None,
        Some(CameraChoice::Gltf) => {
            Some(crate::render::gltf_camera(&args.scene)?.ok_or_else(|| {
                format!(
                    "{}: has no glTF camera (use --camera auto)",
                    args.scene.display()
                )
            })?)
        }
        None => crate::render::gltf_camera(&args.scene)?,
    };
    let height = args.height.unwrap_or_else(|| {
        let aspect = from_file.and_then(|c| c.aspect).unwrap_or(16.0 / 9.0);
        ((args.width as f32 / aspect).round() as u32).clamp(1, 16384)
    });
    let aspect = args.width as f32 / height as f32;
    let stage = Stage::new(&scene, &texels)?;
    let inside = match (from_file, args.camera) {
        (None, None | Some(CameraChoice::Auto)) => Camera::inside(&stage, &lightmap),
        _ => Inside::Open,
    };
    if inside == Inside::Dark {
        eprintln!(
            "guidebake: warning: {}: the space the scene encloses is dark in this lightmap (no point inside sees lit walls): showing it from outside. A level inside a closed shell receives no sun or sky: prepare names the shell and the --role sky=... that opens it (docs/levels.md)",
            args.lightmap.display()
        );
    }
    let inside = inside.view();
    let camera = from_file
        .or(inside)
        .unwrap_or_else(|| Camera::framing(scene.bounds(), aspect));
    let overview = from_file.is_none() && inside.is_none();
    let cutaway = args.cutaway.map_or(overview, |c| c == OnOff::On);
    let overlay = probe_overlay(args)?;
    let view = render_with(
        &stage,
        &lightmap,
        &camera,
        ViewOptions {
            width: args.width,
            height,
            cutaway,
        },
        overlay.as_ref().map(|o| o as &dyn crate::render::Overlay),
    );
    if args.exposure.is_none() {
        exposable(&view, args)?;
    }
    let exposure = args.exposure.unwrap_or_else(|| {
        if inside.is_some() {
            view.key_exposure()
        } else {
            view.auto_exposure()
        }
    });
    crate::preview::write_png_rgb8(&args.out, view.width, view.height, &view.to_rgb8(exposure))?;
    eprintln!(
        "{}: {}×{} from {}, exposure {exposure:.4}",
        args.out.display(),
        view.width,
        view.height,
        if from_file.is_some() {
            "the glTF camera".to_owned()
        } else if inside.is_some() {
            format!(
                "inside, at {:.3?} looking {:.2?}",
                camera.eye.to_array(),
                camera.forward.to_array()
            )
        } else {
            "the overview".to_owned()
        }
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use glam::Vec3;

    use super::*;
    use crate::render::SUBPIXELS;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: RenderArgs,
    }

    /// A view of surfaces that are all black is refused, naming the picture and the lightmap
    /// and what to try; one lit pixel, or a view of the sky alone, is not.
    #[test]
    fn a_view_whose_every_surface_is_black_is_refused() {
        let cli = Cli::parse_from([
            "render",
            "level.glb",
            "--texels",
            "l.texels",
            "--lightmap",
            "lm.exr",
            "-o",
            "v.png",
        ]);
        let full = (SUBPIXELS * SUBPIXELS) as u8;
        let black = View {
            width: 2,
            height: 1,
            radiance: vec![Vec3::ZERO; 2],
            surface: vec![full, full],
        };
        let e = exposable(&black, &cli.args).unwrap_err().to_string();
        assert!(
            e.starts_with("v.png: every surface this view sees is black in lm.exr")
                && e.contains("--camera overview")
                && e.contains("--exposure"),
            "{e}"
        );
        let one_lit = View {
            radiance: vec![Vec3::ZERO, Vec3::splat(0.01)],
            ..black.clone()
        };
        assert!(exposable(&one_lit, &cli.args).is_ok());
        let sky = View {
            radiance: vec![Vec3::ONE; 2],
            surface: vec![0, 0],
            ..black
        };
        assert!(exposable(&sky, &cli.args).is_ok());
    }
}
