//! The scene as the commands that light it load it (`prepare`, `bake`, `render`): `--sun`
//! and `--sky` ([`LightFlags`]), the loader's warnings printed (five, then a count), and a
//! scene nothing lights refused with the flags that would light it.

use std::path::Path;

use crate::scene::{
    LightOverrides, LoadNotes, Scene, SkySpec, SunSpec, TextureOptions, parse_sky, parse_sun,
};

/// `--sun` and `--sky`, the same on `prepare`, `bake` and `render` (they replace a TOML
/// scene file's `[sun]` and `[sky]`; [`LightOverrides`], docs/levels.md).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct LightFlags {
    /// A sun: the direction towards it (+Y up) and optionally its irradiance on a plane
    /// facing it, one value or R,G,B (default 3). Replaces a scene file's sun. Give
    /// prepare, bake and render the same.
    #[arg(long, value_name = "X,Y,Z[:IRRADIANCE]", value_parser = parse_sun, allow_hyphen_values = true)]
    pub sun: Option<SunSpec>,
    /// A sky: constant radiance R,G,B (one value for grey) or an equirectangular .exr
    /// (+Y up). Replaces a scene file's sky. Give prepare, bake and render the same.
    #[arg(long, value_name = "R,G,B|SKY.exr", value_parser = parse_sky, allow_hyphen_values = true)]
    pub sky: Option<SkySpec>,
}

impl LightFlags {
    /// The equirectangular sky map `--sky` names, an input of the command.
    #[must_use]
    pub fn sky_map(&self) -> Option<&Path> {
        self.sky.as_ref().and_then(|s| s.equirect.as_deref())
    }

    /// The flags as [`LightOverrides`].
    #[must_use]
    pub fn overrides(&self) -> LightOverrides {
        LightOverrides {
            sun: self.sun.clone(),
            sky: self.sky.clone(),
        }
    }
}

/// Notes of one kind printed one by one; the rest are counted (a level missing its texture
/// pack would print one per material).
pub const SHOWN: usize = 5;

/// Loads `path` as the commands that light a scene do: textures that cannot be read are
/// warned about (each naming the file and the material) and returned, `lights` replace the
/// scene's sun and sky, and, with `lit`, a scene that nothing lights is an error saying how
/// to add a sun and a sky.
///
/// # Errors
/// The scene cannot be loaded, a flag is invalid, or (with `lit`) nothing lights it.
pub fn load_lit_scene(
    path: &Path,
    textures: TextureOptions,
    lights: &LightFlags,
    lit: bool,
) -> Result<(Scene, LoadNotes), super::CmdError> {
    let (mut scene, notes) = Scene::load_reporting(path, textures)?;
    let warnings = notes.warnings(path);
    for w in warnings.iter().take(SHOWN) {
        eprintln!("guidebake: warning: {w}");
    }
    if warnings.len() > SHOWN {
        eprintln!(
            "guidebake: warning: and {} more warnings ({} in all; the textures are listed in prepare --json and bake --stats)",
            warnings.len() - SHOWN,
            warnings.len()
        );
    }
    lights.overrides().apply(&mut scene)?;
    if lit {
        scene.check_lit()?;
    }
    Ok((scene, notes))
}

/// [`load_lit_scene`] with the base-colour textures capped at `max_texture_size`, then
/// `files` checked again with every file the scene was read from (none may be one of the
/// command's outputs): what `bake`, `render`, `view` and `probes` do before their work.
///
/// # Errors
/// As [`load_lit_scene`], or a file of the scene that is one of the outputs.
pub fn load_checked(
    files: super::files::Files,
    path: &Path,
    max_texture_size: u32,
    lights: &LightFlags,
    lit: bool,
) -> Result<(Scene, LoadNotes), super::CmdError> {
    let textures = TextureOptions {
        max_size: max_texture_size,
    };
    let (scene, notes) = load_lit_scene(path, textures, lights, lit)?;
    files
        .reads_each("a file of the scene", &notes.files_read)
        .check()?;
    Ok((scene, notes))
}
