//! The streaming writer: one tile in memory, a temporary file renamed into place.

use super::*;

/// Where a tile lies: its page and the rectangle of pixels that holds its texels (the writer
/// receives a tile's texels in it, in row-major pixel order; a series pass image reads its
/// source's tiles by it, `transport::pass_image::Source::rect`).
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

/// Streaming texel-file writer. Layout written: header, pages, triangles (known up front),
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
    /// Per triangle: whether it has lightmap UVs (texels may lie only on those).
    mapped: Vec<bool>,
    lo: Vec3,
    hi: Vec3,
    finished: bool,
}

impl TexelWriter {
    /// Starts writing `path` (through a temporary name beside it).
    ///
    /// # Errors
    /// [`TexelFileError::Io`] if the temporary files cannot be created;
    /// [`TexelFileError::Usage`] for pages outside 1..=65536, more than `u32::MAX - 1`
    /// triangles, or a triangle record the reader would refuse (a missing page, UVs that are
    /// not finite, unknown flags).
    pub fn create(
        path: &Path,
        pages: &[PageRecord],
        triangles: &[TriangleRecord],
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
        let Ok(triangle_count) = u32::try_from(triangles.len()) else {
            return Err(usage(format!(
                "{} triangles; at most 2^32 - 1",
                triangles.len()
            )));
        };
        if let Some((i, message)) = check_triangles(triangles, pages.len()) {
            return Err(usage(format!("triangle {i}: {message}")));
        }
        let tmp = crate::atomic::temporary_name(path);
        let tiles_tmp = crate::atomic::with_suffix(path, "tiles");
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
        let triangles_offset = align_up(pages_offset + size_of_val(pages) as u64);
        let texels_offset = align_up(triangles_offset + size_of_val(triangles) as u64);
        let header = Header {
            magic: MAGIC,
            version: VERSION,
            header_size: size_of::<Header>() as u32,
            page_count: pages.len() as u32,
            tile_size: TILE_SIZE,
            triangle_count,
            pages_offset,
            triangles_offset,
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
            mapped: triangles
                .iter()
                .map(|t| t.flags & LIGHTMAPPED != 0)
                .collect(),
            lo: Vec3::splat(f32::INFINITY),
            hi: Vec3::splat(f32::NEG_INFINITY),
            finished: false,
        };
        w.write_at_cursor(bytemuck::bytes_of(&header), 0)?;
        w.write_at_cursor(bytemuck::cast_slice(pages), pages_offset)?;
        w.write_at_cursor(bytemuck::cast_slice(triangles), triangles_offset)?;
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

    /// Records the [`Scene::lighting_fingerprint`](crate::scene::Scene::lighting_fingerprint)
    /// of the lights the seen sides were decided under (header offset 120; 0, the default,
    /// when not recorded).
    pub fn set_lighting(&mut self, fingerprint: u64) {
        self.header.lighting = fingerprint;
    }

    /// Records the [`Scene::geometry_fingerprint`](crate::scene::Scene::geometry_fingerprint)
    /// of the scene the file is prepared from (header offset 128), which `bake` and `render`
    /// check their scene against. Every guidebake command that writes a texel file records it;
    /// a file written without it (0) is checked by its triangle count alone.
    pub fn set_geometry(&mut self, fingerprint: u64) {
        self.header.geometry = fingerprint;
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
        .and_then(|()| {
            let mapped = |i: u32| self.mapped.get(i as usize).copied();
            check_tile_texels(&tile, texels, &mapped)
        })
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
