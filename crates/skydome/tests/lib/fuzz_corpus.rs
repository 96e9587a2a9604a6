//! Replays every file of the fuzzers' corpora (`fuzz/corpus/<target>/`) through the function
//! its fuzz target calls (`fuzz/src/lib.rs`, included here), on stable: whatever a fuzzer once
//! found — a crash since fixed, an input that reached new code — stays checked in CI. A panic
//! is a failure; refusing the bytes is the expected outcome for most files.

use crate::fuzz_targets as targets;
use std::path::Path;

fn replay(target: &str, run: fn(&[u8])) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{}: empty corpus", dir.display());
    for f in &files {
        let bytes = std::fs::read(f).unwrap();
        let outcome = std::panic::catch_unwind(|| run(&bytes));
        assert!(outcome.is_ok(), "{target}: {} panicked", f.display());
    }
    println!("{target}: {} files replayed", files.len());
}

#[test]
fn decode_frame_corpus_replays() {
    replay("decode_frame", targets::decode_frame);
}

#[test]
fn read_dng_corpus_replays() {
    replay("read_dng", targets::read_dng);
}

#[test]
fn ljpeg_corpus_replays() {
    replay("ljpeg", targets::ljpeg);
}

#[test]
fn read_hdr_corpus_replays() {
    replay("read_hdr", targets::read_hdr);
}

#[test]
fn read_exr_corpus_replays() {
    replay("read_exr", targets::read_exr);
}

#[test]
fn times_corpus_replays() {
    replay("times", targets::times);
}

#[test]
fn camera_profile_corpus_replays() {
    replay("camera_profile", targets::camera_profile);
}

#[test]
fn lens_profile_corpus_replays() {
    replay("lens_profile", targets::lens_profile);
}
