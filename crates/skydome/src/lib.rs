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
pub mod overlay;
pub mod pipeline;
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
