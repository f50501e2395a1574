//! The validating, zero-copy reader over a memory map.

use super::*;

/// A validated, memory-mapped texel file. Accessors hand out slices into the map.
pub struct TexelFile {
    path: PathBuf,
    header: Header,
    map: memmap2::Mmap,
    identity: std::sync::OnceLock<u64>,
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
    /// the file, aligned and disjoint, every page, triangle and tile record, and every texel
    /// (finite position and axes, unit normal, known flags, inside its tile, no pixel twice,
    /// on a triangle with lightmap UVs).
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
        // An empty file cannot be mapped; it is no texel file either.
        if file.metadata().map_err(io("stat"))?.len() == 0 {
            return Err(TexelFileError::BadMagic {
                path: path.to_owned(),
                found: [0; 8],
                kind: Some(FileKind::Empty),
            });
        }
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
            identity: std::sync::OnceLock::new(),
        })
    }

    /// The file's identity, never 0: a hash of its header (which records the scene's geometry,
    /// [`Header::geometry`]), page table, triangle table and tile table — everything but the
    /// texel records, which `prepare` derives from those deterministically. A bake's work
    /// directory and its lightmap record it (docs/texels.md, "What a file knows about what
    /// made it"), so `--resume`, `merge` and `render` refuse work made for another texel file.
    /// Computed once, on first use.
    #[must_use]
    pub fn identity(&self) -> u64 {
        *self.identity.get_or_init(|| {
            // Each section's length in words first, then its words.
            let mut h = crate::hash::WordHash::new(3);
            let mut words = |w: &[u32]| {
                h.word(w.len() as u32);
                for &x in w {
                    h.word(x);
                }
            };
            words(bytemuck::cast_slice(std::slice::from_ref(&self.header)));
            words(bytemuck::cast_slice(self.pages()));
            words(bytemuck::cast_slice(self.triangles()));
            words(bytemuck::cast_slice(self.tiles()));
            h.finish()
        })
    }

    /// The header of the texel file at `path` when it starts with a header of this version (read
    /// without mapping or validating the rest: a command's early checks; [`TexelFile::open`]
    /// reports what is wrong with a file), else `None`.
    #[must_use]
    pub fn peek_header(path: &Path) -> Option<Header> {
        use std::io::Read;
        let mut bytes = [0u8; size_of::<Header>()];
        File::open(path).ok()?.read_exact(&mut bytes).ok()?;
        let header: Header = bytemuck::pod_read_unaligned(&bytes);
        (header.magic == MAGIC && header.version == VERSION).then_some(header)
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

    /// Triangle table: every scene triangle's lightmap UVs and seen sides, in the scene's
    /// triangle order.
    #[must_use]
    pub fn triangles(&self) -> &[TriangleRecord] {
        self.section(
            self.header.triangles_offset,
            u64::from(self.header.triangle_count),
        )
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

/// How far around a released range pages are dropped too: the largest page-cache folio a
/// fault may map at once (a PMD, 2 MiB on x86-64). A fault on a file mapping maps the whole
/// folio around it (Linux's fault-around, 64 KiB, or a large folio of up to 2 MiB), so a
/// range released with a smaller margin is mapped again by the next fault in the same folio
/// and stays resident for good: measured on Linux 6.18, reading a 61 MB texel file tile by
/// tile and releasing each with a 64 KiB margin left 28 MB resident; 512 KiB or more left
/// none (docs/farm.md, "Resident memory after the release fix").
pub(super) const RELEASE_MARGIN: u64 = 2 << 20;

/// Drops the pages of `count` texel records at byte `start` of `map` from memory (advice;
/// failures are ignored). The range is widened by [`RELEASE_MARGIN`] on each side (clamped to
/// the map): pages of the folios a fault mapped around the range, which may hold texels of
/// neighbouring tiles, including tiles another shard bakes. Pages released while still in
/// use are simply faulted in again.
fn release_texels(map: &memmap2::Mmap, start: u64, count: u64) {
    let end = start.saturating_add(count * size_of::<TexelRecord>() as u64);
    let from = start.saturating_sub(RELEASE_MARGIN);
    let to = end.saturating_add(RELEASE_MARGIN).min(map.len() as u64);
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
    // The magic and the version first: a file of another kind, or of an older version with a
    // shorter header, is told so rather than called truncated.
    let mut found = [0u8; 8];
    let n = map.len().min(8);
    found[..n].copy_from_slice(&map[..n]);
    if map[..n] != MAGIC[..n] {
        return Err(TexelFileError::BadMagic {
            path: path.to_owned(),
            found,
            kind: what_file_is(&map[..map.len().min(512)]),
        });
    }
    if file_len >= 12 {
        let version = u32::from_le_bytes(map[8..12].try_into().expect("four bytes"));
        if version != VERSION {
            return Err(TexelFileError::UnsupportedVersion {
                path: path.to_owned(),
                found: version,
            });
        }
    }
    if file_len < hsize {
        return Err(TexelFileError::Truncated {
            path: path.to_owned(),
            what: "the header",
            needed: hsize,
            actual: file_len,
        });
    }
    let header: Header = bytemuck::pod_read_unaligned(&map[..hsize as usize]);
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
    if header.flags != 0 {
        return Err(bad("offset 116: reserved field is not zero".into()));
    }
    if header.reserved0 != 0 {
        return Err(bad("offset 48: reserved field is not zero".into()));
    }
    if let Some(i) = header.reserved.iter().position(|&r| r != 0) {
        return Err(bad(format!(
            "offset {}: reserved field is not zero",
            136 + 8 * i
        )));
    }
    let sections = [
        (
            "page",
            header.pages_offset,
            u64::from(header.page_count),
            size_of::<PageRecord>() as u64,
        ),
        (
            "triangle",
            header.triangles_offset,
            u64::from(header.triangle_count),
            size_of::<TriangleRecord>() as u64,
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
    let triangles: &[TriangleRecord] = try_cast(
        path,
        cast(
            header.triangles_offset,
            u64::from(header.triangle_count) * 32,
        ),
        "triangle",
        header.triangles_offset,
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
    validate_records(path, &header, pages, triangles, tiles, texels, release)?;
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
    triangles: &[TriangleRecord],
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
    if let Some((i, message)) = check_triangles(triangles, pages.len()) {
        return Err(TexelFileError::BadTriangle {
            path: path.to_owned(),
            triangle: i as u64,
            offset: h.triangles_offset + 32 * i as u64,
            message,
        });
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
        let mapped = |i: u32| {
            triangles
                .get(i as usize)
                .map(|t| t.flags & LIGHTMAPPED != 0)
        };
        check_tile_texels(t, &texels[next as usize..end as usize], &mapped).map_err(
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
