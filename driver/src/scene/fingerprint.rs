//! What a scene is, in a few words a file can keep: the fingerprints of its geometry and
//! materials (64-bit hashes, never 0) and a description of its lights. `prepare` writes the
//! geometry's into the texel file, so `bake` and `render` refuse a scene of other geometry;
//! a bake's work directory keeps all of them, so `--resume` names what changed
//! (docs/texels.md).

use glam::{Vec2, Vec3};

use super::{Scene, SceneLight, Sky};
use crate::hash::WordHash;

/// [`Scene::geometry_fingerprint`] built triangle by triangle, for a writer that has the
/// triangles but no [`Scene`] (`synth`): the same value for the same positions in the same
/// order.
#[derive(Clone, Copy, Debug)]
pub struct GeometryFingerprint {
    hash: WordHash,
    triangles: u64,
}

impl Default for GeometryFingerprint {
    fn default() -> Self {
        Self {
            hash: WordHash::new(1),
            triangles: 0,
        }
    }
}

impl GeometryFingerprint {
    /// Adds the next triangle's corners.
    pub fn push(&mut self, positions: &[Vec3; 3]) {
        for p in positions {
            self.hash.vec3(*p);
        }
        self.triangles += 1;
    }

    /// The fingerprint of the triangles pushed, never 0.
    #[must_use]
    pub fn finish(&self) -> u64 {
        let mut h = self.hash;
        h.u64(self.triangles).finish()
    }
}

/// One thing that lights a scene, described for people: its name (the command-line option
/// that sets it, where there is one) and its value.
pub type LightEntry = (&'static str, String);

impl Scene {
    /// A fingerprint of the scene's geometry: every corner's position and the triangle count,
    /// in triangle order (the order of the texel file's triangle table), never 0. The lightmap
    /// UVs are left out (the texel file's triangle table holds the ones the bake uses), as are
    /// normals and materials ([`Scene::materials_fingerprint`]). −0 and +0 are one position,
    /// so a scene written back (`prepare --write-gltf`) has its source's fingerprint.
    /// About 50 ms per million triangles (measured: `a_million_triangles`).
    #[must_use]
    pub fn geometry_fingerprint(&self) -> u64 {
        let mut g = GeometryFingerprint::default();
        for t in &self.triangles {
            g.push(&t.positions);
        }
        g.finish()
    }

    /// What differs between this scene's geometry and that of the scene a texel file was
    /// prepared from, which had `triangles` triangles and [`Scene::geometry_fingerprint`]
    /// `geometry` (0: not recorded, then the count alone is compared): a phrase that ends
    /// "prepared from …", or `None` when they agree.
    #[must_use]
    pub fn geometry_differs(&self, triangles: usize, geometry: u64) -> Option<String> {
        let n = self.triangles.len();
        if triangles != n {
            return Some(format!(
                "a scene of {triangles} triangles, but {} has {n} triangles",
                self.path.display()
            ));
        }
        (geometry != 0 && geometry != self.geometry_fingerprint()).then(|| {
            format!(
                "a scene of other geometry than {}: same {n} triangles but other positions",
                self.path.display()
            )
        })
    }

    /// A fingerprint of everything on the surfaces that changes a bake's bits besides the
    /// positions and the lights: each material's albedo, emission and base-colour texture (its
    /// size, wrap modes, factor, average and a grid of 8 × 8 samples: cheap, and any image
    /// loaded differently moves its average), and each triangle's material, normals, texture
    /// UVs and vertex colours; never 0.
    #[must_use]
    pub fn materials_fingerprint(&self) -> u64 {
        let mut h = WordHash::new(2);
        h.u64(self.materials.len() as u64);
        for m in &self.materials {
            h.vec3(m.albedo).vec3(m.emission);
            match &m.base_color_texture {
                None => h.word(0),
                Some(t) => {
                    let (w, hgt) = t.image.size();
                    h.word(1)
                        .word(w)
                        .word(hgt)
                        .vec3(t.factor)
                        .vec3(t.image.average());
                    h.bytes(format!("{:?}", t.wrap).as_bytes());
                    for i in 0..64u32 {
                        let uv = Vec2::new(
                            (i % 8) as f32 / 8.0 + 1.0 / 16.0,
                            (i / 8) as f32 / 8.0 + 1.0 / 16.0,
                        );
                        h.vec3(t.image.bilinear(uv, t.wrap));
                    }
                    &mut h
                }
            };
        }
        for t in &self.triangles {
            h.word(t.material);
            for n in t.normals {
                h.vec3(n);
            }
            match t.texture_uv {
                Some(uv) => uv.iter().fold(h.word(1), |h, v| h.vec2(*v)),
                None => h.word(0),
            };
            match t.colour {
                Some(c) => c.iter().fold(h.word(1), |h, v| h.vec3(*v)),
                None => h.word(0),
            };
        }
        h.finish()
    }

    /// The scene's lights described for people, by the options that set them: `--sun` (the
    /// scene file's `[sun]` or the flag), `--sky`, and the scene file's own lights. Numbers are
    /// rounded for reading; [`Scene::lighting_fingerprint`] tells lights apart exactly.
    #[must_use]
    pub fn light_entries(&self) -> Vec<LightEntry> {
        let sun = match &self.sun {
            None => "none".to_owned(),
            Some(s) => {
                // The direction scaled to a largest component of 1: `--sun 0.3,1,0.45` reads
                // back as given.
                let largest = s.direction.abs().max_element();
                let direction = if largest > 0.0 {
                    s.direction / largest
                } else {
                    s.direction
                };
                let mut d = format!("{}:{}", triple(direction), rgb(s.irradiance));
                let radius = s.angular_radius.to_degrees();
                if (radius - super::SUN_RADIUS_DEG).abs() > 1e-4 {
                    d += &format!(" (radius {}°)", num(radius));
                }
                d
            }
        };
        let sky = match &self.sky {
            Sky::None => "none".to_owned(),
            Sky::Constant(c) => rgb(*c),
            Sky::Equirect {
                path,
                width,
                height,
                ..
            } => format!("{} ({width}×{height})", path.display()),
        };
        let lights = if self.lights.is_empty() {
            "none".to_owned()
        } else {
            const SHOWN: usize = 4;
            let mut d: Vec<String> = self.lights.iter().take(SHOWN).map(describe).collect();
            if self.lights.len() > SHOWN {
                d.push(format!("{} more", self.lights.len() - SHOWN));
            }
            format!("{}: {}", self.lights.len(), d.join("; "))
        };
        vec![("--sun", sun), ("--sky", sky), ("scene lights", lights)]
    }

    /// [`Scene::light_entries`] in one line, for a lightmap's header.
    #[must_use]
    pub fn lights_description(&self) -> String {
        self.light_entries()
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

fn describe(light: &SceneLight) -> String {
    match light {
        SceneLight::Directional {
            direction,
            irradiance,
        } => format!("directional {} of {}", triple(*direction), rgb(*irradiance)),
        SceneLight::Point {
            position,
            intensity,
        } => format!("point at {} of {}", triple(*position), rgb(*intensity)),
        SceneLight::Spot {
            position,
            direction,
            intensity,
            ..
        } => format!(
            "spot at {} towards {} of {}",
            triple(*position),
            triple(*direction),
            rgb(*intensity)
        ),
        SceneLight::Sphere {
            center,
            radius,
            radiance,
        } => format!(
            "sphere at {} radius {} of {}",
            triple(*center),
            num(*radius),
            rgb(*radiance)
        ),
    }
}

/// A number with at most 4 decimals, trailing zeros dropped.
fn num(x: f32) -> String {
    let s = format!("{x:.4}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        &s
    };
    if s == "-0" {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

fn triple(v: Vec3) -> String {
    format!("{},{},{}", num(v.x), num(v.y), num(v.z))
}

/// One value when the channels agree (as `--sun …:4` and `--sky 0.5` take one), else R,G,B.
fn rgb(v: Vec3) -> String {
    if v.x == v.y && v.y == v.z {
        num(v.x)
    } else {
        triple(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Material, Sun, Triangle};

    fn scene() -> Scene {
        let t = |o: Vec3| Triangle {
            positions: [o, o + Vec3::X, o + Vec3::Y],
            normals: [Vec3::Z; 3],
            lightmap_uv: None,
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        Scene::of_triangles(
            "two",
            vec![t(Vec3::ZERO), t(Vec3::new(2.0, 0.0, 0.0))],
            vec![Material::default_grey()],
        )
    }

    #[test]
    fn moving_one_vertex_changes_the_geometry_fingerprint() {
        let a = scene();
        let mut b = scene();
        assert_eq!(a.geometry_fingerprint(), b.geometry_fingerprint());
        b.triangles[1].positions[2].z += 1e-6;
        assert_ne!(a.geometry_fingerprint(), b.geometry_fingerprint());
        // The same triangles in another order are another triangle table.
        let mut c = scene();
        c.triangles.swap(0, 1);
        assert_ne!(a.geometry_fingerprint(), c.geometry_fingerprint());
        // Lightmap UVs, normals and materials are not geometry.
        let mut d = scene();
        d.triangles[0].lightmap_uv = Some([Vec2::ZERO, Vec2::X, Vec2::Y]);
        d.triangles[0].normals = [Vec3::Y; 3];
        d.materials[0].albedo = Vec3::ONE;
        assert_eq!(a.geometry_fingerprint(), d.geometry_fingerprint());
        assert_ne!(a.materials_fingerprint(), d.materials_fingerprint());
        // −0 is +0.
        let mut e = scene();
        e.triangles[0].positions[0] = Vec3::new(-0.0, 0.0, -0.0);
        assert_eq!(a.geometry_fingerprint(), e.geometry_fingerprint());
        assert_ne!(a.geometry_fingerprint(), 0);
    }

    #[test]
    fn a_scene_loaded_twice_has_one_fingerprint() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("q.obj");
        std::fs::write(
            &obj,
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
        )
        .unwrap();
        let (a, b) = (Scene::load(&obj).unwrap(), Scene::load(&obj).unwrap());
        assert_eq!(a.geometry_fingerprint(), b.geometry_fingerprint());
        assert_eq!(a.materials_fingerprint(), b.materials_fingerprint());
        std::fs::write(
            &obj,
            "v 0 0 0\nv 1 0 0\nv 1 1 0.5\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
        )
        .unwrap();
        let c = Scene::load(&obj).unwrap();
        assert_eq!(a.triangles.len(), c.triangles.len());
        assert_ne!(a.geometry_fingerprint(), c.geometry_fingerprint());
    }

    #[test]
    fn lights_are_described_by_their_options() {
        let mut s = scene();
        s.sun = Some(Sun {
            direction: Vec3::new(0.3, 1.0, 0.45).normalize(),
            angular_radius: crate::scene::SUN_RADIUS_DEG.to_radians(),
            irradiance: Vec3::splat(4.0),
        });
        s.sky = Sky::Constant(Vec3::new(0.45, 0.55, 0.7));
        assert_eq!(
            s.lights_description(),
            "--sun 0.3,1,0.45:4, --sky 0.45,0.55,0.7, scene lights none"
        );
    }

    /// A million triangles are fingerprinted in well under the time their BVH takes to build.
    #[test]
    #[ignore = "a measurement: cargo test -p guidebake --release --lib fingerprint -- --ignored --nocapture"]
    fn a_million_triangles() {
        let mut s = scene();
        let t = s.triangles[0];
        s.triangles = (0..1_000_000)
            .map(|i| {
                let mut t = t;
                t.positions[0].x = i as f32;
                t
            })
            .collect();
        let clock = std::time::Instant::now();
        let g = s.geometry_fingerprint();
        let geometry = clock.elapsed();
        let m = s.materials_fingerprint();
        println!(
            "geometry {geometry:?}, geometry and materials {:?} ({g:x} {m:x})",
            clock.elapsed()
        );
    }
}
