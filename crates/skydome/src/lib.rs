//! # skydome
//!
//! Calibrated HDR radiance maps of the sky-dome from bracketed photos taken through a fish-eye
//! lens. One entry point, [`pipeline::run`], runs the whole job; every shell (the `skydome`
//! command line, the phone web app) calls it. The modules are layered, and data flows one way:
//! a module uses only modules on its own line or the lines above it (a test,
//! `layers::no_module_uses_a_module_drawn_above_it`, reads this diagram and checks every
//! `crate::` path of the code against it):
//!
//! ```text
//! image, fastmath   pixels, circles, the bilinear sampler, luminance; fast maths
//!   ─▶ bracket   decoding, EXIF (lenient with piexif's), exposure times, the bracket's checks
//!   ─▶ align   translation of hand-held frames
//!   ─▶ sampling ─▶ response ─▶ exposures   calibration samples; response curves (Debevec & Malik); exposures measured from the photos
//!   ─▶ fisheye   lens circle, projections, lens profile and vignetting (flat fields need the response)
//!   ─▶ noise ─▶ merge   the camera noise model; the HDR merge
//!   ─▶ camera   the camera profile: response, noise model and weighting in one JSON
//!   ─▶ photometry   absolute units from a luminance or illuminance reading
//!   ─▶ sky ─▶ reproject ─▶ sun_disc   sky geometry, north, the sun; maps; the clipped sun put back
//!   ─▶ formats   .hdr, .exr, display pictures
//!   ─▶ tonemap ─▶ overlay, plot, render, compare   display and comparison
//!   ─▶ synth   synthetic brackets with known radiance (tests, the demo)
//!   ─▶ pipeline   runs the stages in order: bracket, lens, response, merge, sky, pictures
//!   ─▶ batch   a station's archive: captures grouped, shards, one table row per pipeline run
//! ```
//!
//! Two places differ from the order a photo travels in: `fisheye` sits above `response`
//! because measuring vignetting on flat fields linearises them with the camera's response, and
//! the camera profile is its own module (`camera`) above `merge` because it holds a response,
//! a noise model and a merge weighting.
//!
//! Photos in, a Radiance `.hdr` out:
//!
//! ```
//! use skydome::formats::{encode_radiance, RadianceFormat};
//! use skydome::pipeline::{self, EncodedFrame, Frames, Input, Options};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo");
//! let mut frames = Vec::new();
//! for name in ["frame_0.jpg", "frame_1.jpg", "frame_2.jpg"] {
//!     let bytes = std::fs::read(format!("{dir}/{name}"))?;
//!     frames.push(EncodedFrame { name: name.into(), bytes });
//! }
//! // Exposure times come from EXIF; these synthetic frames have none, so they are given (s).
//! let input = Input {
//!     times: Some(vec![0.001, 0.004, 0.016]),
//!     ..Input::new(Frames::Encoded(frames))
//! };
//! let dome = pipeline::run(input, &Options::default(), &mut pipeline::no_progress)?;
//! let hdr = encode_radiance(&dome.radiance, &dome.meta, RadianceFormat::Hdr)?.bytes;
//! assert!(hdr.starts_with(b"#?RADIANCE"));
//! println!("{}", serde_json::to_string(&dome.report)?);
//! # Ok(()) }
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

// The one `unsafe` block set is the noise merge's AVX2 kernel (merge/fused.rs), allowed there
// alone, with a SAFETY comment at each use.
#![deny(unsafe_code)]

pub mod align;
pub mod batch;
pub mod bracket;
pub mod camera;
pub mod compare;
pub mod exposures;
mod fastmath;
pub mod fisheye;
pub mod formats;
pub mod image;
#[cfg(test)]
mod layers;
pub mod merge;
pub mod noise;
pub mod overlay;
pub mod photometry;
pub mod pipeline;
pub mod plot;
pub mod render;
pub mod reproject;
pub mod response;
pub mod sampling;
pub mod sky;
pub mod sun_disc;
pub mod synth;
pub mod tonemap;

pub use image::{HdrImage, RgbImage};

/// The library's version, written as `SOFTWARE=skydome <version>` in output headers.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// A name that matches none of a setting's values, from the `FromStr` of the library's
/// option enums ([`merge::Weighting`], [`response::Solver`], [`bracket::OrientationPolicy`],
/// [`sky::DevicePose`], [`formats::exr::ExrCompression`], [`formats::exr::ExrPixelType`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{value}' is not a {what}; expected one of: {expected}")]
pub struct UnknownName {
    /// What was being named ("weighting", …).
    pub what: &'static str,
    /// The text given.
    pub value: String,
    /// The accepted names, comma-separated.
    pub expected: String,
}

/// Implements `Display`, `FromStr` (case-insensitive, [`UnknownName`] on failure) and a
/// `NAMES` list for an option enum, from one table of `Variant => "name"` pairs, so shells
/// parse and print the library's settings the same way.
macro_rules! named_enum {
    ($ty:ty, $what:literal, [$($variant:ident => $name:literal),+ $(,)?]) => {
        impl $ty {
            /// Every accepted name, in declaration order.
            pub const NAMES: &'static [&'static str] = &[$($name),+];

            /// The name of this value, as `Display` writes and `FromStr` reads it.
            pub fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $name,)+
                }
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $ty {
            type Err = $crate::UnknownName;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                let t = s.trim();
                $(if t.eq_ignore_ascii_case($name) {
                    return Ok(Self::$variant);
                })+
                Err($crate::UnknownName {
                    what: $what,
                    value: s.to_string(),
                    expected: Self::NAMES.join(", "),
                })
            }
        }
    };
}
pub(crate) use named_enum;
