//! What [`run`](super::run) returns: the products ([`Dome`]) and the [`Report`].

use serde::{Deserialize, Serialize};

use super::{CaptureReport, GeometryReport};
use crate::align::Alignment;
use crate::bracket::{Frame, RawColour};
use crate::camera::CameraProfile;
use crate::exposures::ExposureReport;
use crate::fisheye::LensProfile;
use crate::formats::HdrMeta;
use crate::image::{HdrImage, RgbImage};
use crate::merge::LinearNoise;
use crate::noise::NoiseEstimate;
use crate::overlay::OverlayMarks;
use crate::photometry::PhotometryReport;
use crate::sampling::SampleReport;

/// One frame in the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameSummary {
    /// Name (file name).
    pub file: String,
    /// Shutter time, seconds.
    pub time_s: f64,
    /// ISO, when known.
    pub iso: Option<f64>,
    /// f-number, when known.
    pub f_number: Option<f64>,
    /// Relative exposure `t · ISO / N²`.
    pub relative_exposure: f64,
}

/// What [`run`](super::run) did, serialisable (the command line's `--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Output width, pixels.
    pub width: usize,
    /// Output height, pixels.
    pub height: usize,
    /// The frames merged, shortest exposure first (with measured exposures: their measured
    /// times, one frame of each exposure).
    pub frames: Vec<FrameSummary>,
    /// Every frame's listed exposure against the one measured from the photos, and which the
    /// merge used (not for RAW brackets or a bracket read one photo at a time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exposures: Option<ExposureReport>,
    /// Where the response came from: "profile" or "calibrated on this bracket".
    pub response: String,
    /// The calibration used on this bracket, as `skydome calibrate --method` names it
    /// ([`crate::response::CalibrateOptions::method_name`]), with the default's `auto`
    /// resolved for the bracket's frame count (`covering` from five frames, `robust` below),
    /// when it calibrated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<String>,
    /// What calibration sampling did, when it calibrated.
    pub sampling: Option<SampleReport>,
    /// Pixels clipped even in the shortest exposure (a lower bound).
    pub clipped_high_pixels: usize,
    /// Pixels black even in the longest exposure.
    pub clipped_low_pixels: usize,
    /// Pixels black in every channel of every frame (kept neutral).
    pub black_pixels: usize,
    /// The noise model the merge used (weighting `noise`, or the consistency test).
    pub noise: Option<NoiseEstimate>,
    /// A RAW bracket's colour, demosaicing and estimated sensor noise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub raw: Option<RawReport>,
    /// The per-pixel standard error in summary, when the confidence map was asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub standard_error: Option<ErrorSummary>,
    /// Fraction of the tested pixels where frames disagree beyond their noise, when tested.
    pub inconsistent_fraction: Option<f64>,
    /// The translation of each frame, when aligned.
    pub alignment: Option<Alignment>,
    /// The header metadata of the radiance map.
    pub meta: HdrMeta,
    /// The fish-eye results, with a lens.
    pub geometry: Option<GeometryReport>,
    /// The absolute calibration, when a measurement was given.
    pub photometry: Option<PhotometryReport>,
    /// When and where the bracket was taken, and where each came from.
    pub capture: CaptureReport,
    /// Warnings, in neutral words, one sentence each.
    pub warnings: Vec<String>,
}

/// The products of [`run`](super::run).
#[derive(Debug, Clone)]
pub struct Dome {
    /// Linear radiance, relative units (cropped to the dome when asked).
    pub radiance: HdrImage,
    /// Header metadata for [`Dome::radiance`].
    pub meta: HdrMeta,
    /// The equirectangular map and its metadata, when asked.
    pub equirect: Option<(HdrImage, HdrMeta)>,
    /// The angular (`-vta`) dome and its metadata (with `VIEW=`), when asked.
    pub angular: Option<(HdrImage, HdrMeta)>,
    /// The tone-mapped preview, when asked.
    pub preview: Option<RgbImage<u8>>,
    /// The overlay picture, when asked (else [`Dome::overlay_picture`] makes it later).
    pub overlay: Option<RgbImage<u8>>,
    /// What the overlay draws (output pixels), when there was a lens.
    pub marks: Option<OverlayMarks>,
    /// The confidence picture, when asked: the per-pixel standard error in false colour with
    /// its scale bar ([`crate::plot::standard_error_picture`]; magenta = not measured), in the
    /// input photos' pixels.
    pub confidence: Option<RgbImage<u8>>,
    /// The per-pixel standard error of the radiance in stops (per channel, `+∞` where the
    /// bracket did not measure), in the input photos' pixels, when the confidence was asked
    /// for: the float map to write as `.exr`.
    pub standard_error: Option<HdrImage>,
    /// The consistency picture (white = frames disagree beyond their noise), when asked.
    pub consistency: Option<RgbImage<u8>>,
    /// The camera profile made by calibrating on this bracket (with the camera's EXIF make,
    /// model, ISO and date), when it calibrated.
    pub camera_profile: Option<CameraProfile>,
    /// Why [`Dome::camera_profile`] got no absolute constant although a meter reading made
    /// this dome absolute (frames without EXIF ISO or f-number, a RAW bracket); `None` when it
    /// got one or when there was nothing to store.
    pub absolute_constant_refused: Option<String>,
    /// The lens profile used, when there was a lens.
    pub lens_profile: Option<LensProfile>,
    /// The report.
    pub report: Report,
}

/// What the RAW path read and estimated.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RawReport {
    /// The colour read from the DNG.
    pub colour: RawColour,
    /// The Poisson–Gaussian noise estimated from the frames.
    pub noise: LinearNoise,
    /// The demosaicing method.
    pub demosaic: String,
}

/// The standard-error map in numbers (see [`crate::merge::standard_error`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    /// Median over the measured pixels (inside the lens circle when there is one) of each
    /// pixel's largest channel standard error, stops.
    pub median_stops: f64,
    /// The 90th percentile of the same, stops.
    pub p90_stops: f64,
    /// Fraction of the pixels the bracket did not measure (clipped in the shortest frame or
    /// black in the longest).
    pub unmeasured_fraction: f64,
}

/// Above this fraction of unmeasured pixels the report warns.
pub const UNMEASURED_WARN_FRACTION: f64 = 0.001;

impl ErrorSummary {
    /// The summary of a standard-error map, over the pixel centres inside `circle` when given.
    pub fn of(sigma: &HdrImage, circle: Option<&crate::image::Circle>) -> Self {
        let w = sigma.width.max(1);
        let inside = |k: usize| {
            circle.is_none_or(|c| {
                let (x, y) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
                (x - c.cx).hypot(y - c.cy) <= c.r
            })
        };
        let (median_stops, p90_stops, unmeasured_fraction) =
            crate::merge::summarise_standard_error(sigma, Some(&inside));
        Self {
            median_stops,
            p90_stops,
            unmeasured_fraction,
        }
    }

    /// The warning when part of the picture is beyond what the bracket measured.
    pub fn warning(&self) -> Option<String> {
        (self.unmeasured_fraction > UNMEASURED_WARN_FRACTION).then(|| {
            format!(
                "{:.2} % of the picture is beyond what the bracket measured (clipped in the shortest frame or black in the longest): its radiance is only a bound (magenta in the confidence map)",
                100.0 * self.unmeasured_fraction
            )
        })
    }
}

impl FrameSummary {
    /// The summary of one frame of the bracket.
    pub(super) fn of(f: &Frame) -> Self {
        Self {
            file: f.name.clone(),
            time_s: f.exposure.time_s,
            iso: f.exposure.iso,
            f_number: f.exposure.f_number,
            relative_exposure: f.exposure.relative(),
        }
    }
}
