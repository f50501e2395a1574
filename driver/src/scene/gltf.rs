//! glTF 2.0 through the `gltf` crate.
use std::sync::Arc;

use super::roles::{default_role, extras_role};
use super::texture::{self, BaseColorTexture, TextureOptions};
use super::*;

pub(super) fn load(
    path: &Path,
    textures: TextureOptions,
    notes: &mut LoadNotes,
) -> Result<Scene, SceneError> {
    let (doc, buffers) = import(path)?;
    notes.files_read.extend(files_named(path, &doc));
    let materials = read_materials(path, &doc, &buffers, textures, notes)?;
    let default_material = materials.len() as u32;
    let mut materials = materials;
    materials.push(Material::default_grey());

    let material_roles = material_roles(path, &doc)?;
    let mut b = SceneBuilder::new(path);
    let mut lights = Vec::new();
    for (node, world) in nodes_in_load_order(&doc) {
        if let Some(mesh) = node.mesh() {
            let roles = PrimitiveRoles::of(&b, &node, &mesh, &material_roles)?;
            read_mesh(
                &mut b,
                &node,
                &mesh,
                &buffers,
                world,
                default_material,
                &roles,
            )?;
        }
        if let Some(light) = node.light() {
            lights.push(read_light(&light, world));
        }
    }
    Ok(b.finish(materials, lights))
}

/// The files the document's buffers and images name by a relative URI, as resolved beside it.
fn files_named(path: &Path, doc: &::gltf::Document) -> Vec<PathBuf> {
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = doc.buffers().filter_map(|b| match b.source() {
        ::gltf::buffer::Source::Uri(uri) => Some(uri),
        ::gltf::buffer::Source::Bin => None,
    });
    let images = doc.images().filter_map(|i| match i.source() {
        ::gltf::image::Source::Uri { uri, .. } => Some(uri),
        ::gltf::image::Source::View { .. } => None,
    });
    buffers
        .chain(images)
        .filter(|uri| !uri.contains(':'))
        .filter_map(|uri| urlencoding::decode(uri).ok().map(|u| base.join(&*u)))
        .collect()
}

/// The nodes of the document's scene (the default one, else the first) with their world
/// transforms, in the order the loader reads them: depth first, children in order. Mesh
/// instances become [`Scene::meshes`] in this order, which the glTF writer relies on.
pub(super) fn nodes_in_load_order(doc: &::gltf::Document) -> Vec<(::gltf::Node<'_>, Mat4)> {
    let roots: Vec<::gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => Vec::new(),
    };
    let mut stack: Vec<(::gltf::Node, Mat4)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Mat4::IDENTITY))
        .collect();
    let mut order = Vec::new();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        for child in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((child, world));
        }
        order.push((node, world));
    }
    order
}

/// `::gltf::import` with checks of ours where the crate panics instead of erring (each
/// found by the `scene` fuzz target): the GLB header's length ([`check_glb_length`]),
/// before the crate's validation that every `POSITION` names an existing accessor
/// (gltf-json 1.4.1 indexes it unchecked in `mesh.rs`, `primitive_validate_hook`;
/// [`check_position_accessors`]) and that every image has a source
/// ([`check_image_sources`]), and every buffer's and image's URI ([`check_uri`]) and
/// image's buffer view ([`check_view`]). Buffers are loaded one by one, so an error names
/// the one at fault; images are not loaded here but one at a time by [`load_image`], so the
/// loader never holds more than one image at full size.
pub(super) fn import(
    path: &Path,
) -> Result<(::gltf::Document, Vec<::gltf::buffer::Data>), SceneError> {
    let whole = |error| SceneError::Gltf {
        path: path.to_owned(),
        error,
    };
    let bytes = std::fs::read(path).map_err(|error| SceneError::Io {
        path: path.to_owned(),
        error,
    })?;
    // A .glb named .gltf (or the other way round) loads: the crate reads either by its
    // first bytes. Anything else is said as what it looks like.
    if let Some(kind) =
        looks_like(&bytes).filter(|k| !matches!(*k, "a binary glTF (.glb)" | "glTF JSON (.gltf)"))
    {
        return Err(SceneError::NotAScene {
            path: path.to_owned(),
            message: format!("looks like {kind}, not a glTF file (.gltf JSON or .glb)"),
        });
    }
    check_glb_length(&bytes).map_err(whole)?;
    let ::gltf::Gltf { document, mut blob } = ::gltf::Gltf::from_slice_without_validation(&bytes)
        .map_err(|e| json_error(path, &bytes, e))?;
    let json = document.into_json();
    check_position_accessors(&json).map_err(whole)?;
    check_image_sources(&json).map_err(whole)?;
    let doc = ::gltf::Document::from_json(json).map_err(whole)?;
    let base = path.parent().unwrap_or_else(|| Path::new("./"));
    let resource = |item: String, message: String| SceneError::GltfResource {
        path: path.to_owned(),
        item,
        message,
    };

    let mut buffers = Vec::with_capacity(doc.buffers().len());
    for buffer in doc.buffers() {
        let item = format!("buffers[{}]", buffer.index());
        let source = buffer.source();
        if let ::gltf::buffer::Source::Uri(uri) = source {
            check_uri(uri).map_err(|m| resource(item.clone(), m))?;
        }
        let data =
            ::gltf::buffer::Data::from_source_and_blob(source.clone(), Some(base), &mut blob)
                .map_err(|e| resource(item.clone(), describe_at(&e, &source, base)))?;
        if data.len() < buffer.length() {
            let message = format!(
                "{} bytes, fewer than its byteLength of {}",
                data.len(),
                buffer.length()
            );
            return Err(resource(item, message));
        }
        buffers.push(data);
    }
    Ok((doc, buffers))
}

/// Image `index` of the glTF at `path` (imported by [`import`]), decoded at full size:
/// `Ok(Err(message))` when it cannot be read or decoded (a missing file: the material falls
/// back to its factor, [`read_materials`]), `Err` naming it when the document itself is at
/// fault — its URI or buffer view checked first ([`check_uri`], [`check_view`]).
fn load_image(
    path: &Path,
    doc: &::gltf::Document,
    buffers: &[::gltf::buffer::Data],
    index: usize,
) -> Result<Result<::gltf::image::Data, String>, SceneError> {
    let item = format!("images[{index}]");
    let resource = |message: String| SceneError::GltfResource {
        path: path.to_owned(),
        item: item.clone(),
        message,
    };
    let image = doc
        .images()
        .nth(index)
        .ok_or_else(|| resource("no such image".into()))?;
    let source = image.source();
    match &source {
        ::gltf::image::Source::Uri { uri, .. } => check_uri(uri).map_err(resource)?,
        ::gltf::image::Source::View { view, .. } => check_view(view, buffers).map_err(resource)?,
    }
    let base = path.parent().unwrap_or_else(|| Path::new("./"));
    let uri = match &source {
        ::gltf::image::Source::Uri { uri, .. } => Some(*uri),
        ::gltf::image::Source::View { .. } => None,
    };
    Ok(
        ::gltf::image::Data::from_source(source, Some(base), buffers).map_err(|e| match uri {
            Some(uri) => describe_uri(&e, uri, base),
            None => describe(&e),
        }),
    )
}

/// The importer's error for a buffer, naming the file a relative URI resolves to.
fn describe_at(e: &::gltf::Error, source: &::gltf::buffer::Source, base: &Path) -> String {
    match source {
        ::gltf::buffer::Source::Uri(uri) => describe_uri(e, uri, base),
        ::gltf::buffer::Source::Bin => describe(e),
    }
}

/// [`describe`], an unreadable file said with its URI and the path it resolves to.
fn describe_uri(e: &::gltf::Error, uri: &str, base: &Path) -> String {
    let file = if let Some(rest) = uri.strip_prefix("file://") {
        Some(PathBuf::from(rest))
    } else if uri.contains(':') {
        None
    } else {
        urlencoding::decode(uri).ok().map(|u| base.join(&*u))
    };
    match (e, file) {
        (::gltf::Error::Io(io), Some(file)) => format!(
            "cannot read {uri:?} ({}): {io}",
            shown_absolute(&file).display()
        ),
        _ => describe(e),
    }
}

/// The importer's error for the document itself; a JSON syntax or data error of a `.gltf`
/// placed at its line and column (a GLB's JSON chunk: said as the chunk's).
fn json_error(path: &Path, bytes: &[u8], e: ::gltf::Error) -> SceneError {
    let ::gltf::Error::Deserialize(json) = &e else {
        return SceneError::Gltf {
            path: path.to_owned(),
            error: e,
        };
    };
    // serde_json's text ends in " at line L column C"; the place goes in front instead.
    let text = json.to_string();
    let message = match text.rfind(" at line ") {
        Some(i) if json.line() > 0 => text[..i].to_owned(),
        _ => text,
    };
    let at = TextPos {
        line: json.line(),
        column: Some(json.column()),
    };
    if bytes.starts_with(b"glTF") {
        return SceneError::NotAScene {
            path: path.to_owned(),
            message: format!(
                "its JSON chunk is not valid glTF JSON (at line {at} of the chunk): {message}"
            ),
        };
    }
    SceneError::Syntax {
        path: path.to_owned(),
        at,
        message: format!("not valid glTF JSON: {message}"),
    }
}

/// A URI the importer can resolve without panicking: gltf 1.4.1 (`import.rs`,
/// `Scheme::parse`) takes a URI without a `:` as a relative path and unwraps its
/// percent-decoding as UTF-8, so `%AC` panicked (found by the `scene` fuzz target, on a
/// buffer URI `data+application/octet-stream;base64,…%AC…`). `urlencoding` is the crate
/// the importer decodes with, so this check refuses exactly what it would panic on.
fn check_uri(uri: &str) -> Result<(), String> {
    if uri.contains(':') || urlencoding::decode(uri).is_ok() {
        return Ok(());
    }
    const SHOWN: usize = 48;
    let shown: String = uri.chars().take(SHOWN).collect();
    let more = if uri.chars().nth(SHOWN).is_some() {
        "…"
    } else {
        ""
    };
    Err(format!(
        "uri \"{shown}{more}\" is a relative path (no scheme) whose percent-escapes \
         decode to bytes that are not UTF-8"
    ))
}

/// An image's buffer view lies inside its buffer: gltf 1.4.1 slices the buffer with the
/// view's range unchecked (`import.rs`, `image::Data::from_source`) and gltf-json does not
/// validate it (found while fixing [`check_uri`]).
fn check_view(view: &::gltf::buffer::View, buffers: &[::gltf::buffer::Data]) -> Result<(), String> {
    let buffer = view.buffer().index();
    let len = buffers[buffer].len();
    let (offset, length) = (view.offset(), view.length());
    if offset.checked_add(length).is_some_and(|end| end <= len) {
        return Ok(());
    }
    Err(format!(
        "bufferViews[{}] (byteOffset {offset}, byteLength {length}) runs past the end of \
         buffers[{buffer}] ({len} bytes)",
        view.index()
    ))
}

/// The importer's error for one buffer or image, said in the loader's words.
fn describe(e: &::gltf::Error) -> String {
    match e {
        ::gltf::Error::Base64(e) => format!("its data URI is not valid base64: {e}"),
        ::gltf::Error::Io(e) => format!("cannot read the file its uri names: {e}"),
        ::gltf::Error::UnsupportedScheme => {
            "unsupported uri scheme (data:, file: or a relative path)".to_owned()
        }
        other => other.to_string(),
    }
}

/// A GLB header's total length covers at least the header: gltf 1.4.1 subtracts the
/// header's 12 bytes from it unchecked (`binary.rs`), which panics on overflow in a debug
/// build and wraps to a 4 GiB read in a release one (found by the `scene` fuzz target).
fn check_glb_length(bytes: &[u8]) -> ::gltf::Result<()> {
    const HEADER: usize = 12;
    match bytes.get(8..HEADER) {
        Some(length) if bytes.starts_with(b"glTF") => {
            let length = u32::from_le_bytes(length.try_into().expect("4 bytes"));
            if (length as usize) < HEADER {
                return Err(::gltf::Error::Binary(::gltf::binary::Error::Length {
                    length,
                    length_read: bytes.len(),
                }));
            }
            Ok(())
        }
        _ => Ok(()),
    }
}

/// Every image has a source the importer can take: a `uri`, or a `bufferView` with a
/// `mimeType` (the spec's rule). gltf 1.4.1's `Image::source` unwraps both, unvalidated
/// (`image.rs`; found by the `scene` fuzz target once images were loaded one by one).
fn check_image_sources(json: &::gltf::json::Root) -> ::gltf::Result<()> {
    use ::gltf::json::{Path as JsonPath, validation::Error};
    let errors: Vec<_> = json
        .images
        .iter()
        .enumerate()
        .filter_map(|(i, image)| {
            let missing = match (&image.buffer_view, &image.mime_type, &image.uri) {
                (Some(_), None, _) => "mimeType",
                (None, _, None) => "uri",
                _ => return None,
            };
            let at = JsonPath::new().field("images").index(i).field(missing);
            Some((at, Error::Missing))
        })
        .collect();
    if errors.is_empty() {
        Ok(())
    } else {
        Err(::gltf::Error::Validation(errors))
    }
}

/// Every primitive's `POSITION` names an accessor that exists.
fn check_position_accessors(json: &::gltf::json::Root) -> ::gltf::Result<()> {
    use ::gltf::json::validation::Error;
    use ::gltf::json::{Path as JsonPath, mesh::Semantic, validation::Checked};
    let mut errors = Vec::new();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let position = prim.attributes.get(&Checked::Valid(Semantic::Positions));
            if position.is_some_and(|a| a.value() >= json.accessors.len()) {
                let at = JsonPath::new()
                    .field("meshes")
                    .index(m)
                    .field("primitives")
                    .index(p)
                    .field("attributes")
                    .key("POSITION");
                errors.push((at, Error::IndexOutOfBounds));
            }
        }
    }
    if errors.is_empty() {
        Ok(())
    } else {
        Err(::gltf::Error::Validation(errors))
    }
}

/// The materials, their base-colour textures decoded once per image (as
/// [`texture::Image`]s, capped as `options` says) and shared. Images are decoded one at a
/// time and capped at once, so the peak while loading is one image at full size beside the
/// capped ones; an image no material uses is decoded too (one at a time, then dropped), so
/// a broken one is still noted. An image that cannot be read or decoded is noted in `notes`
/// and its material falls back to its `baseColorFactor`, or [`MISSING_TEXTURE_ALBEDO`]
/// grey where the factor is glTF's default white (module docs of [`super`]).
fn read_materials(
    path: &Path,
    doc: &::gltf::Document,
    buffers: &[::gltf::buffer::Data],
    options: TextureOptions,
    notes: &mut LoadNotes,
) -> Result<Vec<Material>, SceneError> {
    /// An image decoded, or why not (its name, the message).
    type Decoded = Result<Arc<texture::Image>, (String, String)>;
    let mut decoded: Vec<Option<Decoded>> = vec![None; doc.images().len()];
    let mut image = |t: ::gltf::Texture| -> Result<Decoded, SceneError> {
        let index = t.source().index();
        if let Some(done) = &decoded[index] {
            return Ok(done.clone());
        }
        let item = format!("images[{index}]");
        let source = match t.source().source() {
            ::gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => {
                format!("{item} ({uri})")
            }
            _ => item.clone(),
        };
        let result = load_image(path, doc, buffers, index)?
            .and_then(|full| decode_image(&full, source.clone(), options))
            .map(Arc::new)
            .map_err(|message| (source, message));
        decoded[index] = Some(result.clone());
        Ok(result)
    };
    let mut materials = Vec::with_capacity(doc.materials().len());
    for (i, m) in doc.materials().enumerate() {
        let name = m
            .name()
            .map_or_else(|| format!("material#{i}"), str::to_owned);
        let pbr = m.pbr_metallic_roughness();
        let f = pbr.base_color_factor();
        let factor = Vec3::new(f[0], f[1], f[2]).clamp(Vec3::ZERO, Vec3::ONE);
        let mut albedo = factor;
        let base_color_texture = match pbr.base_color_texture() {
            Some(info) => {
                let sampler = info.texture().sampler();
                match image(info.texture())? {
                    Ok(image) => {
                        albedo = factor * image.average();
                        Some(BaseColorTexture {
                            image,
                            wrap: [sampler.wrap_s(), sampler.wrap_t()].map(wrap),
                            factor,
                        })
                    }
                    Err((file, message)) => {
                        if factor == Vec3::ONE {
                            albedo = Vec3::splat(MISSING_TEXTURE_ALBEDO);
                        }
                        notes.missing_textures.push(MissingTexture {
                            material: name.clone(),
                            file,
                            message,
                            fallback: albedo.to_array(),
                        });
                        None
                    }
                }
            }
            None => None,
        };
        // An emissive texture is averaged: emitters are sampled as lights of uniform
        // radiance (transport::emitters). One that cannot be read leaves the factor.
        let mut e = Vec3::from(m.emissive_factor());
        if let Some(info) = m.emissive_texture() {
            match image(info.texture())? {
                Ok(image) => e *= image.average(),
                Err((file, message)) => notes.missing_textures.push(MissingTexture {
                    material: name.clone(),
                    file,
                    message: format!("{message} (emissive; the emissive factor is kept)"),
                    fallback: albedo.to_array(),
                }),
            }
        }
        let strength = m.emissive_strength().unwrap_or(1.0);
        materials.push(Material {
            name,
            albedo: albedo.clamp(Vec3::ZERO, Vec3::ONE),
            emission: (e * strength).max(Vec3::ZERO),
            base_color_texture,
        });
    }
    for (index, done) in decoded.iter().enumerate() {
        if done.is_none()
            && let Err(message) = load_image(path, doc, buffers, index)?
        {
            notes.missing_textures.push(MissingTexture {
                material: String::new(),
                file: format!("images[{index}]"),
                message,
                fallback: [0.0; 3],
            });
        }
    }
    Ok(materials)
}

/// A glTF sampler's wrap mode.
fn wrap(mode: ::gltf::texture::WrappingMode) -> texture::Wrap {
    use ::gltf::texture::WrappingMode as M;
    match mode {
        M::Repeat => texture::Wrap::Repeat,
        M::ClampToEdge => texture::Wrap::ClampToEdge,
        M::MirroredRepeat => texture::Wrap::MirroredRepeat,
    }
}

/// An imported image as the baker keeps it. Colour textures are sRGB-encoded whatever their
/// depth (glTF 2.0, 3.9.2): 8- and 16-bit texels are decoded as sRGB; float texels (which
/// glTF does not list, but the importer produces from other formats) are taken as linear.
fn decode_image(
    img: &::gltf::image::Data,
    source: String,
    options: TextureOptions,
) -> Result<texture::Image, String> {
    use ::gltf::image::Format as F;
    let (w, h) = (img.width, img.height);
    let eight =
        |channels| texture::Image::from_srgb8(source.clone(), w, h, channels, &img.pixels, options);
    let wide = |channels: usize, bytes: usize, value: &dyn Fn(&[u8]) -> f32| {
        let count = w as usize * h as usize;
        if count == 0 || img.pixels.len() != count * channels * bytes {
            return Err(format!(
                "{w}×{h} texels of {channels} channels do not match its {} bytes",
                img.pixels.len()
            ));
        }
        let stride = channels * bytes;
        let linear = |i: usize| {
            let px = &img.pixels[i * stride..(i + 1) * stride];
            let c = |k: usize| value(&px[k * bytes..(k + 1) * bytes]);
            if channels < 3 {
                Vec3::splat(c(0))
            } else {
                Vec3::new(c(0), c(1), c(2))
            }
        };
        Ok(texture::Image::from_linear_fn(
            source.clone(),
            w,
            h,
            linear,
            options,
        ))
    };
    let srgb16 =
        |b: &[u8]| texture::srgb_to_linear(f32::from(u16::from_ne_bytes([b[0], b[1]])) / 65535.0);
    let float = |b: &[u8]| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
    match img.format {
        F::R8 => eight(1),
        F::R8G8 => eight(2),
        F::R8G8B8 => eight(3),
        F::R8G8B8A8 => eight(4),
        F::R16 => wide(1, 2, &srgb16),
        F::R16G16 => wide(2, 2, &srgb16),
        F::R16G16B16 => wide(3, 2, &srgb16),
        F::R16G16B16A16 => wide(4, 2, &srgb16),
        F::R32G32B32FLOAT => wide(3, 4, &float),
        F::R32G32B32A32FLOAT => wide(4, 4, &float),
    }
}

/// The `gltf` crate's readers assert an accessor's layout (a VEC4 `TEXCOORD_1` panics,
/// found by the scene fuzz target): check what the glTF spec allows first.
fn check_accessors(b: &SceneBuilder, id: u32, prim: &::gltf::Primitive) -> Result<(), SceneError> {
    use ::gltf::Semantic;
    use ::gltf::accessor::{DataType as T, Dimensions as D};
    let fits = |a: &::gltf::Accessor, dims: D, types: &[T]| {
        a.dimensions() == dims && types.contains(&a.data_type())
    };
    let describe = |what: String, a: &::gltf::Accessor| {
        format!(
            "{what} accessor {} is {:?} of {:?}, which the glTF spec does not allow",
            a.index(),
            a.dimensions(),
            a.data_type()
        )
    };
    let attributes = prim.attributes().map(|(semantic, a)| {
        let allowed = match semantic {
            Semantic::Positions | Semantic::Normals => fits(&a, D::Vec3, &[T::F32]),
            Semantic::TexCoords(_) => fits(&a, D::Vec2, &[T::F32, T::U8, T::U16]),
            Semantic::Colors(_) => {
                let types = &[T::F32, T::U8, T::U16];
                fits(&a, D::Vec3, types) || fits(&a, D::Vec4, types)
            }
            _ => true,
        };
        (format!("{semantic:?}"), a, allowed)
    });
    let indices = prim.indices().map(|a| {
        let allowed = fits(&a, D::Scalar, &[T::U8, T::U16, T::U32]);
        ("indices".to_owned(), a, allowed)
    });
    for (what, a, allowed) in attributes.chain(indices) {
        if !allowed {
            return Err(b.bad_mesh(id, describe(what, &a)));
        }
        // The readers compute `count - 1` unchecked (gltf 1.4.1, `accessor/util.rs`; a
        // subtraction overflow found by the `scene` fuzz target): the spec's minimum is 1.
        if a.count() == 0 || a.sparse().is_some_and(|s| s.count() == 0) {
            let message = format!(
                "{what} accessor {} has a count of 0 (the glTF spec's minimum is 1)",
                a.index()
            );
            return Err(b.bad_mesh(id, message));
        }
    }
    Ok(())
}

fn read_light(light: &::gltf::khr_lights_punctual::Light, world: Mat4) -> SceneLight {
    use ::gltf::khr_lights_punctual::Kind;
    let colour = Vec3::from(light.color()) * light.intensity();
    let position = world.transform_point3(Vec3::ZERO);
    let direction = world.transform_vector3(-Vec3::Z).normalize_or(-Vec3::Z);
    match light.kind() {
        Kind::Directional => SceneLight::Directional {
            direction,
            irradiance: colour,
        },
        Kind::Point => SceneLight::Point {
            position,
            intensity: colour,
        },
        Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => SceneLight::Spot {
            position,
            direction,
            intensity: colour,
            inner_cone: inner_cone_angle,
            outer_cone: outer_cone_angle,
        },
    }
}

/// A role the file declares (`extras`) or a name asks for, per material: (declared, by name).
type MaterialRole = (Option<Role>, Option<Role>);

/// Every material's [`MaterialRole`]: its `extras`, and its name's and base-colour image's
/// words (`roles::default_role`).
fn material_roles(path: &Path, doc: &::gltf::Document) -> Result<Vec<MaterialRole>, SceneError> {
    doc.materials()
        .enumerate()
        .map(|(i, m)| {
            let name = m
                .name()
                .map_or_else(|| format!("material#{i}"), str::to_owned);
            let declared =
                extras_role(m.extras().as_ref().map(|r| r.get())).map_err(|message| {
                    SceneError::GltfResource {
                        path: path.to_owned(),
                        item: format!("materials[{i}] '{name}'"),
                        message,
                    }
                })?;
            let image = m
                .pbr_metallic_roughness()
                .base_color_texture()
                .map(|info| image_name(&info.texture().source()))
                .unwrap_or_default();
            Ok((declared, default_role([name.as_str(), image.as_str()])))
        })
        .collect()
}

/// An image's URI, else its name.
fn image_name(image: &::gltf::Image) -> String {
    match image.source() {
        ::gltf::image::Source::Uri { uri, .. } => uri.to_owned(),
        ::gltf::image::Source::View { .. } => image.name().unwrap_or_default().to_owned(),
    }
}

/// The roles of one node's primitives: what the node or mesh declares in `extras` wins over
/// what the material declares, which wins over what the node's, mesh's or material's names
/// ask for.
struct PrimitiveRoles<'a> {
    declared: Option<Role>,
    by_name: Option<Role>,
    materials: &'a [MaterialRole],
}

impl<'a> PrimitiveRoles<'a> {
    fn of(
        b: &SceneBuilder,
        node: &::gltf::Node,
        mesh: &::gltf::Mesh,
        materials: &'a [MaterialRole],
    ) -> Result<Self, SceneError> {
        let named = node.name().or(mesh.name()).unwrap_or_default();
        let declared = |extras: &::gltf::json::Extras, what: String| {
            extras_role(extras.as_ref().map(|r| r.get())).map_err(|message| {
                SceneError::GltfResource {
                    path: b.path.clone(),
                    item: what,
                    message,
                }
            })
        };
        let declared = declared(node.extras(), format!("nodes[{}] '{named}'", node.index()))?.or(
            declared(mesh.extras(), format!("meshes[{}] '{named}'", mesh.index()))?,
        );
        let names = [node.name().unwrap_or(""), mesh.name().unwrap_or("")];
        Ok(Self {
            declared,
            by_name: default_role(names),
            materials,
        })
    }

    /// The role of a primitive of `material` (an index into the document's materials, or
    /// none).
    fn of_material(&self, material: Option<usize>) -> Role {
        let (m_declared, m_named) = material
            .and_then(|m| self.materials.get(m).copied())
            .unwrap_or((None, None));
        self.declared
            .or(m_declared)
            .or(self.by_name)
            .or(m_named)
            .unwrap_or_default()
    }
}

#[allow(clippy::too_many_arguments)]
fn read_mesh(
    b: &mut SceneBuilder,
    node: &::gltf::Node,
    mesh: &::gltf::Mesh,
    buffers: &[::gltf::buffer::Data],
    world: Mat4,
    default_material: u32,
    roles: &PrimitiveRoles,
) -> Result<(), SceneError> {
    let name = node
        .name()
        .or(mesh.name())
        .map_or_else(|| format!("mesh#{}", mesh.index()), str::to_owned);
    let id = b.begin_mesh(name);
    let normal_m = Mat3::from_mat4(world).inverse().transpose();
    let mirrored = Mat3::from_mat4(world).determinant() < 0.0;
    for prim in mesh.primitives() {
        if prim.mode() != ::gltf::mesh::Mode::Triangles {
            return Err(b.bad_mesh(
                id,
                format!(
                    "primitive mode {:?} (only triangles are supported)",
                    prim.mode()
                ),
            ));
        }
        check_accessors(b, id, &prim)?;
        b.set_role(roles.of_material(prim.material().index()));
        let reader = prim.reader(|buf| buffers.get(buf.index()).map(|d| d.0.as_slice()));
        let Some(positions) = reader.read_positions() else {
            return Err(b.bad_mesh(id, "primitive without POSITION".into()));
        };
        let positions: Vec<Vec3> = positions
            .map(|p| world.transform_point3(Vec3::from(p)))
            .collect();
        let normals: Option<Vec<Vec3>> = reader
            .read_normals()
            .map(|n| n.map(|n| normal_m * Vec3::from(n)).collect());
        let uvs: Option<Vec<Vec2>> = reader
            .read_tex_coords(1)
            .map(|t| t.into_f32().map(Vec2::from).collect());
        // The texture's UV set, read only when the material has a base-colour texture.
        let texture_set = prim
            .material()
            .pbr_metallic_roughness()
            .base_color_texture()
            .map(|info| info.tex_coord());
        let texture_uvs: Option<Vec<Vec2>> = texture_set
            .and_then(|set| reader.read_tex_coords(set))
            .map(|t| t.into_f32().map(Vec2::from).collect());
        let colours: Option<Vec<Vec3>> = reader
            .read_colors(0)
            .map(|c| c.into_rgb_f32().map(Vec3::from).collect());
        let count = positions.len();
        check_len(b, id, "NORMAL", normals.as_ref().map(Vec::len), count)?;
        check_len(b, id, "TEXCOORD_1", uvs.as_ref().map(Vec::len), count)?;
        let texture_uv_name = format!("TEXCOORD_{}", texture_set.unwrap_or(0));
        check_len(
            b,
            id,
            &texture_uv_name,
            texture_uvs.as_ref().map(Vec::len),
            count,
        )?;
        check_len(b, id, "COLOR_0", colours.as_ref().map(Vec::len), count)?;
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..count as u32).collect(),
        };
        if !indices.len().is_multiple_of(3) {
            return Err(b.bad_mesh(
                id,
                format!("{} indices is not a multiple of 3", indices.len()),
            ));
        }
        if let Some((k, &bad)) = indices
            .iter()
            .enumerate()
            .find(|&(_, &i)| i as usize >= count)
        {
            return Err(b.bad_mesh(id, format!("index {bad} at position {k} is out of range (the primitive has {count} vertices)")));
        }
        let material = prim
            .material()
            .index()
            .map_or(default_material, |m| m as u32);
        for tri in indices.chunks_exact(3) {
            let mut v = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
            if mirrored {
                v.swap(1, 2);
            }
            b.push(Triangle {
                positions: v.map(|i| positions[i]),
                normals: normals
                    .as_ref()
                    .map_or([Vec3::ZERO; 3], |n| v.map(|i| n[i])),
                lightmap_uv: uvs.as_ref().map(|u| v.map(|i| u[i])),
                texture_uv: texture_uvs.as_ref().map(|u| v.map(|i| u[i])),
                colour: colours.as_ref().map(|c| v.map(|i| c[i])),
                mesh: id,
                material,
            });
        }
    }
    Ok(())
}

fn check_len(
    b: &SceneBuilder,
    id: u32,
    what: &str,
    len: Option<usize>,
    count: usize,
) -> Result<(), SceneError> {
    match len {
        Some(n) if n != count => Err(b.bad_mesh(
            id,
            format!("{what} has {n} entries but POSITION has {count}"),
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::super::*;
    use std::path::PathBuf;

    #[test]
    fn veach_ajar_loads_all_triangles_with_lightmap_uvs() {
        let Some(dir) = crate::test_support::shared_scenes_dir() else {
            return;
        };
        let s = Scene::load(&dir.join("converted/bitterli_veach_ajar_no_teapots.glb")).unwrap();
        assert_eq!(s.triangles.len() + s.degenerate_triangles, 4546);
        assert!(s.meshes_without_lightmap_uvs().is_empty());
        assert!(
            s.triangles
                .iter()
                .all(|t| t.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-5))
        );
        // Two emissive meshes with radiance 1000 (scenes/README.md).
        let emissive: Vec<_> = s
            .materials
            .iter()
            .filter(|m| m.emission != Vec3::ZERO)
            .collect();
        assert!(!emissive.is_empty());
        assert!(
            emissive
                .iter()
                .all(|m| (m.emission.max_element() - 1000.0).abs() < 1e-2)
        );
        assert_eq!(s.triangle_positions().len(), s.triangles.len());
        // The conversion averaged the original's textures: none, and no texture UVs.
        assert_eq!(s.texture_bytes(), 0);
        assert!(s.triangles.iter().all(|t| t.texture_uv.is_none()));
    }

    #[test]
    fn bitterli_cornell_box_matches_its_sidecar() {
        let Some(dir) = crate::test_support::shared_scenes_dir() else {
            return;
        };
        let s = Scene::load(&dir.join("converted/bitterli_cornell_box.glb")).unwrap();
        assert_eq!(s.triangles.len(), 36);
        let names: Vec<_> = s.meshes.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["Light", "LeftWall", "RightWall", "Mesh"]);
        let light = s.triangle_material(0);
        assert!(
            (light.emission - Vec3::new(17.0, 12.0, 4.0))
                .abs()
                .max_element()
                < 1e-3
        );
        assert!(
            (s.triangle_material(2).albedo - Vec3::new(0.63, 0.065, 0.05))
                .abs()
                .max_element()
                < 1e-6
        );
        let (lo, hi) = s.bounds();
        assert!(lo.cmpge(Vec3::splat(-1.01)).all() && hi.cmple(Vec3::splat(2.01)).all());
    }

    #[test]
    fn vinc3r_node_transforms_and_missing_lightmap_uvs() {
        let Some(dir) = crate::test_support::shared_scenes_dir() else {
            return;
        };
        let p = dir
            .join("vinc3r_cornellbox/BJS-2.80-Eevee-gltf/assets/cornellBox-2.80-Eevee-gltf.gltf");
        let s = Scene::load(&p).unwrap();
        assert_eq!(s.triangles.len() + s.degenerate_triangles, 4410);
        let with_uv = s
            .triangles
            .iter()
            .filter(|t| t.lightmap_uv.is_some())
            .count();
        // 8 primitives with TEXCOORD_1 hold 4052 triangles (scenes/README.md).
        assert!(
            with_uv <= 4052 && with_uv + s.degenerate_triangles >= 4052,
            "{with_uv}"
        );
        assert!(s.meshes_without_lightmap_uvs().contains(&"lamp.000"));
        // Bounds [-2,0,-2]..[2,3,2] (scenes/README.md) after node transforms.
        let (lo, hi) = s.bounds();
        assert!(
            (lo - Vec3::new(-2.0, 0.0, -2.0)).abs().max_element() < 0.05,
            "{lo}"
        );
        assert!(
            (hi - Vec3::new(2.0, 3.0, 2.0)).abs().max_element() < 0.05,
            "{hi}"
        );
        // lamp.000 is emissive (1,1,1); the checker texture multiplies the block's albedo.
        let lamp = s.meshes.iter().find(|m| m.name == "lamp.000").unwrap();
        assert_eq!(
            s.triangle_material(lamp.first_triangle as usize).emission,
            Vec3::ONE
        );
        // Two base-colour textures, sampled at TEXCOORD_0: the block's checkerBJS.png
        // (1024², RGBA) and the ground's checker-meter.png (256²), kept as 8-bit RGB.
        let sizes: Vec<_> = s
            .materials
            .iter()
            .filter_map(|m| m.base_color_texture.as_ref().map(|t| t.image.size()))
            .collect();
        assert_eq!(sizes, [(1024, 1024), (256, 256)]);
        assert_eq!(s.texture_bytes(), (1024 * 1024 + 256 * 256) * 3);
        let bloc = s.meshes.iter().find(|m| m.name == "bloc.000").unwrap();
        let first = bloc.first_triangle as usize;
        assert!(s.triangles[first].texture_uv.is_some());
        assert!(matches!(
            s.hit_albedo(first),
            super::super::texture::HitAlbedo::Varying(_)
        ));
        // Capped at 300: the 1024² image is box-filtered by 4 to 256², the 256² one kept.
        let capped = Scene::load_with(&p, TextureOptions { max_size: 300 }).unwrap();
        assert_eq!(capped.texture_bytes(), 2 * 256 * 256 * 3);
    }

    /// A glTF of one buffer (4 bytes long) and one image with these URIs, loaded.
    fn load_gltf_with_uris(buffer_uri: &str, image_uri: &str) -> (PathBuf, SceneError) {
        load_gltf_with(buffer_uri, 4, image_uri)
    }

    fn load_gltf_with(buffer_uri: &str, length: usize, image_uri: &str) -> (PathBuf, SceneError) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("uris.gltf");
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "buffers": [{ "byteLength": length, "uri": buffer_uri }],
            "images": [{ "uri": image_uri }],
        });
        std::fs::write(&path, json.to_string()).unwrap();
        let e = Scene::load(&path).expect_err("a bad URI is an error");
        (path, e)
    }

    #[test]
    fn uris_whose_percent_escapes_are_not_utf8_are_errors_naming_the_buffer() {
        // The `scene` fuzz target's input (fuzz/corpus/scene/gltf-import-non-utf8-data-uri):
        // "data+…" has no ':', so the importer reads it as a relative path and unwrapped its
        // percent-decoding, which `%AC` makes invalid UTF-8.
        let uri = "data+application/octet-stream;base64,AAAA%ACAP%wAA";
        let (path, e) = load_gltf_with_uris(uri, "ok.png");
        let message = e.to_string();
        assert!(
            matches!(&e, SceneError::GltfResource { item, .. } if item == "buffers[0]"),
            "{message}"
        );
        assert!(message.contains(&*path.to_string_lossy()), "{message}");
        assert!(
            message.contains("not UTF-8") && message.contains("%AC"),
            "{message}"
        );

        // The same URI on an image (the importer parses image URIs the same way).
        let data = "data:application/octet-stream;base64,AAAAAA==";
        let (_, e) = load_gltf_with_uris(data, "tex%FF.png");
        assert!(
            matches!(&e, SceneError::GltfResource { item, .. } if item == "images[0]"),
            "{e}"
        );
        // Escapes that decode to UTF-8 are a path like any other: a missing file.
        let (_, e) = load_gltf_with_uris("b%C3%A4r.bin", "ok.png");
        assert!(e.to_string().contains("buffers[0]: cannot read"), "{e}");
    }

    #[test]
    fn data_uris_that_are_not_base64_are_errors_naming_the_buffer() {
        let (path, e) = load_gltf_with_uris("data:application/octet-stream;base64,AA%AC", "x.png");
        let message = e.to_string();
        assert!(
            message.starts_with(&format!(
                "{}: buffers[0]: its data URI is not valid base64",
                path.display()
            )),
            "{message}"
        );
        // 3 bytes, padded to 4 by the importer: short of 8.
        let (_, e) = load_gltf_with("data:application/octet-stream;base64,AAAA", 8, "x.png");
        assert!(
            e.to_string()
                .contains("buffers[0]: 4 bytes, fewer than its byteLength of 8"),
            "{e}"
        );
    }

    #[test]
    fn an_image_whose_buffer_view_runs_past_its_buffer_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("view.gltf");
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "buffers": [{ "byteLength": 4, "uri": "data:application/octet-stream;base64,AAAAAA==" }],
            "bufferViews": [{ "buffer": 0, "byteOffset": 2, "byteLength": 100 }],
            "images": [{ "bufferView": 0, "mimeType": "image/png" }],
        });
        std::fs::write(&path, json.to_string()).unwrap();
        let e = Scene::load(&path).expect_err("a view past its buffer is an error");
        assert_eq!(
            e.to_string(),
            format!(
                "{}: images[0]: bufferViews[0] (byteOffset 2, byteLength 100) runs past the end \
                 of buffers[0] (4 bytes)",
                path.display()
            )
        );
    }

    #[test]
    fn images_without_a_source_are_errors_naming_the_image() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("image.gltf");
        for (image, missing) in [
            (serde_json::json!({ "name": "no source" }), "images[0].uri"),
            (serde_json::json!({ "bufferView": 0 }), "images[0].mimeType"),
        ] {
            let json = serde_json::json!({
                "asset": { "version": "2.0" },
                "buffers": [{ "byteLength": 4, "uri": "data:application/octet-stream;base64,AAAAAA==" }],
                "bufferViews": [{ "buffer": 0, "byteLength": 4 }],
                "images": [image],
            });
            std::fs::write(&path, json.to_string()).unwrap();
            let e = Scene::load(&path).expect_err("an image without a source is an error");
            let message = e.to_string();
            assert!(matches!(e, SceneError::Gltf { .. }), "{message}");
            assert!(
                message.contains(&*path.to_string_lossy()) && message.contains(missing),
                "{message}"
            );
        }
    }

    #[test]
    fn accessors_of_count_zero_are_errors_naming_the_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.gltf");
        let zeros = "A".repeat(64); // 48 zero bytes
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "scene": 0, "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
            "meshes": [{ "name": "tri", "primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1 }] }],
            "accessors": [
                { "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 0] },
                { "bufferView": 1, "componentType": 5125, "count": 0, "type": "SCALAR" },
            ],
            "bufferViews": [
                { "buffer": 0, "byteLength": 36 },
                { "buffer": 0, "byteOffset": 36, "byteLength": 12 },
            ],
            "buffers": [{ "byteLength": 48, "uri": format!("data:application/octet-stream;base64,{zeros}") }],
        });
        std::fs::write(&path, json.to_string()).unwrap();
        let e = Scene::load(&path).expect_err("an accessor of count 0 is an error");
        assert_eq!(
            e.to_string(),
            format!(
                "{}: mesh 'tri': indices accessor 1 has a count of 0 (the glTF spec's minimum is 1)",
                path.display()
            )
        );
    }

    /// Three nodes sharing one triangle mesh: one whose node `extras` declare `skip`, one
    /// named like a clip brush, one plain; two materials, one declaring `no-shadow` in its
    /// `extras`. `extras` win over names, and a role no one knows is an error naming the node.
    #[test]
    fn roles_come_from_extras_then_from_names() {
        let dir = tempfile::tempdir().unwrap();
        let floats: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
        std::fs::write(dir.path().join("tri.bin"), &bytes).unwrap();
        let gltf = |node_role: &str| {
            serde_json::json!({
                "asset": { "version": "2.0" },
                "scene": 0, "scenes": [{ "nodes": [0, 1, 2, 3] }],
                "nodes": [
                    { "name": "shell", "mesh": 0, "extras": { "guidebake_role": node_role } },
                    { "name": "PlayerClip_3", "mesh": 0 },
                    { "name": "wall", "mesh": 0 },
                    { "name": "leaves", "mesh": 1 },
                ],
                "meshes": [
                    { "primitives": [{ "attributes": { "POSITION": 0 }, "material": 0 }] },
                    { "primitives": [{ "attributes": { "POSITION": 0 }, "material": 1 }] },
                ],
                "materials": [
                    { "name": "stone" },
                    { "name": "foliage", "extras": { "guidebake_role": "no_shadow" } },
                ],
                "accessors": [{ "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0] }],
                "bufferViews": [{ "buffer": 0, "byteLength": 36 }],
                "buffers": [{ "byteLength": 36, "uri": "tri.bin" }],
            })
            .to_string()
        };
        let path = dir.path().join("roles.gltf");
        std::fs::write(&path, gltf("sky")).unwrap();
        let scene = Scene::load(&path).unwrap();
        let roles: Vec<Role> = (0..4).map(|t| scene.role(t)).collect();
        assert_eq!(roles, [Role::Sky, Role::Skip, Role::Baked, Role::NoShadow]);
        std::fs::write(&path, gltf("cloud")).unwrap();
        let e = Scene::load(&path).unwrap_err().to_string();
        assert!(
            e.contains("nodes[0] 'shell'") && e.contains("\"cloud\" is not a role"),
            "{e}"
        );
    }

    /// A one-triangle glTF beside a 2×2 PNG (`image` names it; `None`: no PNG is written):
    /// TEXCOORD_0 and TEXCOORD_1 (0,0), (1,0), (0,1); COLOR_0 (VEC4 float) white, half
    /// grey, white; the base-colour texture clamps along u and mirrors along v, factor
    /// (0.5, 1, 1).
    fn textured_triangle(dir: &Path, image: &str, write_png: bool) -> PathBuf {
        let floats: [f32; 9 + 6 + 6 + 12] = [
            0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, // POSITION
            0.0, 0.0, 1.0, 0.0, 0.0, 1.0, // TEXCOORD_0
            0.0, 0.0, 1.0, 0.0, 0.0, 1.0, // TEXCOORD_1
            1.0, 1.0, 1.0, 1.0, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, // COLOR_0
        ];
        let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
        std::fs::write(dir.join("tri.bin"), &bytes).unwrap();
        if write_png {
            let texels = [255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255];
            image::RgbImage::from_raw(2, 2, texels.to_vec())
                .unwrap()
                .save(dir.join(image))
                .unwrap();
        }
        let view = |offset: usize, length: usize| serde_json::json!({ "buffer": 0, "byteOffset": offset, "byteLength": length });
        let json = serde_json::json!({
            "asset": { "version": "2.0" },
            "scene": 0, "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
            "meshes": [{ "name": "tri", "primitives": [{
                "attributes": { "POSITION": 0, "TEXCOORD_0": 1, "TEXCOORD_1": 2, "COLOR_0": 3 },
                "material": 0 }] }],
            "materials": [{ "name": "tex", "pbrMetallicRoughness": {
                "baseColorFactor": [0.5, 1.0, 1.0, 1.0],
                "baseColorTexture": { "index": 0, "texCoord": 0 } } }],
            "textures": [{ "source": 0, "sampler": 0 }],
            "samplers": [{ "wrapS": 33071, "wrapT": 33648 }],
            "images": [{ "uri": image }],
            "accessors": [
                { "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0] },
                { "bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2" },
                { "bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2" },
                { "bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC4" },
            ],
            "bufferViews": [view(0, 36), view(36, 24), view(60, 24), view(84, 48)],
            "buffers": [{ "byteLength": bytes.len(), "uri": "tri.bin" }],
        });
        let path = dir.join("tri.gltf");
        std::fs::write(&path, json.to_string()).unwrap();
        path
    }

    #[test]
    fn base_colour_textures_load_with_their_uv_set_sampler_and_vertex_colours() {
        use super::super::texture::{HitAlbedo, Wrap, srgb_to_linear};
        let dir = tempfile::tempdir().unwrap();
        let s = Scene::load(&textured_triangle(dir.path(), "checker.png", true)).unwrap();
        let t = &s.triangles[0];
        assert_eq!(t.texture_uv, Some([Vec2::ZERO, Vec2::X, Vec2::Y]));
        assert_eq!(t.colour, Some([Vec3::ONE, Vec3::splat(0.5), Vec3::ONE]));
        let m = &s.materials[0];
        let tex = m.base_color_texture.as_ref().unwrap();
        assert_eq!(tex.wrap, [Wrap::ClampToEdge, Wrap::MirroredRepeat]);
        assert_eq!(tex.factor, Vec3::new(0.5, 1.0, 1.0));
        assert_eq!(tex.image.size(), (2, 2));
        assert_eq!(s.texture_bytes(), 12);
        // The material's albedo: the factor × the linear average (red, green, blue, white).
        assert!((m.albedo - Vec3::new(0.25, 0.5, 0.5)).abs().max_element() < 1e-6);
        // At vertex 0 (uv 0,0, clamped to the red texel) and vertex 1 (uv 1,0: green, colour
        // ½), and between texel centres: the linear mean of red and green at uv (½, ¼).
        let a = s.hit_albedo(0);
        assert!(matches!(a, HitAlbedo::Varying(_)));
        assert!((a.at(0.0, 0.0) - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6);
        assert!((a.at(1.0, 0.0) - Vec3::new(0.0, 0.5, 0.0)).length() < 1e-6);
        // uv (½, ¼) is halfway between the red and green texel centres of row 0: their
        // linear mean (½, ½, 0) × factor (½, 1, 1) × colour (¼ + ½·½ + ¼ = ¾).
        let mid = a.at(0.5, 0.25);
        assert!(
            (mid - Vec3::new(0.1875, 0.375, 0.0)).length() < 1e-6,
            "{mid}"
        );
        // The sRGB code 128 would decode to 0.216, not ½: filtering is in linear light.
        assert!((srgb_to_linear(128.0 / 255.0) - 0.2158605).abs() < 1e-6);
    }

    #[test]
    fn a_missing_or_undecodable_texture_image_is_noted_and_its_material_keeps_its_factor() {
        let dir = tempfile::tempdir().unwrap();
        let path = textured_triangle(dir.path(), "missing.png", false);
        let (s, notes) = Scene::load_reporting(&path, TextureOptions::default()).unwrap();
        let m = &s.materials[0];
        assert!(m.base_color_texture.is_none());
        assert_eq!(m.albedo, Vec3::new(0.5, 1.0, 1.0), "the factor");
        assert!(s.triangles[0].texture_uv.is_some());
        assert!(
            matches!(s.hit_albedo(0), texture::HitAlbedo::Varying(_)),
            "vertex colours stay"
        );
        let [note] = notes.missing_textures.as_slice() else {
            panic!("{notes:?}")
        };
        assert_eq!(
            (note.material.as_str(), note.file.as_str()),
            ("tex", "images[0] (missing.png)")
        );
        assert!(note.message.contains("cannot read"), "{}", note.message);
        std::fs::write(dir.path().join("broken.png"), b"not a png").unwrap();
        let path = textured_triangle(dir.path(), "broken.png", false);
        let (_, notes) = Scene::load_reporting(&path, TextureOptions::default()).unwrap();
        assert_eq!(notes.missing_textures[0].file, "images[0] (broken.png)");
        // glTF's default white factor is no colour: the fallback is the grey.
        let text = std::fs::read_to_string(&path)
            .unwrap()
            .replace("[0.5,1.0,1.0,1.0]", "[1.0,1.0,1.0,1.0]");
        assert!(!text.contains("0.5,1.0,1.0"), "{text}");
        std::fs::write(&path, text).unwrap();
        let s = Scene::load(&path).unwrap();
        assert_eq!(s.materials[0].albedo, Vec3::splat(MISSING_TEXTURE_ALBEDO));
    }
}
