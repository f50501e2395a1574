//! Wavefront OBJ + MTL through `tobj`.
use std::sync::Arc;

use super::texture::{self, BaseColorTexture, TextureOptions};
use super::*;

pub(super) fn load(
    path: &Path,
    textures: TextureOptions,
    notes: &mut LoadNotes,
) -> Result<Scene, SceneError> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    check_element_indices(path)?;
    let (models, mtl) = tobj::load_obj(path, &opts).map_err(|source| SceneError::Obj {
        path: path.to_owned(),
        source,
    })?;
    // A missing or broken MTL is an error: the albedo would silently be wrong otherwise.
    let mtl = mtl.map_err(|source| SceneError::Obj {
        path: path.to_owned(),
        source,
    })?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut materials: Vec<Material> = mtl
        .iter()
        .map(|m| read_material(path, m, dir, textures, notes))
        .collect::<Result<_, _>>()?;
    let default_material = materials.len() as u32;
    materials.push(Material::default_grey());

    let textured: Vec<u32> = (0..materials.len() as u32)
        .filter(|&m| materials[m as usize].base_color_texture.is_some())
        .collect();
    let mut b = SceneBuilder::new(path);
    for (k, model) in models.iter().enumerate() {
        let name = if model.name.is_empty() {
            format!("mesh#{k}")
        } else {
            model.name.clone()
        };
        let id = b.begin_mesh(name);
        read_model(&mut b, id, &model.mesh, default_material, &textured)?;
    }
    Ok(b.finish(materials, Vec::new()))
}

/// Every index of a face (`f`) or line (`l`) names an element of the file: tobj 4.0.5
/// resolves a relative index before the first element (`f 1/-5` with one `vt`), or a
/// huge one, to a huge `usize` and computes `vt * 2 + 1` and `vn * 3 + 2` unchecked
/// (`add_vertex`; an overflow found by the `scene` fuzz target). Indices are resolved as
/// tobj does (relative ones against the elements so far; 0 and −count+… resolving to −1
/// mean "none"), and only kinds the file has are checked, as tobj only reads those.
fn check_element_indices(path: &Path) -> Result<(), SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_owned(),
        source,
    })?;
    let text = String::from_utf8_lossy(&bytes);
    const KINDS: [(&str, &str); 3] = [
        ("v", "vertex"),
        ("vt", "texture coordinate"),
        ("vn", "normal"),
    ];
    let kind = |word: Option<&str>| KINDS.iter().position(|k| Some(k.0) == word);
    let mut total = [0isize; 3];
    for line in text.lines() {
        if let Some(k) = kind(line.split_whitespace().next()) {
            total[k] += 1;
        }
    }
    let mut seen = [0isize; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let first = words.next();
        if let Some(k) = kind(first) {
            seen[k] += 1;
            continue;
        }
        if !matches!(first, Some("f" | "l")) {
            continue;
        }
        for (k, field) in words.flat_map(|w| w.split('/').take(3).enumerate()) {
            let Ok(x) = field.parse::<isize>() else {
                continue; // tobj refuses the face itself
            };
            let resolved = if x < 0 {
                seen[k].saturating_add(x)
            } else {
                x - 1
            };
            if total[k] > 0 && (resolved < -1 || resolved >= total[k]) {
                return Err(SceneError::ObjIndex {
                    path: path.to_owned(),
                    line: n + 1,
                    message: format!(
                        "{} index {x} names no {} (the file has {}, {} before this line)",
                        KINDS[k].1, KINDS[k].1, total[k], seen[k]
                    ),
                });
            }
        }
    }
    Ok(())
}

/// A material; its `map_Kd` is a texture sampled at the OBJ's one UV set (repeating; v
/// flipped, as OBJ's v runs up the image), × `Kd`. An image that is missing or cannot be
/// decoded is noted in `notes` and the material keeps its `Kd`, or
/// [`MISSING_TEXTURE_ALBEDO`] grey without one (module docs of [`super`]). `map_Kd` options
/// (`-s`, `-o`, ...) are not read: the rest of the line is taken as the file name.
fn read_material(
    path: &Path,
    m: &tobj::Material,
    dir: &Path,
    options: TextureOptions,
    notes: &mut LoadNotes,
) -> Result<Material, SceneError> {
    // Not clamped before the texture multiplies it (a Kd above 1 brightening a dark map is
    // kept, as when the texture was averaged); the albedo at a hit is clamped to [0, 1].
    let kd = m
        .diffuse
        .map_or(Vec3::splat(0.8), Vec3::from)
        .max(Vec3::ZERO);
    let mut albedo = kd;
    let base_color_texture = match &m.diffuse_texture {
        Some(name) => match read_image(path, dir, name, options) {
            Ok(image) => {
                albedo = kd * image.average();
                Some(BaseColorTexture {
                    image: Arc::new(image),
                    wrap: [texture::Wrap::Repeat; 2],
                    factor: kd,
                })
            }
            Err(SceneError::Texture { image, message, .. }) => {
                albedo = m
                    .diffuse
                    .map_or(Vec3::splat(MISSING_TEXTURE_ALBEDO), Vec3::from)
                    .clamp(Vec3::ZERO, Vec3::ONE);
                notes.missing_textures.push(MissingTexture {
                    material: m.name.clone(),
                    file: image,
                    message,
                    fallback: albedo.to_array(),
                });
                None
            }
            Err(e) => return Err(e),
        },
        None => None,
    };
    // tobj parses `Ke` into `emissive`; older files spell it as an unknown parameter.
    let ke = m
        .emissive
        .map(Vec3::from)
        .or_else(|| m.unknown_param.get("Ke").and_then(|s| parse_vec3(s)))
        .unwrap_or(Vec3::ZERO);
    Ok(Material {
        name: m.name.clone(),
        albedo: albedo.clamp(Vec3::ZERO, Vec3::ONE),
        emission: ke.max(Vec3::ZERO),
        base_color_texture,
    })
}

/// A `map_Kd` image, relative to the OBJ's directory, as 8-bit sRGB (16-bit files keep
/// their high byte).
fn read_image(
    path: &Path,
    dir: &Path,
    name: &str,
    options: TextureOptions,
) -> Result<texture::Image, SceneError> {
    let fail = |message: String| SceneError::Texture {
        path: path.to_owned(),
        image: name.to_owned(),
        message,
    };
    let file = dir.join(name);
    let img = image::open(&file).map_err(|e| fail(e.to_string()))?;
    let rgb = img.to_rgb8();
    texture::Image::from_srgb8(
        file.display().to_string(),
        rgb.width(),
        rgb.height(),
        3,
        rgb.as_raw(),
        options,
    )
    .map_err(fail)
}

fn parse_vec3(s: &str) -> Option<Vec3> {
    let v: Vec<f32> = s
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()?;
    match v.as_slice() {
        [x] => Some(Vec3::splat(*x)),
        [x, y, z] => Some(Vec3::new(*x, *y, *z)),
        _ => None,
    }
}

fn read_model(
    b: &mut SceneBuilder,
    id: u32,
    mesh: &tobj::Mesh,
    default_material: u32,
    textured: &[u32],
) -> Result<(), SceneError> {
    let count = mesh.positions.len() / 3;
    let at3 = |v: &[f32], i: usize| Vec3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    let has_n = mesh.normals.len() == mesh.positions.len();
    let has_uv = mesh.texcoords.len() / 2 == count && count > 0;
    if let Some(&bad) = mesh.indices.iter().find(|&&i| i as usize >= count) {
        return Err(b.bad_mesh(
            id,
            format!("index {bad} is out of range ({count} vertices)"),
        ));
    }
    let material = mesh.material_id.map_or(default_material, |m| m as u32);
    // OBJ has one UV set: the lightmap's and the texture's.
    let textured = textured.contains(&material);
    for tri in mesh.indices.chunks_exact(3) {
        let v = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let uv =
            has_uv.then(|| v.map(|i| Vec2::new(mesh.texcoords[2 * i], mesh.texcoords[2 * i + 1])));
        b.push(Triangle {
            positions: v.map(|i| at3(&mesh.positions, i)),
            normals: if has_n {
                v.map(|i| at3(&mesh.normals, i))
            } else {
                [Vec3::ZERO; 3]
            },
            lightmap_uv: uv,
            // OBJ's v runs up the image, glTF's (and the sampler's) down.
            texture_uv: uv
                .filter(|_| textured)
                .map(|uv| uv.map(|t| Vec2::new(t.x, 1.0 - t.y))),
            colour: None,
            mesh: id,
            material,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::*;

    #[test]
    fn obj_indices_naming_no_element_are_errors_naming_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.obj");
        let head = "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\n";
        for (face, message) in [
            // Relative, before the first texture coordinate: overflowed in tobj.
            (
                "f 1/-3 2/1 3/1",
                "line 6: texture coordinate index -3 names no texture coordinate (the file has 1, 1 before this line)",
            ),
            (
                "f 1//1 2//1 3//9223372036854775807",
                "line 6: normal index 9223372036854775807 names no normal (the file has 1, 1 before this line)",
            ),
            (
                "f 1 2 4",
                "line 6: vertex index 4 names no vertex (the file has 3, 3 before this line)",
            ),
        ] {
            std::fs::write(&path, format!("{head}{face}\n")).unwrap();
            let e = Scene::load(&path).expect_err("an index naming no element is an error");
            assert_eq!(e.to_string(), format!("{}: {message}", path.display()));
        }
        // 0 and a relative index to just before the first element mean "none", as in tobj.
        std::fs::write(&path, format!("{head}f 1/0/-1 2/-2/1 3/1/1\n")).unwrap();
        assert_eq!(Scene::load(&path).unwrap().triangles.len(), 1);
    }

    #[test]
    fn obj_map_kd_is_sampled_and_a_missing_one_falls_back_to_kd_with_a_note() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("quad.obj");
        std::fs::write(
            &obj,
            "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl wood\nf 1/1 2/2 3/3\n",
        )
        .unwrap();
        std::fs::write(
            dir.path().join("quad.mtl"),
            "newmtl wood\nKd 0.5 0.5 0.5\nmap_Kd wood.png\n",
        )
        .unwrap();
        let (s, notes) = Scene::load_reporting(&obj, TextureOptions::default()).unwrap();
        assert_eq!(notes.missing_textures.len(), 1, "{notes:?}");
        let m = &notes.missing_textures[0];
        assert_eq!((m.material.as_str(), m.file.as_str()), ("wood", "wood.png"));
        assert_eq!(m.fallback, [0.5; 3]);
        assert!(s.materials[0].base_color_texture.is_none());
        assert_eq!(s.materials[0].albedo, Vec3::splat(0.5));
        assert!(s.triangles[0].texture_uv.is_none());
        let warning = &notes.warnings(&obj)[0];
        assert!(
            warning.contains("texture wood.png cannot be read")
                && warning.contains("material 'wood'"),
            "{warning}"
        );
        // Without Kd the fallback is the 0.5 grey; with one, Kd.
        std::fs::write(
            dir.path().join("quad.mtl"),
            "newmtl wood\nmap_Kd wood.png\n",
        )
        .unwrap();
        let (s, notes) = Scene::load_reporting(&obj, TextureOptions::default()).unwrap();
        assert_eq!(s.materials[0].albedo, Vec3::splat(MISSING_TEXTURE_ALBEDO));
        assert_eq!(notes.missing_textures[0].fallback, [0.5; 3]);
        std::fs::write(
            dir.path().join("quad.mtl"),
            "newmtl wood\nKd 0.2 0.4 0.6\nmap_Kd wood.png\n",
        )
        .unwrap();
        let s = Scene::load(&obj).unwrap();
        assert_eq!(s.materials[0].albedo, Vec3::new(0.2, 0.4, 0.6));
        std::fs::write(
            dir.path().join("quad.mtl"),
            "newmtl wood\nKd 0.5 0.5 0.5\nmap_Kd wood.png\n",
        )
        .unwrap();
        // A 1×2 image: black over white (rows top to bottom; v = 0 is the top row).
        image::RgbImage::from_raw(1, 2, vec![0, 0, 0, 255, 255, 255])
            .unwrap()
            .save(dir.path().join("wood.png"))
            .unwrap();
        let s = Scene::load(&obj).unwrap();
        let t = &s.triangles[0];
        // OBJ's v runs up the image: the texture UVs are the lightmap UVs with v flipped.
        let flip = |uv: [Vec2; 3]| uv.map(|t| Vec2::new(t.x, 1.0 - t.y));
        assert_eq!(t.texture_uv, t.lightmap_uv.map(flip));
        assert!(
            (s.materials[0].albedo - Vec3::splat(0.25))
                .abs()
                .max_element()
                < 1e-6
        );
        let a = s.hit_albedo(0);
        // OBJ v = 0 is the image's bottom edge, between the white bottom row and the black
        // top row (repeating): halfway, ½ × Kd.
        assert!((a.at(0.0, 0.0) - Vec3::splat(0.25)).abs().max_element() < 1e-6);
        // OBJ v = ¼ is the centre of the bottom (white) row; v = ¾ of the top (black) one.
        assert!((a.at(0.0, 0.25) - Vec3::splat(0.5)).abs().max_element() < 1e-6);
        assert!(a.at(0.0, 0.75).abs().max_element() < 1e-6);
    }
}
