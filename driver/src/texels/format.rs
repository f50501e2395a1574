//! The on-disk records, their sizes and flags, and the rules a tile and its texels obey
//! (shared by the writer and the reader). Layout: docs/texel-format.md.

use super::*;
use crate::scene::Role;

/// `b"GBTEXELS"`: the first eight bytes of every texel file.
pub const MAGIC: [u8; 8] = *b"GBTEXELS";
/// The version this build writes and reads: a 192-byte header that records the geometry of
/// the scene the file was prepared from ([`Header::geometry`]), a triangle table (every
/// triangle's lightmap UVs and seen sides). Files of other versions are refused.
pub const VERSION: u32 = 3;
/// Every section starts at a multiple of this many bytes.
pub const SECTION_ALIGN: u64 = 64;
/// Default tile edge in texels.
pub const TILE_SIZE: u32 = 32;
/// A normal is "unit" when its length is within this of 1.
pub const UNIT_TOLERANCE: f32 = 1e-3;

/// Texel flag: the texel is valid and must be baked.
pub const FLAG_VALID: u32 = 1;
/// Texel flag: no triangle covers the texel centre; the position is the closest point of
/// the triangle that overlaps the texel (conservative rasterization, see `prepare`).
pub const FLAG_PARTIAL: u32 = 2;
/// Texel flag: the texel lies inside geometry (its rays meet sides of surfaces that face no
/// open space, [`crate::prepare::facing::Visibility::inside_geometry`]); such a texel is not
/// [`FLAG_VALID`]: the bake skips it and the lightmap's dilation fills it.
pub const FLAG_INSIDE: u32 = 4;
/// Every texel flag bit this version defines.
pub const KNOWN_FLAGS: u32 = FLAG_VALID | FLAG_PARTIAL | FLAG_INSIDE;

/// [`TriangleRecord::flags`] bit: the winding's front side faces open space
/// ([`crate::prepare::facing`]).
pub const SEEN_FRONT: u32 = 1;
/// [`TriangleRecord::flags`] bit: the back side faces open space.
pub const SEEN_BACK: u32 = 2;
/// [`TriangleRecord::flags`] bit: the triangle has lightmap UVs (`page` and `uv` hold them)
/// and may have texels.
pub const LIGHTMAPPED: u32 = 4;
/// [`TriangleRecord::flags`] bit: its texels describe its back side (their normals face
/// against the winding); only with [`SEEN_BACK`].
pub const TEXELS_BACK: u32 = 8;
/// The bits of [`TriangleRecord::flags`] that say which sides are seen and described.
pub const SIDE_FLAGS: u32 = SEEN_FRONT | SEEN_BACK | TEXELS_BACK;
/// The first of the three bits of [`TriangleRecord::flags`] that hold the triangle's
/// [`Role`]'s code ([`Role::code`]; 0, [`Role::Baked`], in files written before roles).
pub const ROLE_SHIFT: u32 = 4;
/// The bits of [`TriangleRecord::flags`] that hold the role.
pub const ROLE_FLAGS: u32 = 7 << ROLE_SHIFT;
/// Every triangle flag bit this version defines.
pub const KNOWN_TRIANGLE_FLAGS: u32 = SIDE_FLAGS | LIGHTMAPPED | ROLE_FLAGS;

/// File header at offset 0, 192 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Header {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`VERSION`].
    pub version: u32,
    /// `size_of::<Header>()` = 192.
    pub header_size: u32,
    /// Total file length in bytes.
    pub file_size: u64,
    /// Number of [`TexelRecord`]s.
    pub texel_count: u64,
    /// Number of [`TileRecord`]s.
    pub tile_count: u64,
    /// Number of [`PageRecord`]s.
    pub page_count: u32,
    /// Tile edge in texels (tiles are at most `tile_size`² texels).
    pub tile_size: u32,
    /// Reserved, 0.
    pub reserved0: u32,
    /// Number of [`TriangleRecord`]s: the triangles of the scene the file was prepared from.
    pub triangle_count: u32,
    /// Byte offset of the page table.
    pub pages_offset: u64,
    /// Byte offset of the triangle table.
    pub triangles_offset: u64,
    /// Byte offset of the texel records.
    pub texels_offset: u64,
    /// Byte offset of the tile table.
    pub tiles_offset: u64,
    /// World bounds of all texel positions, min corner.
    pub bounds_min: [f32; 3],
    /// World bounds, max corner.
    pub bounds_max: [f32; 3],
    /// Texel density used by `prepare` (texels per world unit along an edge; 0 if none).
    pub texels_per_unit: f32,
    /// Reserved, 0.
    pub flags: u32,
    /// [`Scene::lighting_fingerprint`](crate::scene::Scene::lighting_fingerprint) of the lights
    /// `prepare` decided the seen sides under; 0 when not recorded.
    pub lighting: u64,
    /// [`Scene::geometry_fingerprint`](crate::scene::Scene::geometry_fingerprint) of the scene
    /// the file was prepared from (offset 128): `bake` and `render` refuse a scene of other
    /// geometry. Every guidebake command that writes a texel file records it; 0 (not
    /// recorded) only in files a library caller wrote without [`TexelWriter::set_geometry`].
    pub geometry: u64,
    /// Reserved, 0 (offsets 136..192).
    pub reserved: [u64; 7],
}

/// One atlas page, 8 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct PageRecord {
    /// Width in texels, 1..=65536.
    pub width: u32,
    /// Height in texels, 1..=65536.
    pub height: u32,
}

/// One scene triangle as the lightmap knows it, 32 bytes: where its texels lie and which of its
/// sides face open space. The bake finds a hit's texel through it (series lookups), `render`
/// and `merge` read the lightmap through it, and the gather tells from it whether a ray met a
/// surface from inside geometry — so no scene UV set has to match the file.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TriangleRecord {
    /// Atlas page (0 without [`LIGHTMAPPED`]).
    pub page: u32,
    /// [`SEEN_FRONT`] | [`SEEN_BACK`] | [`TEXELS_BACK`] | [`LIGHTMAPPED`].
    pub flags: u32,
    /// Its corners' lightmap positions in continuous pixel coordinates of its page (texel
    /// (x, y) covers [x, x+1) × [y, y+1)); zero without [`LIGHTMAPPED`].
    pub uv: [[f32; 2]; 3],
}

impl TriangleRecord {
    /// A triangle with lightmap UVs `uv` (pixel coordinates) on `page`, seen from `seen`
    /// ([`SIDE_FLAGS`]).
    #[must_use]
    pub fn lightmapped(page: u32, uv: [Vec2; 3], seen: u32) -> Self {
        Self {
            page,
            flags: LIGHTMAPPED | (seen & SIDE_FLAGS),
            uv: uv.map(|v| v.to_array()),
        }
    }

    /// A triangle without lightmap UVs, seen from `seen`.
    #[must_use]
    pub fn unmapped(seen: u32) -> Self {
        Self {
            flags: seen & SIDE_FLAGS,
            ..Self::default()
        }
    }

    /// Its page and corners in pixel coordinates, when it has lightmap UVs.
    #[must_use]
    pub fn pixel_uv(&self) -> Option<(u32, [Vec2; 3])> {
        (self.flags & LIGHTMAPPED != 0).then(|| (self.page, self.uv.map(Vec2::from)))
    }

    /// Whether its winding's `front` side (or its back) faces open space: a ray meeting it
    /// on a side that does not came from inside geometry.
    #[must_use]
    pub fn seen_from(&self, front: bool) -> bool {
        self.flags & if front { SEEN_FRONT } else { SEEN_BACK } != 0
    }

    /// Its role ([`ROLE_FLAGS`]; [`Role::Baked`] for a code no role has, which
    /// [`check_triangles`] refuses).
    #[must_use]
    pub fn role(&self) -> Role {
        Role::of_code((self.flags & ROLE_FLAGS) >> ROLE_SHIFT).unwrap_or_default()
    }

    /// This record with `role`.
    #[must_use]
    pub fn with_role(self, role: Role) -> Self {
        Self {
            flags: (self.flags & !ROLE_FLAGS) | (role.code() << ROLE_SHIFT),
            ..self
        }
    }

    /// Whether its texels describe its back side ([`TEXELS_BACK`]): their normals face against
    /// the winding.
    #[must_use]
    pub fn texels_face_back(&self) -> bool {
        self.flags & TEXELS_BACK != 0
    }

    /// What is wrong with this record, given the file's page count, if anything.
    fn defect(&self, pages: usize) -> Option<String> {
        if self.flags & !KNOWN_TRIANGLE_FLAGS != 0 {
            return Some(format!(
                "unknown flag bits {:#x}",
                self.flags & !KNOWN_TRIANGLE_FLAGS
            ));
        }
        let role = (self.flags & ROLE_FLAGS) >> ROLE_SHIFT;
        match Role::of_code(role) {
            None => return Some(format!("unknown role code {role}")),
            Some(r) if !r.has_texels() && self.flags & LIGHTMAPPED != 0 => {
                return Some(format!("a {r} triangle with lightmap UVs"));
            }
            Some(_) => {}
        }
        if self.flags & TEXELS_BACK != 0 && self.flags & SEEN_BACK == 0 {
            return Some("TEXELS_BACK without SEEN_BACK".to_owned());
        }
        if self.flags & LIGHTMAPPED == 0 {
            return (self.page != 0 || self.uv != [[0.0; 2]; 3])
                .then(|| "UVs or a page without the LIGHTMAPPED flag".to_owned());
        }
        if self.page as usize >= pages {
            return Some(format!("page {} does not exist ({pages} pages)", self.page));
        }
        if !self.uv.iter().flatten().all(|v| v.is_finite()) {
            return Some(format!("UVs {:?} are not finite", self.uv));
        }
        None
    }
}

/// Checks the triangle table against the page count: the first defective record, if any.
pub(super) fn check_triangles(
    triangles: &[TriangleRecord],
    pages: usize,
) -> Option<(usize, String)> {
    triangles
        .iter()
        .enumerate()
        .find_map(|(i, t)| t.defect(pages).map(|m| (i, m)))
}

/// One tile, 32 bytes: a pixel rectangle of one page and its texels, contiguous.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct TileRecord {
    /// Page index.
    pub page: u32,
    /// Left pixel column.
    pub x: u32,
    /// Top pixel row.
    pub y: u32,
    /// Width in pixels, 1..=tile_size.
    pub width: u32,
    /// Height in pixels, 1..=tile_size.
    pub height: u32,
    /// Number of texels, 1..=width·height.
    pub texel_count: u32,
    /// Index of its first texel; tiles are stored back to back in file order.
    pub first_texel: u64,
}

/// One texel, 64 bytes (a cache line).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct TexelRecord {
    /// World position (the texel centre on its triangle).
    pub position: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
    /// World-space footprint axis: the change of position over one texel in +x.
    pub dpdu: [f32; 3],
    /// World-space footprint axis over one texel in +y.
    pub dpdv: [f32; 3],
    /// Page index (equals its tile's).
    pub page: u32,
    /// Pixel column and row on the page.
    pub pixel: [u16; 2],
    /// Scene triangle the texel lies on (`u32::MAX` if none).
    pub triangle: u32,
    /// [`FLAG_VALID`] | [`FLAG_PARTIAL`].
    pub flags: u32,
}

impl TexelRecord {
    /// Position as a vector.
    #[must_use]
    pub fn position(&self) -> Vec3 {
        Vec3::from(self.position)
    }
    /// Normal as a vector.
    #[must_use]
    pub fn normal(&self) -> Vec3 {
        Vec3::from(self.normal)
    }
    /// The texel's spacing in the world: the longer of its footprint axes.
    #[must_use]
    pub fn spacing(&self) -> f32 {
        Vec3::from(self.dpdu)
            .length()
            .max(Vec3::from(self.dpdv).length())
    }
    /// What is wrong with this record on its own, if anything.
    fn defect(&self) -> Option<String> {
        let finite = |v: &[f32; 3]| v.iter().all(|c| c.is_finite());
        if !finite(&self.position) {
            return Some(format!("position {:?} is not finite", self.position));
        }
        let n = self.normal();
        if !n.is_finite() || (n.length() - 1.0).abs() > UNIT_TOLERANCE {
            return Some(format!("normal {:?} is not unit length", self.normal));
        }
        if !finite(&self.dpdu) || !finite(&self.dpdv) {
            return Some("footprint axes are not finite".into());
        }
        if self.flags & !KNOWN_FLAGS != 0 {
            return Some(format!(
                "unknown flag bits {:#x}",
                self.flags & !KNOWN_FLAGS
            ));
        }
        None
    }
}

const _: () = assert!(size_of::<Header>() == 192);
const _: () = assert!(size_of::<TexelRecord>() == 64);
const _: () = assert!(size_of::<TileRecord>() == 32);
const _: () = assert!(size_of::<TriangleRecord>() == 32);
const _: () = assert!(size_of::<PageRecord>() == 8);

pub(super) fn align_up(x: u64) -> u64 {
    x.div_ceil(SECTION_ALIGN) * SECTION_ALIGN
}

type Defect = (Option<usize>, String);

/// Checks a tile record against the pages and the running texel count.
pub(super) fn check_tile(
    t: &TileRecord,
    pages: &[PageRecord],
    tile_size: u32,
    expected_first: u64,
) -> Result<(), Defect> {
    let Some(page) = pages.get(t.page as usize) else {
        return Err((
            None,
            format!("page {} does not exist ({} pages)", t.page, pages.len()),
        ));
    };
    if t.width == 0 || t.height == 0 || t.width > tile_size || t.height > tile_size {
        return Err((
            None,
            format!("size {}x{} is outside 1..={tile_size}", t.width, t.height),
        ));
    }
    if u64::from(t.x) + u64::from(t.width) > u64::from(page.width)
        || u64::from(t.y) + u64::from(t.height) > u64::from(page.height)
    {
        return Err((
            None,
            format!(
                "rectangle {}+{}x{}+{} leaves the {}x{} page",
                t.x, t.width, t.y, t.height, page.width, page.height
            ),
        ));
    }
    if t.texel_count == 0 || t.texel_count > t.width * t.height {
        return Err((
            None,
            format!(
                "{} texels in a {}x{} tile",
                t.texel_count, t.width, t.height
            ),
        ));
    }
    if t.first_texel != expected_first {
        return Err((
            None,
            format!(
                "first texel {} but the previous tiles end at {expected_first}",
                t.first_texel
            ),
        ));
    }
    Ok(())
}

/// Checks a tile's texels: each valid on its own, on the tile's page and rectangle, strictly
/// increasing row-major pixels (so no pixel appears twice), on a triangle that has lightmap
/// UVs (`mapped(i)`: whether triangle `i` has them, `None` past the table) or on none.
pub(super) fn check_tile_texels(
    t: &TileRecord,
    texels: &[TexelRecord],
    mapped: &dyn Fn(u32) -> Option<bool>,
) -> Result<(), Defect> {
    if texels.len() != t.texel_count as usize || texels.is_empty() {
        return Err((
            None,
            format!(
                "{} texels given for a tile of {}",
                texels.len(),
                t.texel_count
            ),
        ));
    }
    let mut prev: Option<(u32, u32)> = None;
    for (i, x) in texels.iter().enumerate() {
        if let Some(m) = x.defect() {
            return Err((Some(i), m));
        }
        let (px, py) = (u32::from(x.pixel[0]), u32::from(x.pixel[1]));
        if x.page != t.page || px < t.x || py < t.y || px >= t.x + t.width || py >= t.y + t.height {
            return Err((
                Some(i),
                format!("pixel ({px}, {py}) on page {} is outside its tile", x.page),
            ));
        }
        if x.triangle != u32::MAX {
            match mapped(x.triangle) {
                None => return Err((Some(i), format!("triangle {} does not exist", x.triangle))),
                Some(false) => {
                    return Err((
                        Some(i),
                        format!(
                            "triangle {} has no lightmap UVs in the triangle table",
                            x.triangle
                        ),
                    ));
                }
                Some(true) => {}
            }
        }
        if prev.is_some_and(|p| (py, px) <= p) {
            return Err((
                Some(i),
                format!("pixel ({px}, {py}) is not after the previous texel in row-major order"),
            ));
        }
        prev = Some((py, px));
    }
    Ok(())
}
