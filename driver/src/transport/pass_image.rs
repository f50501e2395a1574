//! How a series pass image is stored ([`super::series::PreviousPass`]; docs/series.md, "The
//! pass image: only what is baked"): only the pixels that hold texels, each in 12 bytes,
//! found through a table of 8×8-pixel cells per page, and built on every core straight from
//! the pass's texels.
//!
//! - **Cells.** Each page is cut into [`CELL`]×[`CELL`]-pixel cells; a table holds, per cell,
//!   the last of its [`Block`]s (0: none). A block is what one source tile (a texel file's
//!   tile) holds of one cell: 64-bit masks of its baked, dilated-only and inside-geometry
//!   pixels, and where its colours start. Tiles do not overlap, so the blocks of one cell (a
//!   cell cut by tile edges) hold disjoint pixels; they are chained, each to an earlier one.
//! - **Colours.** One per baked or dilated pixel, in block order and within a block in pixel
//!   (bit) order, so pixel `i` of a block is colour `first + popcount(mask below i)`. A colour
//!   is both layers (gather-only, total), each RGB in 48 bits ([`pack_rgb`]: three 14-bit
//!   mantissas under one 6-bit exponent; the largest channel within 2⁻¹⁴ = 6.1e-5 of its
//!   value, the smaller ones within that much of the largest, 2⁻³² to 4.3·10⁹). Half floats
//!   (rounding up to 2⁻¹¹ of a value, at most 65 504) could put 2.4·10⁻⁴ of error into the
//!   closed rooms' texels, whose checks allow 10⁻⁴, and clip a bright sun (not tried);
//!   RGB9E5 (2⁻⁹) more so.
//! - **Build.** [`build`] reads the source's tiles page by page, top to bottom, in chunks (a
//!   few tiles per thread), every tile of a chunk on its own rayon worker, and appends their
//!   blocks and colours in that order: the bytes depend neither on the thread count nor on
//!   the order the source lists its tiles. With the lookups' filter
//!   ([`crate::transport::lookup_filter`]) each tile's baked colours are then replaced by
//!   their filtered values as soon as every tile within the filter's reach has been read,
//!   every ready tile on its own worker, reading the neighbours through the table from one
//!   [`Surfel`] per colour, held in memory only while a tile still to be filtered can reach
//!   it: a band of rows across a page, not one for every texel of the world
//!   ([`Built::filter_surfels`] counts the most it held).
//!
//! The file is the work directory's (written and read by one process; rebuilt by each run),
//! so its layout is in memory ([`Layout`], [`Built`]), not in a header.

use std::collections::VecDeque;

use glam::Vec3;
use rayon::prelude::*;

use crate::texels::{PageRecord, TileRect};
use crate::transport::lookup_filter::{Surfel, filtered_at};

/// Edge of a cell in pixels: one cell's pixels are one 64-bit mask.
pub const CELL: u32 = 8;

/// Tiles read per parallel step of the build, per worker thread: bounds its buffers (per
/// thread about 0.1 MB a tile, 0.5 MB with the filter's surfels, for 1 024-texel tiles)
/// whatever the world's size. 256 tiles a step held 34 MB of anonymous memory with the filter,
/// more than the whole bake of a 10⁶-texel world.
const CHUNK_TILES_PER_THREAD: usize = 4;

/// Both layers of one pixel: gather-only RGB (0..3) and total RGB (3..6), each [`pack_rgb`].
pub type Packed = [u16; 6];

/// What one source tile holds of one cell.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Block {
    /// Pixels holding a baked texel (one colour each).
    pub baked: u64,
    /// Pixels holding a dilated value only (one colour each; memory images for `render`).
    pub filled: u64,
    /// Pixels of texels inside geometry.
    pub inside: u64,
    /// Colour of the block's first baked or dilated pixel.
    pub first: u32,
    /// The cell's previous block, plus one (0: none); always an earlier block.
    pub next: u32,
    /// The page.
    pub page: u32,
    /// The cell, row-major within its page.
    pub cell: u32,
}

/// Mantissa bits per channel of [`pack_rgb`].
const MANTISSA_BITS: i32 = 14;
/// Bias of [`pack_rgb`]'s 6-bit exponent: stored 0..=63 is 2^(−32..=31).
const EXPONENT_BIAS: i32 = 32;
/// The largest value [`pack_rgb`] keeps; larger ones are clamped to it.
pub const PACKED_MAX: f32 = ((1 << MANTISSA_BITS) - 1) as f32 * (1u64 << 18) as f32;

/// 2^`e` for `e` in the normal range of f32, exactly.
fn pow2(e: i32) -> f32 {
    debug_assert!((-126..=127).contains(&e));
    f32::from_bits(((e + 127) as u32) << 23)
}

/// RGB in 48 bits: three 14-bit mantissas and a 6-bit exponent shared by the channels
/// (bits 0–13 red, 14–27 green, 28–41 blue, 42–47 the exponent + 32), each channel
/// `m · 2^(e − 13)` with the largest channel's `m` in [2¹³, 2¹⁴) where it can be. Rounds to
/// nearest; negative values and NaN become 0, values above [`PACKED_MAX`] (and ∞) that;
/// below 2⁻⁴⁶ values round to 0. Deterministic: a pure function of the bits.
pub fn pack_rgb(c: [f32; 3]) -> [u16; 3] {
    // `v > 0.0` is false for NaN and negatives.
    let c = c.map(|v| if v > 0.0 { v.min(PACKED_MAX) } else { 0.0 });
    let max = c[0].max(c[1]).max(c[2]);
    if max == 0.0 {
        return [0; 3];
    }
    let top = (1u32 << MANTISSA_BITS) as f32;
    let mut e = (((max.to_bits() >> 23) & 0xff) as i32 - 127).clamp(-EXPONENT_BIAS, 31);
    let mut scale = pow2(MANTISSA_BITS - 1 - e);
    if (max * scale).round() >= top {
        // Rounding carried into the next binade (never at e = 31: `PACKED_MAX` rounds down).
        e += 1;
        scale = pow2(MANTISSA_BITS - 1 - e);
    }
    let m = c.map(|v| u64::from((v * scale).round() as u32));
    let bits = m[0] | m[1] << 14 | m[2] << 28 | ((e + EXPONENT_BIAS) as u64) << 42;
    [bits as u16, (bits >> 16) as u16, (bits >> 32) as u16]
}

/// The RGB [`pack_rgb`] packed: always finite and ≥ 0.
pub fn unpack_rgb(p: [u16; 3]) -> Vec3 {
    let bits = u64::from(p[0]) | u64::from(p[1]) << 16 | u64::from(p[2]) << 32;
    let e = (bits >> 42) as i32 - EXPONENT_BIAS;
    let scale = pow2(e - (MANTISSA_BITS - 1));
    let m = |shift: u32| ((bits >> shift) & 0x3fff) as f32 * scale;
    Vec3::new(m(0), m(14), m(28))
}

/// Packs both layers of a pixel.
pub fn pack(gathered: [f32; 3], total: [f32; 3]) -> Packed {
    let (g, t) = (pack_rgb(gathered), pack_rgb(total));
    [g[0], g[1], g[2], t[0], t[1], t[2]]
}

/// One page's cells in the table.
#[derive(Clone, Copy, Debug)]
struct PageCells {
    base: usize,
    across: u32,
    width: u32,
    height: u32,
}

/// Where the table, the blocks and the colours lie in an image's bytes.
#[derive(Clone, Debug)]
pub struct Layout {
    pages: Vec<PageCells>,
    blocks_at: usize,
    block_bound: usize,
    colours_at: usize,
    colour_bound: usize,
}

impl Layout {
    /// The layout of an image of `pages` with at most `block_bound` blocks and
    /// `colour_bound` colours; `None` where they pass what 32-bit indices hold.
    pub fn new(pages: &[PageRecord], block_bound: u64, colour_bound: u64) -> Option<Self> {
        let mut cells = 0usize;
        let pages = pages
            .iter()
            .map(|p| {
                let across = p.width.div_ceil(CELL);
                let page = PageCells {
                    base: cells,
                    across,
                    width: p.width,
                    height: p.height,
                };
                cells += across as usize * p.height.div_ceil(CELL) as usize;
                page
            })
            .collect();
        let limit = u64::from(u32::MAX - 1);
        if block_bound > limit || colour_bound > limit {
            return None;
        }
        let blocks_at = (cells * 4).next_multiple_of(8);
        let colours_at = blocks_at + block_bound as usize * size_of::<Block>();
        Some(Self {
            pages,
            blocks_at,
            block_bound: block_bound as usize,
            colours_at,
            colour_bound: colour_bound as usize,
        })
    }

    /// Width and height of page `page`.
    pub fn page_size(&self, page: u32) -> Option<(u32, u32)> {
        self.pages.get(page as usize).map(|p| (p.width, p.height))
    }

    /// Bytes the build may write: the table, `block_bound` blocks, `colour_bound` colours.
    pub fn bytes(&self) -> usize {
        (self.colours_at + self.colour_bound * size_of::<Packed>()).next_multiple_of(8)
    }
}

/// What a build wrote: the blocks and colours in use.
#[derive(Clone, Copy, Debug, Default)]
pub struct Built {
    /// Blocks written.
    pub blocks: usize,
    /// Colours written.
    pub colours: usize,
    /// The most texels the lookups' filter held at once (0: not filtered).
    pub filter_surfels: usize,
}

impl Built {
    /// Bytes of the image in use: the rest of [`Layout::bytes`] may be cut off.
    pub fn bytes(&self, layout: &Layout) -> usize {
        (layout.colours_at + self.colours * size_of::<Packed>()).next_multiple_of(8)
    }
}

/// One pixel as a lookup sees it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tap {
    /// A baked texel.
    pub baked: bool,
    /// A baked texel or a dilated value.
    pub filled: bool,
    /// A texel inside geometry.
    pub inside: bool,
    /// Gather-only irradiance (0 where not filled).
    pub gathered: Vec3,
    /// Total irradiance (0 where not filled).
    pub total: Vec3,
}

/// A finished image's parts, borrowed from its bytes.
#[derive(Clone, Copy)]
pub struct View<'a> {
    layout: &'a Layout,
    cells: &'a [u32],
    blocks: &'a [Block],
    colours: &'a [Packed],
}

impl<'a> View<'a> {
    /// The parts of `bytes`, an image of `layout` that [`build`] wrote `built` into.
    ///
    /// # Panics
    /// If `bytes` is shorter than `built` needs, or not 8-byte aligned.
    pub fn new(layout: &'a Layout, built: Built, bytes: &'a [u8]) -> Self {
        let cells = layout.pages.last().map_or(0, |p| {
            p.base + p.across as usize * p.height.div_ceil(CELL) as usize
        });
        let blocks_end = layout.blocks_at + built.blocks * size_of::<Block>();
        let colours_end = layout.colours_at + built.colours * size_of::<Packed>();
        Self {
            layout,
            cells: bytemuck::cast_slice(&bytes[..cells * 4]),
            blocks: bytemuck::cast_slice(&bytes[layout.blocks_at..blocks_end]),
            colours: bytemuck::cast_slice(&bytes[layout.colours_at..colours_end]),
        }
    }

    /// The block holding pixel (`x`, `y`) of `page` and the pixel's bit in it.
    fn find(&self, page: u32, x: u32, y: u32) -> Option<(&'a Block, u64)> {
        let p = self.layout.pages.get(page as usize)?;
        if x >= p.width || y >= p.height {
            return None;
        }
        let cell = p.base + (y / CELL * p.across + x / CELL) as usize;
        let bit = 1u64 << ((y % CELL) * CELL + x % CELL);
        let mut at = *self.cells.get(cell)? as usize;
        while at > 0 {
            let b = self.blocks.get(at - 1)?;
            if (b.baked | b.filled | b.inside) & bit != 0 {
                return Some((b, bit));
            }
            // Chains run to earlier blocks only, so this ends.
            at = (b.next as usize).min(at - 1);
        }
        None
    }

    /// The colour of a pixel with one: its index.
    fn colour_index(b: &Block, bit: u64) -> Option<usize> {
        let with = b.baked | b.filled;
        (with & bit != 0).then(|| b.first as usize + (with & (bit - 1)).count_ones() as usize)
    }

    /// Pixel (`x`, `y`) of `page`; an empty tap off the page or where no texel lies.
    pub fn tap(&self, page: u32, x: u32, y: u32) -> Tap {
        let Some((b, bit)) = self.find(page, x, y) else {
            return Tap::default();
        };
        let mut tap = Tap {
            baked: b.baked & bit != 0,
            filled: (b.baked | b.filled) & bit != 0,
            inside: b.inside & bit != 0,
            ..Tap::default()
        };
        if let Some(c) = Self::colour_index(b, bit).and_then(|i| self.colours.get(i)) {
            tap.gathered = unpack_rgb([c[0], c[1], c[2]]);
            tap.total = unpack_rgb([c[3], c[4], c[5]]);
        }
        tap
    }

    /// The colour index of baked pixel (`x`, `y`) of `page`, if it is one.
    fn baked_index(&self, page: u32, x: u32, y: u32) -> Option<usize> {
        let (b, bit) = self.find(page, x, y)?;
        (b.baked & bit != 0)
            .then(|| Self::colour_index(b, bit))
            .flatten()
    }
}

/// One texel of a source tile.
#[derive(Clone, Copy, Debug, Default)]
pub struct SourceTexel {
    /// Column and row on the tile's page.
    pub pixel: (u32, u32),
    /// Baked: its values are read (kept only where finite).
    pub baked: bool,
    /// A dilated value, not a texel (memory images).
    pub filled: bool,
    /// Inside geometry.
    pub inside: bool,
    /// Gather-only irradiance.
    pub gathered: [f32; 3],
    /// Total irradiance.
    pub total: [f32; 3],
    /// What the lookups' filter knows of it (`None`: not filtered, nor a neighbour).
    pub surfel: Option<Surfel>,
}

/// Where an image's texels come from, tile by tile: tiles do not overlap, and each lies on
/// one page.
pub trait Source: Sync {
    /// Why a tile could not be read.
    type Error: Send;
    /// Tiles.
    fn tile_count(&self) -> usize;
    /// Where tile `tile` lies. The build reads the tiles page by page, top to bottom (by
    /// their top rows, then their left columns), whatever their order here.
    fn rect(&self, tile: usize) -> TileRect;
    /// At most this many blocks over every tile (the cells each tile's rectangle meets) and
    /// this many texels.
    fn bounds(&self) -> (u64, u64);
    /// Tile `tile`'s page, its texels put in `out` (cleared first).
    ///
    /// # Errors
    /// The source's, when the tile cannot be read.
    fn read_tile(&self, tile: usize, out: &mut Vec<SourceTexel>) -> Result<u32, Self::Error>;
}

/// One tile's blocks (`first` counted from the tile's first colour) and colours, and with the
/// filter each colour's texel as the filter sees it (`baked` 0 where it has none, and then it
/// is neither filtered nor a neighbour; its `gathered` the pixel's all the same) and its total
/// irradiance, unquantised.
#[derive(Default)]
struct TileOut {
    page: u32,
    blocks: Vec<Block>,
    colours: Vec<Packed>,
    surfels: Vec<Surfel>,
    totals: Vec<[f32; 3]>,
}

/// Groups one tile's texels into blocks, in cell order, and packs their colours.
fn tile_blocks(
    layout: &Layout,
    page: u32,
    texels: &[SourceTexel],
    filter: bool,
    keys: &mut Vec<(u32, u32, u32)>,
) -> TileOut {
    let mut out = TileOut {
        page,
        ..TileOut::default()
    };
    let Some(p) = layout.pages.get(page as usize) else {
        return out;
    };
    keys.clear();
    for (i, t) in texels.iter().enumerate() {
        let (x, y) = t.pixel;
        let finite = t.gathered.iter().chain(&t.total).all(|c| c.is_finite());
        let coloured = (t.baked || t.filled) && finite;
        if x < p.width && y < p.height && (coloured || t.inside) {
            let cell = y / CELL * p.across + x / CELL;
            keys.push((cell, (y % CELL) * CELL + x % CELL, i as u32));
        }
    }
    keys.sort_unstable();
    // A pixel given twice keeps its first texel.
    keys.dedup_by_key(|k| (k.0, k.1));
    for &(cell, bit, i) in keys.iter() {
        if out.blocks.last().is_none_or(|b| b.cell != cell) {
            out.blocks.push(Block {
                first: out.colours.len() as u32,
                page,
                cell,
                ..Block::default()
            });
        }
        let block = out.blocks.last_mut().expect("pushed above");
        let t = &texels[i as usize];
        let bit = 1u64 << bit;
        let finite = t.gathered.iter().chain(&t.total).all(|c| c.is_finite());
        if t.inside {
            block.inside |= bit;
        }
        if finite && (t.baked || t.filled) {
            if t.baked {
                block.baked |= bit;
            } else {
                block.filled |= bit;
            }
            out.colours.push(pack(t.gathered, t.total));
            if filter {
                let mut surfel = t.surfel.filter(|_| t.baked).unwrap_or_default();
                surfel.gathered = t.gathered;
                out.surfels.push(surfel);
                out.totals.push(t.total);
            }
        }
    }
    out
}

/// Builds the image of `source` into `bytes` (zeroed, [`Layout::bytes`] long, 8-byte
/// aligned), its baked pixels' gathered light filtered over `filter` texels (0: not
/// filtered). Runs on the current rayon pool; the bytes do not depend on its size, nor on the
/// order of the source's tiles: they are read page by page, top to bottom ([`Source::rect`]).
///
/// The filter holds what it knows of each texel (its [`Surfel`]) only while a tile within
/// its reach is still to be filtered: a tile is filtered as soon as every tile that may hold
/// its neighbours has been read (the next tile to read starts `filter` rows below it, or on
/// another page), and its surfels are let go once every tile still to be filtered starts
/// `filter` rows below its bottom. The filter's memory is a band of rows across a page, not
/// the world: [`Built::filter_surfels`] says how many it held at most.
///
/// # Errors
/// The source's, when a tile cannot be read.
///
/// # Panics
/// If the source holds more blocks or texels than its [`Source::bounds`] said.
pub fn build<S: Source>(
    layout: &Layout,
    source: &S,
    bytes: &mut [u8],
    filter: u32,
) -> Result<Built, S::Error> {
    let mut built = Built::default();
    let mut order: Vec<(TileRect, usize)> = (0..source.tile_count())
        .map(|t| (source.rect(t), t))
        .collect();
    order.sort_unstable_by_key(|&(r, t)| (r.page, r.y, r.x, t));
    let mut window = FilterWindow::default();
    let chunk_tiles = CHUNK_TILES_PER_THREAD * rayon::current_num_threads();
    let chunks: Vec<&[(TileRect, usize)]> = order.chunks(chunk_tiles).collect();
    let read = |chunk: Option<&&[(TileRect, usize)]>| -> Vec<Result<TileOut, S::Error>> {
        chunk.map_or_else(Vec::new, |chunk| {
            chunk
                .par_iter()
                .map_init(
                    || (Vec::new(), Vec::new()),
                    |(texels, keys), &(_, t)| {
                        let page = source.read_tile(t, texels)?;
                        Ok(tile_blocks(layout, page, texels, filter > 0, keys))
                    },
                )
                .collect()
        })
    };
    let mut outs = read(chunks.first());
    for (c, chunk) in chunks.iter().enumerate() {
        for (out, &(rect, _)) in std::mem::take(&mut outs).into_iter().zip(chunk.iter()) {
            let out = out?;
            let (blocks, first) = append(layout, bytes, &mut built, &out);
            if filter > 0 {
                window.read(rect, blocks, first, out.surfels, out.totals);
            }
        }
        // The next chunk is read while the tiles this one made ready are filtered: they need
        // none of its tiles.
        outs = if filter > 0 {
            let next = chunks.get(c + 1).map(|chunk| chunk[0].0);
            let filter_ready = || window.filter_ready(layout, built, bytes, next, filter);
            rayon::join(|| read(chunks.get(c + 1)), filter_ready).0
        } else {
            read(chunks.get(c + 1))
        };
    }
    built.filter_surfels = window.peak;
    Ok(built)
}

/// Appends one tile's blocks (chained into the cell table) and colours to the image; returns
/// its blocks and its first colour.
///
/// # Panics
/// If the image's bounds cannot hold them.
fn append(
    layout: &Layout,
    bytes: &mut [u8],
    built: &mut Built,
    out: &TileOut,
) -> (std::ops::Range<usize>, usize) {
    let (head, colours) = bytes.split_at_mut(layout.colours_at);
    let (cells, blocks) = head.split_at_mut(layout.blocks_at);
    let cells: &mut [u32] = bytemuck::cast_slice_mut(cells);
    let blocks: &mut [Block] = bytemuck::cast_slice_mut(blocks);
    let colours: &mut [Packed] =
        bytemuck::cast_slice_mut(&mut colours[..layout.colour_bound * size_of::<Packed>()]);
    let first = built.colours;
    let (b, c) = (out.blocks.len(), out.colours.len());
    assert!(
        built.blocks + b <= layout.block_bound && first + c <= layout.colour_bound,
        "a pass image's source holds more than its bounds"
    );
    let base = layout.pages[out.page as usize].base;
    for (i, block) in out.blocks.iter().enumerate() {
        let at = built.blocks + i;
        let cell = &mut cells[base + block.cell as usize];
        blocks[at] = Block {
            first: block.first + first as u32,
            next: *cell,
            ..*block
        };
        *cell = at as u32 + 1;
    }
    colours[first..first + c].copy_from_slice(&out.colours);
    let range = built.blocks..built.blocks + b;
    built.blocks += b;
    built.colours += c;
    (range, first)
}

/// A tile read but not yet filtered: where it lies, its blocks, its colours and their totals.
struct Pending {
    rect: TileRect,
    blocks: std::ops::Range<usize>,
    colours: std::ops::Range<usize>,
    totals: Vec<[f32; 3]>,
}

/// What the filter knows of the texels a tile still to be filtered may reach, in colour
/// order: `surfels[i]` is colour `first + i`'s.
#[derive(Default)]
struct FilterWindow {
    surfels: VecDeque<Surfel>,
    first: usize,
    /// The tiles whose surfels are held, in colour order: where each lies, its colour count.
    held: VecDeque<(TileRect, usize)>,
    /// Tiles read and not yet filtered, in the order they were read.
    pending: Vec<Pending>,
    /// The most surfels held at once (the ring's capacity).
    peak: usize,
}

impl FilterWindow {
    /// Takes a tile just read: its rectangle, blocks, first colour, surfels and totals.
    fn read(
        &mut self,
        rect: TileRect,
        blocks: std::ops::Range<usize>,
        first: usize,
        surfels: Vec<Surfel>,
        totals: Vec<[f32; 3]>,
    ) {
        debug_assert_eq!(first, self.first + self.surfels.len());
        self.held.push_back((rect, surfels.len()));
        self.pending.push(Pending {
            rect,
            blocks,
            colours: first..first + surfels.len(),
            totals,
        });
        self.surfels.extend(surfels);
        self.peak = self.peak.max(self.surfels.capacity());
    }

    /// Filters every pending tile whose neighbours within `radius` rows have all been read
    /// (`next`, the next tile to read, starts `radius` rows below it or on another page; none:
    /// every tile), then lets go of the surfels no tile still to be filtered can reach.
    fn filter_ready(
        &mut self,
        layout: &Layout,
        built: Built,
        bytes: &mut [u8],
        next: Option<TileRect>,
        radius: u32,
    ) {
        let ready =
            |t: &TileRect| next.is_none_or(|n| n.page != t.page || n.y >= t.y + t.height + radius);
        let (now, later): (Vec<Pending>, Vec<Pending>) = std::mem::take(&mut self.pending)
            .into_iter()
            .partition(|p| ready(&p.rect));
        self.pending = later;
        filter_colours(layout, built, bytes, &now, radius, self);
        // The first tile still to be filtered starts highest: earlier tiles ending `radius`
        // rows above it are out of every later tile's reach.
        let frontier = self.pending.first().map(|p| p.rect).or(next);
        while let Some(&(held, n)) = self.held.front() {
            let done = frontier.is_none_or(|f| {
                held.page < f.page || (held.page == f.page && held.y + held.height + radius <= f.y)
            });
            if !done {
                break;
            }
            self.held.pop_front();
            self.surfels.drain(..n);
            self.first += n;
        }
    }

    /// Colour `colour`'s surfel, if the window holds it.
    fn surfel(&self, colour: usize) -> Option<&Surfel> {
        let i = colour.checked_sub(self.first);
        debug_assert!(
            i.is_some_and(|i| i < self.surfels.len()),
            "a colour the window let go"
        );
        self.surfels.get(i?)
    }
}

/// Replaces each baked colour of the tiles `tiles` with a surfel by its filtered value: the
/// filtered gathered light, and the total moved by as much (the direct light stays), from the
/// unquantised values the window holds. Every tile on its own worker, writing its own colours.
fn filter_colours(
    layout: &Layout,
    built: Built,
    bytes: &mut [u8],
    tiles: &[Pending],
    radius: u32,
    window: &FilterWindow,
) {
    let (head, tail) = bytes.split_at_mut(layout.colours_at);
    let colours: &mut [Packed] =
        bytemuck::cast_slice_mut(&mut tail[..built.colours * size_of::<Packed>()]);
    let view = View {
        layout,
        cells: bytemuck::cast_slice(&head[..layout.blocks_at]),
        blocks: bytemuck::cast_slice(
            &head[layout.blocks_at..layout.blocks_at + built.blocks * size_of::<Block>()],
        ),
        colours: &[],
    };
    // Every tile's colours, disjoint (the tiles are in colour order).
    let mut rest = colours;
    let mut at = 0;
    let mut work = Vec::with_capacity(tiles.len());
    for t in tiles {
        let (_, tail) = std::mem::take(&mut rest).split_at_mut(t.colours.start - at);
        let (mine, later) = tail.split_at_mut(t.colours.len());
        work.push((t, mine));
        rest = later;
        at = t.colours.end;
    }
    work.into_par_iter()
        .for_each_init(Vec::new, |around, (tile, mine)| {
            let (x0, y0, w, h) = surfels_around(&view, window, tile.rect, radius, around);
            for b in &view.blocks[tile.blocks.clone()] {
                let p = layout.pages[b.page as usize];
                let (cx, cy) = (b.cell % p.across * CELL, b.cell / p.across * CELL);
                let mut mask = b.baked;
                while mask != 0 {
                    let bit = mask.trailing_zeros();
                    mask &= mask - 1;
                    let colour = View::colour_index(b, 1 << bit).expect("a baked pixel");
                    let (x, y) = (
                        (cx + bit % CELL - x0) as usize,
                        (cy + bit / CELL - y0) as usize,
                    );
                    let me = &around[y * w + x];
                    if me.baked != 1.0 {
                        continue;
                    }
                    let at = |nx: usize, ny: usize| around[ny * w + nx];
                    let f = filtered_at(me, (x, y), (w, h), radius as usize, at);
                    let change = f - Vec3::from(me.gathered);
                    let i = colour - tile.colours.start;
                    let g: [f32; 3] = core::array::from_fn(|c| me.gathered[c] + change[c]);
                    let t: [f32; 3] = core::array::from_fn(|c| tile.totals[i][c] + change[c]);
                    mine[i] = pack(g, t);
                }
            }
        });
}

/// Puts the surfels of the pixels within `radius` of `rect` (cut at its page's edges) in
/// `around`, row-major, a default (not baked) surfel where no baked texel lies; returns the
/// rectangle's left column, top row, width and height. The filter then reads a texel's
/// neighbours by index, not each through the cell table: a tap outside this rectangle is
/// outside the page, so [`filtered_at`] over it gives the page's values.
fn surfels_around(
    view: &View<'_>,
    window: &FilterWindow,
    rect: TileRect,
    radius: u32,
    around: &mut Vec<Surfel>,
) -> (u32, u32, usize, usize) {
    let (pw, ph) = view.layout.page_size(rect.page).unwrap_or((0, 0));
    let (x0, y0) = (rect.x.saturating_sub(radius), rect.y.saturating_sub(radius));
    let x1 = (rect.x + rect.width + radius).min(pw);
    let y1 = (rect.y + rect.height + radius).min(ph);
    let (w, h) = (
        x1.saturating_sub(x0) as usize,
        y1.saturating_sub(y0) as usize,
    );
    around.clear();
    around.resize(w * h, Surfel::default());
    for y in y0..y1 {
        for x in x0..x1 {
            if let Some(s) = view
                .baked_index(rect.page, x, y)
                .and_then(|i| window.surfel(i))
            {
                around[(y - y0) as usize * w + (x - x0) as usize] = *s;
            }
        }
    }
    (x0, y0, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_keeps_the_largest_channel_within_its_precision_over_the_whole_range() {
        let mut state = 7u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..100_000 {
            // 10⁻⁹ to 10⁹, and channels up to 10⁴ apart.
            let scale = 10f32.powf(18.0 * next() - 9.0);
            let c = [next(), next() * 1e-4, next()].map(|v| v * scale);
            let back = unpack_rgb(pack_rgb(c)).to_array();
            let max = c[0].max(c[1]).max(c[2]);
            // Below 2⁻³² the exponent is at its least: steps of 2⁻⁴⁵.
            let step = (max * 6.11e-5).max(2f32.powi(-46));
            for (a, b) in c.iter().zip(back) {
                assert!(
                    (a - b).abs() <= step,
                    "{c:?} → {back:?}: channel {a} off by more than 2⁻¹⁴ of {max}"
                );
            }
            let (m, mb) = (max, back[0].max(back[1]).max(back[2]));
            assert!((m - mb).abs() <= step, "{c:?} → {back:?}");
        }
        // Exact where the value fits: 0, small integers, powers of two, sums of a few.
        for v in [
            0.0,
            1.0,
            3.0,
            0.5,
            1024.0,
            1.0 + 2f32.powi(-13),
            2f32.powi(-30),
        ] {
            assert_eq!(unpack_rgb(pack_rgb([v, v, v])), Vec3::splat(v), "{v}");
        }
    }

    #[test]
    fn packing_clamps_what_it_cannot_hold_and_never_makes_a_non_finite_value() {
        let cases = [
            ([-1.0, f32::NAN, 2.0], [0.0, 0.0, 2.0]),
            ([f32::INFINITY, 1.0, 0.0], [PACKED_MAX, 0.0, 0.0]),
            ([1e12, 0.0, 0.0], [PACKED_MAX, 0.0, 0.0]),
            ([1e-20, 0.0, 0.0], [0.0, 0.0, 0.0]),
            ([f32::MIN_POSITIVE / 2.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        ];
        for (c, want) in cases {
            assert_eq!(unpack_rgb(pack_rgb(c)).to_array(), want, "{c:?}");
        }
        // Rounding up into the next binade.
        let v = 2.0 - 2f32.powi(-20);
        assert_eq!(unpack_rgb(pack_rgb([v, 0.0, 0.0])).x, 2.0);
        // Every bit pattern decodes to finite values.
        for e in 0..64u64 {
            let bits = 0x3fff | 0x3fff << 14 | 0x3fff << 28 | e << 42;
            let p = [bits as u16, (bits >> 16) as u16, (bits >> 32) as u16];
            assert!(unpack_rgb(p).is_finite());
        }
    }

    /// A source of one page given as a map from pixel to texel, in tiles of `tile` × `tile`
    /// pixels (row-major), which need not align with the cells.
    struct Grid {
        size: PageRecord,
        tile: u32,
        texels: Vec<Option<SourceTexel>>,
    }

    impl Source for Grid {
        type Error = ();
        fn tile_count(&self) -> usize {
            (self.size.width.div_ceil(self.tile) * self.size.height.div_ceil(self.tile)) as usize
        }
        fn rect(&self, tile: usize) -> TileRect {
            let across = self.size.width.div_ceil(self.tile);
            let (x, y) = (
                tile as u32 % across * self.tile,
                tile as u32 / across * self.tile,
            );
            TileRect {
                page: 0,
                x,
                y,
                width: self.tile.min(self.size.width - x),
                height: self.tile.min(self.size.height - y),
            }
        }
        fn bounds(&self) -> (u64, u64) {
            let cells = (self.tile.div_ceil(CELL) + 1).pow(2);
            (
                self.tile_count() as u64 * u64::from(cells),
                self.texels.len() as u64,
            )
        }
        fn read_tile(&self, tile: usize, out: &mut Vec<SourceTexel>) -> Result<u32, ()> {
            out.clear();
            let across = self.size.width.div_ceil(self.tile);
            let (tx, ty) = (
                tile as u32 % across * self.tile,
                tile as u32 / across * self.tile,
            );
            for y in ty..(ty + self.tile).min(self.size.height) {
                for x in tx..(tx + self.tile).min(self.size.width) {
                    if let Some(t) = self.texels[(y * self.size.width + x) as usize] {
                        out.push(t);
                    }
                }
            }
            Ok(0)
        }
    }

    fn grid(w: u32, h: u32, tile: u32, texel: impl Fn(u32, u32) -> Option<SourceTexel>) -> Grid {
        let texels = (0..w * h)
            .map(|i| {
                texel(i % w, i / w).map(|t| SourceTexel {
                    pixel: (i % w, i / w),
                    ..t
                })
            })
            .collect();
        Grid {
            size: PageRecord {
                width: w,
                height: h,
            },
            tile,
            texels,
        }
    }

    fn build_grid(g: &Grid, filter: u32) -> (Layout, Built, Vec<u64>) {
        let (blocks, texels) = g.bounds();
        let layout = Layout::new(&[g.size], blocks, texels).unwrap();
        let mut words = vec![0u64; layout.bytes() / 8];
        let built = build(&layout, g, bytemuck::cast_slice_mut(&mut words), filter).unwrap();
        (layout, built, words)
    }

    #[test]
    fn every_pixel_reads_back_whatever_the_tiles_and_the_thread_count() {
        // A 37 × 21 page, texels on a pattern, tiles of 5 pixels (cut every cell), a pixel
        // inside geometry, one baked texel non-finite (dropped), one dilated value.
        let texel = |x: u32, y: u32| {
            let v = (x * 100 + y) as f32;
            let t = SourceTexel {
                baked: !(x + 2 * y).is_multiple_of(3),
                inside: x == 7 && y == 3,
                filled: x == 30 && y == 20,
                gathered: [v, 0.5 * v, 0.0],
                total: [2.0 * v, v, 1.0],
                ..SourceTexel::default()
            };
            if x == 11 && y == 11 {
                return Some(SourceTexel {
                    gathered: [f32::NAN; 3],
                    ..t
                });
            }
            (t.baked || t.inside || t.filled).then_some(t)
        };
        let g = grid(37, 21, 5, texel);
        let (layout, built, words) = build_grid(&g, 0);
        let view = View::new(&layout, built, bytemuck::cast_slice(&words));
        for y in 0..21 {
            for x in 0..37 {
                let tap = view.tap(0, x, y);
                let want = texel(x, y).filter(|_| (x, y) != (11, 11));
                let baked = want.is_some_and(|t| t.baked);
                let filled = want.is_some_and(|t| t.baked || t.filled);
                assert_eq!((tap.baked, tap.filled), (baked, filled), "({x}, {y})");
                assert_eq!(tap.inside, (x, y) == (7, 3), "({x}, {y})");
                if let Some(t) = want.filter(|_| filled) {
                    assert_eq!(tap.gathered.to_array(), t.gathered, "({x}, {y})");
                    assert_eq!(tap.total.to_array(), t.total, "({x}, {y})");
                }
            }
        }
        assert_eq!(view.tap(0, 37, 0), Tap::default());
        assert_eq!(view.tap(1, 0, 0), Tap::default());
        // One thread or two: the same bytes.
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let (_, b, w) = pool.install(|| build_grid(&g, 0));
            assert_eq!((b.blocks, b.colours), (built.blocks, built.colours));
            assert_eq!(w, words, "{threads} threads");
        }
    }

    #[test]
    fn the_filtered_image_holds_the_dense_filter_s_values() {
        use crate::transport::lookup_filter::filter_page;
        // Noisy gathered light on a plane, direct light on top; tiles of 8 and of 5.
        let value = |x: u32, y: u32| 1.0 + ((x * 7 + y * 13) % 5) as f32 * 0.2;
        let texel = |x: u32, y: u32| {
            let g = value(x, y);
            let s = Surfel::new(
                Vec3::new(x as f32, y as f32, 0.0),
                Vec3::Z,
                1.0,
                [g; 3],
                0.3,
            );
            Some(SourceTexel {
                baked: !(x + y).is_multiple_of(7),
                gathered: [g; 3],
                total: [g + x as f32; 3],
                surfel: s,
                ..SourceTexel::default()
            })
            .filter(|t| t.baked)
        };
        let (w, h) = (19, 13);
        let surfels: Vec<Surfel> = (0..w * h)
            .map(|i| {
                texel(i % w, i / w)
                    .and_then(|t| t.surfel)
                    .unwrap_or_default()
            })
            .collect();
        let mut want: Vec<Vec3> = surfels.iter().map(|s| Vec3::from(s.gathered)).collect();
        filter_page(&surfels, (w as usize, h as usize), 2, |i, c| want[i] += c);
        for tile in [8, 5] {
            let g = grid(w, h, tile, texel);
            let (layout, built, words) = build_grid(&g, 2);
            let view = View::new(&layout, built, bytemuck::cast_slice(&words));
            for y in 0..h {
                for x in 0..w {
                    let tap = view.tap(0, x, y);
                    let Some(t) = texel(x, y) else {
                        assert!(!tap.filled);
                        continue;
                    };
                    let i = (y * w + x) as usize;
                    let (g, total) = (want[i], want[i] + Vec3::splat(t.total[0] - t.gathered[0]));
                    let near =
                        |a: Vec3, b: Vec3| (a - b).abs().max_element() <= 1e-4 * b.max_element();
                    assert!(near(tap.gathered, g), "({x}, {y}): {} vs {g}", tap.gathered);
                    assert!(
                        near(tap.total, total),
                        "({x}, {y}): {} vs {total}",
                        tap.total
                    );
                }
            }
        }
    }

    /// A source given as a list of tiles, in any order.
    struct Listed {
        pages: Vec<PageRecord>,
        tiles: Vec<(TileRect, Vec<SourceTexel>)>,
    }

    impl Source for Listed {
        type Error = ();
        fn tile_count(&self) -> usize {
            self.tiles.len()
        }
        fn rect(&self, tile: usize) -> TileRect {
            self.tiles[tile].0
        }
        fn bounds(&self) -> (u64, u64) {
            let cells = |from: u32, len: u32| u64::from((from + len).div_ceil(CELL) - from / CELL);
            let blocks = self
                .tiles
                .iter()
                .map(|(r, _)| cells(r.x, r.width) * cells(r.y, r.height));
            let texels = self.tiles.iter().map(|(_, t)| t.len() as u64);
            (blocks.sum(), texels.sum())
        }
        fn read_tile(&self, tile: usize, out: &mut Vec<SourceTexel>) -> Result<u32, ()> {
            out.clear();
            out.extend_from_slice(&self.tiles[tile].1);
            Ok(self.tiles[tile].0.page)
        }
    }

    #[test]
    fn the_filtered_bytes_do_not_depend_on_the_tiles_order_and_the_filter_holds_a_band() {
        // Two pages, 24 × 200 and 16 × 40, in tiles of 6 × 5 (cutting the cells), a noisy
        // plane each, the tiles listed in their order and shuffled.
        let pages = [
            PageRecord {
                width: 24,
                height: 200,
            },
            PageRecord {
                width: 16,
                height: 40,
            },
        ];
        let mut tiles = Vec::new();
        for (p, size) in pages.iter().enumerate() {
            for ty in (0..size.height).step_by(5) {
                for tx in (0..size.width).step_by(6) {
                    let rect = TileRect {
                        page: p as u32,
                        x: tx,
                        y: ty,
                        width: 6.min(size.width - tx),
                        height: 5.min(size.height - ty),
                    };
                    let mut texels = Vec::new();
                    for y in ty..ty + rect.height {
                        for x in tx..tx + rect.width {
                            let g = 1.0 + ((x * 7 + y * 13 + p as u32) % 5) as f32 * 0.2;
                            let at = Vec3::new(x as f32, y as f32, p as f32 * 100.0);
                            texels.push(SourceTexel {
                                pixel: (x, y),
                                baked: !(x + y).is_multiple_of(7),
                                gathered: [g; 3],
                                total: [g + x as f32; 3],
                                surfel: Surfel::new(at, Vec3::Z, 1.0, [g; 3], 0.3),
                                ..SourceTexel::default()
                            });
                        }
                    }
                    tiles.push((rect, texels));
                }
            }
        }
        let build_of = |tiles: Vec<(TileRect, Vec<SourceTexel>)>, threads: usize| {
            let source = Listed {
                pages: pages.to_vec(),
                tiles,
            };
            let (blocks, texels) = source.bounds();
            let layout = Layout::new(&source.pages, blocks, texels).unwrap();
            let mut words = vec![0u64; layout.bytes() / 8];
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let built = pool
                .install(|| build(&layout, &source, bytemuck::cast_slice_mut(&mut words), 2))
                .unwrap();
            (built, words)
        };
        let (built, words) = build_of(tiles.clone(), 1);
        // Reversed, then stirred.
        let mut shuffled: Vec<_> = tiles.iter().rev().cloned().collect();
        shuffled.sort_by_key(|(r, _)| (r.x * 31 + r.y * 17 + r.page * 7) % 11);
        assert_ne!(shuffled[0].0, tiles[0].0);
        for threads in [1, 3] {
            let (b, w) = build_of(shuffled.clone(), threads);
            assert_eq!((b.blocks, b.colours), (built.blocks, built.colours));
            assert!(w == words, "{threads} threads, shuffled tiles: other bytes");
        }
        // The filter held a band of rows, not the 4 660 baked texels: on one thread, four
        // tiles (one row of tiles across the first page) a step, the rows the filter reaches
        // above and below a row of tiles (3 rows of tiles, 15 rows of 24 pixels) and one step
        // more, in a ring whose capacity is a power of two.
        assert!(built.filter_surfels > 0, "nothing held");
        assert!(
            built.filter_surfels <= 1024,
            "the filter held {} texels",
            built.filter_surfels
        );
    }
}
