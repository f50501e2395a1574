//! The result file: one [`TexelResult`] per texel, preallocated, written in place.
//!
//! Layout (little-endian): a 64-byte [`ResultHeader`], then `texel_count` records of 52 bytes
//! at `64 + 52 · texel_id`. The file is created sparse at its full size, so a bake of 10^8
//! texels does not write 5.2 GB of zeros first, and it is written with positioned writes
//! (`pwrite`), never mapped: nothing of it stays in anonymous memory, and the kernel's page
//! cache is free to drop what has been synced.
//!
//! The header carries the identity of the bake (a hash of its settings and of its texel file)
//! so that `--resume` refuses to continue a different bake's results.
//!
//! The same layout, with its own magic, holds the *batch file* of `--combine global`
//! ([`BatchFile`]): every texel's K per-iteration [`Welford`] batches, combined in the final
//! pass once the global per-iteration weights are known.

use std::fs::File;
use std::marker::PhantomData;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};
use guidebake_kernels::estimator::Welford;

use super::{OutputFileError, create_with_header, io_error, open_with_header};

/// Magic bytes at the start of a result file.
pub const RESULT_MAGIC: [u8; 8] = *b"GBRESULT";
/// The result-file version this build writes and reads.
pub const RESULT_VERSION: u32 = 4;
/// Bytes before the first record.
pub const RESULT_HEADER_BYTES: u64 = 64;

/// The texel was baked (set by the writer; unset records were never baked).
pub const FLAG_BAKED: u32 = 1;
/// The texel is valid in the texel file (invalid texels are skipped, not traced).
pub const FLAG_VALID: u32 = 1 << 1;
/// No finite gather sample reached the texel's estimators: its irradiance is zero by rule.
pub const FLAG_NO_FINITE_SAMPLES: u32 = 1 << 2;
/// The texel's cluster was baked unguided because its guide was near uniform or empty.
pub const FLAG_UNGUIDED: u32 = 1 << 3;

/// One texel's bake result, before the global bias correction ρ is applied.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TexelResult {
    /// Irradiance, RGB, the per-texel combination of the iterations' estimates.
    pub irradiance: [f32; 3],
    /// The final gather's share of it (without the texel's next-event estimate and the
    /// emission its rays hit), the plain average over all iterations: what a next series
    /// pass looks up where its hit's direct light is connected there (a surface's unbaked side).
    pub gathered: [f32; 3],
    /// Relative standard error of the luminance estimate (0 when unknown).
    pub rel_std_error: f32,
    /// Gather samples taken, all iterations together.
    pub samples: u32,
    /// `FLAG_*` bits.
    pub flags: u32,
    /// The whole irradiance (direct and gathered), the plain average over all iterations,
    /// unbiased whatever the combination: what a next series pass looks up on the side the
    /// texel bakes, in place of next-event estimation there.
    pub total: [f32; 3],
    /// One cell of the texel's cluster's guide seed, kept by the pass before a guided last
    /// pass (0 elsewhere): the cluster's j-th texel holds cell j of the histogram the last
    /// pass builds the cluster's first guide from (`bake/gather/learning.rs`, `SeedHistogram`).
    pub seed: f32,
}

/// Bytes of one [`TexelResult`] in the file.
pub const RECORD_BYTES: u64 = 52;

const _: () = assert!(size_of::<TexelResult>() as u64 == RECORD_BYTES);

/// The result file's header.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct ResultHeader {
    /// [`RESULT_MAGIC`].
    pub magic: [u8; 8],
    /// [`RESULT_VERSION`].
    pub version: u32,
    /// Bytes of one texel's records: 52 in a result file, K · 80 in a batch file of K
    /// iterations.
    pub record_bytes: u32,
    /// Records in the file.
    pub texel_count: u64,
    /// Identity of the bake: hash of its settings and texel file.
    pub bake_id: u64,
    /// Reserved, zero.
    pub reserved: [u64; 4],
}

const _: () = assert!(size_of::<ResultHeader>() as u64 == RESULT_HEADER_BYTES);

/// A record kept per texel in a file of its own kind: the bake's [`TexelResult`]s, or the
/// iterations' [`Welford`] batches that `--combine global` combines at the end.
pub trait PerTexel: Pod {
    /// The file's magic.
    const MAGIC: [u8; 8];
    /// The file's format version.
    const VERSION: u32;
    /// The file's kind, in messages.
    const KIND: &'static str;
}

impl PerTexel for TexelResult {
    const MAGIC: [u8; 8] = RESULT_MAGIC;
    const VERSION: u32 = RESULT_VERSION;
    const KIND: &'static str = "result file";
}

impl PerTexel for Welford {
    const MAGIC: [u8; 8] = *b"GBBATCH\0";
    const VERSION: u32 = 1;
    const KIND: &'static str = "batch file";
}

/// A file of `T` records, `per_texel` of them for each texel, open for writing (a bake) or
/// reading (the final pass, `merge`).
#[derive(Debug)]
pub struct RecordFile<T> {
    file: File,
    path: PathBuf,
    texel_count: u64,
    per_texel: u64,
    record: PhantomData<T>,
}

/// The bake's result file: one [`TexelResult`] per texel.
pub type ResultFile = RecordFile<TexelResult>;

/// The iterations' batches of every texel (`--combine global`): K [`Welford`]s per texel.
pub type BatchFile = RecordFile<Welford>;

impl<T: PerTexel> RecordFile<T> {
    /// Creates (or truncates) the file at `path` for `texel_count` texels of bake `bake_id`,
    /// one record each, preallocated sparse at its full size and synced.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when the file cannot be created, sized or synced.
    pub fn create(path: &Path, texel_count: u64, bake_id: u64) -> Result<Self, OutputFileError> {
        Self::create_with(path, texel_count, 1, bake_id)
    }

    /// [`Self::create`] with `per_texel` records for each texel.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when the file cannot be created, sized or synced.
    pub fn create_with(
        path: &Path,
        texel_count: u64,
        per_texel: u32,
        bake_id: u64,
    ) -> Result<Self, OutputFileError> {
        let too_big = || OutputFileError::Mismatch {
            path: path.to_owned(),
            what: format!("{texel_count} texels of {per_texel} records do not fit in a file"),
        };
        let record_bytes =
            u32::try_from(size_of::<T>() * per_texel.max(1) as usize).map_err(|_| too_big())?;
        let header = ResultHeader {
            magic: T::MAGIC,
            version: T::VERSION,
            record_bytes,
            texel_count,
            bake_id,
            reserved: [0; 4],
        };
        let len = records_end(texel_count, u64::from(record_bytes)).ok_or_else(too_big)?;
        let file = create_with_header(path, &bytemuck::cast(header), len)?;
        Ok(Self {
            file,
            path: path.to_owned(),
            texel_count,
            per_texel: u64::from(per_texel.max(1)),
            record: PhantomData,
        })
    }

    /// Opens an existing file of one `T` record per texel (a result file) and checks that it
    /// belongs to bake `bake_id` with `texel_count` texels (pass `None` to accept any bake, as
    /// `merge` does after checking the shards agree among themselves).
    ///
    /// # Errors
    /// As [`Self::open_with`] with one record per texel.
    pub fn open(
        path: &Path,
        writable: bool,
        expect: Option<(u64, u64)>,
    ) -> Result<(Self, ResultHeader), OutputFileError> {
        Self::open_with(path, writable, 1, expect)
    }

    /// [`Self::open`] for a file of `per_texel` `T` records per texel (as [`Self::create_with`]
    /// wrote it). The header's record size must be exactly `per_texel` records of `T`: a file
    /// of another layout is refused, never read with the wrong stride.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when it cannot be opened or read; [`OutputFileError::Mismatch`]
    /// when the magic, version, record layout, length or bake identity differ. Every error
    /// names the file.
    pub fn open_with(
        path: &Path,
        writable: bool,
        per_texel: u32,
        expect: Option<(u64, u64)>,
    ) -> Result<(Self, ResultHeader), OutputFileError> {
        let (file, len, bytes) = open_with_header(path, writable, T::KIND, T::MAGIC, T::VERSION)?;
        let header: ResultHeader = bytemuck::cast(bytes);
        let mismatch = |what: String| OutputFileError::Mismatch {
            path: path.to_owned(),
            what,
        };
        let per_texel = u64::from(per_texel.max(1));
        let expected = per_texel * size_of::<T>() as u64;
        if u64::from(header.record_bytes) != expected {
            let records = |n: u64| if n == 1 { "record" } else { "records" };
            return Err(mismatch(format!(
                "record layout of {} bytes per texel, where this {} holds {per_texel} {} of {} bytes per texel ({expected} bytes)",
                header.record_bytes,
                T::KIND,
                records(per_texel),
                size_of::<T>(),
            )));
        }
        if records_end(header.texel_count, expected) != Some(len) {
            return Err(mismatch(format!(
                "length {len} does not hold the {} texels its header declares",
                header.texel_count
            )));
        }
        if let Some((texels, bake_id)) = expect
            && (header.texel_count != texels || header.bake_id != bake_id)
        {
            return Err(mismatch(format!(
                "belongs to another bake (texels {}, id {:016x}; this bake: texels {texels}, id {bake_id:016x})",
                header.texel_count, header.bake_id
            )));
        }
        let texel_count = header.texel_count;
        Ok((
            Self {
                file,
                path: path.to_owned(),
                texel_count,
                per_texel,
                record: PhantomData,
            },
            header,
        ))
    }

    /// Texels in the file.
    pub fn texel_count(&self) -> u64 {
        self.texel_count
    }

    /// Records per texel.
    pub fn per_texel(&self) -> u64 {
        self.per_texel
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes `results` (whole texels' records) for the texels from `first_texel` on, in place.
    ///
    /// # Errors
    /// [`OutputFileError::OutOfRange`] past the end; [`OutputFileError::PartialTexel`] when
    /// `results` is not whole texels; [`OutputFileError::Io`] on a failed write.
    pub fn write(&self, first_texel: u64, results: &[T]) -> Result<(), OutputFileError> {
        let offset = self.range_offset(first_texel, results.len())?;
        self.file
            .write_all_at(bytemuck::cast_slice(results), offset)
            .map_err(|e| io_error(&self.path, "write results", e))
    }

    /// Reads the records of the texels from `first_texel` on into `out` (whole texels).
    ///
    /// # Errors
    /// [`OutputFileError::OutOfRange`] past the end; [`OutputFileError::PartialTexel`] when
    /// `out` is not whole texels; [`OutputFileError::Io`] on a failed read.
    pub fn read(&self, first_texel: u64, out: &mut [T]) -> Result<(), OutputFileError> {
        let offset = self.range_offset(first_texel, out.len())?;
        self.file
            .read_exact_at(bytemuck::cast_slice_mut(out), offset)
            .map_err(|e| io_error(&self.path, "read results", e))
    }

    /// Makes every write so far durable (`fdatasync`): call before journalling the tiles.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when the sync fails.
    pub fn sync(&self) -> Result<(), OutputFileError> {
        self.file
            .sync_data()
            .map_err(|e| io_error(&self.path, "sync", e))
    }

    /// Where the records of `records` / `per_texel` texels from `first` on start.
    fn range_offset(&self, first: u64, records: usize) -> Result<u64, OutputFileError> {
        let records = records as u64;
        if !records.is_multiple_of(self.per_texel) {
            return Err(OutputFileError::PartialTexel {
                path: self.path.clone(),
                records,
                per_texel: self.per_texel,
            });
        }
        let end = first.checked_add(records / self.per_texel);
        let stride = self.per_texel * size_of::<T>() as u64;
        match end {
            Some(end) if end <= self.texel_count => Ok(RESULT_HEADER_BYTES + first * stride),
            _ => Err(OutputFileError::OutOfRange {
                path: self.path.clone(),
                first,
                end: end.unwrap_or(u64::MAX),
                count: self.texel_count,
            }),
        }
    }
}

fn records_end(texel_count: u64, record_bytes: u64) -> Option<u64> {
    texel_count
        .checked_mul(record_bytes)?
        .checked_add(RESULT_HEADER_BYTES)
}

/// Records a [`FinishedResults`] reads at once, per thread (13 KB).
const SEED_BLOCK_TEXELS: u64 = 256;
/// Blocks each thread keeps: a cluster's texels lie in one texel-file tile, up to 1 024
/// texels (five blocks) in files guidebake writes.
const SEED_BLOCKS: usize = 8;

/// Tells apart the [`FinishedResults`] whose blocks a thread keeps.
static NEXT_READER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// One thread's blocks of records: the reader, the block, its bytes; the next to replace.
type SeedBlocks = (Vec<(u64, u64, Vec<u8>)>, usize);

thread_local! {
    static SEED_BLOCKS_READ: std::cell::RefCell<SeedBlocks> =
        const { std::cell::RefCell::new((Vec::new(), 0)) };
}

/// A finished result file, read one texel at a time without a call each (the last pass reads
/// the guide seeds the pass before it kept: `bake/gather/learning.rs`): each thread reads
/// blocks of [`SEED_BLOCK_TEXELS`] records with `pread` and keeps its last [`SEED_BLOCKS`], so
/// what it reads stays in the page cache, not in the bake's memory. Mapping the file instead
/// kept every page the pass touched resident: 518 MB of the default bake's 792 MB peak of
/// file-backed memory at 10⁷ texels (docs/series.md).
#[derive(Debug)]
pub struct FinishedResults {
    file: File,
    texel_count: u64,
    /// Keys this reader's blocks in each thread's cache.
    id: u64,
}

impl FinishedResults {
    /// Opens `results`, a file no one writes any more (a finished pass's), for reading.
    ///
    /// # Errors
    /// [`OutputFileError::Io`] when the file cannot be opened again, or is shorter than its
    /// texels.
    pub fn new(results: &ResultFile) -> Result<Self, OutputFileError> {
        let io = |e| io_error(&results.path, "open results", e);
        let file = results.file.try_clone().map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let want = RESULT_HEADER_BYTES + results.texel_count * RECORD_BYTES;
        if len < want {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!("{len} bytes, where its texels need {want}"),
            )));
        }
        Ok(Self {
            file,
            texel_count: results.texel_count,
            id: NEXT_READER.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        })
    }

    /// Texel `texel`'s record (`None` past the file's texels, or where its block cannot be
    /// read: a file cut under the bake; the texel then bakes as if the pass before had kept
    /// nothing for it).
    pub fn get(&self, texel: u64) -> Option<TexelResult> {
        if texel >= self.texel_count {
            return None;
        }
        let block = texel / SEED_BLOCK_TEXELS;
        let at = ((texel % SEED_BLOCK_TEXELS) * RECORD_BYTES) as usize;
        SEED_BLOCKS_READ.with_borrow_mut(|(blocks, next)| {
            let found = blocks
                .iter()
                .position(|(id, b, _)| (*id, *b) == (self.id, block));
            let i = match found {
                Some(i) => i,
                None => {
                    let first = block * SEED_BLOCK_TEXELS;
                    let n = SEED_BLOCK_TEXELS.min(self.texel_count - first);
                    let mut bytes = vec![0u8; (n * RECORD_BYTES) as usize];
                    let offset = RESULT_HEADER_BYTES + first * RECORD_BYTES;
                    self.file.read_exact_at(&mut bytes, offset).ok()?;
                    if blocks.len() < SEED_BLOCKS {
                        blocks.push((self.id, block, bytes));
                        blocks.len() - 1
                    } else {
                        let i = *next;
                        *next = (i + 1) % SEED_BLOCKS;
                        blocks[i] = (self.id, block, bytes);
                        i
                    }
                }
            };
            let bytes = blocks[i].2.get(at..at + RECORD_BYTES as usize)?;
            Some(bytemuck::pod_read_unaligned(bytes))
        })
    }
}

#[cfg(test)]
mod tests {
    use std::fs::OpenOptions;

    use super::*;

    fn result(i: u32) -> TexelResult {
        TexelResult {
            irradiance: [i as f32, 0.5, -0.0],
            rel_std_error: 0.01,
            samples: i,
            flags: FLAG_BAKED | FLAG_VALID,
            gathered: [0.25, 0.0, 1.0],
            total: [0.5, 0.25, 1.0],
            seed: 0.125,
        }
    }

    #[test]
    fn writes_in_place_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.bin");
        let file = ResultFile::create(&path, 100, 7).unwrap();
        let tile: Vec<_> = (0..10).map(result).collect();
        file.write(40, &tile).unwrap();
        file.sync().unwrap();
        let (reopened, header) = ResultFile::open(&path, false, Some((100, 7))).unwrap();
        assert_eq!(header.texel_count, 100);
        let mut back = vec![TexelResult::default(); 12];
        reopened.read(39, &mut back).unwrap();
        assert_eq!(
            back[0],
            TexelResult::default(),
            "unwritten texels read as zero"
        );
        assert_eq!(&back[1..11], &tile[..]);
        assert_eq!(
            std::fs::metadata(&path).unwrap().len(),
            64 + 100 * RECORD_BYTES
        );
        // Read a block at a time, the same records, and none past the end.
        let reader = FinishedResults::new(&reopened).unwrap();
        assert_eq!(reader.get(39), Some(TexelResult::default()));
        assert!((0..10).all(|i| reader.get(40 + i) == Some(tile[i as usize])));
        assert_eq!(reader.get(99), Some(TexelResult::default()));
        assert_eq!(reader.get(100), None);
    }

    #[test]
    fn two_readers_on_one_thread_read_their_own_records_across_many_blocks() {
        let dir = tempfile::tempdir().unwrap();
        let n = 9 * SEED_BLOCK_TEXELS + 17;
        let files: Vec<ResultFile> = (0..2)
            .map(|f| {
                let file = ResultFile::create(&dir.path().join(format!("r{f}.bin")), n, 7).unwrap();
                let all: Vec<_> = (0..n as u32).map(|i| result(i + 100_000 * f)).collect();
                file.write(0, &all).unwrap();
                file
            })
            .collect();
        let readers: Vec<_> = files
            .iter()
            .map(|f| FinishedResults::new(f).unwrap())
            .collect();
        // Strides that walk every block, forwards and back, the two readers interleaved.
        for step in [1u64, 255, 257, 1031] {
            for k in 0..n {
                let texel = (k * step) % n;
                for (f, r) in readers.iter().enumerate() {
                    assert_eq!(
                        r.get(texel),
                        Some(result(texel as u32 + 100_000 * f as u32)),
                        "reader {f}, texel {texel}"
                    );
                }
            }
        }
        assert_eq!(readers[0].get(n), None);
    }

    #[test]
    fn refuses_ranges_past_the_end() {
        let dir = tempfile::tempdir().unwrap();
        let file = ResultFile::create(&dir.path().join("r.bin"), 10, 1).unwrap();
        let err = file.write(8, &[result(0); 3]).unwrap_err();
        assert!(matches!(
            err,
            OutputFileError::OutOfRange {
                first: 8,
                end: 11,
                count: 10,
                ..
            }
        ));
        assert!(file.write(u64::MAX, &[result(0)]).is_err());
    }

    #[test]
    fn refuses_another_bake_a_bad_magic_and_a_short_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.bin");
        ResultFile::create(&path, 10, 1).unwrap();
        let err = ResultFile::open(&path, true, Some((10, 2)))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("another bake") && err.contains("r.bin"),
            "{err}"
        );

        let file = OpenOptions::new().write(true).open(&path).unwrap();
        file.write_all_at(b"NOTMAGIC", 0).unwrap();
        let err = ResultFile::open(&path, false, None)
            .unwrap_err()
            .to_string();
        assert!(err.contains("bad magic"), "{err}");

        ResultFile::create(&path, 10, 1).unwrap();
        OpenOptions::new()
            .write(true)
            .open(&path)
            .unwrap()
            .set_len(64 + 9 * RECORD_BYTES)
            .unwrap();
        let err = ResultFile::open(&path, false, None)
            .unwrap_err()
            .to_string();
        assert!(err.contains("does not hold"), "{err}");
        std::fs::write(&path, b"short").unwrap();
        let err = ResultFile::open(&path, false, None)
            .unwrap_err()
            .to_string();
        assert!(err.contains("too short"), "{err}");
    }

    /// A result file whose header declares 7 records per texel (found by the `result_file`
    /// fuzz target) is refused with an error naming it, not read with the wrong stride; so
    /// is a batch file of another iteration count.
    #[test]
    fn refuses_a_record_layout_other_than_its_own() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.bin");
        // 7 TexelResults per texel, as a 7-iteration batch file would hold Welfords.
        RecordFile::<TexelResult>::create_with(&path, 3, 7, 1).unwrap();
        let err = ResultFile::open(&path, false, None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("r.bin") && err.contains("record layout of 364 bytes per texel"),
            "{err}"
        );
        let (seven, _) = RecordFile::<TexelResult>::open_with(&path, false, 7, None).unwrap();
        assert_eq!(seven.per_texel(), 7);

        let batches = dir.path().join("b.bin");
        BatchFile::create_with(&batches, 3, 4, 1).unwrap();
        for k in [1, 3, 5, 16] {
            let err = BatchFile::open_with(&batches, false, k, None)
                .unwrap_err()
                .to_string();
            assert!(err.contains("b.bin") && err.contains("320 bytes"), "{err}");
        }
        let (four, header) = BatchFile::open_with(&batches, false, 4, None).unwrap();
        assert_eq!((four.per_texel(), header.record_bytes), (4, 320));
    }

    /// Reads and writes of records that are not whole texels are errors, not panics.
    #[test]
    fn refuses_partial_texels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.bin");
        let file = BatchFile::create_with(&path, 3, 4, 1).unwrap();
        let mut out = vec![Welford::new(); 6];
        let err = file.read(0, &mut out).unwrap_err();
        assert!(
            matches!(
                err,
                OutputFileError::PartialTexel {
                    records: 6,
                    per_texel: 4,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("b.bin"), "{err}");
        assert!(file.write(1, &out[..3]).is_err());
        assert!(file.read(1, &mut out[..4]).is_ok());
    }
}
