#![no_main]
//! `cargo +nightly fuzz run read_exr`: see [`skydome_fuzz::read_exr`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::read_exr(data));
