//! Wavefront OBJ + MTL through `tobj`, checked line by line first ([`lint`]) so that what
//! tobj would refuse without saying where is said with its line and column; material
//! libraries are read here ([`load_mtl`]), a missing or malformed one a warning.
use std::sync::Arc;

use super::roles::default_role;
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
    let bytes = std::fs::read(path).map_err(|error| SceneError::Io {
        path: path.to_owned(),
        error,
    })?;
    if let Some(kind) = looks_like(&bytes).filter(|k| *k != "a Wavefront OBJ file") {
        return Err(SceneError::NotAScene {
            path: path.to_owned(),
            message: format!("looks like {kind}, not a Wavefront OBJ file"),
        });
    }
    let lint = lint(path, &bytes)?;
    notes.file_warnings.extend(lint.warnings);
    // Material libraries are read here, not by tobj, so that one that cannot be read is
    // named (its path as resolved and the `mtllib` line naming it) and the OBJ still loads,
    // its materials the default grey, as other tools do.
    let libraries = std::cell::RefCell::new(Vec::new());
    let dir = path.parent().unwrap_or(Path::new("."));
    let read = std::cell::RefCell::new(Vec::new());
    let loaded = tobj::load_obj_buf(&mut &bytes[..], &opts, |name| {
        read.borrow_mut().push(dir.join(name));
        let mut libraries = libraries.borrow_mut();
        let line = lint.mtllib_lines.get(libraries.len()).copied();
        match load_mtl(path, line, name) {
            Ok(loaded) => {
                libraries.push(None);
                loaded
            }
            Err(warning) => {
                libraries.push(Some(warning));
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    });
    notes.files_read.extend(read.into_inner());
    let failed: Vec<String> = libraries.into_inner().into_iter().flatten().collect();
    let (models, mtl) = loaded.map_err(|error| SceneError::Obj {
        path: path.to_owned(),
        error,
    })?;
    // Every library that failed is warned about; the ones that loaded are here.
    let mtl = mtl.unwrap_or_default();
    if failed.is_empty() {
        // A material no library defines: its faces are the default grey (said once a name).
        let mut said = std::collections::HashSet::new();
        for (n, name) in &lint.usemtl {
            if !mtl.iter().any(|m| &m.name == name) && said.insert(name) {
                let libraries = if lint.mtllib_lines.is_empty() {
                    "the file names no material library (mtllib)".to_owned()
                } else {
                    "no material library of the file defines it".to_owned()
                };
                notes.file_warnings.push(format!(
                    "{}:{n}: usemtl {name:?}: {libraries}; its faces are the default grey (0.8)",
                    path.display()
                ));
            }
        }
    }
    notes.file_warnings.extend(failed);
    let mut materials: Vec<Material> = mtl
        .iter()
        .map(|m| read_material(path, m, dir, textures, notes))
        .collect::<Result<_, _>>()?;
    let default_material = materials.len() as u32;
    materials.push(Material::default_grey());

    let textured: Vec<u32> = (0..materials.len() as u32)
        .filter(|&m| materials[m as usize].base_color_texture.is_some())
        .collect();
    // What each material's names ask for by default (`roles::default_role`): its own name and
    // its texture's path, read or not (levels come without their texture packs).
    let mut material_role: Vec<Option<Role>> = mtl
        .iter()
        .map(|m| default_role([m.name.as_str(), m.diffuse_texture.as_deref().unwrap_or("")]))
        .collect();
    material_role.push(None);
    let mut b = SceneBuilder::new(path);
    for (k, model) in models.iter().enumerate() {
        let name = if model.name.is_empty() {
            format!("mesh#{k}")
        } else {
            model.name.clone()
        };
        let material = model
            .mesh
            .material_id
            .map_or(default_material, |m| m as u32);
        let role = default_role([name.as_str()])
            .or(material_role.get(material as usize).copied().flatten());
        b.set_role(role.unwrap_or_default());
        let id = b.begin_mesh(name);
        read_model(&mut b, id, &model.mesh, default_material, &textured)?;
    }
    Ok(b.finish(materials, Vec::new()))
}

/// What [`lint`] found that the load goes on with.
struct Lint {
    /// The line (from 1) of each `mtllib`, in order: tobj asks for the libraries in it.
    mtllib_lines: Vec<usize>,
    /// Each `usemtl`'s line and the material name it gives (as tobj reads it).
    usemtl: Vec<(usize, String)>,
    /// Warnings, each naming the file and line.
    warnings: Vec<String>,
}

/// The lines of a file as `BufRead::lines` (tobj's reader) gives them: split at `\n`, a
/// final `\r` dropped, no empty line after a final `\n`; with their numbers from 1.
fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    let body = bytes.strip_suffix(b"\n").unwrap_or(bytes);
    let empty = bytes.is_empty();
    body.split(|&b| b == b'\n')
        .filter(move |_| !empty)
        .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
        .enumerate()
        .map(|(n, l)| (n + 1, l))
}

/// The first word of a line.
fn first_word(line: &[u8]) -> Option<&[u8]> {
    line.split(u8::is_ascii_whitespace).find(|w| !w.is_empty())
}

/// The words of a line with the column (from 1, in characters) each starts at.
fn words(line: &str) -> Vec<(usize, &str)> {
    line.split_whitespace()
        .map(|w| {
            let at = w.as_ptr() as usize - line.as_ptr() as usize;
            (line[..at].chars().count() + 1, w)
        })
        .collect()
}

/// Checks an OBJ line by line, in file order, for everything tobj 4.0.5 refuses without
/// saying where (`parse_obj_line`: a line that is not UTF-8; a `v`, `vt` or `vn` with too
/// few numbers or one that is not a number; a `v`'s weight of 0 or a colour of two
/// components; a face without vertices or with an index that is not a whole number; an
/// empty `usemtl`), so the error names the line and column; and that every face (`f`) and
/// line (`l`) index names an element of the file: tobj resolves a relative index before
/// the first element (`f 1/-5` with one `vt`), or a huge one, to a huge `usize` and
/// computes `vt * 2 + 1` and `vn * 3 + 2` unchecked (`add_vertex`; an overflow found by the
/// `scene` fuzz target). Indices are resolved as tobj does (relative ones against the
/// elements so far; 0 and −count+… resolving to −1 mean "none" for `vt` and `vn`), and only
/// kinds the file has are checked, as tobj only reads those. A vertex position that is not
/// finite (`nan`, `inf`, `1e39`) is a warning: its triangles are dropped and counted.
fn lint(path: &Path, bytes: &[u8]) -> Result<Lint, SceneError> {
    // (keyword, element, its values, how many, their names)
    const KINDS: [(&str, &str, &str, usize, &str); 3] = [
        ("v", "vertex", "vertex position", 3, "x y z"),
        ("vt", "texture coordinate", "texture coordinate", 2, "u v"),
        ("vn", "normal", "normal", 3, "x y z"),
    ];
    let kind = |word: Option<&[u8]>| KINDS.iter().position(|k| Some(k.0.as_bytes()) == word);
    let mut total = [0isize; 3];
    for (_, line) in lines(bytes) {
        if let Some(k) = kind(first_word(line)) {
            total[k] += 1;
        }
    }
    let err = |line: usize, column: usize, message: String| SceneError::Syntax {
        path: path.to_owned(),
        at: TextPos {
            line,
            column: Some(column),
        },
        message,
    };
    let mut lint = Lint {
        mtllib_lines: Vec::new(),
        usemtl: Vec::new(),
        warnings: Vec::new(),
    };
    let mut not_finite: Option<(usize, usize, String)> = None;
    let mut more_not_finite = 0usize;
    let mut seen = [0isize; 3];
    for (n, raw) in lines(bytes) {
        let line = match std::str::from_utf8(raw) {
            Ok(line) => line,
            Err(e) => {
                let good = String::from_utf8_lossy(&raw[..e.valid_up_to()]);
                return Err(err(
                    n,
                    good.chars().count() + 1,
                    "not UTF-8 text (an OBJ file is text; tobj reads it as UTF-8)".into(),
                ));
            }
        };
        let words = words(line);
        let end = line.trim_end().chars().count() + 1;
        let Some(&(_, first)) = words.first() else {
            continue;
        };
        if let Some(k) = kind(Some(first.as_bytes())) {
            let (_, _, what, count, names) = KINDS[k];
            seen[k] += 1;
            for i in 0..count {
                let Some(&(col, w)) = words.get(1 + i) else {
                    return Err(err(
                        n,
                        end,
                        format!(
                            "{what} has {i} number{}; it needs {count} ({names})",
                            if i == 1 { "" } else { "s" }
                        ),
                    ));
                };
                match w.parse::<f32>() {
                    Err(_) => {
                        return Err(err(n, col, format!("{what} \"{w}\" is not a number")));
                    }
                    Ok(x) if k == 0 && !x.is_finite() => {
                        if not_finite.is_none() {
                            not_finite = Some((n, col, w.to_owned()));
                        } else {
                            more_not_finite += 1;
                        }
                    }
                    Ok(_) => {}
                }
            }
            if k == 0 {
                // After x y z: nothing, a weight w, or a colour r g b (tobj).
                match &words[4..] {
                    [] => {}
                    [(col, w)] => match w.parse::<f32>() {
                        Err(_) => {
                            return Err(err(
                                n,
                                *col,
                                format!("vertex weight \"{w}\" is not a number"),
                            ));
                        }
                        Ok(0.0) => {
                            return Err(err(
                                n,
                                *col,
                                "vertex weight is 0 (x y z are divided by it)".into(),
                            ));
                        }
                        Ok(_) => {}
                    },
                    [_, _, _] => {}
                    [(col, _), ..] => {
                        return Err(err(
                            n,
                            *col,
                            format!(
                                "vertex has {} numbers; it takes x y z, then a weight w or a colour r g b",
                                words.len() - 1
                            ),
                        ));
                    }
                }
            }
            continue;
        }
        match first {
            "mtllib" => lint.mtllib_lines.push(n),
            "usemtl" => {
                let name = line.split_once(' ').unwrap_or_default().1.trim();
                if name.is_empty() {
                    return Err(err(n, end, "usemtl names no material".into()));
                }
                lint.usemtl.push((n, name.to_owned()));
            }
            "f" | "l" if words.len() == 1 => {
                return Err(err(n, end, format!("\"{first}\" lists no vertices")));
            }
            "f" | "l" => {
                for &(col, word) in &words[1..] {
                    for (k, field) in word.split('/').enumerate() {
                        if field.is_empty() {
                            continue;
                        }
                        if k >= 3 {
                            return Err(err(
                                n,
                                col,
                                format!("face vertex \"{word}\" has more than 3 indices (v/vt/vn)"),
                            ));
                        }
                        let Ok(x) = field.parse::<isize>() else {
                            return Err(err(
                                n,
                                col,
                                format!("{} index \"{field}\" is not a whole number", KINDS[k].1),
                            ));
                        };
                        let resolved = if x < 0 {
                            seen[k].saturating_add(x)
                        } else {
                            x - 1
                        };
                        // A missing vertex is out of bounds in tobj; a missing texture
                        // coordinate or normal means none.
                        let lowest = if k == 0 { 0 } else { -1 };
                        if (k == 0 || total[k] > 0) && (resolved < lowest || resolved >= total[k]) {
                            return Err(err(
                                n,
                                col,
                                format!(
                                    "{} index {x} names no {} (the file has {}, {} before this line)",
                                    KINDS[k].1, KINDS[k].1, total[k], seen[k]
                                ),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    if let Some((n, col, w)) = not_finite {
        let more = match more_not_finite {
            0 => String::new(),
            m => format!(" ({m} more such coordinates after it)"),
        };
        lint.warnings.push(format!(
            "{}:{n}:{col}: vertex position \"{w}\" is not a finite number{more}; the triangles using it are dropped",
            path.display()
        ));
    }
    Ok(lint)
}

/// Reads the material library `name` that line `line` of the OBJ at `obj` names (relative to
/// the OBJ's directory, as tobj resolves it), or says in a warning why not: the file cannot
/// be read, or a line of it is malformed. tobj 4.0.5's `parse_float3` unwraps a `Ka`, `Kd`,
/// `Ks` or `Ke` of fewer than three numbers (a panic); one number is taken as a grey, as
/// [`read_material`] does for an unknown `Ke`, and none or two is said as malformed.
fn load_mtl(obj: &Path, line: Option<usize>, name: &Path) -> Result<tobj::MTLLoadResult, String> {
    let file = obj.parent().map_or(name.to_owned(), |p| p.join(name));
    let shown = shown_absolute(&file);
    let named = match line {
        Some(line) => format!("{}:{line}", obj.display()),
        None => obj.display().to_string(),
    };
    let fallback = "its materials are the default grey (0.8)";
    let bytes = std::fs::read(&file).map_err(|e| {
        format!(
            "{named}: material library {:?} cannot be read ({}: {e}); {fallback}",
            name.display().to_string(),
            shown.display()
        )
    })?;
    let malformed = |n: usize, col: Option<usize>, message: String| {
        let at = TextPos {
            line: n,
            column: col,
        };
        format!(
            "{}:{at}: {message} (material library named on {named}); {fallback}",
            shown.display()
        )
    };
    let mut text = String::with_capacity(bytes.len());
    for (n, raw) in lines(&bytes) {
        let Ok(line) = std::str::from_utf8(raw) else {
            return Err(malformed(n, None, "not UTF-8 text".into()));
        };
        let words = words(line);
        match words.as_slice() {
            [(_, key @ ("Ka" | "Kd" | "Ks" | "Ke")), rest @ ..] => {
                if let Some((col, w)) = rest.iter().take(3).find(|(_, w)| w.parse::<f32>().is_err())
                {
                    return Err(malformed(
                        n,
                        Some(*col),
                        format!("{key} \"{w}\" is not a number"),
                    ));
                }
                match rest {
                    [(_, x)] => text.push_str(&format!("{key} {x} {x} {x}")),
                    [_, _, _, ..] => text.push_str(line),
                    _ => {
                        let end = line.trim_end().chars().count() + 1;
                        return Err(malformed(
                            n,
                            Some(end),
                            format!(
                                "{key} has {} numbers; it needs 3 (r g b) or 1 (a grey)",
                                rest.len()
                            ),
                        ));
                    }
                }
            }
            _ => text.push_str(line),
        }
        text.push('\n');
    }
    match tobj::load_mtl_buf(&mut text.as_bytes()) {
        Ok(loaded) => Ok(Ok(loaded)),
        Err(e) => {
            // The first line at which tobj fails: it reads line by line, so a prefix of
            // the file fails once it holds the bad line.
            let all: Vec<&str> = text.lines().collect();
            let (mut good, mut bad) = (0, all.len());
            while bad - good > 1 {
                let mid = (good + bad) / 2;
                let prefix = all[..mid].join("\n");
                if tobj::load_mtl_buf(&mut prefix.as_bytes()).is_ok() {
                    good = mid;
                } else {
                    bad = mid;
                }
            }
            Err(malformed(
                bad.max(1),
                None,
                format!("{e}: {:?}", all.get(bad.max(1) - 1).unwrap_or(&"")),
            ))
        }
    }
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
    if let Some(name) = &m.diffuse_texture {
        notes.files_read.push(dir.join(name));
    }
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
    let img = image::open(&file)
        .map_err(|e| fail(format!("{}: {e}", shown_absolute(&file).display())))?;
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
                "6:3: texture coordinate index -3 names no texture coordinate (the file has 1, 1 before this line)",
            ),
            (
                "f 1//1 2//1 3//9223372036854775807",
                "6:13: normal index 9223372036854775807 names no normal (the file has 1, 1 before this line)",
            ),
            (
                "f 1 2 4",
                "6:7: vertex index 4 names no vertex (the file has 3, 3 before this line)",
            ),
        ] {
            std::fs::write(&path, format!("{head}{face}\n")).unwrap();
            let e = Scene::load(&path).expect_err("an index naming no element is an error");
            assert_eq!(e.to_string(), format!("{}:{message}", path.display()));
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
