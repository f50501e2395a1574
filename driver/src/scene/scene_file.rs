//! The TOML scene file: geometry plus sky and sun, and the equirectangular sky it may name;
//! and the same sun and sky given on the command line ([`LightOverrides`], `--sun` and
//! `--sky` of `prepare`, `bake` and `render`; docs/levels.md, "Lights from the command
//! line").
use super::*;

/// The TOML scene file: geometry plus sky and sun.
///
/// ```toml
/// geometry = "city.glb"          # relative to this file; .gltf, .glb or .obj
/// roles = ["sky=material:sky*", "skip=mesh:clip*"]  # ROLE=PATTERN, as prepare --role
/// [sky]
/// constant = [0.5, 0.6, 0.8]     # radiance, or:
/// # equirect = "sky.exr"         # latitude-longitude EXR, +Y up
/// [sun]
/// direction = [0.3, 1.0, 0.2]    # towards the sun, need not be unit
/// angular_radius_deg = 0.267
/// irradiance = [4.0, 3.8, 3.5]
/// [[sphere_light]]               # any number of sphere lights
/// center = [0.0, 2.0, 0.0]
/// radius = 0.1
/// radiance = [50.0, 50.0, 50.0]
/// ```
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Path of the geometry, relative to the scene file.
    pub geometry: PathBuf,
    /// Sky, if any.
    pub sky: Option<SkySpec>,
    /// Sun, if any.
    pub sun: Option<SunSpec>,
    /// Sphere lights.
    #[serde(default)]
    pub sphere_light: Vec<SphereSpec>,
    /// Roles of meshes and materials, `ROLE=PATTERN` in order ([`super::roles`]); before the
    /// command line's `--role`.
    #[serde(default)]
    pub roles: Vec<String>,
}

/// `[[sphere_light]]` of a [`SceneFile`].
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    /// Centre.
    pub center: [f32; 3],
    /// Radius, > 0.
    pub radius: f32,
    /// Radiance, linear RGB.
    pub radiance: [f32; 3],
}

impl SphereSpec {
    /// Validates and converts.
    ///
    /// # Errors
    /// A message when the centre is not finite, the radius not positive and finite, or the
    /// radiance negative or not finite.
    pub fn to_light(&self) -> Result<SceneLight, String> {
        let center = Vec3::from(self.center);
        let radiance = Vec3::from(self.radiance);
        if !center.is_finite() {
            return Err(format!("sphere_light center {center} must be finite"));
        }
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return Err(format!(
                "sphere_light radius {} must be positive and finite",
                self.radius
            ));
        }
        if !radiance.is_finite() || radiance.min_element() < 0.0 {
            return Err(format!(
                "sphere_light radiance {radiance} must be finite and non-negative"
            ));
        }
        Ok(SceneLight::Sphere {
            center,
            radius: self.radius,
            radiance,
        })
    }
}

/// `[sky]` of a [`SceneFile`]: exactly one of the two fields.
#[derive(Clone, Debug, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkySpec {
    /// Constant radiance.
    pub constant: Option<[f32; 3]>,
    /// Equirectangular EXR path, relative to the scene file.
    pub equirect: Option<PathBuf>,
}

/// `[sun]` of a [`SceneFile`].
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunSpec {
    /// Direction towards the sun.
    pub direction: [f32; 3],
    /// Angular radius in degrees.
    pub angular_radius_deg: f32,
    /// Irradiance, linear RGB.
    pub irradiance: [f32; 3],
}

impl SunSpec {
    /// Validates and converts.
    ///
    /// # Errors
    /// A message when the direction is zero or not finite, the radius is outside
    /// [0°, 90°), or the irradiance is negative or not finite.
    pub fn to_sun(&self) -> Result<Sun, String> {
        let d = Vec3::from(self.direction);
        let direction = d
            .try_normalize()
            .ok_or("sun direction must be finite and non-zero")?;
        let r = self.angular_radius_deg;
        if !(0.0..90.0).contains(&r) {
            return Err(format!("sun angular_radius_deg {r} is outside [0, 90)"));
        }
        let irr = Vec3::from(self.irradiance);
        if !irr.is_finite() || irr.min_element() < 0.0 {
            return Err(format!(
                "sun irradiance {irr} must be finite and non-negative"
            ));
        }
        Ok(Sun {
            direction,
            angular_radius: r.to_radians(),
            irradiance: irr,
        })
    }
}

impl SceneFile {
    /// Loads a TOML scene file and the geometry it names (its textures kept as `textures`
    /// says).
    ///
    /// # Errors
    /// [`SceneError::SceneFile`] for a malformed file, otherwise whatever loading the
    /// geometry or the sky returns.
    pub fn load(path: &Path, textures: super::TextureOptions) -> Result<Scene, SceneError> {
        Self::load_noting(path, textures, &mut LoadNotes::default())
    }

    /// [`SceneFile::load`], noting what the geometry's loader went on with.
    pub(super) fn load_noting(
        path: &Path,
        textures: super::TextureOptions,
        notes: &mut LoadNotes,
    ) -> Result<Scene, SceneError> {
        let at = |span: Option<std::ops::Range<usize>>, text: &str| {
            span.map(|s| TextPos::of_offset(text, s.start))
        };
        let bytes = std::fs::read(path).map_err(|error| SceneError::Io {
            path: path.to_owned(),
            error,
        })?;
        if let Some(kind) = looks_like(&bytes) {
            return Err(SceneError::NotAScene {
                path: path.to_owned(),
                message: format!(
                    "looks like {kind}, not a TOML scene file (a scene file names its \
                     geometry: geometry = \"level.glb\"; docs/levels.md)"
                ),
            });
        }
        let text = String::from_utf8(bytes).map_err(|e| SceneError::SceneFile {
            path: path.to_owned(),
            at: Some(TextPos::of_offset(
                &String::from_utf8_lossy(&e.as_bytes()[..e.utf8_error().valid_up_to()]),
                usize::MAX,
            )),
            message: "not UTF-8 text (a TOML scene file is UTF-8)".into(),
        })?;
        let located =
            |span: Option<std::ops::Range<usize>>, message: String| SceneError::SceneFile {
                path: path.to_owned(),
                at: at(span, &text),
                message,
            };
        let file: SceneFile = toml::from_str(&text)
            .map_err(|e| located(e.span(), e.message().trim_end().to_owned()))?;
        // Where each part is, for the messages about its values (parses: the file did).
        let spans: Spans = toml::from_str(&text)
            .map_err(|e| located(e.span(), e.message().trim_end().to_owned()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let geometry = dir.join(&file.geometry);
        let geometry_at = Some(spans.geometry.span());
        if geometry
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        {
            return Err(located(
                geometry_at,
                "geometry must be .gltf, .glb or .obj, not another scene file".into(),
            ));
        }
        let mut scene = match Scene::load_noting(&geometry, textures, notes) {
            Ok(scene) => scene,
            // Which line names a file that is not there: the geometry's own errors name it.
            Err(SceneError::Io { error, .. }) => {
                return Err(located(
                    geometry_at,
                    format!(
                        "geometry {:?} cannot be read: {}: {error}",
                        file.geometry.display().to_string(),
                        shown_absolute(&geometry).display()
                    ),
                ));
            }
            Err(e) => return Err(e),
        };
        let span_of = |s: &Option<toml::Spanned<toml::Value>>| s.as_ref().map(toml::Spanned::span);
        if let Some(sun) = &file.sun {
            scene.sun = Some(sun.to_sun().map_err(|m| located(span_of(&spans.sun), m))?);
        }
        for (i, sphere) in file.sphere_light.iter().enumerate() {
            let span = spans.sphere_light.get(i).map(toml::Spanned::span);
            scene
                .lights
                .push(sphere.to_light().map_err(|m| located(span, m))?);
        }
        let rules = file
            .roles
            .iter()
            .map(|r| RoleRule::parse(r))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|m| {
                located(
                    spans.roles.as_ref().map(toml::Spanned::span),
                    format!("roles: {m}"),
                )
            })?;
        let unmatched = scene.apply_roles(&rules);
        if !unmatched.is_empty() {
            notes.file_warnings.push(format!(
                "{}: roles: {} matches no mesh or material",
                path.display(),
                unmatched.join(", ")
            ));
        }
        scene.sky = match &file.sky {
            None => Sky::None,
            Some(spec) => spec.to_sky(dir).map_err(|e| match e {
                SkyError::Spec(message) => located(span_of(&spans.sky), message),
                SkyError::Scene(e) => e,
            })?,
        };
        Ok(scene)
    }
}

/// Where the parts of a [`SceneFile`] are in its text, for messages about their values.
#[derive(serde::Deserialize)]
struct Spans {
    geometry: toml::Spanned<toml::Value>,
    sky: Option<toml::Spanned<toml::Value>>,
    sun: Option<toml::Spanned<toml::Value>>,
    #[serde(default)]
    sphere_light: Vec<toml::Spanned<toml::Value>>,
    roles: Option<toml::Spanned<toml::Value>>,
}

/// Why a [`SkySpec`] gives no sky.
enum SkyError {
    /// The spec is invalid.
    Spec(String),
    /// The EXR it names cannot be read.
    Scene(SceneError),
}

impl SkySpec {
    /// Validates and converts; an `equirect` path is relative to `dir`.
    fn to_sky(&self, dir: &Path) -> Result<Sky, SkyError> {
        match self {
            SkySpec {
                constant: Some(c),
                equirect: None,
            } => {
                let c = Vec3::from(*c);
                if !c.is_finite() || c.min_element() < 0.0 {
                    return Err(SkyError::Spec(format!(
                        "sky constant {c} must be finite and non-negative"
                    )));
                }
                Ok(Sky::Constant(c))
            }
            SkySpec {
                constant: None,
                equirect: Some(p),
            } => load_equirect(&dir.join(p)).map_err(SkyError::Scene),
            _ => Err(SkyError::Spec(
                "[sky] needs exactly one of `constant` or `equirect`".into(),
            )),
        }
    }
}

/// The irradiance of a `--sun` given without one (on a plane facing the sun, each channel):
/// with a sky of radiance ~0.5 the sun then gives about twice the sky's irradiance
/// (π · 0.5), a clear day's ratio within a few times.
pub const DEFAULT_SUN_IRRADIANCE: f32 = 3.0;
/// The angular radius of a `--sun`, degrees: the real sun's.
pub const SUN_RADIUS_DEG: f32 = 0.267;

/// A sun and a sky given on the command line (`--sun`, `--sky`), applied to a loaded scene.
///
/// **How they combine with a scene file**: `--sun` replaces the TOML file's `[sun]` (the one
/// sun a scene has), `--sky` its `[sky]`; the scene's other lights (glTF
/// `KHR_lights_punctual`, TOML sphere lights) and emissive materials are kept. `prepare`
/// decides from the lights which side of every surface is seen ([`crate::prepare::facing`]), so
/// `prepare`, `bake` and `render` must be given the same flags (docs/levels.md).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LightOverrides {
    /// `--sun`, parsed by [`parse_sun`].
    pub sun: Option<SunSpec>,
    /// `--sky`, parsed by [`parse_sky`].
    pub sky: Option<SkySpec>,
}

impl LightOverrides {
    /// Whether either is given.
    #[must_use]
    pub fn any(&self) -> bool {
        self.sun.is_some() || self.sky.is_some()
    }

    /// Replaces the scene's sun and sky with the ones given; an equirect path is relative to
    /// the working directory.
    ///
    /// # Errors
    /// [`SceneError::SceneFile`] naming the scene (`--sun`/`--sky` and what is wrong) for an
    /// invalid value, [`SceneError::Sky`] when the sky EXR cannot be read.
    pub fn apply(&self, scene: &mut Scene) -> Result<(), SceneError> {
        let bad = |flag: &str, message: String| SceneError::SceneFile {
            path: scene.path.clone(),
            at: None,
            message: format!("{flag}: {message}"),
        };
        if let Some(sun) = &self.sun {
            scene.sun = Some(sun.to_sun().map_err(|m| bad("--sun", m))?);
        }
        if let Some(sky) = &self.sky {
            scene.sky = sky.to_sky(Path::new(".")).map_err(|e| match e {
                SkyError::Spec(m) => bad("--sky", m),
                SkyError::Scene(e) => e,
            })?;
        }
        Ok(())
    }
}

/// Parses `A,B,C` (or one value `A`, repeated) of finite numbers.
fn parse_triple(s: &str, what: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|c| {
            c.trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("'{s}': {what} needs finite numbers, '{c}' is not one"))
        })
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [a] => Ok([*a; 3]),
        [a, b, c] => Ok([*a, *b, *c]),
        _ => Err(format!("'{s}': {what} is one number or three (R,G,B)")),
    }
}

/// Parses `--sun X,Y,Z[:IRRADIANCE]`: the direction towards the sun (+Y up, need not be
/// unit) and its irradiance on a plane facing it, one value or `R,G,B` (default
/// [`DEFAULT_SUN_IRRADIANCE`]); the angular radius is the real sun's ([`SUN_RADIUS_DEG`]).
/// Validated as a TOML `[sun]` is ([`SunSpec::to_sun`]).
///
/// # Errors
/// A message for clap's usage error.
pub fn parse_sun(s: &str) -> Result<SunSpec, String> {
    let (direction, irradiance) = match s.split_once(':') {
        Some((d, i)) => (d, Some(i)),
        None => (s, None),
    };
    let d: Vec<&str> = direction.split(',').collect();
    if d.len() != 3 {
        return Err(format!(
            "'{s}' is not X,Y,Z[:IRRADIANCE] (the direction towards the sun, +Y up)"
        ));
    }
    let spec = SunSpec {
        direction: parse_triple(direction, "the sun's direction")?,
        angular_radius_deg: SUN_RADIUS_DEG,
        irradiance: match irradiance {
            Some(i) => parse_triple(i, "the sun's irradiance")?,
            None => [DEFAULT_SUN_IRRADIANCE; 3],
        },
    };
    spec.to_sun().map_err(|m| format!("'{s}': {m}"))?;
    Ok(spec)
}

/// Parses `--sky R,G,B` (constant radiance; one value for grey) or `--sky FILE.exr` (an
/// equirectangular sky, +Y up), as a TOML `[sky]`'s `constant` or `equirect`.
///
/// # Errors
/// A message for clap's usage error.
pub fn parse_sky(s: &str) -> Result<SkySpec, String> {
    if Path::new(s)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        return Ok(SkySpec {
            constant: None,
            equirect: Some(PathBuf::from(s)),
        });
    }
    let c = parse_triple(s, "--sky (R,G,B radiance, or an .exr file)")?;
    if c.iter().any(|&x| x < 0.0) {
        return Err(format!("'{s}': the sky's radiance must be non-negative"));
    }
    Ok(SkySpec {
        constant: Some(c),
        equirect: None,
    })
}

/// Reads the first RGBA layer of an EXR as an equirectangular sky.
///
/// # Errors
/// [`SceneError::Sky`] when the file cannot be read or holds a non-finite or negative value.
pub fn load_equirect(path: &Path) -> Result<Sky, SceneError> {
    use exr::prelude::*;
    let err = |message: String| SceneError::Sky {
        path: path.to_owned(),
        message,
    };
    let image = read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![Vec3::ZERO; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<Vec3>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = Vec3::new(r, g, b);
        },
    )
    .map_err(|e| err(e.to_string()))?;
    let size = image.layer_data.size;
    let (_, pixels) = image.layer_data.channel_data.pixels;
    if let Some(i) = pixels
        .iter()
        .position(|p| !p.is_finite() || p.min_element() < 0.0)
    {
        return Err(err(format!(
            "pixel ({}, {}) is {} (must be finite, >= 0)",
            i % size.0,
            i / size.0,
            pixels[i]
        )));
    }
    Ok(Sky::Equirect {
        path: path.to_owned(),
        width: size.0 as u32,
        height: size.1 as u32,
        pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sun_and_sky_flags_parse_as_the_scene_file_spells_them() {
        let sun = parse_sun("0,2,0").unwrap();
        assert_eq!(sun.direction, [0.0, 2.0, 0.0]);
        assert_eq!(sun.irradiance, [DEFAULT_SUN_IRRADIANCE; 3]);
        assert_eq!(sun.angular_radius_deg, SUN_RADIUS_DEG);
        let sun = parse_sun("-0.3, 1, 0.2:2.5").unwrap();
        assert_eq!(
            (sun.direction, sun.irradiance),
            ([-0.3, 1.0, 0.2], [2.5; 3])
        );
        let sun = parse_sun("1,1,0:1,2,3").unwrap();
        assert_eq!(sun.irradiance, [1.0, 2.0, 3.0]);
        for (bad, says) in [
            ("1,1", "X,Y,Z"),
            ("0,0,0", "non-zero"),
            ("1,x,0", "'x' is not one"),
            ("0,1,0:-1", "non-negative"),
            ("0,1,0:1,2", "one number or three"),
            ("0,1,0:inf", "finite"),
        ] {
            let e = parse_sun(bad).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
        assert_eq!(parse_sky("0.5").unwrap().constant, Some([0.5; 3]));
        assert_eq!(
            parse_sky("0.1,0.2,0.3").unwrap().constant,
            Some([0.1, 0.2, 0.3])
        );
        assert_eq!(
            parse_sky("sky.EXR").unwrap().equirect,
            Some(PathBuf::from("sky.EXR"))
        );
        assert!(parse_sky("-1").unwrap_err().contains("non-negative"));
        assert!(parse_sky("sky.png").is_err());
    }

    /// The flags replace a scene file's sun and sky and keep its other lights; an unlit
    /// scene is lit by either.
    #[test]
    fn flags_replace_the_scene_files_sun_and_sky_and_keep_its_other_lights() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("tri.obj");
        std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let bare = Scene::load(&obj).unwrap();
        assert!(!bare.is_lit());
        let e = bare.check_lit().unwrap_err().to_string();
        assert!(
            e.contains("--sun") && e.contains("--sky") && e.contains("tri.obj"),
            "{e}"
        );
        let toml = dir.path().join("s.toml");
        std::fs::write(
            &toml,
            "geometry = \"tri.obj\"\n[sky]\nconstant = [1, 1, 1]\n[sun]\ndirection = [1, 0, 0]\nangular_radius_deg = 1\nirradiance = [9, 9, 9]\n[[sphere_light]]\ncenter = [0, 5, 0]\nradius = 1\nradiance = [1, 1, 1]\n",
        )
        .unwrap();
        let mut scene = Scene::load(&toml).unwrap();
        LightOverrides {
            sun: Some(parse_sun("0,1,0:2").unwrap()),
            sky: None,
        }
        .apply(&mut scene)
        .unwrap();
        let sun = scene.sun.as_ref().unwrap();
        assert_eq!((sun.direction, sun.irradiance), (Vec3::Y, Vec3::splat(2.0)));
        assert_eq!(scene.sky, Sky::Constant(Vec3::ONE));
        assert_eq!(scene.lights.len(), 1);
        let mut lit = bare.clone();
        LightOverrides {
            sun: None,
            sky: Some(parse_sky("0.2").unwrap()),
        }
        .apply(&mut lit)
        .unwrap();
        assert!(lit.is_lit());
        // A black sky lights nothing.
        let mut dark = bare;
        LightOverrides {
            sun: None,
            sky: Some(parse_sky("0").unwrap()),
        }
        .apply(&mut dark)
        .unwrap();
        assert!(!dark.is_lit());
    }
}
