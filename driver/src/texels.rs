//! `texels`: the texel file — the contract between whatever laid out the lightmap and the
//! bake (docs/ARCHITECTURE.md). Field-by-field layout: `docs/texel-format.md`.
//!
//! The paper (Silvennoinen & Sloan 2019, §2.1) bakes texels grouped into clusters of nearby
//! texels with similar normals; the bake therefore streams **tiles** of up to 32×32 texels
//! and clusters inside a tile. This module owns the file: a streaming [`TexelWriter`] that
//! never holds more than one tile, and a validating, zero-copy [`TexelFile`] reader over a
//! memory map.
//!
//! Records are **array of structures**, one 64-byte [`TexelRecord`] per texel (a cache line):
//! every consumer of a texel reads nearly all of it together — clustering reads position and
//! normal, ray generation reads position, normal and both footprint axes, the output writer
//! reads page and pixel — so SoA would touch four streams where AoS touches one line.
//!
//! ## Memory-map invariant
//! [`TexelFile`] is the only owner of texel-file maps in the driver. **The file must not be
//! modified or truncated by anyone while it is mapped**: validation happens once, on open,
//! and everything after trusts it. Writers never write in place: they write `NAME.tmp-PID`
//! and rename over `NAME` on success, so a reader holding the old inode is unaffected.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

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
    /// Bit 0: the mesh has lightmap UVs (otherwise it has no texels).
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

/// Why a texel file could not be written or opened. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum TexelFileError {
    /// Reading, writing, mapping or renaming failed.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is shorter than its header or than its header says.
    #[error("{path}: truncated: {what} needs {needed} bytes, the file has {actual}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Which part.
        what: &'static str,
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        actual: u64,
    },
    /// The first eight bytes are not [`MAGIC`].
    #[error("{path}: offset 0: not a texel file (magic {found:?}, expected \"GBTEXELS\")")]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The bytes found.
        found: [u8; 8],
    },
    /// A version this build does not read.
    #[error(
        "{path}: offset 8: version {found} is not supported (this build reads version {VERSION})"
    )]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The version found.
        found: u32,
    },
    /// A header field is inconsistent.
    #[error("{path}: header: {message}")]
    BadHeader {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A section lies (partly) past the end of the file, or its size overflows.
    #[error(
        "{path}: {section} section at offset {offset} with {len} bytes ends past the end of the {file_len}-byte file"
    )]
    SectionOutOfBounds {
        /// The file.
        path: PathBuf,
        /// Section name.
        section: &'static str,
        /// Its offset.
        offset: u64,
        /// Its length (saturated at `u64::MAX` when it overflows).
        len: u64,
        /// File length.
        file_len: u64,
    },
    /// A section does not start at a multiple of [`SECTION_ALIGN`].
    #[error("{path}: {section} section offset {offset} is not a multiple of {SECTION_ALIGN}")]
    Misaligned {
        /// The file.
        path: PathBuf,
        /// Section name.
        section: &'static str,
        /// Its offset.
        offset: u64,
    },
    /// Two sections overlap.
    #[error("{path}: sections {a} and {b} overlap")]
    Overlap {
        /// The file.
        path: PathBuf,
        /// One section.
        a: &'static str,
        /// The other.
        b: &'static str,
    },
    /// A page record is invalid.
    #[error("{path}: page {page} (offset {offset}): {message}")]
    BadPage {
        /// The file.
        path: PathBuf,
        /// Page index.
        page: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// A mesh record is invalid.
    #[error("{path}: mesh {mesh} (offset {offset}): {message}")]
    BadMesh {
        /// The file.
        path: PathBuf,
        /// Mesh index.
        mesh: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// A tile record is invalid.
    #[error("{path}: tile {tile} (offset {offset}): {message}")]
    BadTile {
        /// The file.
        path: PathBuf,
        /// Tile index.
        tile: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// A texel record is invalid.
    #[error("{path}: texel {texel} (offset {offset}): {message}")]
    BadTexel {
        /// The file.
        path: PathBuf,
        /// Texel index.
        texel: u64,
        /// Byte offset of the record.
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// The writer was used out of order (a caller bug, reported instead of panicking).
    #[error("{path}: writer misuse: {message}")]
    Usage {
        /// The file being written.
        path: PathBuf,
        /// What happened.
        message: String,
    },
}

fn align_up(x: u64) -> u64 {
    x.div_ceil(SECTION_ALIGN) * SECTION_ALIGN
}

/// A tile as the writer receives it: its rectangle and its texels in row-major pixel order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileRect {
    /// Page index.
    pub page: u32,
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
}

/// Streaming texel-file writer. Layout written: header, pages, meshes (known up front),
/// texels (appended tile by tile), tile table (spooled to a side file while writing and
/// appended by [`TexelWriter::finish`], which then patches the header and renames the
/// temporary file into place). Memory use is one tile, whatever the world size.
///
/// Dropping a writer without `finish` removes its temporary files.
pub struct TexelWriter {
    path: PathBuf,
    tmp: PathBuf,
    tiles_tmp: PathBuf,
    out: BufWriter<File>,
    tiles_out: BufWriter<File>,
    header: Header,
    pages: Vec<PageRecord>,
    lo: Vec3,
    hi: Vec3,
    finished: bool,
}

impl TexelWriter {
    /// Starts writing `path` (through a temporary name beside it).
    ///
    /// # Errors
    /// [`TexelFileError::Io`] if the temporary files cannot be created;
    /// [`TexelFileError::Usage`] for pages outside 1..=65536 or meshes on missing pages.
    pub fn create(
        path: &Path,
        pages: &[PageRecord],
        meshes: &[MeshRecord],
        triangle_count: u32,
        texels_per_unit: f32,
    ) -> Result<Self, TexelFileError> {
        let usage = |message: String| TexelFileError::Usage {
            path: path.to_owned(),
            message,
        };
        if let Some(p) = pages
            .iter()
            .find(|p| !(1..=65536).contains(&p.width) || !(1..=65536).contains(&p.height))
        {
            return Err(usage(format!(
                "page size {}x{} is outside 1..=65536",
                p.width, p.height
            )));
        }
        if let Some(m) = meshes.iter().find(|m| m.page as usize >= pages.len()) {
            return Err(usage(format!("mesh on page {} of {}", m.page, pages.len())));
        }
        if let Some(m) = meshes.iter().find(|m| {
            u64::from(m.first_triangle) + u64::from(m.triangle_count) > u64::from(triangle_count)
                || !m.uv_scale.iter().chain(&m.uv_offset).all(|v| v.is_finite())
        }) {
            return Err(usage(format!(
                "mesh record {m:?} does not fit {triangle_count} triangles or is not finite"
            )));
        }
        let tmp = crate::output::atomic::temporary_name(path);
        let tiles_tmp = crate::output::atomic::with_suffix(path, "tiles");
        let io = |what| {
            move |source| TexelFileError::Io {
                path: path.to_owned(),
                what,
                source,
            }
        };
        let out = BufWriter::with_capacity(
            1 << 20,
            File::create(&tmp).map_err(io("create temporary file"))?,
        );
        let tiles_out =
            BufWriter::new(File::create(&tiles_tmp).map_err(io("create temporary tile file"))?);
        let pages_offset = align_up(size_of::<Header>() as u64);
        let meshes_offset = align_up(pages_offset + size_of_val(pages) as u64);
        let texels_offset = align_up(meshes_offset + size_of_val(meshes) as u64);
        let header = Header {
            magic: MAGIC,
            version: VERSION,
            header_size: size_of::<Header>() as u32,
            page_count: pages.len() as u32,
            tile_size: TILE_SIZE,
            mesh_count: meshes.len() as u32,
            triangle_count,
            pages_offset,
            meshes_offset,
            texels_offset,
            texels_per_unit,
            ..Zeroable::zeroed()
        };
        let mut w = Self {
            path: path.to_owned(),
            tmp,
            tiles_tmp,
            out,
            tiles_out,
            header,
            pages: pages.to_vec(),
            lo: Vec3::splat(f32::INFINITY),
            hi: Vec3::splat(f32::NEG_INFINITY),
            finished: false,
        };
        w.write_at_cursor(bytemuck::bytes_of(&header), 0)?;
        w.write_at_cursor(bytemuck::cast_slice(pages), pages_offset)?;
        w.write_at_cursor(bytemuck::cast_slice(meshes), meshes_offset)?;
        w.pad_to(texels_offset)?;
        Ok(w)
    }

    fn cursor(&self) -> u64 {
        self.header.texels_offset + self.header.texel_count * size_of::<TexelRecord>() as u64
    }

    fn io(&self, what: &'static str) -> impl FnOnce(std::io::Error) -> TexelFileError + '_ {
        move |source| TexelFileError::Io {
            path: self.path.clone(),
            what,
            source,
        }
    }

    fn write_at_cursor(&mut self, bytes: &[u8], offset: u64) -> Result<(), TexelFileError> {
        self.pad_to(offset)?;
        self.out
            .write_all(bytes)
            .map_err(|source| TexelFileError::Io {
                path: self.path.clone(),
                what: "write",
                source,
            })
    }

    fn pad_to(&mut self, offset: u64) -> Result<(), TexelFileError> {
        let pos = self
            .out
            .stream_position()
            .map_err(|source| TexelFileError::Io {
                path: self.path.clone(),
                what: "seek",
                source,
            })?;
        let zeros = [0u8; SECTION_ALIGN as usize];
        let mut left = offset.saturating_sub(pos);
        while left > 0 {
            let n = left.min(SECTION_ALIGN) as usize;
            self.out
                .write_all(&zeros[..n])
                .map_err(|source| TexelFileError::Io {
                    path: self.path.clone(),
                    what: "write",
                    source,
                })?;
            left -= n as u64;
        }
        Ok(())
    }

    /// Appends one tile. `texels` must be non-empty, on `rect.page`, inside `rect`, in
    /// strictly increasing row-major pixel order, and pass the reader's checks.
    ///
    /// # Errors
    /// [`TexelFileError::Usage`] naming the first offending texel, or an I/O error.
    pub fn push_tile(
        &mut self,
        rect: TileRect,
        texels: &[TexelRecord],
    ) -> Result<(), TexelFileError> {
        let tile = TileRecord {
            page: rect.page,
            x: rect.x,
            y: rect.y,
            width: rect.width,
            height: rect.height,
            texel_count: texels.len() as u32,
            first_texel: self.header.texel_count,
        };
        let index = self.header.tile_count;
        check_tile(
            &tile,
            &self.pages,
            self.header.tile_size,
            self.header.texel_count,
        )
        .and_then(|()| check_tile_texels(&tile, texels))
        .map_err(|(i, m)| TexelFileError::Usage {
            path: self.path.clone(),
            message: match i {
                Some(i) => format!("tile {index}, texel {i}: {m}"),
                None => format!("tile {index}: {m}"),
            },
        })?;
        for t in texels {
            self.lo = self.lo.min(t.position());
            self.hi = self.hi.max(t.position());
        }
        self.out
            .write_all(bytemuck::cast_slice(texels))
            .map_err(self.io("write texels"))?;
        self.tiles_out
            .write_all(bytemuck::bytes_of(&tile))
            .map_err(self.io("write tile table"))?;
        self.header.texel_count += texels.len() as u64;
        self.header.tile_count += 1;
        Ok(())
    }

    /// Number of texels written so far.
    #[must_use]
    pub fn texel_count(&self) -> u64 {
        self.header.texel_count
    }

    /// Appends the tile table, patches the header, syncs and renames into place.
    ///
    /// # Errors
    /// An I/O error; the temporary files are removed and `path` is left untouched.
    pub fn finish(mut self) -> Result<Header, TexelFileError> {
        let tiles_offset = align_up(self.cursor());
        self.pad_to(tiles_offset)?;
        self.tiles_out
            .flush()
            .map_err(self.io("flush tile table"))?;
        let mut spool = File::open(&self.tiles_tmp).map_err(self.io("reopen tile table"))?;
        std::io::copy(&mut spool, &mut self.out).map_err(self.io("append tile table"))?;
        self.header.tiles_offset = tiles_offset;
        self.header.file_size =
            tiles_offset + self.header.tile_count * size_of::<TileRecord>() as u64;
        if self.header.texel_count > 0 {
            self.header.bounds_min = self.lo.to_array();
            self.header.bounds_max = self.hi.to_array();
        }
        let header = self.header;
        self.out.seek(SeekFrom::Start(0)).map_err(self.io("seek"))?;
        self.out
            .write_all(bytemuck::bytes_of(&header))
            .map_err(self.io("patch header"))?;
        self.out.flush().map_err(self.io("flush"))?;
        self.out.get_ref().sync_all().map_err(self.io("sync"))?;
        std::fs::rename(&self.tmp, &self.path).map_err(self.io("rename into place"))?;
        self.finished = true;
        let _ = std::fs::remove_file(&self.tiles_tmp);
        Ok(header)
    }
}

impl Drop for TexelWriter {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.tiles_tmp);
        if !self.finished {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

type Defect = (Option<usize>, String);

/// Checks a tile record against the pages and the running texel count.
fn check_tile(
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
fn check_tile_texels(t: &TileRecord, texels: &[TexelRecord]) -> Result<(), Defect> {
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

/// A validated, memory-mapped texel file. Accessors hand out slices into the map.
pub struct TexelFile {
    path: PathBuf,
    header: Header,
    map: memmap2::Mmap,
}

impl std::fmt::Debug for TexelFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TexelFile")
            .field("path", &self.path)
            .field("header", &self.header)
            .finish()
    }
}

impl TexelFile {
    /// Maps and validates a texel file: magic, version, header fields, every section within
    /// the file, aligned and disjoint, every page, mesh and tile record, and every texel
    /// (finite position and axes, unit normal, known flags, inside its tile, no pixel twice).
    ///
    /// # Errors
    /// A [`TexelFileError`] naming the file, the offset and the record.
    pub fn open(path: &Path) -> Result<Self, TexelFileError> {
        let io = |what| {
            move |source| TexelFileError::Io {
                path: path.to_owned(),
                what,
                source,
            }
        };
        let file = File::open(path).map_err(io("open"))?;
        // SAFETY: the module invariant — nobody modifies or truncates the file while it is
        // mapped (writers write a temporary file and rename it). Every byte read below is
        // bounds-checked against `map.len()` before it is cast.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io("map"))?;
        // Validation reads every texel once; each tile's pages are released behind it, so
        // opening a file larger than memory does not fill the resident set.
        let header = validate(path, &map, &mut |start, count| {
            release_texels(&map, start, count);
        })?;
        Ok(Self {
            path: path.to_owned(),
            header,
            map,
        })
    }

    /// The file's path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header.
    #[must_use]
    pub fn header(&self) -> &Header {
        &self.header
    }

    fn section<T: Pod>(&self, offset: u64, count: u64) -> &[T] {
        let start = offset as usize;
        let bytes = &self.map[start..start + count as usize * size_of::<T>()];
        // Validated on open: in bounds, 64-byte aligned within a page-aligned map.
        bytemuck::cast_slice(bytes)
    }

    /// Atlas pages.
    #[must_use]
    pub fn pages(&self) -> &[PageRecord] {
        self.section(self.header.pages_offset, u64::from(self.header.page_count))
    }

    /// Mesh table (UV → page/pixel mapping per mesh).
    #[must_use]
    pub fn meshes(&self) -> &[MeshRecord] {
        self.section(self.header.meshes_offset, u64::from(self.header.mesh_count))
    }

    /// Tile table in file order.
    #[must_use]
    pub fn tiles(&self) -> &[TileRecord] {
        self.section(self.header.tiles_offset, self.header.tile_count)
    }

    /// All texel records.
    #[must_use]
    pub fn texels(&self) -> &[TexelRecord] {
        self.section(self.header.texels_offset, self.header.texel_count)
    }

    /// Lets the kernel drop the pages holding tile `tile`'s texels from this process's memory
    /// (`madvise(MADV_DONTNEED)`): a bake calls it when the tile is done, so a streaming bake's
    /// resident set does not grow with the texel file. The data stays valid: a later read
    /// faults the pages back in from the file. Pages shared with a neighbouring tile are
    /// dropped too and reread when needed. Failures are ignored (the advice is optional).
    pub fn release_tile(&self, tile: usize) {
        if let Some(t) = self.tiles().get(tile) {
            let start = self.header.texels_offset + t.first_texel * size_of::<TexelRecord>() as u64;
            release_texels(&self.map, start, u64::from(t.texel_count));
        }
    }

    /// The texels of one tile.
    ///
    /// # Panics
    /// If `tile` is out of range.
    #[must_use]
    pub fn tile_texels(&self, tile: usize) -> &[TexelRecord] {
        let t = self.tiles()[tile];
        let first = t.first_texel as usize;
        &self.texels()[first..first + t.texel_count as usize]
    }
}

/// Bytes the kernel may map around a page fault (Linux's default `fault_around_bytes`).
const FAULT_AROUND: u64 = 64 * 1024;

/// Drops the pages of `count` texel records at byte `start` of `map` from memory (advice;
/// failures are ignored). The range is widened by [`FAULT_AROUND`] on each side (clamped to
/// the map): the kernel maps pages around each fault, so a tile's neighbours' pages may be
/// mapped too, and those of tiles another shard bakes would otherwise stay behind. Pages
/// released while still in use are simply faulted in again.
fn release_texels(map: &memmap2::Mmap, start: u64, count: u64) {
    let end = start.saturating_add(count * size_of::<TexelRecord>() as u64);
    let from = start.saturating_sub(FAULT_AROUND);
    let to = end.saturating_add(FAULT_AROUND).min(map.len() as u64);
    if from >= to {
        return;
    }
    // SAFETY: the range lies within the map. MADV_DONTNEED on this read-only, file-backed
    // mapping only discards cached pages; the module invariant (the file is never modified
    // while mapped) makes every later read see the same bytes, so slices handed out earlier
    // stay valid and unchanged.
    let _ = unsafe {
        map.unchecked_advise_range(
            memmap2::UncheckedAdvice::DontNeed,
            from as usize,
            (to - from) as usize,
        )
    };
}

/// Header and section checks, then every record; `release(byte offset, texels)` is called
/// behind each validated tile.
fn validate(
    path: &Path,
    map: &[u8],
    release: &mut dyn FnMut(u64, u64),
) -> Result<Header, TexelFileError> {
    let file_len = map.len() as u64;
    let hsize = size_of::<Header>() as u64;
    if file_len < hsize {
        return Err(TexelFileError::Truncated {
            path: path.to_owned(),
            what: "the header",
            needed: hsize,
            actual: file_len,
        });
    }
    let header: Header = bytemuck::pod_read_unaligned(&map[..hsize as usize]);
    if header.magic != MAGIC {
        return Err(TexelFileError::BadMagic {
            path: path.to_owned(),
            found: header.magic,
        });
    }
    if header.version != VERSION {
        return Err(TexelFileError::UnsupportedVersion {
            path: path.to_owned(),
            found: header.version,
        });
    }
    let bad = |message: String| TexelFileError::BadHeader {
        path: path.to_owned(),
        message,
    };
    if u64::from(header.header_size) != hsize {
        return Err(bad(format!(
            "offset 12: header_size {} (expected {hsize})",
            header.header_size
        )));
    }
    if header.file_size != file_len {
        if header.file_size > file_len {
            return Err(TexelFileError::Truncated {
                path: path.to_owned(),
                what: "the size in the header",
                needed: header.file_size,
                actual: file_len,
            });
        }
        return Err(bad(format!(
            "offset 16: file_size {} but the file has {file_len} bytes",
            header.file_size
        )));
    }
    if header.tile_size == 0 || header.tile_size > 256 {
        return Err(bad(format!(
            "offset 44: tile_size {} is outside 1..=256",
            header.tile_size
        )));
    }
    if header.flags != 0 || header.reserved != [0; 8] {
        return Err(bad("offset 116: reserved fields are not zero".into()));
    }
    let sections = [
        (
            "page",
            header.pages_offset,
            u64::from(header.page_count),
            size_of::<PageRecord>() as u64,
        ),
        (
            "mesh",
            header.meshes_offset,
            u64::from(header.mesh_count),
            size_of::<MeshRecord>() as u64,
        ),
        (
            "texel",
            header.texels_offset,
            header.texel_count,
            size_of::<TexelRecord>() as u64,
        ),
        (
            "tile",
            header.tiles_offset,
            header.tile_count,
            size_of::<TileRecord>() as u64,
        ),
    ];
    let mut spans = Vec::with_capacity(4);
    for (name, offset, count, size) in sections {
        let len = count.checked_mul(size);
        let end = len.and_then(|l| offset.checked_add(l));
        match end {
            Some(end) if end <= file_len && offset >= hsize => {}
            _ => {
                return Err(TexelFileError::SectionOutOfBounds {
                    path: path.to_owned(),
                    section: name,
                    offset,
                    len: len.unwrap_or(u64::MAX),
                    file_len,
                });
            }
        }
        if offset % SECTION_ALIGN != 0 {
            return Err(TexelFileError::Misaligned {
                path: path.to_owned(),
                section: name,
                offset,
            });
        }
        spans.push((name, offset, offset + count * size));
    }
    for (i, a) in spans.iter().enumerate() {
        for b in &spans[i + 1..] {
            if a.1 < a.2 && b.1 < b.2 && a.1 < b.2 && b.1 < a.2 {
                return Err(TexelFileError::Overlap {
                    path: path.to_owned(),
                    a: a.0,
                    b: b.0,
                });
            }
        }
    }
    // Sections are in bounds and 64-aligned from a page-aligned map: the casts succeed.
    let cast = |offset: u64, bytes: u64| &map[offset as usize..(offset + bytes) as usize];
    let pages: &[PageRecord] = try_cast(
        path,
        cast(header.pages_offset, u64::from(header.page_count) * 8),
        "page",
        header.pages_offset,
    )?;
    let meshes: &[MeshRecord] = try_cast(
        path,
        cast(header.meshes_offset, u64::from(header.mesh_count) * 32),
        "mesh",
        header.meshes_offset,
    )?;
    let tiles: &[TileRecord] = try_cast(
        path,
        cast(header.tiles_offset, header.tile_count * 32),
        "tile",
        header.tiles_offset,
    )?;
    let texels: &[TexelRecord] = try_cast(
        path,
        cast(header.texels_offset, header.texel_count * 64),
        "texel",
        header.texels_offset,
    )?;
    validate_records(path, &header, pages, meshes, tiles, texels, release)?;
    Ok(header)
}

fn try_cast<'a, T: Pod>(
    path: &Path,
    bytes: &'a [u8],
    section: &'static str,
    offset: u64,
) -> Result<&'a [T], TexelFileError> {
    bytemuck::try_cast_slice(bytes).map_err(|_| TexelFileError::Misaligned {
        path: path.to_owned(),
        section,
        offset,
    })
}

fn validate_records(
    path: &Path,
    h: &Header,
    pages: &[PageRecord],
    meshes: &[MeshRecord],
    tiles: &[TileRecord],
    texels: &[TexelRecord],
    release: &mut dyn FnMut(u64, u64),
) -> Result<(), TexelFileError> {
    for (i, p) in pages.iter().enumerate() {
        if !(1..=65536).contains(&p.width) || !(1..=65536).contains(&p.height) {
            return Err(TexelFileError::BadPage {
                path: path.to_owned(),
                page: i as u64,
                offset: h.pages_offset + 8 * i as u64,
                message: format!("size {}x{} is outside 1..=65536", p.width, p.height),
            });
        }
    }
    for (i, m) in meshes.iter().enumerate() {
        let finite = m.uv_scale.iter().chain(&m.uv_offset).all(|v| v.is_finite());
        let msg = if m.page as usize >= pages.len() {
            Some(format!("page {} does not exist", m.page))
        } else if !finite {
            Some("UV transform is not finite".to_owned())
        } else if u64::from(m.first_triangle) + u64::from(m.triangle_count)
            > u64::from(h.triangle_count)
        {
            Some(format!(
                "triangles {}+{} exceed the scene's {}",
                m.first_triangle, m.triangle_count, h.triangle_count
            ))
        } else {
            None
        };
        if let Some(message) = msg {
            return Err(TexelFileError::BadMesh {
                path: path.to_owned(),
                mesh: i as u64,
                offset: h.meshes_offset + 32 * i as u64,
                message,
            });
        }
    }
    let mut next = 0u64;
    for (i, t) in tiles.iter().enumerate() {
        let tile_err = |message: String| TexelFileError::BadTile {
            path: path.to_owned(),
            tile: i as u64,
            offset: h.tiles_offset + 32 * i as u64,
            message,
        };
        check_tile(t, pages, h.tile_size, next).map_err(|(_, m)| tile_err(m))?;
        let end = next + u64::from(t.texel_count);
        if end > h.texel_count {
            return Err(tile_err(format!(
                "texels {next}..{end} exceed the {} in the file",
                h.texel_count
            )));
        }
        check_tile_texels(t, &texels[next as usize..end as usize]).map_err(
            |(j, message)| match j {
                Some(j) => {
                    let texel = next + j as u64;
                    TexelFileError::BadTexel {
                        path: path.to_owned(),
                        texel,
                        offset: h.texels_offset + 64 * texel,
                        message: format!("{message} (tile {i})"),
                    }
                }
                None => tile_err(message),
            },
        )?;
        if let Some((j, x)) =
            texels[next as usize..end as usize]
                .iter()
                .enumerate()
                .find(|(_, x)| {
                    x.triangle != u32::MAX && x.triangle >= h.triangle_count && h.triangle_count > 0
                })
        {
            let texel = next + j as u64;
            return Err(TexelFileError::BadTexel {
                path: path.to_owned(),
                texel,
                offset: h.texels_offset + 64 * texel,
                message: format!("triangle {} of {}", x.triangle, h.triangle_count),
            });
        }
        release(h.texels_offset + 64 * next, end - next);
        next = end;
    }
    if next != h.texel_count {
        return Err(TexelFileError::BadHeader {
            path: path.to_owned(),
            message: format!(
                "offset 24: texel_count {} but the tiles hold {next}",
                h.texel_count
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::Pcg32;

    pub(crate) fn random_texel(rng: &mut Pcg32, page: u32, x: u16, y: u16) -> TexelRecord {
        let mut v = || {
            [
                rng.next_f32() * 20.0 - 10.0,
                rng.next_f32() * 20.0 - 10.0,
                rng.next_f32() * 20.0 - 10.0,
            ]
        };
        let p = v();
        let n = Vec3::from(v()).normalize_or(Vec3::Z).to_array();
        TexelRecord {
            position: p,
            normal: n,
            dpdu: v(),
            dpdv: v(),
            page,
            pixel: [x, y],
            triangle: 7,
            flags: FLAG_VALID,
        }
    }

    #[test]
    fn round_trip_is_identical() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.texels");
        let pages = [
            PageRecord {
                width: 70,
                height: 40,
            },
            PageRecord {
                width: 32,
                height: 32,
            },
        ];
        let meshes = [MeshRecord {
            first_triangle: 0,
            triangle_count: 8,
            page: 1,
            flags: 1,
            uv_scale: [32.0; 2],
            uv_offset: [0.0; 2],
        }];
        let mut w = TexelWriter::create(&path, &pages, &meshes, 8, 4.0).unwrap();
        let mut rng = Pcg32::new(5, 1);
        let mut all = Vec::new();
        for (page, tx, ty, tw, th) in [
            (0u32, 64u32, 32u32, 6u32, 8u32),
            (0, 0, 0, 32, 32),
            (1, 0, 0, 32, 32),
        ] {
            let mut tile = Vec::new();
            for y in ty..ty + th {
                for x in tx..tx + tw {
                    if !rng.next_u32().is_multiple_of(3) {
                        tile.push(random_texel(&mut rng, page, x as u16, y as u16));
                    }
                }
            }
            w.push_tile(
                TileRect {
                    page,
                    x: tx,
                    y: ty,
                    width: tw,
                    height: th,
                },
                &tile,
            )
            .unwrap();
            all.push(tile);
        }
        let h = w.finish().unwrap();
        let f = TexelFile::open(&path).unwrap();
        assert_eq!(*f.header(), h);
        assert_eq!(f.pages(), pages);
        assert_eq!(f.meshes(), meshes);
        assert_eq!(f.tiles().len(), 3);
        for (i, tile) in all.iter().enumerate() {
            assert_eq!(f.tile_texels(i), tile.as_slice());
        }
        assert_eq!(f.texels().len(), all.iter().map(Vec::len).sum::<usize>());
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "temporary files left behind"
        );
    }

    #[test]
    fn writer_rejects_bad_texels_and_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.texels");
        let mut w = TexelWriter::create(
            &path,
            &[PageRecord {
                width: 8,
                height: 8,
            }],
            &[],
            0,
            0.0,
        )
        .unwrap();
        let mut rng = Pcg32::new(1, 1);
        let mut t = random_texel(&mut rng, 0, 1, 1);
        t.normal = [0.0; 3];
        let e = w
            .push_tile(
                TileRect {
                    page: 0,
                    x: 0,
                    y: 0,
                    width: 8,
                    height: 8,
                },
                &[t],
            )
            .unwrap_err();
        assert!(e.to_string().contains("normal"), "{e}");
        drop(w);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
