//! The whole sky-dome job in one call: encoded photos in, radiance map, header metadata,
//! pictures and a report out.
//!
//! Every shell — the `skydome` command line, the phone web app, a future Python binding —
//! calls [`run`] and only maps its own arguments onto [`Options`], moves bytes and shows
//! [`Progress`]. The product's rules live here, once:
//!
//! 1. **decode** the frames ([`Frames::Encoded`]; JPEG, PNG, TIFF) and validate the
//!    [`bracket::Bracket`] (exposure times from EXIF unless [`Input::times`]);
//! 2. **lens**: a given [`LensProfile`], or the image circle detected on the best-exposed frame
//!    and modelled with the nominal projection and field of view ([`LensSource`]);
//! 3. **response**: a camera profile, or calibration on these frames, sampling inside
//!    [`Options::calibration_circle`] or else inside the lens circle ([`ResponseSource`]);
//! 4. **merge** to linear radiance ([`crate::merge`]);
//! 5. **sky** (only with a lens): crop to the dome, north, the sun (detected, tapped or from the
//!    ephemeris, cross-checked when two sources exist), Radiance `VIEW=`, the equirectangular map
//!    ([`SkyOptions`]);
//! 6. **pictures** that were asked for in [`Products`] (nothing unrequested is computed).
//!
//! Encoders return bytes ([`crate::formats::encode_radiance`],
//! [`crate::formats::picture::encode_rgb8`]); writing files is the shell's business.
//!
//! See the crate documentation for a complete example.

mod sky_stage;

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::bracket::{self, Bracket, BracketError, DecodeOptions, DecodedFrame, OrientationPolicy};
use crate::fisheye::{self, CircleFit, FisheyeError, LensKind, LensProfile};
use crate::formats::picture::PictureError;
use crate::formats::{HdrMeta, PixelPoint};
use crate::image::{Circle, HdrImage, RgbImage};
use crate::merge::{self, MergeError, MergeOptions, Weighting};
use crate::reproject::{Ground, ReprojectError};
use crate::response::{self, CalibrateOptions, CameraProfile, ResponseError};
use crate::sampling::SampleReport;
use crate::sky::{DevicePose, SkyError};
use crate::tonemap::{self, ToneMap, TonemapError};

pub use sky_stage::{GeometryReport, NorthFromSun, SunSource};

/// Errors of [`run`]: the stage's own error, or cancellation.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Decoding or validating the bracket failed (the message names the file).
    #[error(transparent)]
    Bracket(#[from] BracketError),
    /// The camera profile is unusable, or calibration failed.
    #[error("calibration failed: {0}")]
    Calibration(#[from] ResponseError),
    /// The lens profile or circle detection failed.
    #[error("{0}")]
    Lens(#[from] FisheyeError),
    /// The image circle could not be found.
    #[error("{frame}: cannot find the fish-eye image circle ({reason}); give the circle")]
    CircleNotFound {
        /// The frame it was looked for in.
        frame: String,
        /// What the detector said.
        reason: String,
    },
    /// The merge failed.
    #[error("merge failed: {0}")]
    Merge(#[from] MergeError),
    /// Sky geometry or the ephemeris failed.
    #[error("{0}")]
    Sky(#[from] SkyError),
    /// The capture time could not be read.
    #[error(
        "capture time '{0}': expected ISO 8601 with a UTC offset, e.g. 2026-06-21T12:30:00+02:00"
    )]
    BadTime(String),
    /// The ephemeris sun was asked for without a time or place.
    #[error("the sun from the ephemeris needs the capture time (EXIF or given) and the place (EXIF GPS or given latitude and longitude)")]
    NoEphemeris,
    /// North from the sun without an observed sun.
    #[error("north from the sun needs the sun in the image: detected (sun auto) or tapped, and none was found")]
    NoSunForNorth,
    /// A sky option was given without a lens.
    #[error("{0} needs a fish-eye lens (a lens profile or circle detection)")]
    NeedsLens(&'static str),
    /// The equirectangular map failed.
    #[error("equirectangular map: {0}")]
    Reproject(#[from] ReprojectError),
    /// The absolute calibration failed.
    #[error("{0}")]
    Photometry(#[from] crate::photometry::PhotometryError),
    /// Tone mapping a picture failed.
    #[error("{0}")]
    Tonemap(#[from] TonemapError),
    /// Encoding a picture failed.
    #[error("{0}")]
    Picture(#[from] PictureError),
    /// The progress callback asked to stop.
    #[error("cancelled")]
    Cancelled,
}

/// One encoded photo (JPEG, PNG or TIFF bytes) and the name used in messages (a file name).
#[derive(Debug, Clone)]
pub struct EncodedFrame {
    /// Name for messages, usually the file name.
    pub name: String,
    /// The file's bytes.
    pub bytes: Vec<u8>,
}

/// The frames of a bracket, encoded or already decoded.
#[derive(Debug, Clone)]
pub enum Frames {
    /// Encoded photos, decoded by [`run`] (in parallel with the `parallel` feature).
    Encoded(Vec<EncodedFrame>),
    /// Frames decoded by [`bracket::decode`].
    Decoded(Vec<DecodedFrame>),
}

/// What [`run`] reads.
#[derive(Debug, Clone)]
pub struct Input {
    /// The photos, in any order (they are sorted by exposure).
    pub frames: Frames,
    /// Exposure times in seconds, one per frame in the order given; overrides EXIF.
    pub times: Option<Vec<f64>>,
    /// Whether EXIF orientation is applied to the pixels.
    pub orientation: OrientationPolicy,
    /// Decoding limits.
    pub decode: DecodeOptions,
}

impl Input {
    /// Frames with exposure from EXIF, orientation applied, default limits.
    pub fn new(frames: Frames) -> Self {
        Self {
            frames,
            times: None,
            orientation: OrientationPolicy::Apply,
            decode: DecodeOptions::default(),
        }
    }
}

/// Where the camera response comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResponseSource {
    /// A stored camera profile.
    Profile(CameraProfile),
    /// Calibrate on this bracket.
    Calibrate(CalibrateOptions),
}

impl Default for ResponseSource {
    fn default() -> Self {
        Self::Calibrate(CalibrateOptions::default())
    }
}

/// Where the lens model comes from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LensSource {
    /// Not a fish-eye job: no circle, no sky geometry.
    #[default]
    None,
    /// A stored lens profile.
    Profile(LensProfile),
    /// The nominal model: the image circle (given, or detected on the best-exposed frame),
    /// a projection and the full field of view across the circle in degrees.
    Detect {
        /// Projection model.
        model: LensKind,
        /// Full field of view across the visible circle, degrees.
        fov_deg: f64,
        /// The circle when known; detected when `None`.
        circle: Option<Circle>,
    },
}

/// How the sun is found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SunMode {
    /// Detect the brightest compact blob inside the horizon.
    #[default]
    Auto,
    /// No sun.
    None,
    /// Compute it from the capture time and place (NREL SPA).
    Ephemeris,
    /// A tapped point in the input photos' pixels (origin top-left, before any crop).
    Tap(PixelPoint),
}

/// The sky part of the job; used only when there is a lens.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SkyOptions {
    /// Crop to a square around the dome of `fov_out_deg`.
    pub crop: bool,
    /// Field of view kept by the crop, degrees (180 = the horizon).
    pub fov_out_deg: f64,
    /// Compass azimuth of the phone's top edge, degrees from true north towards east. `None`:
    /// unknown (north is not marked and azimuths are not reported).
    pub north_deg: Option<f64>,
    /// Set north from the sun (observed: detected or tapped) and the ephemeris instead of the
    /// compass; `north_deg`, when given, is then only reported against. Needs time and place.
    pub north_from_sun: bool,
    /// How the phone lay.
    pub pose: DevicePose,
    /// The phone's tilt, when it was not level (from its accelerometer, or a measured tilt):
    /// the crop is then resampled so that the zenith is at its centre (north at the top), and
    /// every map is levelled.
    pub level: Option<crate::sky::Level>,
    /// How the sun is found.
    pub sun: SunMode,
    /// Capture time, ISO 8601 with a UTC offset; default: EXIF `DateTimeOriginal` + offset.
    pub time: Option<String>,
    /// Latitude in degrees, north positive; default: EXIF GPS.
    pub latitude_deg: Option<f64>,
    /// Longitude in degrees, east positive; default: EXIF GPS.
    pub longitude_deg: Option<f64>,
    /// What to do with a sun that clipped even in the shortest exposure (see
    /// [`crate::sun_disc`]).
    pub sun_disc: SunDisc,
}

/// What to do with a sun that clipped even in the shortest exposure.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SunDisc {
    /// Replace the clipped disc by the solar disc whose luminance makes the direct part right
    /// (from the illuminance reading, else the clear-sky model), and say so in the header.
    #[default]
    Reconstruct,
    /// Keep the clipped values (a lower bound).
    Keep,
}

crate::named_enum!(SunDisc, "sun disc", [Reconstruct => "reconstruct", Keep => "keep"]);

impl Default for SkyOptions {
    fn default() -> Self {
        Self {
            crop: false,
            fov_out_deg: 180.0,
            north_deg: None,
            north_from_sun: false,
            pose: DevicePose::ScreenDown,
            level: None,
            sun: SunMode::Auto,
            time: None,
            latitude_deg: None,
            longitude_deg: None,
            sun_disc: SunDisc::Reconstruct,
        }
    }
}

/// The equirectangular (lat-long) map: east at the centre, north at a quarter of the width.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EquirectOptions {
    /// Width in pixels (even); default [`default_equirect_width`] of the horizon radius.
    pub width: Option<usize>,
    /// What fills the lower hemisphere.
    pub ground: Ground,
}

/// The default width of the equirectangular map for a horizon of radius `horizon_r` pixels:
/// about 4 r (the horizon's circumference over π keeps the zenith's resolution), even,
/// within 64..=8192.
pub fn default_equirect_width(horizon_r: f64) -> usize {
    ((4.0 * horizon_r).round() as usize).clamp(64, 8192) & !1
}

/// Which products [`run`] makes besides the radiance map.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Products {
    /// The tone-mapped 8-bit preview (default operator and automatic exposure).
    pub preview: bool,
    /// The preview with the circles, north and sun drawn on it (needs a lens).
    pub overlay: bool,
    /// The per-pixel merge confidence as a grey picture.
    pub confidence: bool,
    /// The per-pixel consistency test as a picture (white = frames disagree; implies the test).
    pub consistency: bool,
    /// The equirectangular map (needs a lens).
    pub equirect: Option<EquirectOptions>,
    /// The 180° dome as Radiance's angular fish-eye (`-vta`, north up), whatever the lens's
    /// projection, for Radiance's tools (needs a lens).
    pub angular: bool,
}

/// Everything [`run`] is told besides the frames. Serialisable, so a web page can pass it as
/// JSON; every field has a default.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Options {
    /// Camera response.
    pub response: ResponseSource,
    /// Sample calibration pixels inside this circle; default: the lens circle, if any.
    pub calibration_circle: Option<Circle>,
    /// Frame weighting of the merge.
    pub weighting: Weighting,
    /// Black level of the frames, 8-bit code (0 for most cameras, ≈ 16 for film scans): codes
    /// at or below count as black.
    pub black_level: u8,
    /// Align hand-held frames by translation before calibrating and merging (see
    /// [`crate::align`]).
    pub align: bool,
    /// Test every pixel for frames disagreeing beyond their noise (moving clouds, shifts);
    /// the fraction goes to the report, with a warning above 2 %.
    pub consistency: bool,
    /// Ghost-aware merge (implies `consistency`): where frames disagree, keep what most frames
    /// agree on (see [`MergeOptions::ghosts`](crate::merge::MergeOptions::ghosts)).
    pub ghosts: bool,
    /// Lens model.
    pub lens: LensSource,
    /// Sky geometry (with a lens).
    pub sky: SkyOptions,
    /// Products besides the radiance map.
    pub products: Products,
    /// Measurements that make the radiance absolute (see [`crate::photometry`]).
    pub reference: crate::photometry::Reference,
}

/// A stage of [`run`], in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Decoding the photos.
    Decoding,
    /// Finding the lens circle.
    Lens,
    /// Calibrating the response.
    Calibrating,
    /// Merging.
    Merging,
    /// Crop, north, sun, maps.
    Sky,
    /// Tone-mapped pictures.
    Pictures,
}

impl Stage {
    /// Lower-case name for progress displays ("decoding", "calibrating", …).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Decoding => "decoding",
            Stage::Lens => "lens",
            Stage::Calibrating => "calibrating",
            Stage::Merging => "merging",
            Stage::Sky => "sky",
            Stage::Pictures => "pictures",
        }
    }
}

/// A progress event: `fraction` of `stage` done, in `0..=1`. Each stage sends 0 when it starts
/// and 1 when it ends, with steps in between where it has them (one per decoded frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// The stage.
    pub stage: Stage,
    /// Fraction done, `0..=1`.
    pub fraction: f64,
}

/// A progress callback that ignores the events and never cancels.
pub fn no_progress(_: &Progress) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

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

/// What [`run`] did, serialisable (the command line's `--json`).
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
    pub noise: Option<crate::noise::NoiseEstimate>,
    /// Fraction of the tested pixels where frames disagree beyond their noise, when tested.
    pub inconsistent_fraction: Option<f64>,
    /// The translation of each frame, when aligned.
    pub alignment: Option<crate::align::Alignment>,
    /// The header metadata of the radiance map.
    pub meta: HdrMeta,
    /// The fish-eye results, with a lens.
    pub geometry: Option<GeometryReport>,
    /// The absolute calibration, when a measurement was given.
    pub photometry: Option<crate::photometry::PhotometryReport>,
    /// Warnings, in neutral words, one sentence each.
    pub warnings: Vec<String>,
}

/// The products of [`run`].
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
    pub marks: Option<crate::overlay::OverlayMarks>,
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

/// Runs the job. `progress` receives [`Progress`] events and returns
/// [`ControlFlow::Break`] to cancel, which ends the run with [`PipelineError::Cancelled`]
/// at the next check (between frames and between stages).
pub fn run(
    input: Input,
    options: &Options,
    progress: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Dome, PipelineError> {
    let mut p = Reporter(progress);
    check_options(options)?;
    let mut br = read_bracket(input, &mut p)?;
    let mut warnings = br.warnings.clone();
    let alignment = if options.align {
        let a = crate::align::align(&br.frames, &crate::align::AlignOptions::default());
        br.frames = crate::align::apply_shifts(&br.frames, &a);
        Some(a)
    } else {
        None
    };

    p.at(Stage::Lens, 0.0)?;
    let lens = lens_profile(&options.lens, &br)?;
    p.at(Stage::Lens, 1.0)?;

    let circle = options
        .calibration_circle
        .or(lens.as_ref().map(|(l, _)| l.circle));
    p.at(Stage::Calibrating, 0.0)?;
    let (response, camera_profile, sampling, response_from) = match &options.response {
        ResponseSource::Profile(prof) => (prof.response()?, None, None, "profile".to_string()),
        ResponseSource::Calibrate(o) => {
            let cal = response::calibrate(&br.frames, circle, o)?;
            warnings.extend(cal.report().relaxed_warning());
            warnings.extend(cal.report().shortfall_warning());
            warnings.extend(cal.report().range_warning());
            let mut prof = cal.to_profile();
            describe_camera(&mut prof, &br);
            let report = cal.report().clone();
            let r = cal.response;
            (
                r,
                Some(prof),
                Some(report),
                "calibrated on this bracket".to_string(),
            )
        }
    };
    p.at(Stage::Calibrating, 1.0)?;

    p.at(Stage::Merging, 0.0)?;
    let profile_noise = match &options.response {
        ResponseSource::Profile(prof) => prof.noise.as_deref().copied(),
        ResponseSource::Calibrate(_) => None,
    };
    let check = options.consistency || options.ghosts || options.products.consistency;
    // Nothing after the merge reads the frames' pixels: give them back as the merge goes, so
    // the frames and the radiance are never both whole in memory.
    let merged = merge::merge_releasing(
        &mut br.frames,
        &response,
        &MergeOptions {
            weighting: options.weighting,
            confidence: options.products.confidence,
            // Only needed to count black pixels inside the lens circle.
            clipped_mask: lens.is_some(),
            noise: profile_noise,
            black_level: options.black_level,
            consistency: check,
            ghosts: options.ghosts,
        },
    )?;
    p.at(Stage::Merging, 1.0)?;
    // Black pixels and disagreement are judged inside the lens circle when there is one (the
    // housing outside is black in every frame by design).
    warnings.extend(merged.warnings(lens.as_ref().map(|(l, _)| &l.circle)));
    let inconsistent_fraction = merged
        .inconsistent
        .is_some()
        .then(|| merged.inconsistent_fraction());
    let camera_profile = camera_profile.map(|mut prof| {
        prof.noise = merged.noise.filter(|n| n.fitted).map(|n| Box::new(n.model));
        prof
    });
    let consistency = match (&merged.inconsistent, options.products.consistency) {
        (Some(f), true) => {
            let v: Vec<f32> = f.iter().map(|&b| b as f32).collect();
            Some(crate::formats::picture::grey_picture(
                br.width(),
                br.height(),
                &v,
            )?)
        }
        _ => None,
    };
    if merged.clipped_high > 0 {
        warnings.push(format!(
            "{} pixels are clipped even in the shortest exposure; their radiance is a lower bound",
            merged.clipped_high
        ));
    }
    let confidence = match &merged.confidence {
        Some(c) => Some(crate::formats::picture::grey_picture(
            br.width(),
            br.height(),
            c,
        )?),
        None => None,
    };

    let (capdate, gmt) = br.info.header_times();
    let mut meta = HdrMeta {
        capdate,
        gmt,
        ..HdrMeta::default()
    };
    let mut radiance = merged.radiance;
    if let Some((l, _)) = &lens {
        if let Some(v) = &l.vignetting {
            fisheye::devignette(&mut radiance, l, v);
        }
    }
    let mut photometry =
        calibrate_absolute(options, &br, lens.as_ref().map(|l| &l.0), &mut radiance)?;
    let (mut geometry, mut equirect, mut angular, mut marks) = (None, None, None, None);
    let lens_profile = lens.as_ref().map(|(l, _)| l.clone());
    let mut sun_from_reading = false;
    if let Some(lens) = lens {
        p.at(Stage::Sky, 0.0)?;
        let facts = sky_stage::MergeFacts {
            clipped: merged.clipped.as_deref(),
            photometry: photometry.as_ref(),
        };
        let g = sky_stage::apply(options, &br, lens, radiance, facts)?;
        if let Some(d) = &g.report.sun_disc {
            if let Some(p) = photometry.as_mut() {
                p.scale *= g.rescale;
                p.patch_luminance_cd_m2 = p.patch_luminance_cd_m2.map(|l| l * g.rescale);
                p.horizontal_illuminance_lux = Some(g.report.horizontal_illuminance);
            }
            sun_from_reading = d.from == crate::sun_disc::DirectSource::MeasuredIlluminance;
        }
        if let Some(p) = &photometry {
            meta.other.push(absolute_header_line(p));
        }
        if let Some(d) = &g.report.sun_disc {
            meta.other.push(d.header_line());
        }
        radiance = g.image;
        meta.sun = g.meta.sun;
        meta.north = g.meta.north;
        meta.view = g.meta.view;
        equirect = g.equirect.map(|e| (e, equirect_meta(&meta)));
        angular = g.angular.map(|(img, m)| {
            let m = HdrMeta {
                view: m.view,
                sun: m.sun,
                north: m.north,
                ..equirect_meta(&meta)
            };
            (img, m)
        });
        marks = Some(g.marks);
        warnings.extend(g.warnings);
        geometry = Some(g.report);
        p.at(Stage::Sky, 1.0)?;
    } else if let Some(p) = &photometry {
        meta.other.push(absolute_header_line(p));
    }
    if let Some(p) = &photometry {
        // A sun rebuilt from the illuminance reading is what the disagreement was.
        let d = p.disagreement_percent.filter(|d| d.abs() > 10.0);
        if let Some(d) = d.filter(|_| !sun_from_reading) {
            warnings.push(format!(
                "the dome's horizontal illuminance is {d:+.0} % off the illuminance reading (after the luminance reading's scale): a clipped sun, vignetting or a meter that saw a different sky"
            ));
        }
    }

    p.at(Stage::Pictures, 0.0)?;
    let preview = match options.products.preview {
        true => Some(tonemap::tonemap_u8(&radiance, &default_tonemap(None))?),
        false => None,
    };
    let overlay = match options.products.overlay {
        true => overlay_of(&radiance, marks.as_ref())?,
        false => None,
    };
    p.at(Stage::Pictures, 1.0)?;

    let report = Report {
        width: radiance.width,
        height: radiance.height,
        frames: br.frames.iter().map(frame_summary).collect(),
        response: response_from,
        sampling,
        clipped_high_pixels: merged.clipped_high,
        clipped_low_pixels: merged.clipped_low,
        black_pixels: merged.black_pixels,
        noise: merged.noise,
        inconsistent_fraction,
        alignment,
        meta: meta.clone(),
        geometry,
        photometry,
        warnings,
    };
    Ok(Dome {
        radiance,
        meta,
        equirect,
        angular,
        preview,
        overlay,
        marks,
        confidence,
        consistency,
        camera_profile,
        lens_profile,
        report,
    })
}

impl Dome {
    /// The overlay picture ([`Products::overlay`]), made now from the radiance and the marks:
    /// the same picture [`run`] makes when asked, for a caller that makes it only if it is
    /// wanted (the phone, when the user saves it). `None` without a lens (nothing to mark).
    pub fn overlay_picture(&self) -> Result<Option<RgbImage<u8>>, PipelineError> {
        overlay_of(&self.radiance, self.marks.as_ref())
    }
}

fn overlay_of(
    radiance: &HdrImage,
    marks: Option<&crate::overlay::OverlayMarks>,
) -> Result<Option<RgbImage<u8>>, PipelineError> {
    Ok(match marks {
        Some(m) => Some(crate::overlay::overlay_picture(
            radiance,
            m,
            &default_tonemap(m.visible),
        )?),
        None => None,
    })
}

/// The tone map of previews and overlays: the defaults, keyed on `circle` when given.
pub fn default_tonemap(circle: Option<Circle>) -> ToneMap {
    ToneMap {
        mask: circle,
        ..ToneMap::default()
    }
}

/// The metadata a map reprojected from a dome inherits: what describes the pixel values (the
/// capture times, `EXPOSURE=`, the units line of an absolute dome), not the dome's geometry
/// (its pixel positions of sun and north, its fish-eye `VIEW=`).
pub fn equirect_meta(dome: &HdrMeta) -> HdrMeta {
    HdrMeta {
        capdate: dome.capdate.clone(),
        gmt: dome.gmt.clone(),
        exposure: dome.exposure,
        other: dome.other.clone(),
        ..HdrMeta::default()
    }
}

/// Fills a camera profile's description from the bracket's EXIF: make, model, the first
/// frame's ISO and the capture date.
pub fn describe_camera(profile: &mut CameraProfile, br: &Bracket) {
    profile.make = br.info.make.clone();
    profile.model = br.info.model.clone();
    profile.iso = br.frames.first().and_then(|f| f.exposure.iso);
    profile.date = br.info.datetime_original.clone();
}

fn frame_summary(f: &bracket::Frame) -> FrameSummary {
    FrameSummary {
        file: f.name.clone(),
        time_s: f.exposure.time_s,
        iso: f.exposure.iso,
        f_number: f.exposure.f_number,
        relative_exposure: f.exposure.relative(),
    }
}

/// Scales `radiance` to Radiance's absolute units when a measurement is given.
fn calibrate_absolute(
    o: &Options,
    br: &Bracket,
    lens: Option<&LensProfile>,
    radiance: &mut HdrImage,
) -> Result<Option<crate::photometry::PhotometryReport>, PipelineError> {
    use crate::photometry;
    let r = &o.reference;
    if r.is_empty() {
        return Ok(None);
    }
    let patch = match &r.luminance {
        Some(s) => Some(photometry::patch_luminance(radiance, s)?),
        None => None,
    };
    let illuminance = match (r.illuminance_lux, lens) {
        (Some(_), Some(lens)) => {
            let g = sky_stage::full_geometry(o, br, lens)?;
            Some(crate::sky::radiance_luminance(
                crate::reproject::horizontal_irradiance_fisheye(radiance, &g),
            ))
        }
        _ => None,
    };
    let rep = photometry::absolute_scale(r, patch, illuminance)?;
    let k = rep.scale as f32;
    radiance.data.iter_mut().for_each(|v| *v *= k);
    Ok(Some(rep))
}

/// The header comment that states the units of an absolute dome.
fn absolute_header_line(p: &crate::photometry::PhotometryReport) -> String {
    let mut s = format!(
        "{}: Radiance W/sr/m2, luminance = 179*(0.265 R + 0.670 G + 0.065 B) cd/m2; scaled by {} from the {} reading",
        crate::formats::ABSOLUTE_UNITS_LINE,
        crate::image::fmt_num(p.scale),
        p.from
    );
    if let Some(d) = p.disagreement_percent {
        s += &format!(" (illuminance reading disagrees by {d:+.1} %)");
    }
    s
}

/// Refuses sky options and products that need a lens when there is none.
fn check_options(o: &Options) -> Result<(), PipelineError> {
    if o.lens != LensSource::None {
        return Ok(());
    }
    let s = &o.sky;
    let needs = [
        (s.crop, "cropping to the dome"),
        (s.north_deg.is_some() || s.north_from_sun, "north"),
        (s.level.is_some(), "a tilt"),
        (o.products.equirect.is_some(), "the equirectangular map"),
        (o.products.overlay, "the overlay"),
        (o.products.angular, "the angular dome"),
        (
            o.reference.illuminance_lux.is_some(),
            "an illuminance reading",
        ),
        (
            matches!(s.sun, SunMode::Tap(_) | SunMode::Ephemeris),
            "a sun position",
        ),
    ];
    match needs.iter().find(|(given, _)| *given) {
        Some((_, what)) => Err(PipelineError::NeedsLens(what)),
        None => Ok(()),
    }
}

/// Forwards progress events and turns a cancel into an error.
struct Reporter<'a>(&'a mut dyn FnMut(&Progress) -> ControlFlow<()>);

impl Reporter<'_> {
    fn at(&mut self, stage: Stage, fraction: f64) -> Result<(), PipelineError> {
        match (self.0)(&Progress { stage, fraction }) {
            ControlFlow::Continue(()) => Ok(()),
            ControlFlow::Break(()) => Err(PipelineError::Cancelled),
        }
    }
}

/// Decodes (when needed) and validates the bracket: the first step of [`run`], for callers
/// that need only the bracket (calibration alone).
pub fn load_bracket(
    input: Input,
    progress: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Bracket, PipelineError> {
    read_bracket(input, &mut Reporter(progress))
}

fn read_bracket(input: Input, p: &mut Reporter<'_>) -> Result<Bracket, PipelineError> {
    p.at(Stage::Decoding, 0.0)?;
    let decoded = match input.frames {
        Frames::Decoded(d) => d,
        Frames::Encoded(e) => decode_all(&e, &input.decode, p)?,
    };
    let br = bracket::assemble(decoded, input.times.as_deref(), input.orientation)?;
    p.at(Stage::Decoding, 1.0)?;
    Ok(br)
}

/// Decodes frames, a few at a time (in parallel with the `parallel` feature), reporting after
/// each group. The first frame's error wins, so the message is the same on every machine.
fn decode_all(
    frames: &[EncodedFrame],
    opts: &DecodeOptions,
    p: &mut Reporter<'_>,
) -> Result<Vec<DecodedFrame>, PipelineError> {
    if frames.len() < 2 {
        return Err(BracketError::TooFewFrames(frames.len()).into());
    }
    #[cfg(feature = "parallel")]
    let group = rayon::current_num_threads().max(1);
    #[cfg(not(feature = "parallel"))]
    let group = 1;
    let mut out = Vec::with_capacity(frames.len());
    for chunk in frames.chunks(group) {
        let decode = |f: &EncodedFrame| bracket::decode(&f.name, &f.bytes, opts);
        #[cfg(feature = "parallel")]
        let done: Vec<_> = {
            use rayon::prelude::*;
            chunk.par_iter().map(decode).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let done: Vec<_> = chunk.iter().map(decode).collect();
        for d in done {
            out.push(d?);
        }
        p.at(
            Stage::Decoding,
            out.len() as f64 / frames.len() as f64 * 0.99,
        )?;
    }
    Ok(out)
}

/// The lens profile and, when the circle was detected, the fit.
fn lens_profile(
    src: &LensSource,
    br: &Bracket,
) -> Result<Option<(LensProfile, Option<CircleFit>)>, PipelineError> {
    match src {
        LensSource::None => Ok(None),
        LensSource::Profile(l) => {
            l.validate()?;
            Ok(Some((l.clone(), None)))
        }
        LensSource::Detect {
            model,
            fov_deg,
            circle,
        } => {
            let (c, fit) = match circle {
                Some(c) => (*c, None),
                None => {
                    let fit = detect_circle(br)?;
                    (fit.circle, Some(fit))
                }
            };
            Ok(Some((LensProfile::from_fov(c, *fov_deg, *model)?, fit)))
        }
    }
}

/// Detects the image circle on the best-exposed frame (see [`bracket::best_exposed_u8`]).
pub fn detect_circle(br: &Bracket) -> Result<CircleFit, PipelineError> {
    let failed = |e: fisheye::FisheyeError| PipelineError::CircleNotFound {
        frame: br
            .frames
            .first()
            .map_or_else(String::new, |f| f.name.clone()),
        reason: e.to_string(),
    };
    match bracket::best_exposed(&br.frames) {
        // 8-bit frames are read where they are; 16-bit ones binned to a copy.
        Some(bracket::Frame {
            pixels: bracket::Pixels::U8(rgb),
            width,
            height,
            ..
        }) => fisheye::detect_circle_rgb8(rgb, *width, *height).map_err(failed),
        _ => detect_circle_in(&br.frames).map(|(fit, _)| fit),
    }
}

/// Detects the image circle in one photo or a bracket, on the best-exposed frame, and returns
/// the fit with that frame in 8 bits (for drawing on). One photo needs no exposure time; two or
/// more are validated as a bracket first.
pub fn detect_lens_circle(input: Input) -> Result<(CircleFit, RgbImage<u8>), PipelineError> {
    let frames = match input.frames {
        Frames::Encoded(e) if e.len() == 1 => {
            vec![bracket::decode(&e[0].name, &e[0].bytes, &input.decode)?]
        }
        Frames::Decoded(d) if d.len() == 1 => d,
        frames => {
            let input = Input { frames, ..input };
            let br = read_bracket(input, &mut Reporter(&mut no_progress))?;
            return detect_circle_in(&br.frames);
        }
    };
    let frames: Vec<bracket::Frame> = frames
        .into_iter()
        .map(|d| bracket::Frame {
            name: d.name,
            width: d.width,
            height: d.height,
            pixels: d.pixels,
            // Unused: one photo is not merged.
            exposure: bracket::Exposure {
                time_s: 1.0,
                iso: d.iso,
                f_number: d.f_number,
            },
        })
        .collect();
    detect_circle_in(&frames)
}

fn detect_circle_in(frames: &[bracket::Frame]) -> Result<(CircleFit, RgbImage<u8>), PipelineError> {
    let photo = bracket::best_exposed_u8(frames);
    let fit = fisheye::detect_circle(&photo).map_err(|e| PipelineError::CircleNotFound {
        frame: frames.first().map_or_else(String::new, |f| f.name.clone()),
        reason: e.to_string(),
    })?;
    Ok((fit, photo))
}
