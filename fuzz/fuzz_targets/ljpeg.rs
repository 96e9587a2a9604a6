#![no_main]
//! `cargo +nightly fuzz run ljpeg`: see [`skydome_fuzz::ljpeg`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::ljpeg(data));
