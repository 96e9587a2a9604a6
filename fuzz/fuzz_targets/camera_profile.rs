#![no_main]
//! `cargo +nightly fuzz run camera_profile`: see [`skydome_fuzz::camera_profile`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::camera_profile(data));
