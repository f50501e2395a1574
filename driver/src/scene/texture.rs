//! Base-colour textures and the albedo at a hit: one home for "what colour is this surface
//! here" — the bake's gather hits ([`crate::transport::world::World`]) and `guidebake render`
//! both read [`HitAlbedo`].
//!
//! The albedo at a point of a triangle is `texture(uv) × factor × vertex colour`: the UV and
//! the vertex colour interpolated with the hit's barycentrics, the texture sampled bilinearly
//! with its sampler's wrap modes (glTF `REPEAT`, `CLAMP_TO_EDGE`, `MIRRORED_REPEAT`; OBJ
//! `map_Kd` repeats). A triangle whose albedo does not vary (no texture or no texture UVs,
//! no vertex colours) has the material's constant albedo and costs nothing per hit.
//!
//! No mip level is chosen from the ray's footprint: a texel's irradiance is a Monte Carlo
//! integral over many gather rays, and point-sampling the texture at each hit is an unbiased
//! estimate of the texture's average over the footprint those rays cover; a prefiltered
//! level would only trade that for a blur (bias) toward the level's average.
//!
//! Memory: an image is stored as 8-bit sRGB RGB (3 bytes a texel; alpha is dropped — the
//! baker's surfaces are opaque), decoded to linear through a 256-entry table at each of the
//! four bilinear taps, so filtering happens in linear light. Images larger than the cap
//! ([`TextureOptions::max_size`]) are box-filtered down (in linear light) by the smallest
//! integer factor that fits; the bytes kept are counted ([`Image::bytes`]).

use std::sync::{Arc, LazyLock};

use glam::{Vec2, Vec3};

use super::{Material, Triangle};

/// How images are kept in memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureOptions {
    /// Largest width or height kept; larger images are box-filtered down to fit.
    pub max_size: u32,
}

impl TextureOptions {
    /// The default cap: 1024 texels, 3 MiB an image at most.
    pub const DEFAULT_MAX_SIZE: u32 = 1024;
}

impl Default for TextureOptions {
    fn default() -> Self {
        Self {
            max_size: Self::DEFAULT_MAX_SIZE,
        }
    }
}

/// How a texture coordinate outside [0, 1] is brought back (glTF sampler `wrapS`/`wrapT`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// The image tiles the plane (glTF's default, and OBJ's).
    #[default]
    Repeat,
    /// Coordinates are clamped to the edge texels.
    ClampToEdge,
    /// The image tiles the plane, every other copy mirrored.
    MirroredRepeat,
}

impl Wrap {
    /// The two texels of a row (or column) of `n` texels whose centres bracket coordinate `t`,
    /// and the weight of the second. The coordinate is first brought into one period in
    /// floating point (`[0, 1)` repeating; `[0, 1]` mirrored or clamped), so the indices need
    /// only a fix-up at the ends, and no integer division (the glTF definitions, index by
    /// index, are the tests' reference: `tests::reference_index`).
    #[inline]
    fn taps(self, t: f32, n: u32) -> (usize, usize, f32) {
        let t = match self {
            Wrap::Repeat => t - t.floor(),
            Wrap::ClampToEdge => t.clamp(0.0, 1.0),
            Wrap::MirroredRepeat => {
                let m = t - 2.0 * (0.5 * t).floor();
                if m > 1.0 { 2.0 - m } else { m }
            }
        };
        let x = t * n as f32 - 0.5;
        let x0 = x.floor();
        let (i, last) = (x0 as i64, i64::from(n) - 1);
        let (a, b) = match self {
            Wrap::Repeat => (
                if i < 0 { last } else { i },
                if i >= last { 0 } else { i + 1 },
            ),
            Wrap::ClampToEdge | Wrap::MirroredRepeat => (i, i + 1),
        };
        (a.clamp(0, last) as usize, b.clamp(0, last) as usize, x - x0)
    }
}

/// sRGB transfer function → linear, for a value in [0, 1].
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear → 8-bit sRGB, rounded (values outside [0, 1] clamped).
fn linear_to_srgb8(c: f32) -> u8 {
    let c = if c.is_finite() {
        c.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// The 256 linear values of the 8-bit sRGB codes.
static SRGB8_TO_LINEAR: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)));

/// A decoded image as the baker keeps it: 8-bit sRGB RGB, at most the cap in each dimension.
#[derive(Clone, PartialEq)]
pub struct Image {
    /// Where it came from, for messages (`images[2] (wood.png)`, or a file path).
    pub source: String,
    width: u32,
    height: u32,
    /// Row-major sRGB RGB, row 0 at v = 0 (glTF's and the image file's top row).
    srgb: Vec<[u8; 3]>,
    /// The linear average of the kept texels.
    average: Vec3,
}

impl std::fmt::Debug for Image {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Image")
            .field("source", &self.source)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("average", &self.average)
            .finish_non_exhaustive()
    }
}

impl Image {
    /// An image from `width × height` texels of 8-bit sRGB, `channels` (1–4) interleaved
    /// (1: grey, 2: grey + alpha, 3: RGB, 4: RGBA; alpha is dropped), box-filtered down to
    /// `options.max_size`.
    ///
    /// # Errors
    /// A message (without the source, which the caller names) when the sizes do not match.
    pub fn from_srgb8(
        source: String,
        width: u32,
        height: u32,
        channels: usize,
        pixels: &[u8],
        options: TextureOptions,
    ) -> Result<Image, String> {
        let count = width as usize * height as usize;
        if !(1..=4).contains(&channels) || count == 0 || pixels.len() != count * channels {
            return Err(format!(
                "{width}×{height} texels of {channels} channels do not match its {} bytes",
                pixels.len()
            ));
        }
        let rgb = |px: &[u8]| {
            if channels < 3 {
                [px[0]; 3]
            } else {
                [px[0], px[1], px[2]]
            }
        };
        let factor = downsample_factor(width, height, options.max_size);
        if factor == 1 {
            let texels: Vec<[u8; 3]> = pixels.chunks_exact(channels).map(rgb).collect();
            return Ok(Self::from_texels(source, width, height, texels));
        }
        // Filtered straight from the bytes: no full-size copy beside the decoded image.
        let lut = &*SRGB8_TO_LINEAR;
        let linear = |i: usize| {
            let t = rgb(&pixels[i * channels..(i + 1) * channels]);
            Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
        };
        Ok(Self::from_linear_fn(source, width, height, linear, options))
    }

    /// An image from linear RGB texels (16-bit and float sources), box-filtered down to
    /// `options.max_size` and encoded as 8-bit sRGB.
    pub fn from_linear(
        source: String,
        width: u32,
        height: u32,
        linear: &[Vec3],
        options: TextureOptions,
    ) -> Image {
        Self::from_linear_fn(source, width, height, |i| linear[i], options)
    }

    /// [`Self::from_linear`] with texel `i` (row-major) given by `linear(i)`, read once
    /// each: the caller need not hold the image in linear light at full size.
    pub fn from_linear_fn(
        source: String,
        width: u32,
        height: u32,
        linear: impl Fn(usize) -> Vec3,
        options: TextureOptions,
    ) -> Image {
        let factor = downsample_factor(width, height, options.max_size) as usize;
        let (w, h) = (width as usize, height as usize);
        let (nw, nh) = (w.div_ceil(factor), h.div_ceil(factor));
        let mut texels = Vec::with_capacity(nw * nh);
        for y in 0..nh {
            for x in 0..nw {
                let mut sum = Vec3::ZERO;
                let mut n = 0u32;
                for sy in y * factor..((y + 1) * factor).min(h) {
                    for sx in x * factor..((x + 1) * factor).min(w) {
                        let c = linear(sy * w + sx);
                        sum += if c.is_finite() { c } else { Vec3::ZERO };
                        n += 1;
                    }
                }
                let c = sum / n.max(1) as f32;
                texels.push([c.x, c.y, c.z].map(linear_to_srgb8));
            }
        }
        Self::from_texels(source, nw as u32, nh as u32, texels)
    }

    fn from_texels(source: String, width: u32, height: u32, srgb: Vec<[u8; 3]>) -> Image {
        let lut = &*SRGB8_TO_LINEAR;
        let mut sum = glam::DVec3::ZERO;
        for t in &srgb {
            sum += glam::DVec3::new(
                f64::from(lut[t[0] as usize]),
                f64::from(lut[t[1] as usize]),
                f64::from(lut[t[2] as usize]),
            );
        }
        let average = (sum / srgb.len().max(1) as f64).as_vec3();
        Image {
            source,
            width,
            height,
            srgb,
            average,
        }
    }

    /// Width and height as kept (after the cap).
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Bytes of texels kept.
    pub fn bytes(&self) -> usize {
        self.srgb.len() * 3
    }

    /// The linear average of the kept texels.
    pub fn average(&self) -> Vec3 {
        self.average
    }

    /// Linear RGB at `uv` (texel centres at `(i + ½) / width`), bilinear between the four
    /// nearest texels, each decoded from sRGB first; `wrap` for u and v.
    pub fn bilinear(&self, uv: Vec2, wrap: [Wrap; 2]) -> Vec3 {
        let (xa, xb, fx) = wrap[0].taps(uv.x, self.width);
        let (ya, yb, fy) = wrap[1].taps(uv.y, self.height);
        let lut = &*SRGB8_TO_LINEAR;
        let texel = |x: usize, y: usize| {
            let t = self.srgb[y * self.width as usize + x];
            Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
        };
        let top = texel(xa, ya).lerp(texel(xb, ya), fx);
        let bottom = texel(xa, yb).lerp(texel(xb, yb), fx);
        top.lerp(bottom, fy)
    }
}

/// The smallest integer factor that brings `width × height` within `max_size` (1: none).
fn downsample_factor(width: u32, height: u32, max_size: u32) -> u32 {
    width.max(height).div_ceil(max_size.max(1)).max(1)
}

/// A material's base-colour texture: the image, its sampler's wrap modes for u and v, and
/// the base colour factor it is multiplied by.
#[derive(Clone, Debug, PartialEq)]
pub struct BaseColorTexture {
    /// The image (shared by every material that uses it).
    pub image: Arc<Image>,
    /// Wrap modes along u (`wrapS`) and v (`wrapT`).
    pub wrap: [Wrap; 2],
    /// glTF `baseColorFactor` (RGB), OBJ `Kd`.
    pub factor: Vec3,
}

/// The albedo of a triangle: constant, or varying over it (module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum HitAlbedo {
    /// No texture with UVs, no vertex colours: the material's albedo everywhere.
    Constant(Vec3),
    /// A texture, vertex colours, or both.
    Varying(VaryingAlbedo),
}

/// What a triangle's varying albedo is made of.
#[derive(Clone, Debug, PartialEq)]
pub struct VaryingAlbedo {
    /// The base-colour texture and its UVs at the three vertices, if any.
    texture: Option<(BaseColorTexture, [Vec2; 3])>,
    /// The material's constant albedo, used where the texture is absent.
    constant: Vec3,
    /// Vertex colours (linear RGB), or white.
    colour: [Vec3; 3],
}

impl HitAlbedo {
    /// How `triangle` of `material` is coloured: a texture needs the triangle's texture UVs
    /// (without them, the material's albedo — factor × the texture's average — is used).
    pub fn of(triangle: &Triangle, material: &Material) -> HitAlbedo {
        let texture = match (&material.base_color_texture, triangle.texture_uv) {
            (Some(t), Some(uv)) => Some((t.clone(), uv)),
            _ => None,
        };
        if texture.is_none() && triangle.colour.is_none() {
            return HitAlbedo::Constant(material.albedo);
        }
        HitAlbedo::Varying(VaryingAlbedo {
            texture,
            constant: material.albedo,
            colour: triangle.colour.unwrap_or([Vec3::ONE; 3]),
        })
    }

    /// The albedo at barycentrics `(u, v)` (weights of the second and third vertices).
    #[inline]
    pub fn at(&self, u: f32, v: f32) -> Vec3 {
        match self {
            HitAlbedo::Constant(c) => *c,
            HitAlbedo::Varying(a) => a.at(u, v),
        }
    }
}

impl VaryingAlbedo {
    /// `texture(uv) × factor × colour` at barycentrics `(u, v)`, in [0, 1]; the material's
    /// constant albedo where that is not finite (a UV too large for `f32` to place).
    pub fn at(&self, u: f32, v: f32) -> Vec3 {
        let w = 1.0 - u - v;
        let base = match &self.texture {
            Some((t, uv)) => {
                let p = uv[0] * w + uv[1] * u + uv[2] * v;
                t.image.bilinear(p, t.wrap) * t.factor
            }
            None => self.constant,
        };
        let [c0, c1, c2] = self.colour;
        let albedo = base * (c0 * w + c1 * u + c2 * v);
        if albedo.is_finite() {
            albedo.clamp(Vec3::ZERO, Vec3::ONE)
        } else {
            self.constant
        }
    }
}

/// Bytes of texels the materials keep, each image counted once however many materials share
/// it.
pub fn texture_bytes(materials: &[Material]) -> usize {
    let mut seen: Vec<*const Image> = Vec::new();
    let mut bytes = 0;
    for t in materials
        .iter()
        .filter_map(|m| m.base_color_texture.as_ref())
    {
        let p = Arc::as_ptr(&t.image);
        if !seen.contains(&p) {
            seen.push(p);
            bytes += t.image.bytes();
        }
    }
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: u32, height: u32, srgb: &[[u8; 3]]) -> Image {
        let bytes: Vec<u8> = srgb.iter().flatten().copied().collect();
        Image::from_srgb8(
            "test".into(),
            width,
            height,
            3,
            &bytes,
            TextureOptions::default(),
        )
        .unwrap()
    }

    #[test]
    fn srgb_decodes_to_the_standard_linear_values() {
        // IEC 61966-2-1: 0 → 0, 255 → 1, the linear segment below 0.04045, and mid-grey
        // 128/255 → 0.2158605.
        let lut = &*SRGB8_TO_LINEAR;
        assert_eq!(lut[0], 0.0);
        assert!((lut[255] - 1.0).abs() < 1e-6);
        assert!((lut[10] - 10.0 / 255.0 / 12.92).abs() < 1e-7);
        assert!((lut[128] - 0.215_860_5).abs() < 1e-6, "{}", lut[128]);
        for code in 0..=255u8 {
            assert_eq!(
                linear_to_srgb8(lut[code as usize]),
                code,
                "round trip of {code}"
            );
        }
        // A 1×1 image of code 128 samples as its linear value anywhere.
        let img = image(1, 1, &[[128, 0, 255]]);
        let c = img.bilinear(Vec2::new(0.3, 0.9), [Wrap::Repeat; 2]);
        assert!((c - Vec3::new(0.215_860_5, 0.0, 1.0)).abs().max_element() < 1e-6);
    }

    #[test]
    fn bilinear_filters_in_linear_light_between_texel_centres() {
        let img = image(2, 1, &[[0; 3], [255; 3]]);
        let clamp = [Wrap::ClampToEdge; 2];
        // Texel centres at u = ¼ and ¾; halfway between them is the linear mean, ½ (not the
        // sRGB mean 128 → 0.216).
        assert!((img.bilinear(Vec2::new(0.25, 0.5), clamp).x).abs() < 1e-6);
        assert!((img.bilinear(Vec2::new(0.75, 0.5), clamp).x - 1.0).abs() < 1e-6);
        assert!((img.bilinear(Vec2::new(0.5, 0.5), clamp).x - 0.5).abs() < 1e-6);
        assert!((img.bilinear(Vec2::new(0.375, 0.5), clamp).x - 0.25).abs() < 1e-6);
    }

    /// The glTF sampler definitions, texel index by texel index: index `i` of a row of `n`
    /// texels brought into `0..n`.
    fn reference_index(wrap: Wrap, i: i64, n: i64) -> usize {
        let j = match wrap {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m >= n { 2 * n - 1 - m } else { m }
            }
        };
        j as usize
    }

    /// Bilinear filtering by [`reference_index`]: texel centres at `(i + ½) / n`.
    fn reference_bilinear(img: &Image, uv: Vec2, wrap: [Wrap; 2]) -> Vec3 {
        let (w, h) = (i64::from(img.width), i64::from(img.height));
        let x = f64::from(uv.x) * w as f64 - 0.5;
        let y = f64::from(uv.y) * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let lut = &*SRGB8_TO_LINEAR;
        let texel = |i: i64, j: i64| {
            let (i, j) = (
                reference_index(wrap[0], i, w),
                reference_index(wrap[1], j, h),
            );
            let t = img.srgb[j * img.width as usize + i];
            Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
        };
        let top = texel(x0, y0).lerp(texel(x0 + 1, y0), fx);
        let bottom = texel(x0, y0 + 1).lerp(texel(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }

    #[test]
    fn bilinear_taps_match_the_reference_wrap_definitions() {
        // A 5×3 image of distinct texels, every pair of modes, UVs over several periods
        // either side of [0, 1] and exactly on texel centres and edges.
        let mut rng = guidebake_kernels::testing::Pcg32::new(3, 0);
        let srgb: Vec<[u8; 3]> = (0..15u8).map(|i| [i * 17, 255 - i * 17, i * 5]).collect();
        let img = image(5, 3, &srgb);
        let modes = [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat];
        let mut uvs: Vec<Vec2> = (0..4000)
            .map(|_| Vec2::new(rng.next_f32() * 8.0 - 4.0, rng.next_f32() * 8.0 - 4.0))
            .collect();
        for k in -12..=12 {
            let (u, v) = (k as f32 / 10.0, k as f32 / 6.0);
            uvs.push(Vec2::new(u, v));
        }
        for wx in modes {
            for wy in modes {
                for &uv in &uvs {
                    let fast = img.bilinear(uv, [wx, wy]);
                    let want = reference_bilinear(&img, uv, [wx, wy]);
                    assert!(
                        (fast - want).abs().max_element() < 1e-4,
                        "{wx:?} {wy:?} at {uv}: {fast} against {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn wrap_modes_follow_the_gltf_sampler_definitions() {
        let n = 4;
        let at = |w: Wrap| {
            (-6..10)
                .map(|i| reference_index(w, i, n))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            at(Wrap::Repeat),
            [2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1]
        );
        assert_eq!(
            at(Wrap::ClampToEdge),
            [0, 0, 0, 0, 0, 0, 0, 1, 2, 3, 3, 3, 3, 3, 3, 3]
        );
        // Mirrored: …, 1, 0 | 0, 1, 2, 3 | 3, 2, 1, 0 | 0, …
        assert_eq!(
            at(Wrap::MirroredRepeat),
            [2, 3, 3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0, 0, 1]
        );
        // Through sampling: a 4×1 ramp at u = 1.125 (texel 0 of the next copy when
        // repeating, texel 3 when mirrored or clamped).
        let img = image(4, 1, &[[0; 3], [85; 3], [170; 3], [255; 3]]);
        let lut = &*SRGB8_TO_LINEAR;
        let u = Vec2::new(1.125, 0.5);
        let at = |w: Wrap| img.bilinear(u, [w, Wrap::ClampToEdge]).x;
        assert_eq!(at(Wrap::Repeat), lut[0]);
        assert_eq!(at(Wrap::ClampToEdge), lut[255]);
        assert_eq!(at(Wrap::MirroredRepeat), lut[255]);
        let u = Vec2::new(-0.375, 0.5); // texel 2 repeating, texel 1 mirrored, 0 clamped
        let at = |w: Wrap| img.bilinear(u, [w, Wrap::ClampToEdge]).x;
        assert_eq!(at(Wrap::Repeat), lut[170]);
        assert_eq!(at(Wrap::MirroredRepeat), lut[85]);
        assert_eq!(at(Wrap::ClampToEdge), lut[0]);
    }

    #[test]
    fn images_over_the_cap_are_box_filtered_in_linear_light() {
        // A 6×3 checker of black and white texels, capped at 2: factor 3, each 3×3 block
        // holds 4 or 5 white texels of 9.
        let srgb: Vec<[u8; 3]> = (0..18)
            .map(|i| {
                if (i % 6 + i / 6) % 2 == 0 {
                    [255; 3]
                } else {
                    [0; 3]
                }
            })
            .collect();
        let bytes: Vec<u8> = srgb.iter().flatten().copied().collect();
        let img =
            Image::from_srgb8("c".into(), 6, 3, 3, &bytes, TextureOptions { max_size: 2 }).unwrap();
        assert_eq!(img.size(), (2, 1));
        assert_eq!(img.bytes(), 6);
        let lut = &*SRGB8_TO_LINEAR;
        let left = lut[img.srgb[0][0] as usize];
        let right = lut[img.srgb[1][0] as usize];
        assert!((left - 5.0 / 9.0).abs() < 3e-3, "{left}");
        assert!((right - 4.0 / 9.0).abs() < 3e-3, "{right}");
        // The average survives the filtering (up to 8-bit rounding).
        assert!((img.average().x - 0.5).abs() < 3e-3);
        // A bad size is an error, not a panic.
        assert!(
            Image::from_srgb8("x".into(), 2, 2, 3, &[0; 5], TextureOptions::default()).is_err()
        );
    }

    #[test]
    fn varying_albedo_multiplies_texture_factor_and_vertex_colour() {
        let img = Arc::new(image(1, 1, &[[255, 128, 0]]));
        let material = Material {
            name: "m".into(),
            albedo: Vec3::new(0.5, 0.5 * 0.215_860_5, 0.0),
            emission: Vec3::ZERO,
            base_color_texture: Some(BaseColorTexture {
                image: img,
                wrap: [Wrap::Repeat; 2],
                factor: Vec3::splat(0.5),
            }),
        };
        let mut t = Triangle {
            positions: [Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: [Vec3::Z; 3],
            lightmap_uv: None,
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        // No UVs: the material's albedo, constant.
        assert_eq!(
            HitAlbedo::of(&t, &material),
            HitAlbedo::Constant(material.albedo)
        );
        t.texture_uv = Some([Vec2::ZERO, Vec2::X, Vec2::Y]);
        t.colour = Some([Vec3::ONE, Vec3::ZERO, Vec3::ONE]);
        let a = HitAlbedo::of(&t, &material);
        let at_first = a.at(0.0, 0.0);
        assert!((at_first - material.albedo).abs().max_element() < 1e-6);
        assert_eq!(a.at(1.0, 0.0), Vec3::ZERO);
        assert!((a.at(0.5, 0.0) - material.albedo * 0.5).abs().max_element() < 1e-6);
        // A UV beyond f32's reach, NaN barycentrics: finite, the constant.
        assert!(a.at(f32::NAN, 0.0).is_finite());
        t.texture_uv = Some([Vec2::splat(3e38); 3]);
        assert!(HitAlbedo::of(&t, &material).at(0.2, 0.2).is_finite());
    }
}
