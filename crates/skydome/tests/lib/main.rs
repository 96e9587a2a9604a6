//! The library's integration tests, one module per subject, in one test binary: each test
//! binary links the library and its dependencies anew, so one binary instead of two dozen
//! saves minutes of linking on a small machine. `cargo test -p skydome --test lib merge::`
//! runs one subject's tests.

#[path = "../common/mod.rs"]
mod common;
#[path = "../common/dng.rs"]
mod dng_build;
#[path = "../common/encode.rs"]
mod encode;
#[path = "../fisheye_support/mod.rs"]
mod fisheye_support;
/// The fuzz targets' functions, replayed on their corpora by `fuzz_corpus`.
#[path = "../../../../fuzz/src/lib.rs"]
mod fuzz_targets;

mod absolute;
mod align;
mod bracket_real;
mod bracket_zoo;
mod calibration;
mod capture;
mod curve_range;
mod exif_stations;
mod exposures;
mod film_scan;
mod fisheye;
mod fisheye_overlay;
mod formats_exr;
mod formats_rgbe;
mod fuzz_corpus;
mod independent_readers;
mod merge;
mod noise_merge;
mod oracle;
mod pipeline;
mod plot;
mod raw;
mod raw_rawler;
mod raw_real;
mod render;
mod reproducible;
mod reproject;
mod sky;
mod sub_brackets;
mod sun_sweep;
mod sun_truth;
mod synth;
mod tilt;
mod tonemap;
mod truncated_jpeg;
mod uncertainty;
mod vignetting;
