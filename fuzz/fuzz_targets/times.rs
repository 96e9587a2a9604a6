#![no_main]
//! `cargo +nightly fuzz run times`: see [`skydome_fuzz::times`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::times(data));
