//! The on-disk records, their sizes and flags, and the rules a tile and its texels obey
//! (shared by the writer and the reader). Layout: docs/texel-format.md.

use super::*;

/// `b"GBTEXELS"`: the first eight bytes of every texel file.
pub const MAGIC: [u8; 8] = *b"GBTEXELS";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;
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
/// Every flag bit version 1 defines.
pub const KNOWN_FLAGS: u32 = FLAG_VALID | FLAG_PARTIAL;

/// File header at offset 0, 128 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Header {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`VERSION`].
    pub version: u32,
    /// `size_of::<Header>()` = 128.
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
    /// Number of [`MeshRecord`]s.
    pub mesh_count: u32,
    /// Triangles of the scene the file was prepared from (0 if unknown).
    pub triangle_count: u32,
    /// Byte offset of the page table.
    pub pages_offset: u64,
    /// Byte offset of the mesh table.
    pub meshes_offset: u64,
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
    /// Reserved, 0.
    pub reserved: [u8; 8],
}

/// [`MeshRecord::flags`] bit: the mesh has lightmap UVs, and texels.
pub const MESH_HAS_LIGHTMAP_UVS: u32 = 1;

/// One atlas page, 8 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct PageRecord {
    /// Width in texels, 1..=65536.
    pub width: u32,
    /// Height in texels, 1..=65536.
    pub height: u32,
}

/// Where a mesh's lightmap UVs land: `pixel = uv * uv_scale + uv_offset` on `page`
/// (continuous pixel coordinates; texel (x, y) has its centre at (x + 0.5, y + 0.5)).
/// 32 bytes. The bake's series transport maps (hit triangle, barycentrics) → page/pixel
/// through it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct MeshRecord {
    /// First triangle of the mesh in the scene's triangle order.
    pub first_triangle: u32,
    /// Number of triangles.
    pub triangle_count: u32,
    /// Atlas page.
    pub page: u32,
    /// Bit 0 ([`MESH_HAS_LIGHTMAP_UVS`]): the mesh has lightmap UVs (otherwise it has no
    /// texels).
    pub flags: u32,
    /// UV → pixel scale.
    pub uv_scale: [f32; 2],
    /// UV → pixel offset.
    pub uv_offset: [f32; 2],
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

const _: () = assert!(size_of::<Header>() == 128);
const _: () = assert!(size_of::<TexelRecord>() == 64);
const _: () = assert!(size_of::<TileRecord>() == 32);
const _: () = assert!(size_of::<MeshRecord>() == 32);
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
/// increasing row-major pixels (so no pixel appears twice).
pub(super) fn check_tile_texels(t: &TileRecord, texels: &[TexelRecord]) -> Result<(), Defect> {
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
