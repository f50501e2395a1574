//! Fuzz target bodies. Each takes arbitrary bytes and panics only when an invariant is
//! broken; `fuzz/fuzz_targets/NAME.rs` calls `NAME`, and `tests/fuzz_corpus.rs` replays every
//! file under `fuzz/corpus/NAME/` through it on stable Rust.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use guidebake::output::journal::Journal;
use guidebake::output::result_file::{ResultFile, TexelResult};

/// A fuzz target's body: arbitrary bytes in, a panic only on a broken invariant.
pub type Body = fn(&[u8]);

/// The names of the targets, as `fuzz/corpus/` folders and `fuzz/fuzz_targets/` files.
pub const TARGETS: &[(&str, Body)] = &[("journal", journal), ("result_file", result_file)];

/// A unique path in the temporary directory for one input, removed when dropped.
struct ScratchFile(PathBuf);

impl ScratchFile {
    fn with(bytes: &[u8]) -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("guidebake-fuzz-{}-{n}", std::process::id()));
        std::fs::write(&path, bytes).expect("the temporary directory is writable");
        ScratchFile(path)
    }
}

impl Drop for ScratchFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Arbitrary bytes as a journal: opening never panics; what it accepts is a header plus
/// whole, intact records, and the file is truncated to exactly those.
pub fn journal(data: &[u8]) {
    let file = ScratchFile::with(data);
    let Ok((_, header, records)) = Journal::open(&file.0, true, None) else {
        return;
    };
    assert!(records.iter().all(|r| r.tile < header.tile_count));
    let len = std::fs::metadata(&file.0).expect("still there").len();
    assert_eq!(len, 64 + 48 * records.len() as u64, "torn tail truncated");
    let (_, _, again) = Journal::open(&file.0, false, None).expect("a truncated journal reopens");
    assert_eq!(again, records);
}

/// Arbitrary bytes as a result file: opening never panics, and an accepted file's every
/// record can be read.
pub fn result_file(data: &[u8]) {
    let file = ScratchFile::with(data);
    let Ok((results, header)) = ResultFile::open(&file.0, false, None) else {
        return;
    };
    assert_eq!(results.texel_count(), header.texel_count);
    let mut buffer = [TexelResult::default(); 64];
    let mut first = 0;
    while first < header.texel_count {
        let n = (header.texel_count - first).min(64) as usize;
        results
            .read(first, &mut buffer[..n])
            .expect("declared records are readable");
        first += n as u64;
    }
    assert!(results.read(header.texel_count, &mut buffer[..1]).is_err());
}
