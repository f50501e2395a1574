//! The TOML scene file: geometry plus sky and sun, and the equirectangular sky it may name.
use super::*;

/// The TOML scene file: geometry plus sky and sun.
///
/// ```toml
/// geometry = "city.glb"          # relative to this file; .gltf, .glb or .obj
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
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkySpec {
    /// Constant radiance.
    pub constant: Option<[f32; 3]>,
    /// Equirectangular EXR path, relative to the scene file.
    pub equirect: Option<PathBuf>,
}

/// `[sun]` of a [`SceneFile`].
#[derive(Debug, serde::Deserialize)]
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
        let bad = |message: String| SceneError::SceneFile {
            path: path.to_owned(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_owned(),
            source,
        })?;
        let file: SceneFile = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let geometry = dir.join(&file.geometry);
        if geometry
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
        {
            return Err(bad(
                "geometry must be .gltf, .glb or .obj, not another scene file".into(),
            ));
        }
        let mut scene = Scene::load_with(&geometry, textures)?;
        if let Some(sun) = &file.sun {
            scene.sun = Some(sun.to_sun().map_err(bad)?);
        }
        for sphere in &file.sphere_light {
            scene.lights.push(sphere.to_light().map_err(bad)?);
        }
        scene.sky = match &file.sky {
            None => Sky::None,
            Some(SkySpec {
                constant: Some(c),
                equirect: None,
            }) => {
                let c = Vec3::from(*c);
                if !c.is_finite() || c.min_element() < 0.0 {
                    return Err(bad(format!(
                        "sky constant {c} must be finite and non-negative"
                    )));
                }
                Sky::Constant(c)
            }
            Some(SkySpec {
                constant: None,
                equirect: Some(p),
            }) => load_equirect(&dir.join(p))?,
            Some(_) => {
                return Err(bad(
                    "[sky] needs exactly one of `constant` or `equirect`".into()
                ));
            }
        };
        Ok(scene)
    }
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
