#![no_main]
//! `cargo +nightly fuzz run lens_profile`: see [`skydome_fuzz::lens_profile`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::lens_profile(data));
