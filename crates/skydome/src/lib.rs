//! # skydome
//!
//! Calibrated HDR radiance maps of the sky-dome from bracketed photos taken through a fish-eye
//! lens. The modules follow the pipeline, and data flows one way:
//!
//! ```text
//! bracket ─▶ sampling/response ─▶ merge ─▶ fisheye/sky/reproject ─▶ formats ─▶ tonemap/plot/render
//! ```
//!
//! Conventions used throughout (stated where they are decided):
//! - pixels: origin top-left, `x` right, `y` down, `(x, y)` order, sizes `(width, height)` — see [`image`];
//! - angles: degrees at user-facing boundaries (CLI, JSON, headers), radians inside;
//! - azimuth: from true north towards east; the camera looks **up**, so a sky image with north at
//!   the top has east on the **left**;
//! - radiance: linear, relative units unless an absolute calibration is known.
//!
//! The crate has no command-line or filesystem-walking dependencies and builds for
//! `wasm32-unknown-unknown`.

pub mod bracket;
pub mod compare;
pub mod fisheye;
pub mod formats;
pub mod image;
pub mod merge;
pub mod noise;
pub mod overlay;
pub mod plot;
pub mod render;
pub mod reproject;
pub mod response;
pub mod sampling;
pub mod sky;
pub mod synth;
pub mod tonemap;

pub use image::{HdrImage, RgbImage};

/// The library's version, written as `SOFTWARE=skydome <version>` in output headers.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
