//! The bounded tile pipeline: workers on a rayon pool bake tiles into buffers drawn from a
//! fixed pool; one writer commits them to the [result file](crate::output::result_file) and
//! [journal](crate::output::journal) (docs/ARCHITECTURE.md,
//! "Invariants").
//!
//! - **Bounded memory.** A tile's results live in one of `window` buffers. A worker takes a
//!   free buffer before it bakes and the writer hands it back after writing it, so at most
//!   `window` tiles are in flight whatever the world's size; each worker's own scratch state
//!   (`make_worker`) is made once per thread.
//! - **Determinism.** Workers take tiles in the given order from a shared counter, so which
//!   thread bakes a tile varies, but a tile's bits depend only on the tile (every random
//!   number derives from seed, texel, iteration and sample). The writer writes each tile at
//!   its own texel offset; ρ's sums are reduced in tile order later. Thread count and finishing
//!   order therefore never change the output.
//! - **Crash safety.** Results are written in place as tiles arrive; every `commit_every`
//!   tiles (and at the end) the writer syncs the result file, then appends the tiles to the
//!   journal and syncs it. A crash loses at most the uncommitted tiles, which a resumed run
//!   bakes again to the same bits.
//! - **Interruption.** `cancel` (set by a Ctrl-C handler) stops workers from starting new
//!   tiles; tiles in flight are finished and committed, and the run reports it was cut short.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crossbeam::channel;

use super::directional::{DirectionalFile, ShL1};
use crate::output::OutputFileError;
use crate::output::journal::{Journal, TileRecord};
use crate::output::result_file::{BatchFile, ResultFile, TexelResult};
use guidebake_kernels::estimator::Welford;

/// One tile's output, in a buffer of the pool.
#[derive(Debug, Default)]
pub struct TileBuffer {
    /// One result per texel of the tile.
    pub results: Vec<TexelResult>,
    /// Every texel's per-iteration batches (K per texel), when a batch file is written.
    pub batches: Vec<Welford>,
    /// Every texel's directional coefficients (K per texel with a batch file, else one),
    /// when a directional file is written.
    pub directional: Vec<ShL1>,
}

impl TileBuffer {
    fn clear(&mut self) {
        self.results.clear();
        self.batches.clear();
        self.directional.clear();
    }
}

/// Where finished tiles go: the result file and, for `--combine global`, the batch file.
#[derive(Clone, Copy, Debug)]
pub struct TileFiles<'a> {
    /// The results.
    pub results: &'a ResultFile,
    /// The per-iteration batches, if kept.
    pub batches: Option<&'a BatchFile>,
    /// The directional coefficients, if kept.
    pub directional: Option<&'a DirectionalFile>,
}

/// What a worker produced for one tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileBaked {
    /// Global id of the tile's first texel: where its results go in the result file.
    pub first_texel: u64,
    /// The tile's journal record (its ρ sums and counts).
    pub record: TileRecord,
}

/// How the pipeline runs.
#[derive(Clone, Copy, Debug)]
pub struct PipelineConfig {
    /// Worker threads (≥ 1).
    pub threads: usize,
    /// Tiles in flight at most: buffers in the pool (≥ 1).
    pub window: usize,
    /// Tiles per commit (sync of results, then of the journal).
    pub commit_every: usize,
}

/// What a pipeline run did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PipelineReport {
    /// Tiles baked and committed to the journal.
    pub tiles_committed: usize,
    /// Commits (journal syncs) made.
    pub commits: usize,
    /// Most tiles in flight at once (never more than the window).
    pub max_in_flight: usize,
    /// Whether `cancel` cut the run short.
    pub interrupted: bool,
}

/// Why the pipeline stopped early.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Writing, reading or syncing the result file or the journal failed.
    #[error(transparent)]
    Output(#[from] OutputFileError),
    /// The worker pool could not be started.
    #[error("cannot start {threads} worker threads: {why}")]
    Threads {
        /// Threads asked for.
        threads: usize,
        /// What rayon said.
        why: String,
    },
}

/// Bakes `tiles` (in this order) with `bake`, committing them to `results` and `journal`.
///
/// `make_worker` builds one worker's scratch state per thread; `bake(state, tile, buffer)`
/// fills `buffer` (cleared, with capacity from earlier tiles) with the tile's results and
/// returns where they go. `progress` is called by the writer after each tile is written.
///
/// # Errors
/// The first I/O failure of the writer; workers stop taking tiles when it happens, and the
/// tiles committed before it stay valid for `--resume`.
#[allow(clippy::too_many_arguments)]
pub fn run<W, M, B>(
    config: PipelineConfig,
    tiles: &[u32],
    files: TileFiles<'_>,
    journal: &mut Journal,
    cancel: &AtomicBool,
    make_worker: M,
    bake: B,
    progress: &mut dyn FnMut(&TileBaked),
) -> Result<PipelineReport, PipelineError>
where
    M: Fn() -> W + Sync,
    B: Fn(&mut W, u32, &mut TileBuffer) -> TileBaked + Sync,
{
    let threads = config.threads.max(1);
    let window = config.window.max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("guidebake-worker-{i}"))
        .build()
        .map_err(|e| PipelineError::Threads {
            threads,
            why: e.to_string(),
        })?;

    let (free_tx, free_rx) = channel::bounded::<TileBuffer>(window);
    for _ in 0..window {
        free_tx
            .send(TileBuffer::default())
            .expect("the pool holds exactly `window` buffers");
    }
    let (done_tx, done_rx) = channel::bounded::<(TileBaked, TileBuffer)>(window);
    let next = AtomicUsize::new(0);
    let in_flight = AtomicUsize::new(0);
    let max_in_flight = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);

    let worker = |free_rx: &channel::Receiver<TileBuffer>,
                  done_tx: &channel::Sender<(TileBaked, TileBuffer)>| {
        let mut state = make_worker();
        loop {
            if cancel.load(Ordering::Relaxed) || stop.load(Ordering::Relaxed) {
                break;
            }
            let Ok(mut buffer) = free_rx.recv() else {
                break;
            };
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(&tile) = tiles.get(i) else { break };
            let now = in_flight.fetch_add(1, Ordering::Relaxed) + 1;
            max_in_flight.fetch_max(now, Ordering::Relaxed);
            buffer.clear();
            let baked = bake(&mut state, tile, &mut buffer);
            if done_tx.send((baked, buffer)).is_err() {
                break;
            }
        }
    };

    // Workers run on the pool from a helper thread; the writer runs here, so `progress`
    // need not be `Send`. Dropping the writer's ends of the channels on an error unblocks
    // every worker.
    let mut report = std::thread::scope(|scope| {
        scope.spawn(move || {
            pool.scope(|s| {
                for _ in 0..threads {
                    s.spawn(|_| worker(&free_rx, &done_tx));
                }
            });
        });
        let writer = Writer {
            files,
            journal,
            commit_every: config.commit_every.max(1),
        };
        writer
            .drain(done_rx, free_tx, &in_flight, progress)
            .inspect_err(|_| {
                stop.store(true, Ordering::Relaxed);
            })
    })?;
    report.max_in_flight = max_in_flight.load(Ordering::Relaxed);
    report.interrupted = report.tiles_committed < tiles.len();
    Ok(report)
}

/// The writer's side: write each tile in place, hand its buffer back, commit in batches.
struct Writer<'a> {
    files: TileFiles<'a>,
    journal: &'a mut Journal,
    commit_every: usize,
}

impl Writer<'_> {
    fn drain(
        mut self,
        done_rx: channel::Receiver<(TileBaked, TileBuffer)>,
        free_tx: channel::Sender<TileBuffer>,
        in_flight: &AtomicUsize,
        progress: &mut dyn FnMut(&TileBaked),
    ) -> Result<PipelineReport, PipelineError> {
        let mut report = PipelineReport::default();
        let mut pending: Vec<TileRecord> = Vec::with_capacity(self.commit_every);
        for (baked, buffer) in done_rx.iter() {
            let written = self.write(baked.first_texel, &buffer);
            in_flight.fetch_sub(1, Ordering::Relaxed);
            let _ = free_tx.send(buffer);
            written?;
            progress(&baked);
            pending.push(baked.record);
            if pending.len() >= self.commit_every {
                self.commit(&mut pending, &mut report)?;
            }
        }
        self.commit(&mut pending, &mut report)?;
        Ok(report)
    }

    fn write(&self, first_texel: u64, buffer: &TileBuffer) -> Result<(), OutputFileError> {
        self.files.results.write(first_texel, &buffer.results)?;
        if let Some(batches) = self.files.batches {
            batches.write(first_texel, &buffer.batches)?;
        }
        if let Some(directional) = self.files.directional {
            directional.write(first_texel, &buffer.directional)?;
        }
        Ok(())
    }

    /// Results first, journal second: a journalled tile's results are always on disk.
    fn commit(
        &mut self,
        pending: &mut Vec<TileRecord>,
        report: &mut PipelineReport,
    ) -> Result<(), PipelineError> {
        if pending.is_empty() {
            return Ok(());
        }
        self.files.results.sync()?;
        if let Some(batches) = self.files.batches {
            batches.sync()?;
        }
        if let Some(directional) = self.files.directional {
            directional.sync()?;
        }
        self.journal.append(pending)?;
        report.tiles_committed += pending.len();
        report.commits += 1;
        pending.clear();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;
    use crate::bake::shard::{Shard, tiles_to_bake};
    use crate::output::journal::{dedup_tiles, rho_sums};
    use guidebake_kernels::estimator::RhoAccumulator;

    const TILE_TEXELS: u64 = 37;
    const TILES: u32 = 60;

    /// A stand-in for the real tile bake: deterministic per texel, with a per-worker
    /// scratch buffer to show state is per thread.
    fn fake_bake(scratch: &mut Vec<f32>, tile: u32, out: &mut TileBuffer) -> TileBaked {
        let first = u64::from(tile) * TILE_TEXELS;
        scratch.clear();
        let (mut unweighted, mut weighted) = (0.0, 0.0);
        for t in first..first + TILE_TEXELS {
            let x = ((t * 2_654_435_761) % 1000) as f32 / 97.0;
            scratch.push(x);
            out.results.push(TexelResult {
                irradiance: [x, x * 0.5, 1.0 / (1.0 + x)],
                samples: 64,
                ..Default::default()
            });
            unweighted += f64::from(x);
            weighted += f64::from(x) * 0.9;
        }
        let record = TileRecord {
            tile,
            texels: TILE_TEXELS as u32,
            unweighted_luminance: unweighted,
            weighted_luminance: weighted,
            ..Default::default()
        };
        TileBaked {
            first_texel: first,
            record,
        }
    }

    struct Run {
        dir: tempfile::TempDir,
    }

    impl Run {
        fn new() -> Self {
            let dir = tempfile::tempdir().unwrap();
            ResultFile::create(&dir.path().join("r"), u64::from(TILES) * TILE_TEXELS, 9).unwrap();
            Journal::create(&dir.path().join("j"), TILES, 9).unwrap();
            Run { dir }
        }

        fn bake(
            &self,
            threads: usize,
            shard: Shard,
            cancel_after: Option<usize>,
        ) -> PipelineReport {
            let (results, _) = ResultFile::open(&self.dir.path().join("r"), true, None).unwrap();
            let (mut journal, _, done) =
                Journal::open(&self.dir.path().join("j"), true, None).unwrap();
            let done: HashSet<u32> = done.iter().map(|r| r.tile).collect();
            let tiles = tiles_to_bake(
                std::iter::repeat_n(TILE_TEXELS as u32, TILES as usize),
                shard,
                &done,
            );
            let cancel = AtomicBool::new(false);
            let mut seen = 0;
            let config = PipelineConfig {
                threads,
                window: 4,
                commit_every: 3,
            };
            run(
                config,
                &tiles,
                TileFiles {
                    results: &results,
                    batches: None,
                    directional: None,
                },
                &mut journal,
                &cancel,
                Vec::new,
                fake_bake,
                &mut |_| {
                    seen += 1;
                    if Some(seen) == cancel_after {
                        cancel.store(true, Ordering::Relaxed);
                    }
                },
            )
            .unwrap()
        }

        fn contents(&self) -> (Vec<u8>, RhoAccumulator) {
            let bytes = std::fs::read(self.dir.path().join("r")).unwrap();
            let (_, _, mut records) =
                Journal::open(&self.dir.path().join("j"), false, None).unwrap();
            dedup_tiles(&mut records);
            assert_eq!(records.len(), TILES as usize, "every tile journalled once");
            (bytes, rho_sums(&records))
        }
    }

    #[test]
    fn one_or_two_threads_give_the_same_bits() {
        let (one, two) = (Run::new(), Run::new());
        let r1 = one.bake(1, Shard::WHOLE, None);
        let r2 = two.bake(2, Shard::WHOLE, None);
        assert_eq!((r1.tiles_committed, r2.tiles_committed), (60, 60));
        assert!(!r1.interrupted && !r2.interrupted);
        assert_eq!(one.contents(), two.contents());
        assert!(
            r2.max_in_flight <= 4,
            "window bounds the tiles in flight: {r2:?}"
        );
    }

    #[test]
    fn an_interrupted_then_resumed_bake_equals_an_uninterrupted_one() {
        let (whole, resumed) = (Run::new(), Run::new());
        whole.bake(2, Shard::WHOLE, None);
        let cut = resumed.bake(2, Shard::WHOLE, Some(7));
        assert!(
            cut.interrupted && cut.tiles_committed >= 7 && cut.tiles_committed < 60,
            "{cut:?}"
        );
        let rest = resumed.bake(1, Shard::WHOLE, None);
        assert_eq!(cut.tiles_committed + rest.tiles_committed, 60);
        assert_eq!(whole.contents(), resumed.contents());
    }

    #[test]
    fn three_shards_into_one_file_equal_one_run() {
        let (whole, sharded) = (Run::new(), Run::new());
        whole.bake(2, Shard::WHOLE, None);
        for index in [2, 0, 1] {
            sharded.bake(1, Shard { index, count: 3 }, None);
        }
        assert_eq!(whole.contents(), sharded.contents());
    }

    #[test]
    fn a_failing_writer_stops_the_workers_and_reports_the_file() {
        let fixture = Run::new();
        let path = fixture.dir.path().join("r");
        let (read_only, _) = ResultFile::open(&path, false, None).unwrap();
        let (mut journal, _, _) = Journal::open(&fixture.dir.path().join("j"), true, None).unwrap();
        let tiles: Vec<u32> = (0..TILES).collect();
        let config = PipelineConfig {
            threads: 2,
            window: 2,
            commit_every: 1,
        };
        let cancel = AtomicBool::new(false);
        let err = run(
            config,
            &tiles,
            TileFiles {
                results: &read_only,
                batches: None,
                directional: None,
            },
            &mut journal,
            &cancel,
            Vec::new,
            fake_bake,
            &mut |_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("write results") && err.contains(path.to_str().unwrap()),
            "{err}"
        );
        let (_, _, records) = Journal::open(&fixture.dir.path().join("j"), false, None).unwrap();
        assert!(records.is_empty(), "nothing unwritten is journalled");
    }
}
