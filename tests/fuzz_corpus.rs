//! Replays the committed fuzz corpus (`fuzz/corpus/<target>/`: seeds and the inputs cargo-fuzz found interesting)
//! through what the fuzz targets do, on the stable toolchain, so every one of them stays panic-free. The targets
//! themselves run on nightly: `cargo +nightly fuzz run reader` (or `pipeline`).

#[path = "../fuzz/src/lib.rs"]
mod targets;

use std::path::{Path, PathBuf};

/// The corpus of `target`, in a stable order.
fn corpus(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
}

/// Runs `f` on every input of the corpus of `target`, naming the input that panics.
fn replay(target: &str, f: fn(&[u8]), at_least: usize) {
    let files = corpus(target);
    assert!(files.len() >= at_least, "{target}: {} inputs", files.len());
    for path in files {
        let data = std::fs::read(&path).unwrap();
        if std::panic::catch_unwind(|| f(&data)).is_err() {
            panic!("{target}: {} panics", path.display());
        }
    }
}

#[test]
fn the_reader_corpus_stays_panic_free() {
    replay("reader", targets::reader, 100);
}

#[test]
fn the_pipeline_corpus_stays_panic_free() {
    replay("pipeline", targets::pipeline, 100);
}
