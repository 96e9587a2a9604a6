#![no_main]
//! `cargo +nightly fuzz run read_dng` (add `--features raw-rawler` for the rawler route too):
//! see [`skydome_fuzz::read_dng`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::read_dng(data));
