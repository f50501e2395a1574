//! Whether and how a scene is lit: a scene nothing lights is refused ([`Scene::check_lit`]),
//! and the fingerprint of its lighting that `prepare`'s facing depends on.

use glam::Vec3;

use super::*;

impl Scene {
    /// Whether anything lights the scene: a sun, a sky that is not black, a punctual light,
    /// or an emissive material on some triangle.
    #[must_use]
    pub fn is_lit(&self) -> bool {
        let emitters = {
            let mut used = vec![false; self.materials.len()];
            for t in &self.triangles {
                used[t.material as usize] = true;
            }
            self.materials
                .iter()
                .zip(&used)
                .any(|(m, &u)| u && m.emission.max_element() > 0.0)
        };
        self.lit_from_outside() || !self.lights.is_empty() || emitters
    }

    /// Whether a sun or a sky that is not black lights the scene: the light from outside that
    /// a shell around a level keeps out (`prepare::shell`).
    #[must_use]
    pub fn lit_from_outside(&self) -> bool {
        let sky = match &self.sky {
            Sky::None => false,
            Sky::Constant(c) => c.max_element() > 0.0,
            Sky::Equirect { pixels, .. } => pixels.iter().any(|p| p.max_element() > 0.0),
        };
        let sun = self
            .sun
            .as_ref()
            .is_some_and(|s| s.irradiance.max_element() > 0.0);
        sky || sun
    }

    /// A fingerprint of everything that lights the scene — punctual and sphere lights, the
    /// sun, the sky (an equirect map by its pixels) and the materials' emission — never 0.
    /// `prepare` stores it in the texel file (it decides the seen sides under these lights,
    /// `facing`), so a bake under other lights is told (docs/levels.md).
    #[must_use]
    pub fn lighting_fingerprint(&self) -> u64 {
        let mut h = Fnv::default();
        for light in &self.lights {
            match light {
                SceneLight::Directional {
                    direction,
                    irradiance,
                } => h.tag(1).vec(*direction).vec(*irradiance),
                SceneLight::Point {
                    position,
                    intensity,
                } => h.tag(2).vec(*position).vec(*intensity),
                SceneLight::Spot {
                    position,
                    direction,
                    intensity,
                    inner_cone,
                    outer_cone,
                } => h
                    .tag(3)
                    .vec(*position)
                    .vec(*direction)
                    .vec(*intensity)
                    .f(*inner_cone)
                    .f(*outer_cone),
                SceneLight::Sphere {
                    center,
                    radius,
                    radiance,
                } => h.tag(4).vec(*center).f(*radius).vec(*radiance),
            };
        }
        if let Some(sun) = &self.sun {
            h.tag(5)
                .vec(sun.direction)
                .f(sun.angular_radius)
                .vec(sun.irradiance);
        }
        match &self.sky {
            Sky::None => h.tag(6),
            Sky::Constant(c) => h.tag(7).vec(*c),
            Sky::Equirect {
                width,
                height,
                pixels,
                ..
            } => {
                h.tag(8).tag(u64::from(*width)).tag(u64::from(*height));
                for p in pixels {
                    h.vec(*p);
                }
                &mut h
            }
        };
        for m in &self.materials {
            h.tag(9).vec(m.emission);
        }
        h.0.max(1)
    }

    /// [`Scene::is_lit`] as a check for the commands that light a scene (`prepare`, whose
    /// facing analysis needs the lights, and `bake`).
    ///
    /// # Errors
    /// [`SceneError::Unlit`], which says how to add a sun and a sky from the command line.
    pub fn check_lit(&self) -> Result<(), SceneError> {
        if self.is_lit() {
            Ok(())
        } else {
            Err(SceneError::Unlit {
                path: self.path.clone(),
            })
        }
    }
}

/// [`crate::hash::fnv1a64`] built word by word (little-endian bytes), for
/// [`Scene::lighting_fingerprint`].
pub(super) struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Self(crate::hash::FNV1A64_EMPTY)
    }
}

impl Fnv {
    fn tag(&mut self, word: u64) -> &mut Self {
        self.0 = crate::hash::fnv1a64_more(self.0, &word.to_le_bytes());
        self
    }

    fn f(&mut self, x: f32) -> &mut Self {
        self.tag(u64::from(x.to_bits()))
    }

    fn vec(&mut self, v: Vec3) -> &mut Self {
        self.f(v.x).f(v.y).f(v.z)
    }
}
