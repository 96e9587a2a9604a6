#![no_main]
//! `cargo +nightly fuzz run decode_frame`: see [`skydome_fuzz::decode_frame`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::decode_frame(data));
