//! Replays the checked-in fuzz corpus (`fuzz/corpus/TARGET/*`) through the same bodies the
//! cargo-fuzz targets run, so every input that once crashed a target stays a regression
//! test on stable Rust. Run the fuzzers themselves with `fuzz/run.sh`.

use std::path::Path;

use guidebake_suite::fuzzing::TARGETS;

#[test]
fn every_corpus_input_passes_its_target() {
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    let mut replayed = 0;
    for (name, body) in TARGETS {
        let dir = corpus.join(name);
        let entries = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: every target keeps a seed corpus: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("readable corpus directory").path();
            let bytes = std::fs::read(&path).expect("readable corpus file");
            let outcome = std::panic::catch_unwind(|| body(&bytes));
            assert!(
                outcome.is_ok(),
                "fuzz target {name} fails on {}",
                path.display()
            );
            replayed += 1;
        }
    }
    assert!(
        replayed >= TARGETS.len(),
        "the corpus is not empty ({replayed} inputs)"
    );
    println!(
        "replayed {replayed} fuzz corpus inputs over {} targets",
        TARGETS.len()
    );
}
