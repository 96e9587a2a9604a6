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
//! 4. **merge** to linear radiance ([`crate::merge`]) — only the square the crop keeps when a
//!    plain crop to the dome is the first reader of the merged pixels (the same pixels, a third
//!    of a 235° fish-eye's memory; the clipped flags stay the whole photo's);
//! 5. **sky** (only with a lens): crop to the dome, north, the sun (detected, tapped or from the
//!    ephemeris, cross-checked when two sources exist), Radiance `VIEW=`, the equirectangular map
//!    ([`SkyOptions`]);
//! 6. **pictures** that were asked for in [`Products`] (nothing unrequested is computed).
//!
//! Encoders return bytes ([`crate::formats::encode_radiance`],
//! [`crate::formats::picture::encode_rgb8`]); writing files is the shell's business.
//!
//! See the crate documentation for a complete example.

mod absolute;
mod capture;
mod options;
mod progress;
mod report;
mod sky_stage;
mod stream;

use std::ops::ControlFlow;

use crate::align::{self, AlignOptions, Alignment};
use crate::bracket::{self, Bracket, BracketError, DecodeOptions, DecodedFrame, RawColour};
use crate::camera::CameraProfile;
use crate::exposures::{self, ExposureReport, ExposureSource};
use crate::fisheye::{self, CircleFit, FisheyeError, LensProfile};
use crate::formats::picture::{grey_picture, PictureError};
use crate::formats::{HdrMeta, ABSOLUTE_UNITS_LINE};
use crate::image::{fmt_num, Circle, HdrImage, RgbImage};
use crate::merge::{self, MergeError, MergeOptions, Merged};
use crate::noise;
use crate::overlay::{self, OverlayMarks};
use crate::photometry::{PhotometryError, PhotometryReport};
use crate::reproject::ReprojectError;
use crate::response::{self, Response, ResponseError};
use crate::sampling::SampleReport;
use crate::sky::SkyError;
use crate::sun_disc::DirectSource;
use crate::tonemap::{self, ToneMap, TonemapError};

pub use capture::{CaptureReport, Provenance};
pub use options::{
    default_equirect_width, AbsoluteMode, EncodedFrame, EquirectOptions, Frames, Input, LensSource,
    Options, Products, ResponseSource, SkyOptions, SunDisc, SunMode,
};
use progress::Reporter;
pub use progress::{no_progress, Progress, Stage};
pub use report::{Dome, ErrorSummary, FrameSummary, RawReport, Report};
pub use sky_stage::{GeometryReport, NorthFromSun, SunSource};
use sky_stage::{SkyOutcome, SkyResult};
pub use stream::{decoded_size, streams, streams_input};

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
    /// The time zone could not be read.
    #[error("time zone '{0}': expected a UTC offset such as +02:00, -05:00 or Z")]
    BadTimeZone(String),
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
    Photometry(#[from] PhotometryError),
    /// Tone mapping a picture failed.
    #[error("{0}")]
    Tonemap(#[from] TonemapError),
    /// Encoding a picture failed.
    #[error("{0}")]
    Picture(#[from] PictureError),
    /// Drawing the confidence picture failed.
    #[error("{0}")]
    Plot(#[from] crate::plot::PlotError),
    /// An absolute dome from the reflected-light meter equation was asked for, and the
    /// bracket cannot give one (the reason names the frames and what they lack).
    #[error("an absolute dome from EXIF (the meter equation): {0}")]
    AbsoluteExif(String),
    /// The progress callback asked to stop.
    #[error("cancelled")]
    Cancelled,
}

/// Runs the job. `progress` receives [`Progress`] events and returns
/// [`ControlFlow::Break`] to cancel, which ends the run with [`PipelineError::Cancelled`]
/// at the next check (between frames and between stages).
pub fn run(
    input: Input,
    options: &Options,
    progress: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Dome, PipelineError> {
    let mut progress = Reporter(progress);
    check_options(options)?;
    // A plain crop of a bracket of encoded photos is read one frame at a time (see
    // `stream`); otherwise, and whenever that path meets anything unusual, the whole frames.
    let (mut br, raw, alignment, lens, calibrated, mut prepared) =
        match stream::intake(&input, options, &mut progress)? {
            Some(s) => (s.br, None, None, s.lens, s.calibrated, Some(s.prepared)),
            None => {
                let measuring = options.exposures == ExposureSource::Measured;
                let (mut br, raw, same) =
                    read_bracket_as(input, options.black_level, measuring, &mut progress)?;
                // A RAW bracket's frames share one colour filter array: shifts keep its phase.
                let mosaic = raw.as_ref().is_some_and(|c| c.cfa.is_some());
                let alignment = options.align.then(|| align_frames(&mut br, mosaic));
                let lens = lens_stage(&options.lens, &br, &mut progress)?;
                let lens_circle = lens.as_ref().map(|(l, _)| l.circle);
                let calibrated = match &raw {
                    Some(_) => linear_response(options.exposures),
                    None => response_stage(options, &mut br, &same, lens_circle, &mut progress)?,
                };
                (br, raw, alignment, lens, calibrated, None)
            }
        };
    let lens_circle = lens.as_ref().map(|(l, _)| l.circle);
    let lens_profile = lens.as_ref().map(|(l, _)| l.clone());
    let (constant, absolute_warnings) =
        absolute::scale_without_reading(options, &br, &calibrated.response, raw.is_some())?;
    let whole_frames = prepared.is_some() || frames_are_whole(&br);
    let window = lens.as_ref().and_then(|(l, _)| {
        merge_window(
            options,
            l,
            (br.width(), br.height()),
            whole_frames,
            raw.is_some() || constant.is_some(),
        )
    });
    if window.is_none() {
        // The streamed intake merges only the window its options imply.
        prepared = None;
    }
    let MergeOutcome {
        mut merged,
        inconsistent_fraction,
        warnings: merge_warnings,
        sigma,
        raw: raw_report,
        at_ceiling,
    } = match &raw {
        Some(colour) => raw_merge_stage(options, &mut br, colour, lens_circle, &mut progress)?,
        None => merge_stage(
            options,
            &mut br,
            &calibrated.response,
            calibrated.wide_step,
            lens_circle,
            window,
            prepared,
            &mut progress,
        )?,
    };
    let standard_error = sigma
        .as_ref()
        .map(|s| ErrorSummary::of(s, lens_circle.as_ref()));
    let merged_radiance = std::mem::replace(&mut merged.radiance, HdrImage::new(0, 0));
    let sun_mask = sun_clip_mask(merged.clipped.as_deref(), &at_ceiling);
    let clipped = sun_mask.as_deref();
    let SkyOutcome {
        image: radiance,
        photometry,
        sky,
    } = sky_stage::run(
        options,
        &br,
        lens,
        merged_radiance,
        window.map_or((0, 0), |w| (w.x as i64, w.y as i64)),
        clipped,
        constant.as_ref(),
        &mut progress,
    )?;
    let capture = capture::resolve(options, &br)?;
    let meta = dome_meta(&capture, photometry.as_ref(), sky.as_ref());
    let marks = sky.as_ref().map(|s| s.marks);
    let pictures = pictures_stage(
        options,
        &radiance,
        marks.as_ref(),
        &merged,
        &br,
        &mut progress,
    )?;
    // The standard error in false colour, in the input photos' pixels (as the float map).
    let confidence = sigma
        .as_ref()
        .map(|s| crate::plot::standard_error_picture(s, lens_circle.as_ref(), 150))
        .transpose()?;
    let (equirect, angular, geometry, sky_warnings) = match sky.map(|s| sky_maps(s, &meta)) {
        Some(m) => (m.equirect, m.angular, Some(m.report), m.warnings),
        None => (None, None, None, Vec::new()),
    };
    // A sun rebuilt from the illuminance reading is what the reading's disagreement was.
    let sun_from_reading = geometry
        .as_ref()
        .and_then(|g| g.sun_disc.as_ref())
        .is_some_and(|d| d.from == DirectSource::MeasuredIlluminance);
    let warnings = [
        br.warnings.clone(),
        calibrated.warnings,
        absolute_warnings,
        merge_warnings,
        standard_error
            .as_ref()
            .and_then(ErrorSummary::warning)
            .into_iter()
            .collect(),
        sky_warnings,
        photometry_warning(photometry.as_ref(), sun_from_reading)
            .into_iter()
            .collect(),
    ]
    .concat();
    let report = Report {
        width: radiance.width,
        height: radiance.height,
        frames: br.frames.iter().map(FrameSummary::of).collect(),
        exposures: calibrated.exposures,
        response: calibrated.from.to_string(),
        calibration: calibrated.method,
        sampling: calibrated.sampling,
        clipped_high_pixels: merged.clipped_high,
        clipped_low_pixels: merged.clipped_low,
        black_pixels: merged.black_pixels,
        noise: merged.noise,
        raw: raw_report,
        standard_error,
        inconsistent_fraction,
        alignment,
        meta: meta.clone(),
        geometry,
        photometry,
        capture: capture.report,
        warnings,
    };
    // The profile made by calibrating carries the noise model the merge fitted and used, with
    // what came from the prior (on real JPEG brackets the white balance usually does), so a
    // merge with it need not fit its own.
    let mut camera_profile = calibrated.profile.map(|mut prof| {
        if let Some(n) = &merged.noise {
            prof.set_noise(n);
        }
        prof
    });
    // A reading (or the meter equation) made this dome absolute: the camera's constant goes
    // into its profile (the given one, when the response came from a profile).
    let (absolute_constant, absolute_constant_refused) =
        match absolute::constant_for_profile(&br, raw.is_some(), report.photometry.as_ref()) {
            Ok(c) => (c, None),
            Err(why) => (None, Some(why)),
        };
    if let Some(c) = absolute_constant {
        if let ResponseSource::Profile(given) = &options.response {
            camera_profile = Some(given.clone());
        }
        if let Some(p) = camera_profile.as_mut() {
            p.absolute = Some(c);
        }
    }
    Ok(Dome {
        radiance,
        meta,
        equirect,
        angular,
        preview: pictures.preview,
        overlay: pictures.overlay,
        marks,
        confidence,
        standard_error: sigma,
        consistency: pictures.consistency,
        camera_profile,
        absolute_constant_refused,
        lens_profile,
        report,
    })
}

/// Aligns hand-held frames by translation (see [`crate::align`]): the same step
/// `calibrate --align` runs. `mosaic`: the frames were demosaiced from one colour filter
/// array, so the shifts are even ([`AlignOptions::even`]).
fn align_frames(br: &mut Bracket, mosaic: bool) -> Alignment {
    let opts = AlignOptions {
        even: mosaic,
        ..AlignOptions::default()
    };
    align::align_bracket(&mut br.frames, &opts)
}

/// What the response stage found.
struct Calibrated {
    response: Response,
    /// The profile made by calibrating on this bracket (described from its EXIF).
    profile: Option<CameraProfile>,
    /// What calibration sampling did.
    sampling: Option<SampleReport>,
    /// The calibration's method name ([`response::CalibrateOptions::method_name`]), when it
    /// calibrated.
    method: Option<String>,
    /// Where the response came from, for the report.
    from: &'static str,
    warnings: Vec<String>,
    /// The listed exposures against those measured from the photos.
    exposures: Option<ExposureReport>,
    /// The calibration's step-periodic correction applied
    /// ([`response::Calibration::wide_step`]): the merge fits its noise model from codes
    /// [`noise::WIDE_STEP_NOISE_LO`] up.
    wide_step: bool,
}

/// A RAW bracket's response: linear by construction, nothing to fit. Its listed exposures are
/// used (measured ones are not offered for RAW yet: said in a warning when asked for).
fn linear_response(exposures: ExposureSource) -> Calibrated {
    let warnings = match exposures {
        ExposureSource::Listed => Vec::new(),
        ExposureSource::Measured => {
            vec!["exposures are not measured from RAW frames: the listed times were used".into()]
        }
    };
    Calibrated {
        response: Response::linear(),
        profile: None,
        sampling: None,
        method: None,
        from: "linear (RAW)",
        warnings,
        exposures: None,
        wide_step: false,
    }
}

/// The response stage: the camera profile's response, or a calibration on these frames,
/// sampled inside [`Options::calibration_circle`] or else the lens circle; and the exposures
/// ([`Options::exposures`]): the listed ones as they are, or the measured ones put into the
/// bracket (one frame of each exposure kept; with a calibration, alternating with the
/// measurement, [`exposures::calibrate_measuring`]) and reported against the listed ones.
/// `same` says which neighbouring frames carry the same picture (only when measuring).
fn response_stage(
    options: &Options,
    br: &mut Bracket,
    same: &[bool],
    lens_circle: Option<Circle>,
    progress: &mut Reporter<'_>,
) -> Result<Calibrated, PipelineError> {
    let circle = options.calibration_circle.or(lens_circle);
    let black = options.black_level;
    let source = options.exposures;
    progress.at(Stage::Calibrating, 0.0)?;
    // The listed times are used as they are, unchecked: a check on every merge read the
    // self-calibrated toe of a 16-frame film scan as times 1–3 stops off (false alarms), and
    // the streamed intake cannot make it; measuring is asked for (`--exposures measured`),
    // and its report lists every frame's listed and measured exposure.
    let calibrated = match (&options.response, source) {
        (ResponseSource::Profile(prof), ExposureSource::Listed) => Calibrated {
            response: prof.response()?,
            profile: None,
            sampling: None,
            method: None,
            from: "profile",
            warnings: Vec::new(),
            exposures: None,
            wide_step: false,
        },
        (ResponseSource::Calibrate(o), ExposureSource::Listed) => {
            let name = o.for_frames(br.frames.len()).method_name();
            calibrated_on(response::calibrate(&br.frames, circle, o)?, br, name)
        }
        (ResponseSource::Profile(prof), ExposureSource::Measured) => {
            let response = prof.response()?;
            let m = exposures::measure(&br.frames, &response, black, same);
            let mut c = Calibrated {
                response,
                profile: None,
                sampling: None,
                method: None,
                from: "profile",
                warnings: Vec::new(),
                exposures: None,
                wide_step: false,
            };
            measured_into(&mut c, br, &m, 0);
            c
        }
        (ResponseSource::Calibrate(o), ExposureSource::Measured) => {
            let (cal, m, rounds) =
                exposures::calibrate_measuring(&mut br.frames, same, circle, o, black)?;
            let mut c = calibrated_on(cal, br, exposures::measuring_options(o).method_name());
            measured_into(&mut c, br, &m, rounds);
            c
        }
    };
    progress.at(Stage::Calibrating, 1.0)?;
    Ok(calibrated)
}

/// Puts the measured exposures into the bracket's frames and their report (listed against
/// measured, with its warnings) into `c`.
fn measured_into(c: &mut Calibrated, br: &mut Bracket, m: &exposures::Measurement, rounds: usize) {
    let report = exposures::report(&br.frames, m, ExposureSource::Measured, rounds);
    c.warnings.extend(report.warnings());
    exposures::apply(&mut br.frames, m);
    c.exposures = Some(report);
}

/// What a calibration on this bracket gives the run: its response, the profile made from it
/// (described from the bracket's EXIF), the sampling report and its warnings, and the
/// method's name (saying so when a joined calibration gave the grid curve alone).
fn calibrated_on(cal: response::Calibration, br: &Bracket, method: String) -> Calibrated {
    let method = match cal.grid_alone {
        true => format!("{method} (the grid curve alone: the covering fit failed)"),
        false => method,
    };
    let sampling = cal.report().clone();
    let warnings = [
        sampling.relaxed_warning(),
        sampling.shortfall_warning(),
        sampling.range_warning(),
    ];
    let mut profile = CameraProfile::from_calibration(&cal);
    describe_camera(&mut profile, br);
    let wide_step = cal.wide_step;
    Calibrated {
        response: cal.response,
        profile: Some(profile),
        warnings: warnings.into_iter().flatten().collect(),
        sampling: Some(sampling),
        method: Some(method),
        from: "calibrated on this bracket",
        exposures: None,
        wide_step,
    }
}

/// What the merge stage found.
struct MergeOutcome {
    merged: Merged,
    /// Fraction of the tested pixels where frames disagree, when tested.
    inconsistent_fraction: Option<f64>,
    warnings: Vec<String>,
    /// The per-pixel standard error (stops, per channel), when the confidence was asked for.
    sigma: Option<HdrImage>,
    /// What the RAW path read and estimated, for a RAW bracket.
    raw: Option<RawReport>,
    /// The pixels (row-major indices) the shortest 8-bit frame reads at its ceiling
    /// ([`CEILING_CODE`]) in some channel, when a lens is known ([`shortest_at_ceiling`]).
    at_ceiling: Vec<u32>,
}

/// From this code up, a pixel of the shortest 8-bit frame is taken as clipped when the sky stage
/// looks for the sun and decides whether to rebuild its disc: a JPEG's ringing pulls a clipped
/// 255 down by a few codes (the merge's consistency test treats the same codes as lower bounds),
/// and a sun read at 251–254 in the shortest frame was otherwise merged as measured, its disc
/// never rebuilt, and the dome's illuminance 40–87 % short.
pub const CEILING_CODE: u8 = 250;

/// The pixels of the shortest frame of `frames` (shortest first) that read at least
/// [`CEILING_CODE`] in some channel; empty for 16-bit frames, which have no JPEG ringing.
fn shortest_at_ceiling(frames: &[bracket::Frame]) -> Vec<u32> {
    frames
        .first()
        .map_or_else(Vec::new, |f| at_ceiling(&f.pixels))
}

/// The pixels of `p` (the shortest frame) at [`CEILING_CODE`] or above in some channel; empty
/// for 16-bit pixels.
///
/// In blocks of [`CEILING_BLOCK`] pixels, in parallel with the `parallel` feature: a block whose
/// largest sample is below the ceiling (a loop that vectorises) is skipped, which is nearly every
/// block of a shortest frame; the others are scanned pixel by pixel. The indices come out in
/// ascending order, as from one scan (which took 17 ms natively and 27 ms in the browser on
/// 12 MP, on one thread).
fn at_ceiling(p: &bracket::Pixels) -> Vec<u32> {
    let bracket::Pixels::U8(v) = p else {
        return Vec::new();
    };
    let block = |(b, s): (usize, &[u8])| -> Vec<u32> {
        if s.iter().copied().max().unwrap_or(0) < CEILING_CODE {
            return Vec::new();
        }
        s.chunks_exact(3)
            .enumerate()
            .filter(|(_, p)| p.iter().any(|&c| c >= CEILING_CODE))
            .map(|(i, _)| (b * CEILING_BLOCK + i) as u32)
            .collect()
    };
    #[cfg(feature = "parallel")]
    let blocks: Vec<Vec<u32>> = {
        use rayon::prelude::*;
        v.par_chunks(3 * CEILING_BLOCK)
            .enumerate()
            .map(block)
            .collect()
    };
    #[cfg(not(feature = "parallel"))]
    let blocks: Vec<Vec<u32>> = v.chunks(3 * CEILING_BLOCK).enumerate().map(block).collect();
    blocks.concat()
}

/// Pixels per block of [`at_ceiling`].
const CEILING_BLOCK: usize = 4096;

/// The clip mask the sky stage judges the sun by: the merge's flags, with the pixels at the
/// shortest frame's ceiling flagged [`merge::CLIPPED_HIGH`] too.
fn sun_clip_mask<'a>(
    clipped: Option<&'a [u8]>,
    at_ceiling: &[u32],
) -> Option<std::borrow::Cow<'a, [u8]>> {
    let mask = clipped?;
    if at_ceiling.is_empty() {
        return Some(std::borrow::Cow::Borrowed(mask));
    }
    let mut m = mask.to_vec();
    for &i in at_ceiling {
        if let Some(f) = m.get_mut(i as usize) {
            *f |= merge::CLIPPED_HIGH;
        }
    }
    Some(std::borrow::Cow::Owned(m))
}

/// The merge stage of a RAW bracket: linear frames merged per camera channel with their
/// Poisson–Gaussian noise, then to linear Rec.709 (see [`merge::merge_linear`]).
fn raw_merge_stage(
    options: &Options,
    br: &mut Bracket,
    colour: &RawColour,
    lens_circle: Option<Circle>,
    progress: &mut Reporter<'_>,
) -> Result<MergeOutcome, PipelineError> {
    progress.at(Stage::Merging, 0.0)?;
    let lin = merge::merge_linear(&br.frames, colour, None)?;
    for f in br.frames.iter_mut() {
        f.pixels.release_from(0);
    }
    progress.at(Stage::Merging, 1.0)?;
    let merged = Merged {
        radiance: lin.radiance,
        confidence: None,
        clipped: lens_circle.is_some().then(|| lin.clipped.clone()),
        clipped_high: lin.clipped_high,
        clipped_low: lin.clipped_low,
        black_pixels: 0,
        noise: None,
        inconsistent: None,
        inconsistent_pixels: 0,
        tested_pixels: 0,
    };
    let mut warnings = Vec::new();
    if !lin.noise.fitted {
        warnings.push("the sensor's noise could not be estimated from this RAW bracket (too few photosites well exposed in two frames): a typical phone sensor was assumed for the weights".into());
    }
    if merged.clipped_high > 0 {
        warnings.push(format!(
            "{} pixels are clipped even in the shortest exposure; their radiance is a lower bound",
            merged.clipped_high
        ));
    }
    if colour.matrix_from.starts_with("identity") {
        warnings.push("the DNG has no colour matrix: camera RGB was kept (white-balanced), not converted to Rec.709".into());
    }
    Ok(MergeOutcome {
        merged,
        inconsistent_fraction: None,
        warnings,
        sigma: options.products.confidence.then_some(lin.sigma_stops),
        at_ceiling: Vec::new(),
        raw: Some(RawReport {
            colour: colour.clone(),
            noise: lin.noise,
            demosaic: "bilinear".into(),
        }),
    })
}

/// The merge stage: linear radiance from the frames, whose pixels are given back as the merge
/// goes (nothing after it reads them, so the frames and the radiance are never both whole in
/// memory). Black pixels and disagreement are judged inside the lens circle when there is one
/// (the housing outside is black in every frame by design). `wide_step`: the calibration's
/// step-periodic correction applied, so a fitted noise model is fitted from code 24 up
/// ([`noise::estimate_for_calibration`]).
#[allow(clippy::too_many_arguments)]
fn merge_stage(
    options: &Options,
    br: &mut Bracket,
    response: &Response,
    wide_step: bool,
    lens_circle: Option<Circle>,
    window: Option<Window>,
    prepared: Option<stream::Prepared>,
    progress: &mut Reporter<'_>,
) -> Result<MergeOutcome, PipelineError> {
    progress.at(Stage::Merging, 0.0)?;
    // A profile's noise model (with what in it came from the prior) stands in for a fit,
    // scaled to the bracket's ISO when the profile was measured at another.
    let profile_estimate = match &options.response {
        ResponseSource::Profile(prof) => prof.noise_estimate_at_iso(bracket_iso(&br.frames)),
        ResponseSource::Calibrate(_) => None,
    };
    // Without one, the noise-aware merge's model is fitted here, on the whole frames (or the
    // pixels of them that the streamed intake kept for it, which give the same fit): a merge of
    // the dome's window alone then weighs every pixel as the whole photo's merge would.
    let fitted_estimate = match (profile_estimate, options.weighting, &prepared) {
        (None, merge::Weighting::Noise, Some(p)) => Some(noise::estimate_for_calibration(
            &p.noise_samples,
            response,
            options.black_level,
            None,
            wide_step,
        )),
        (None, merge::Weighting::Noise, None) => Some(noise::estimate_for_calibration(
            &br.frames,
            response,
            options.black_level,
            None,
            wide_step,
        )),
        _ => None,
    };
    let known_estimate = profile_estimate.or(fitted_estimate);
    let known_noise = known_estimate.map(|n| n.model);
    // The standard error needs a noise model; the frames are given back during the merge.
    let error_noise = options.products.confidence.then(|| match known_noise {
        Some(n) => n,
        None => {
            let black = options.black_level;
            noise::estimate_for_calibration(&br.frames, response, black, None, wide_step).model
        }
    });
    let log_exposures: Vec<f64> = br
        .frames
        .iter()
        .map(|f| f.exposure.relative().ln())
        .collect();
    let at_ceiling = match (lens_circle, &prepared) {
        (Some(_), Some(p)) => p.at_ceiling.clone(),
        (Some(_), None) => shortest_at_ceiling(&br.frames),
        (None, _) => Vec::new(),
    };
    let merge_options = MergeOptions {
        weighting: options.weighting,
        confidence: options.products.confidence,
        // Only needed to count black pixels inside the lens circle.
        clipped_mask: lens_circle.is_some() || options.products.confidence,
        noise: known_noise,
        black_level: options.black_level,
        consistency: options.consistency || options.ghosts || options.products.consistency,
        ghosts: options.ghosts,
    };
    let (mut merged, mut warnings) = match (window, prepared) {
        (Some(_), Some(p)) => merge_parts(
            p.parts,
            p.flags,
            (br.width(), br.height()),
            response,
            &merge_options,
            lens_circle.as_ref(),
        )?,
        (None, _) => {
            let merged = merge::merge_releasing(&mut br.frames, response, &merge_options)?;
            let warnings = merged.warnings(lens_circle.as_ref());
            (merged, warnings)
        }
        (Some(w), None) => merge_in_window(
            &mut br.frames,
            w,
            response,
            &merge_options,
            lens_circle.as_ref(),
        )?,
    };
    progress.at(Stage::Merging, 1.0)?;
    // The merge reports a given model as fitted; the profile or the fit says what was the
    // prior's.
    if let (Some(n), Some(p)) = (merged.noise.as_mut(), known_estimate) {
        if n.model == p.model {
            *n = p;
        }
    }
    if merged.clipped_high > 0 {
        warnings.push(format!(
            "{} pixels are clipped even in the shortest exposure; their radiance is a lower bound",
            merged.clipped_high
        ));
    }
    let inconsistent_fraction = merged
        .inconsistent
        .is_some()
        .then(|| merged.inconsistent_fraction());
    let sigma = error_noise.map(|n| {
        let model = merged.noise.map_or(n, |e| e.model);
        merge::standard_error(
            &merged.radiance,
            merged.clipped.as_deref(),
            &log_exposures,
            response,
            &model,
            options.weighting,
            options.black_level,
        )
    });
    Ok(MergeOutcome {
        merged,
        inconsistent_fraction,
        warnings,
        sigma,
        raw: None,
        at_ceiling,
    })
}

/// The bracket's ISO speed: the frames' one ISO, when every frame states the same (a bracket
/// that varies ISO is warned about in the bracket checks and gets no single value).
fn bracket_iso(frames: &[bracket::Frame]) -> Option<f64> {
    let first = frames.first()?.exposure.iso?;
    frames
        .iter()
        .all(|f| f.exposure.iso == Some(first))
        .then_some(first)
}

/// The part of the photos (input pixels, origin top-left) that [`run`] merges when the dome is
/// all it keeps of them: the square the crop copies ([`fisheye::dome_crop_box`]) within the
/// frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Window {
    x: usize,
    y: usize,
    width: usize,
    height: usize,
}

/// The [`Window`] to merge, when a plain crop to the dome is the only reader of the merged
/// pixels: nothing reads the photo beyond the crop's square (no level dome, vignetting, reading,
/// absolute scale or north from the sun, all of which work on the whole photo before the crop),
/// and no per-pixel product of the whole photo is asked for (confidence, consistency). The
/// noise-aware merge's fit reads the whole bracket, so [`merge_stage`] makes it before the
/// window's merge. `whole` is true for a RAW
/// bracket or an absolute scale without a reading (merged whole). The merged pixels are the
/// same either way; a 12 MP phone dome's radiance shrinks from 144 to about 49 MB.
fn merge_window(
    o: &Options,
    lens: &LensProfile,
    (w, h): (usize, usize),
    whole_frames: bool,
    whole: bool,
) -> Option<Window> {
    let plain = !whole && plain_crop(o) && lens.vignetting.is_none();
    if !plain {
        return None;
    }
    let (ox, oy, n, _) = fisheye::dome_crop_box(lens, o.sky.fov_out_deg).ok()?;
    let clamp = |v: i64, max: usize| v.clamp(0, max as i64) as usize;
    let (x0, y0) = (clamp(ox, w), clamp(oy, h));
    let (x1, y1) = (clamp(ox + n as i64, w), clamp(oy + n as i64, h));
    let win = Window {
        x: x0,
        y: y0,
        width: x1.saturating_sub(x0),
        height: y1.saturating_sub(y0),
    };
    (whole_frames && win.width > 0 && win.height > 0 && win.width * win.height < w * h)
        .then_some(win)
}

/// Whether every frame of `br` holds its whole picture (`3 · width · height` samples).
fn frames_are_whole(br: &Bracket) -> bool {
    let (w, h) = (br.width(), br.height());
    br.frames
        .iter()
        .all(|f| (f.width, f.height, f.pixels.len()) == (w, h, 3 * w * h))
}

/// The options' part of [`merge_window`]'s rule: a plain crop to the dome is the first reader
/// of the merged pixels (the lens's vignetting is the other part).
fn plain_crop(o: &Options) -> bool {
    o.sky.crop
        && o.sky.level.is_none()
        && !o.sky.north_from_sun
        && o.reference.is_empty()
        && !o.products.confidence
        && !o.products.consistency
        && !o.consistency
        && !o.ghosts
}

/// The merge of `frames`' `window` alone, each frame's pixels given back once its part is
/// copied; the clipped-pixel flags, their counts and the merge's warnings (black pixels inside
/// the lens circle `area`) still of the whole photo, from the codes ([`merge::clipped_flags`]),
/// as the sky stage and the report expect them.
fn merge_in_window(
    frames: &mut [bracket::Frame],
    window: Window,
    response: &Response,
    opts: &MergeOptions,
    area: Option<&Circle>,
) -> Result<(Merged, Vec<String>), PipelineError> {
    let (w, h) = frames.first().map_or((0, 0), |f| (f.width, f.height));
    let flags = merge::clipped_flags(frames, opts.black_level);
    let parts: Vec<bracket::Frame> = frames.iter_mut().map(|f| window_of(f, window)).collect();
    merge_parts(parts, flags, (w, h), response, opts, area)
}

/// The merge of `parts` (the frames' window) with the whole photo's `flags` (of a `w × h`
/// photo), as [`merge_in_window`] describes.
fn merge_parts(
    mut parts: Vec<bracket::Frame>,
    flags: merge::ClippedFlags,
    (w, h): (usize, usize),
    response: &Response,
    opts: &MergeOptions,
    area: Option<&Circle>,
) -> Result<(Merged, Vec<String>), PipelineError> {
    let part = merge::merge_releasing(
        &mut parts,
        response,
        &MergeOptions {
            // The flags are the whole photo's (above).
            clipped_mask: false,
            ..*opts
        },
    )?;
    let whole = Merged {
        // The whole photo's size, for the warnings' per-pixel flags; the pixels come below.
        radiance: HdrImage {
            width: w,
            height: h,
            data: Vec::new(),
        },
        clipped: opts.clipped_mask.then_some(flags.mask),
        clipped_high: flags.high,
        clipped_low: flags.low,
        black_pixels: flags.black,
        ..part
    };
    let warnings = whole.warnings(area);
    Ok((
        Merged {
            radiance: part.radiance,
            ..whole
        },
        warnings,
    ))
}

/// `f`'s pixels inside `window` as a frame of their own (same name and exposure); `f`'s pixel
/// buffer is given back (its size, name and exposure are kept).
fn window_of(f: &mut bracket::Frame, window: Window) -> bracket::Frame {
    let pixels = window_pixels(&f.pixels, f.width, window);
    f.pixels.release_from(0);
    bracket::Frame {
        name: f.name.clone(),
        width: window.width,
        height: window.height,
        pixels,
        exposure: f.exposure,
    }
}

/// The pixels of `p` (a frame `width` pixels wide) inside `window`.
fn window_pixels(p: &bracket::Pixels, width: usize, window: Window) -> bracket::Pixels {
    fn rows<T: Copy>(v: &[T], width: usize, win: Window) -> Vec<T> {
        let mut out = Vec::with_capacity(3 * win.width * win.height);
        for y in win.y..win.y + win.height {
            let s = 3 * (y * width + win.x);
            out.extend_from_slice(&v[s..s + 3 * win.width]);
        }
        out
    }
    match p {
        bracket::Pixels::U8(v) => bracket::Pixels::U8(rows(v, width, window)),
        bracket::Pixels::U16(v) => bracket::Pixels::U16(rows(v, width, window)),
    }
}

/// The radiance map's header, every line in one place: the capture times; the units line of an
/// absolute dome; and from the sky stage the line of a reconstructed sun, the sun, north and
/// `VIEW=`.
fn dome_meta(
    capture: &capture::Capture,
    photometry: Option<&PhotometryReport>,
    sky: Option<&SkyResult>,
) -> HdrMeta {
    let (capdate, gmt) = capture.header_times();
    let mut meta = HdrMeta {
        capdate,
        gmt,
        ..HdrMeta::default()
    };
    meta.other.extend(capture.site_line());
    if let Some(p) = photometry {
        meta.other.push(absolute_header_line(p));
    }
    if let Some(s) = sky {
        if let Some(d) = &s.report.sun_disc {
            meta.other.push(d.header_line());
        }
        meta.sun = s.meta.sun;
        meta.north = s.meta.north;
        meta.view = s.meta.view.clone();
    }
    meta
}

/// The sky stage's products with their headers, which inherit the dome's ([`equirect_meta`]).
struct SkyMaps {
    equirect: Option<(HdrImage, HdrMeta)>,
    angular: Option<(HdrImage, HdrMeta)>,
    report: GeometryReport,
    warnings: Vec<String>,
}

fn sky_maps(sky: SkyResult, dome: &HdrMeta) -> SkyMaps {
    SkyMaps {
        equirect: sky.equirect.map(|e| (e, equirect_meta(dome))),
        angular: sky.angular.map(|(img, m)| {
            let m = HdrMeta {
                view: m.view,
                sun: m.sun,
                north: m.north,
                ..equirect_meta(dome)
            };
            (img, m)
        }),
        report: sky.report,
        warnings: sky.warnings,
    }
}

/// The warning when the dome's horizontal illuminance is more than 10 % off the illuminance
/// reading, unless the sun was rebuilt from that reading.
fn photometry_warning(p: Option<&PhotometryReport>, sun_from_reading: bool) -> Option<String> {
    let d = p?.disagreement_percent.filter(|d| d.abs() > 10.0);
    d.filter(|_| !sun_from_reading).map(|d| {
        format!(
            "the dome's horizontal illuminance is {d:+.0} % off the illuminance reading (after the luminance reading's scale): a clipped sun, vignetting or a meter that saw a different sky"
        )
    })
}

/// The pictures asked for in [`Products`].
struct Pictures {
    preview: Option<RgbImage<u8>>,
    overlay: Option<RgbImage<u8>>,
    consistency: Option<RgbImage<u8>>,
}

/// The pictures stage: the merge's consistency picture (in the input photos'
/// pixels), the preview and the overlay of the final dome; nothing unrequested is computed.
fn pictures_stage(
    options: &Options,
    radiance: &HdrImage,
    marks: Option<&OverlayMarks>,
    merged: &Merged,
    br: &Bracket,
    progress: &mut Reporter<'_>,
) -> Result<Pictures, PipelineError> {
    let products = &options.products;
    let (w, h) = (br.width(), br.height());
    let consistency = match (&merged.inconsistent, products.consistency) {
        (Some(f), true) => {
            let v: Vec<f32> = f.iter().map(|&b| b as f32).collect();
            Some(grey_picture(w, h, &v)?)
        }
        _ => None,
    };
    progress.at(Stage::Pictures, 0.0)?;
    let preview = match products.preview {
        true => Some(tonemap::tonemap_u8(radiance, &default_tonemap(None))?),
        false => None,
    };
    let overlay = match products.overlay {
        true => overlay_of(radiance, marks)?,
        false => None,
    };
    progress.at(Stage::Pictures, 1.0)?;
    Ok(Pictures {
        preview,
        overlay,
        consistency,
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
    marks: Option<&OverlayMarks>,
) -> Result<Option<RgbImage<u8>>, PipelineError> {
    Ok(match marks {
        Some(m) => Some(overlay::overlay_picture(
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

/// The header comment that states the units of an absolute dome. The scale is written to nine
/// significant digits: the WebAssembly build's maths library differs from the native one in the
/// last bits, and the app must write the CLI's bytes.
fn absolute_header_line(p: &PhotometryReport) -> String {
    let source = match p.from {
        crate::photometry::FROM_PROFILE => {
            "the camera profile's constant and EXIF time, ISO and f-number".to_string()
        }
        crate::photometry::FROM_METER_EQUATION => format!(
            "EXIF time, ISO and f-number by the reflected-light meter equation (K = {}), an estimate",
            crate::camera::METER_CONSTANT_K
        ),
        reading => format!("the {reading} reading"),
    };
    let mut s = format!(
        "{}: Radiance W/sr/m2, luminance = 179*(0.265 R + 0.670 G + 0.065 B) cd/m2; scaled by {} from {source}",
        ABSOLUTE_UNITS_LINE,
        fmt_num(format!("{:.8e}", p.scale).parse().unwrap_or(p.scale)),
    );
    if let Some(u) = p.uncertainty_percent {
        s += &format!(" (+/-{} %)", fmt_num(u));
    }
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

/// Decodes (when needed) and validates the bracket: the first step of [`run`], for callers
/// that need only the bracket (calibration alone).
pub fn load_bracket(
    input: Input,
    progress: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Bracket, PipelineError> {
    read_bracket(input, 0, &mut Reporter(progress)).map(|(b, _)| b)
}

/// Decodes and assembles the bracket; `black_level` is [`Options::black_level`] (0 = not
/// known), which the bracket's checks honour. The second value is the colour of a RAW bracket.
fn read_bracket(
    input: Input,
    black_level: u8,
    p: &mut Reporter<'_>,
) -> Result<(Bracket, Option<RawColour>), PipelineError> {
    read_bracket_as(input, black_level, false, p).map(|(b, raw, _)| (b, raw))
}

/// [`read_bracket`]; with `measuring` (exposures measured from the photos), neighbours that
/// carry the same picture are kept ([`bracket::assemble_for_measuring`]), and the third value
/// says which neighbouring pairs do (all `false` otherwise).
fn read_bracket_as(
    input: Input,
    black_level: u8,
    measuring: bool,
    p: &mut Reporter<'_>,
) -> Result<(Bracket, Option<RawColour>, Vec<bool>), PipelineError> {
    p.at(Stage::Decoding, 0.0)?;
    let (decoded, raw) = match input.frames {
        Frames::Decoded(d) => (d, None),
        Frames::Encoded(e) => decode_all(&e, &input.decode, p)?,
    };
    // RAW frames keep their sensor order (the CFA phase), whatever EXIF says.
    let orientation = match raw {
        Some(_) => bracket::OrientationPolicy::Ignore,
        None => input.orientation,
    };
    let times = input.times.as_deref();
    let (br, same) = match measuring && raw.is_none() {
        true => bracket::assemble_for_measuring(decoded, times, orientation, black_level)?,
        false => {
            let br = bracket::assemble_with_black_level(decoded, times, orientation, black_level)?;
            let same = vec![false; br.frames.len().saturating_sub(1)];
            (br, same)
        }
    };
    p.at(Stage::Decoding, 1.0)?;
    Ok((br, raw, same))
}

/// Decodes frames, a few at a time (in parallel with the `parallel` feature), reporting after
/// each group. The first frame's error wins, so the message is the same on every machine.
/// A bracket is RAW (DNG) or not as a whole; the colour is the first DNG's.
fn decode_all(
    frames: &[EncodedFrame],
    opts: &DecodeOptions,
    p: &mut Reporter<'_>,
) -> Result<(Vec<DecodedFrame>, Option<RawColour>), PipelineError> {
    if frames.len() < 2 {
        return Err(BracketError::TooFewFrames(frames.len()).into());
    }
    #[cfg(feature = "parallel")]
    let group = rayon::current_num_threads().max(1);
    #[cfg(not(feature = "parallel"))]
    let group = 1;
    let mut out = Vec::with_capacity(frames.len());
    let mut raw_of: Option<RawColour> = None;
    for chunk in frames.chunks(group) {
        let decode = |f: &EncodedFrame| bracket::decode_raw(&f.name, &f.bytes, opts);
        #[cfg(feature = "parallel")]
        let done: Vec<_> = {
            use rayon::prelude::*;
            chunk.par_iter().map(decode).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let done: Vec<_> = chunk.iter().map(decode).collect();
        for d in done {
            let (frame, colour) = d?;
            if !out.is_empty() && colour.is_some() != raw_of.is_some() {
                return Err(BracketError::MixedRaw {
                    file: frame.name.clone(),
                }
                .into());
            }
            if out.is_empty() {
                raw_of = colour;
            }
            out.push(frame);
        }
        p.at(
            Stage::Decoding,
            out.len() as f64 / frames.len() as f64 * 0.99,
        )?;
    }
    Ok((out, raw_of))
}

/// The lens stage: the lens profile and, when the circle was detected, the fit.
fn lens_stage(
    src: &LensSource,
    br: &Bracket,
    progress: &mut Reporter<'_>,
) -> Result<Option<(LensProfile, Option<CircleFit>)>, PipelineError> {
    progress.at(Stage::Lens, 0.0)?;
    let lens = lens_of(src, || detect_circle(br))?;
    progress.at(Stage::Lens, 1.0)?;
    Ok(lens)
}

/// The lens profile of `src` and, when the circle was detected (by `detect`), the fit.
fn lens_of(
    src: &LensSource,
    detect: impl FnOnce() -> Result<CircleFit, PipelineError>,
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
                    let fit = detect()?;
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
            let br = read_bracket(input, 0, &mut Reporter(&mut no_progress))?;
            return detect_circle_in(&br.0.frames);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fisheye::LensKind;

    /// The blocked, parallel [`at_ceiling`] finds exactly the pixels of a plain scan, in order:
    /// ceiling samples in every channel, at block edges, in a partial last block, and none.
    #[test]
    fn at_ceiling_matches_a_plain_scan() {
        let plain = |v: &[u8]| -> Vec<u32> {
            v.chunks_exact(3)
                .enumerate()
                .filter(|(_, p)| p.iter().any(|&c| c >= CEILING_CODE))
                .map(|(i, _)| i as u32)
                .collect()
        };
        let n = 3 * CEILING_BLOCK + 1234;
        let mut v = vec![0u8; 3 * n];
        // A deterministic spread of codes 0..=255 (an LCG's high bits), so about 2 % of the
        // samples reach 250.
        let mut x = 12345u32;
        for s in v.iter_mut() {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *s = (x >> 24) as u8;
        }
        // Whole blocks with nothing at the ceiling, and pixels on the blocks' edges.
        for s in &mut v[3 * CEILING_BLOCK..6 * CEILING_BLOCK] {
            *s = (*s).min(CEILING_CODE - 1);
        }
        for (i, c) in [
            (CEILING_BLOCK - 1, 0),
            (2 * CEILING_BLOCK, 2),
            (3 * CEILING_BLOCK - 1, 1),
            (n - 1, 2),
        ] {
            v[3 * i + c] = CEILING_CODE;
        }
        let want = plain(&v);
        assert!(want.len() > 100, "{}", want.len());
        assert_eq!(at_ceiling(&bracket::Pixels::U8(v.clone())), want);
        assert!(at_ceiling(&bracket::Pixels::U8(vec![CEILING_CODE - 1; 3 * n])).is_empty());
        assert!(at_ceiling(&bracket::Pixels::U16(vec![u16::MAX; 3 * n])).is_empty());
    }

    /// A small synthetic fish-eye bracket (420 × 360), its lens and the options of a plain
    /// crop to the dome.
    fn crop_case() -> (Bracket, LensProfile, Options) {
        let b = crate::synth::generate(&crate::synth::SynthOptions {
            width: 420,
            height: 360,
            ..Default::default()
        })
        .expect("synth");
        let lens =
            LensProfile::from_fov(b.circle.expect("fish-eye"), 235.0, LensKind::Stereographic)
                .expect("lens");
        let frames = b.frames.into_iter().map(DecodedFrame::from).collect();
        let br = bracket::assemble(frames, None, bracket::OrientationPolicy::Apply).expect("br");
        let crop = Options {
            sky: SkyOptions {
                crop: true,
                ..SkyOptions::default()
            },
            ..Options::default()
        };
        (br, lens, crop)
    }

    /// The options of `tests/lib/pipeline.rs`'s window test merge the crop's square alone (so
    /// that test compares the two paths), and every reader of the whole photo turns it off.
    #[test]
    fn the_window_is_merged_only_when_the_crop_reads_the_pixels_first() {
        let (br, lens, crop) = crop_case();
        let size = (br.width(), br.height());
        let w = merge_window(&crop, &lens, size, true, false).expect("a window");
        assert!(
            w.width < 360 && w.width == w.height && w.x > 0 && w.y > 0,
            "{w:?}"
        );
        assert_eq!(merge_window(&crop, &lens, size, true, true), None);
        assert_eq!(merge_window(&crop, &lens, size, false, false), None);
        let mut off = Vec::new();
        for f in [
            |o: &mut Options| o.sky.crop = false,
            |o: &mut Options| o.sky.north_from_sun = true,
            |o: &mut Options| o.products.confidence = true,
            |o: &mut Options| o.products.consistency = true,
            |o: &mut Options| o.consistency = true,
            |o: &mut Options| o.ghosts = true,
            |o: &mut Options| o.reference.illuminance_lux = Some(1e4),
        ] {
            let mut o = crop.clone();
            f(&mut o);
            off.push(merge_window(&o, &lens, size, true, false));
        }
        assert!(off.iter().all(Option::is_none), "{off:?}");
        // The hat merge and the noise-aware one (the default) merge the window alike.
        for weighting in [merge::Weighting::Hat, merge::Weighting::Noise] {
            let o = Options {
                weighting,
                ..crop.clone()
            };
            assert_eq!(merge_window(&o, &lens, size, true, false), Some(w));
        }
    }

    /// The noise-aware merge of the dome's window alone, its model fitted on the whole frames
    /// first, gives the whole photo's merged pixels inside the window bit for bit, and the same
    /// noise model in the report (a fit on the window's pixels would weigh them differently).
    #[test]
    fn the_noise_merge_of_the_window_is_the_whole_merge_inside_it() {
        let (br, lens, crop) = crop_case();
        assert_eq!(crop.weighting, merge::Weighting::Noise, "the default");
        let size = (br.width(), br.height());
        let w = merge_window(&crop, &lens, size, true, false).expect("a window");
        let response = crate::response::calibrate(
            &br.frames,
            Some(lens.circle),
            &crate::response::CalibrateOptions::default(),
        )
        .expect("calibrate")
        .response;
        let mut quiet = |_: &Progress| ControlFlow::Continue(());
        let mut merge = |window| {
            let mut br = br.clone();
            merge_stage(
                &crop,
                &mut br,
                &response,
                false,
                Some(lens.circle),
                window,
                None,
                &mut Reporter(&mut quiet),
            )
            .expect("merge")
        };
        let whole = merge(None);
        let part = merge(Some(w));
        let (a, b) = (&whole.merged.radiance, &part.merged.radiance);
        assert_eq!((b.width, b.height), (w.width, w.height));
        for y in 0..w.height {
            let s = 3 * ((w.y + y) * a.width + w.x);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&a.data[s..s + 3 * w.width]),
                bits(&b.data[3 * y * w.width..3 * (y + 1) * w.width]),
                "row {y}"
            );
        }
        let (na, nb) = (whole.merged.noise.expect("a model"), part.merged.noise);
        assert_eq!(Some(na), nb);
        assert!(na.differences > 0, "fitted from the frames: {na:?}");
    }
}
