#![no_main]
//! `cargo +nightly fuzz run read_hdr`: see [`skydome_fuzz::read_hdr`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| skydome_fuzz::read_hdr(data));
