//! What [`run`](super::run) returns: the products ([`Dome`]) and the [`Report`].

use serde::{Deserialize, Serialize};

use super::{CaptureReport, GeometryReport};
use crate::align::Alignment;
use crate::bracket::Frame;
use crate::camera::CameraProfile;
use crate::fisheye::LensProfile;
use crate::formats::HdrMeta;
use crate::image::{HdrImage, RgbImage};
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
    /// The frames, shortest exposure first.
    pub frames: Vec<FrameSummary>,
    /// Where the response came from: "profile" or "calibrated on this bracket".
    pub response: String,
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
    /// The confidence picture (grey, black = no frame well exposed), when asked.
    pub confidence: Option<RgbImage<u8>>,
    /// The consistency picture (white = frames disagree beyond their noise), when asked.
    pub consistency: Option<RgbImage<u8>>,
    /// The camera profile made by calibrating on this bracket (with the camera's EXIF make,
    /// model, ISO and date), when it calibrated.
    pub camera_profile: Option<CameraProfile>,
    /// The lens profile used, when there was a lens.
    pub lens_profile: Option<LensProfile>,
    /// The report.
    pub report: Report,
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
