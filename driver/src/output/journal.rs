//! The journal of finished tiles: what `--resume` trusts and where ρ's sums live.
//!
//! Layout (little-endian): a 64-byte [`JournalHeader`] naming the bake, then 48-byte
//! [`TileRecord`]s appended in the order tiles were committed. Each record carries an FNV-1a
//! checksum of its other fields. Opening a journal reads records up to the first one that is
//! short, fails its checksum or holds what no bake writes (non-finite or negative sums, a
//! set reserved word) — the torn tail of a crash — and truncates the file there:
//! those tiles are simply baked again, which gives the same bits because every random number
//! derives from (seed, texel, iteration, sample).
//!
//! The contract with the [result file](super::result_file): a tile is appended to the
//! journal only after its results were written and synced, so every journalled tile's
//! results are on disk.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};
use guidebake_kernels::estimator::RhoAccumulator;

use super::{OutputFileError, create_with_header, io_error, open_with_header};
use crate::hash::fnv1a64;

/// Magic bytes at the start of a journal.
pub const JOURNAL_MAGIC: [u8; 8] = *b"GBJOURNL";
/// The journal version this build writes and reads.
pub const JOURNAL_VERSION: u32 = 1;
const HEADER_BYTES: u64 = 64;
const RECORD_BYTES: u64 = 48;

/// The journal's header.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct JournalHeader {
    /// [`JOURNAL_MAGIC`].
    pub magic: [u8; 8],
    /// [`JOURNAL_VERSION`].
    pub version: u32,
    /// Tiles in the whole world (not only this shard's).
    pub tile_count: u32,
    /// Identity of the bake, as in the result file.
    pub bake_id: u64,
    /// Reserved, zero.
    pub reserved: [u64; 5],
}

const _: () = assert!(size_of::<JournalHeader>() as u64 == HEADER_BYTES);

/// One finished tile and its contribution to the bias correction ρ (paper §2.5).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TileRecord {
    /// The tile's index in the texel file's tile table.
    pub tile: u32,
    /// Valid texels that contributed to the sums.
    pub texels: u32,
    /// Σ over the tile's texels of the unweighted mean luminance (L̂).
    pub unweighted_luminance: f64,
    /// Σ over the tile's texels of the combined (weighted) mean luminance (L̂_GD).
    pub weighted_luminance: f64,
    /// Rays traced for the tile, all kinds (for statistics).
    pub rays: u64,
    /// Reserved, zero.
    pub reserved: u64,
    /// FNV-1a of the 40 bytes above.
    pub checksum: u64,
}

const _: () = assert!(size_of::<TileRecord>() as u64 == RECORD_BYTES);

impl TileRecord {
    /// The record with its checksum filled in.
    pub fn sealed(mut self) -> Self {
        self.checksum = self.computed_checksum();
        self
    }

    fn computed_checksum(&self) -> u64 {
        fnv1a64(&bytemuck::bytes_of(self)[..40])
    }

    /// Its checksum holds and its fields are ones the bake writes: finite, non-negative
    /// sums and a zero reserved word. A checksum alone is 64 bits a forged or corrupted
    /// file can match (the fuzzer does); NaN sums would poison ρ.
    fn is_intact(&self) -> bool {
        let sum_ok = |s: f64| s.is_finite() && s >= 0.0;
        self.checksum == self.computed_checksum()
            && self.reserved == 0
            && sum_ok(self.unweighted_luminance)
            && sum_ok(self.weighted_luminance)
    }
}

/// The world-wide sums behind ρ = L̂ / L̂_GD (the kernels' [`RhoAccumulator`]: exact sums,
/// so the result is the same bits whatever order tiles finished in, on however many threads
/// or shards). Duplicates must have been removed by the caller, see [`dedup_tiles`].
pub fn rho_sums(records: &[TileRecord]) -> RhoAccumulator {
    let mut sums = RhoAccumulator::new();
    for r in records {
        sums.add_sums(
            r.unweighted_luminance,
            r.weighted_luminance,
            u64::from(r.texels),
        );
    }
    sums
}

/// Keeps the last record of each tile (a tile baked again after a torn write appears twice
/// with equal contents), in ascending tile order.
pub fn dedup_tiles(records: &mut Vec<TileRecord>) {
    records.sort_by_key(|r| r.tile);
    records.dedup_by_key(|r| r.tile);
}

/// An open journal, appending.
#[derive(Debug)]
pub struct Journal {
    file: File,
    path: PathBuf,
    len: u64,
}

impl Journal {
    /// Creates (or truncates) a journal for bake `bake_id` over `tile_count` tiles, synced.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when the file cannot be created or synced.
    pub fn create(path: &Path, tile_count: u32, bake_id: u64) -> Result<Self, OutputFileError> {
        let header = JournalHeader {
            magic: JOURNAL_MAGIC,
            version: JOURNAL_VERSION,
            tile_count,
            bake_id,
            reserved: [0; 5],
        };
        let file = create_with_header(path, &bytemuck::cast(header), HEADER_BYTES)?;
        Ok(Self {
            file,
            path: path.to_owned(),
            len: HEADER_BYTES,
        })
    }

    /// Opens an existing journal, returns its header and intact records (in file order), and
    /// truncates a torn tail so later appends follow the last intact record. With `expect`
    /// = `Some((tile_count, bake_id))` a journal of another bake is refused.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when it cannot be read or truncated; [`OutputFileError::Mismatch`]
    /// on a bad magic, version, tile count or bake identity.
    pub fn open(
        path: &Path,
        writable: bool,
        expect: Option<(u32, u64)>,
    ) -> Result<(Self, JournalHeader, Vec<TileRecord>), OutputFileError> {
        let io = |what| move |source| io_error(path, what, source);
        let mismatch = |what: String| OutputFileError::Mismatch {
            path: path.to_owned(),
            what,
        };
        let (file, len, head) =
            open_with_header(path, writable, "journal", JOURNAL_MAGIC, JOURNAL_VERSION)?;
        let header: JournalHeader = bytemuck::cast(head);
        let mut bytes = vec![0u8; (len - HEADER_BYTES) as usize];
        file.read_exact_at(&mut bytes, HEADER_BYTES)
            .map_err(io("read records"))?;
        if let Some((tiles, bake_id)) = expect
            && (header.tile_count != tiles || header.bake_id != bake_id)
        {
            return Err(mismatch(format!(
                "belongs to another bake (tiles {}, id {:016x}; this bake: tiles {tiles}, id {bake_id:016x})",
                header.tile_count, header.bake_id
            )));
        }
        let records = intact_records(&bytes, header.tile_count);
        let intact_len = HEADER_BYTES + records.len() as u64 * RECORD_BYTES;
        if writable && intact_len != len {
            file.set_len(intact_len).map_err(io("truncate torn tail"))?;
            file.sync_all().map_err(io("sync"))?;
        }
        Ok((
            Self {
                file,
                path: path.to_owned(),
                len: intact_len,
            },
            header,
            records,
        ))
    }

    /// Appends `records` (sealing their checksums) and syncs. Call only after the tiles'
    /// results were written to the result file and synced.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when the write or the sync fails.
    pub fn append(&mut self, records: &[TileRecord]) -> Result<(), OutputFileError> {
        let sealed: Vec<TileRecord> = records.iter().map(|r| r.sealed()).collect();
        let bytes: &[u8] = bytemuck::cast_slice(&sealed);
        self.file
            .write_all_at(bytes, self.len)
            .map_err(|e| io_error(&self.path, "append", e))?;
        self.file
            .sync_data()
            .map_err(|e| io_error(&self.path, "sync", e))?;
        self.len += bytes.len() as u64;
        Ok(())
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Records up to the first short, torn or out-of-range one.
fn intact_records(bytes: &[u8], tile_count: u32) -> Vec<TileRecord> {
    bytes
        .chunks_exact(RECORD_BYTES as usize)
        .map(bytemuck::pod_read_unaligned::<TileRecord>)
        .take_while(|r| r.is_intact() && r.tile < tile_count)
        .collect()
}

#[cfg(test)]
mod tests {
    use std::fs::OpenOptions;

    use super::*;

    fn record(tile: u32) -> TileRecord {
        TileRecord {
            tile,
            texels: 10,
            unweighted_luminance: 1.5 * f64::from(tile),
            weighted_luminance: 1.25 * f64::from(tile),
            rays: 1000,
            ..Default::default()
        }
    }

    #[test]
    fn appended_records_survive_reopening() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("j.bin");
        let mut journal = Journal::create(&path, 8, 42).unwrap();
        journal.append(&[record(3), record(1)]).unwrap();
        journal.append(&[record(7)]).unwrap();
        let (_, header, records) = Journal::open(&path, false, Some((8, 42))).unwrap();
        assert_eq!(header.tile_count, 8);
        let tiles: Vec<u32> = records.iter().map(|r| r.tile).collect();
        assert_eq!(tiles, [3, 1, 7]);
        assert_eq!(records[0], record(3).sealed());
    }

    #[test]
    fn a_torn_tail_is_dropped_and_truncated() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("j.bin");
        let mut journal = Journal::create(&path, 8, 42).unwrap();
        journal.append(&[record(0), record(1), record(2)]).unwrap();
        // Tear the last record: half of it, then a flipped byte in the one before.
        let len = std::fs::metadata(&path).unwrap().len();
        let file = OpenOptions::new().write(true).open(&path).unwrap();
        file.set_len(len - 20).unwrap();
        file.write_all_at(&[0xff], 64 + 48 + 9).unwrap();
        let (mut reopened, _, records) = Journal::open(&path, true, Some((8, 42))).unwrap();
        assert_eq!(records, [record(0).sealed()]);
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 64 + 48);
        reopened.append(&[record(5)]).unwrap();
        let (_, _, records) = Journal::open(&path, false, None).unwrap();
        assert_eq!(records, [record(0).sealed(), record(5).sealed()]);
    }

    #[test]
    fn a_sealed_record_with_non_finite_sums_ends_the_intact_records() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("j.bin");
        let nan = TileRecord {
            unweighted_luminance: f64::NAN,
            ..record(2)
        };
        let reserved = TileRecord {
            reserved: 1 << 45,
            ..record(3)
        };
        let negative = TileRecord {
            weighted_luminance: -1.0,
            ..record(4)
        };
        for bad in [nan, reserved, negative] {
            let mut journal = Journal::create(&path, 8, 42).unwrap();
            journal.append(&[record(1), bad, record(5)]).unwrap();
            drop(journal);
            let (_, _, records) = Journal::open(&path, true, Some((8, 42))).unwrap();
            assert_eq!(records, [record(1).sealed()], "{bad:?}");
            assert_eq!(std::fs::metadata(&path).unwrap().len(), 64 + 48);
        }
    }

    #[test]
    fn refuses_another_bake_and_non_journals() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("j.bin");
        Journal::create(&path, 8, 42).unwrap();
        let err = Journal::open(&path, false, Some((8, 43)))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("another bake") && err.contains("j.bin"),
            "{err}"
        );
        std::fs::write(&path, [0u8; 64]).unwrap();
        let err = Journal::open(&path, false, None).unwrap_err().to_string();
        assert!(err.contains("bad magic"), "{err}");
    }

    #[test]
    fn rho_is_the_same_bits_in_any_finishing_order() {
        let records: Vec<TileRecord> = (0..200u32)
            .map(|t| TileRecord {
                tile: t,
                texels: 1,
                unweighted_luminance: 1.0 / (f64::from(t) + 0.3),
                weighted_luminance: 1e8 / (f64::from(t * t) + 0.7),
                ..Default::default()
            })
            .collect();
        let forward = rho_sums(&records);
        let mut shuffled = records.clone();
        shuffled.reverse();
        shuffled.swap(3, 150);
        let backward = rho_sums(&shuffled);
        assert_eq!(forward.rho().to_bits(), backward.rho().to_bits());
        assert_eq!(forward.texels(), 200);
    }

    #[test]
    fn rho_is_one_for_a_black_or_broken_world() {
        assert_eq!(rho_sums(&[]).rho(), 1.0);
        let tile = |unweighted: f64, weighted: f64| TileRecord {
            texels: 1,
            unweighted_luminance: unweighted,
            weighted_luminance: weighted,
            ..Default::default()
        };
        assert_eq!(rho_sums(&[tile(f64::NAN, 1.0)]).rho(), 1.0);
        assert_eq!(rho_sums(&[tile(3.0, f64::INFINITY)]).rho(), 1.0);
        assert_eq!(rho_sums(&[tile(3.0, 2.0)]).rho(), 1.5);
        // A broken tile enters neither sum.
        let mixed = rho_sums(&[
            tile(3.0, 2.0),
            tile(f64::NAN, 5.0),
            tile(1.0, f64::INFINITY),
        ]);
        assert_eq!((mixed.rho(), mixed.texels(), mixed.skipped()), (1.5, 1, 2));
    }

    #[test]
    fn dedup_keeps_one_record_per_tile() {
        let mut records = vec![record(4), record(2), record(4), record(0)];
        dedup_tiles(&mut records);
        let tiles: Vec<u32> = records.iter().map(|r| r.tile).collect();
        assert_eq!(tiles, [0, 2, 4]);
    }
}
