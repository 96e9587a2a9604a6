//! The command line's integration tests, one module per subject, in one test binary (see
//! `crates/skydome/tests/lib/main.rs` for why). `cargo test -p skydome-cli --test cli demo::`
//! runs one subject's tests.

#[path = "../../../skydome/tests/common/mod.rs"]
mod common;

/// The fish-eye options for the synthetic lens (`skydome synth`'s 235° equidistant circle),
/// cropped to the dome.
pub const SYNTH_DOME: &[&str] = &[
    "--fisheye",
    "--lens-model",
    "equidistant",
    "--fov",
    "235",
    "--crop",
];

mod absolute;
mod bad_input;
mod batch;
mod batch_slurm;
mod calibrate_align;
mod demo;
mod flat_field;
mod memory_budget;
mod pipeline_identity;
mod radiance_tools;
mod raw;
mod real_sets;
