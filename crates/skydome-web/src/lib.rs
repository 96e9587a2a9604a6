//! # skydome-web
//!
//! The WebAssembly surface of the skydome phone app: a thin shell over
//! [`skydome::pipeline::run`]. It takes the photos' bytes and the pipeline's
//! [`Options`] as JSON, and hands back encoded bytes (Radiance `.hdr`, OpenEXR, JPEG) and the
//! pipeline's report as JSON. It decides nothing about images: every rule lives in the library,
//! so the phone and the laptop write the same file from the same frames (`tests/same_bytes.rs`
//! proves it against the library; the browser tests in `web-tests/` against the command line).
//!
//! The static app that loads this module lives in `www/` beside this crate; `build.sh` builds
//! both into one folder.
//!
//! Conventions are the library's: pixels origin top-left, `x` right, `y` down, in the input
//! photos' pixels unless said otherwise; angles in degrees; azimuth from true north towards
//! east; the phone's compass heading is the azimuth of its top edge.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};
use skydome::bracket::{CaptureInfo, DecodeOptions, DecodedFrame, Pixels};
use skydome::camera::CameraProfile;
use skydome::fisheye::{LensKind, LensProfile};
use skydome::formats::exr::ExrOptions;
use skydome::formats::picture::{encode_rgb8, PictureFormat, DEFAULT_JPEG_QUALITY};
use skydome::formats::{encode_radiance, PixelPoint, RadianceFormat};
use skydome::image::Circle;
use skydome::pipeline::{
    self, Dome, EncodedFrame, Frames, Input, Options, PipelineError, Progress, Stage,
};
use skydome::sky::{DevicePose, ImageOrientation, SkyGeometry};
use wasm_bindgen::prelude::*;

/// The threaded build's pool (feature `threads`): `initThreadPool(n)` starts `n` Web Workers
/// that run the library's rayon parallelism; call it once per module, from a worker (rayon
/// busy-waits, which would block the page's main thread), before the first run.
#[cfg(feature = "threads")]
pub use wasm_bindgen_rayon::init_thread_pool;

/// How many threads the core computes on: rayon's pool in the threaded build, 1 in the
/// single-threaded one.
#[wasm_bindgen]
pub fn core_threads() -> usize {
    #[cfg(feature = "threads")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "threads"))]
    {
        1
    }
}

/// An error of the web surface, shown to the user as one sentence ([`sentence`]).
#[derive(Debug)]
pub enum WebError {
    /// The pipeline failed (its message names the file where one is to blame).
    Pipeline(PipelineError),
    /// The options JSON from the page did not parse.
    Options(String),
    /// A profile file did not parse.
    Profile(String),
    /// Something the page asked for does not exist (e.g. the equirect map was not made).
    Missing(&'static str),
    /// Encoding an output failed.
    Encode(String),
}

impl std::fmt::Display for WebError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WebError::Pipeline(PipelineError::Cancelled) => f.write_str("cancelled"),
            // The library's message tells a command-line user to give the circle; on the phone
            // the way out is a button (see `kind`).
            WebError::Pipeline(PipelineError::CircleNotFound { frame, .. }) => write!(
                f,
                "{frame}: no fish-eye picture circle was found in these photos; if they were taken \
                 without a fish-eye lens, merge them as ordinary photos, else drag the circle into place"
            ),
            WebError::Pipeline(e) => write!(f, "{}", in_app_words(&e.to_string())),
            WebError::Options(e) => write!(f, "the app's options are not valid ({e})"),
            WebError::Profile(e) => write!(f, "{}", in_app_words(e)),
            WebError::Missing(what) => write!(f, "{what} was not made in this run"),
            WebError::Encode(e) => write!(f, "cannot encode the file: {e}"),
        }
    }
}

/// One human sentence for the screen: the message on one line, ending in a full stop, and
/// capitalised unless it starts with a file name (which keeps its spelling).
pub fn sentence(message: &str) -> String {
    let one_line = message.split_whitespace().collect::<Vec<_>>().join(" ");
    let first = one_line.split([' ', ':']).next().unwrap_or("");
    let first = first.trim_end_matches([',', ';', '!', '?', '.']);
    let plain_word = first.chars().all(|c| c.is_alphabetic() || c == '\'');
    let mut s = match plain_word {
        true => {
            let mut chars = one_line.chars();
            match chars.next() {
                Some(c) => c.to_uppercase().chain(chars).collect::<String>(),
                None => return "Something went wrong.".to_string(),
            }
        }
        false => one_line,
    };
    if !s.ends_with(['.', '!', '?']) {
        s.push('.');
    }
    s
}

/// [`sentence`] for the page: every message the app shows goes through it (the worker's errors
/// and the report's warnings arrive made; the page sends its own to the worker), so the app has
/// one way of turning a message into a sentence.
#[wasm_bindgen(js_name = sentence)]
pub fn sentence_js(message: &str) -> String {
    sentence(message)
}

impl WebError {
    /// What kind of failure this is, for the page to offer the way out (a button) beside the
    /// sentence: `no-circle` (no fish-eye circle found: merge as ordinary photos, or give the
    /// circle), `missing-times` (a photo without an exposure time: type them), `cancelled`, or
    /// `error`.
    pub fn kind(&self) -> &'static str {
        match self {
            WebError::Pipeline(PipelineError::CircleNotFound { .. }) => "no-circle",
            WebError::Pipeline(PipelineError::Bracket(
                skydome::bracket::BracketError::MissingExposure { .. },
            )) => "missing-times",
            WebError::Pipeline(PipelineError::Cancelled) => "cancelled",
            _ => "error",
        }
    }

    /// The error for the page: a JavaScript `Error` whose message is [`sentence`] and whose
    /// `name` is [`WebError::kind`].
    fn to_js(&self) -> JsValue {
        let e = js_sys::Error::new(&sentence(&self.to_string()));
        e.set_name(self.kind());
        e.into()
    }
}

/// A profile message in the app's words: the command-line advice (`skydome calibrate`,
/// `skydome lens`) becomes what to do in the app.
fn in_app_words(message: &str) -> String {
    message
        .replace(
            " (re-create it with `skydome calibrate`)",
            "; delete it in Settings and merge a bracket with “Calibrate the camera again” on",
        )
        .replace(
            "; fix the file or regenerate it with `skydome lens`",
            "; delete it in Settings, and the next bracket finds the lens circle again",
        )
}

impl From<WebError> for JsError {
    fn from(e: WebError) -> JsError {
        JsError::new(&sentence(&e.to_string()))
    }
}

/// Parses the page's options: [`Options`] as JSON (snake_case field names, every field
/// optional).
pub fn parse_options(json: &str) -> Result<Options, WebError> {
    serde_json::from_str(json).map_err(|e| WebError::Options(e.to_string()))
}

/// The stages of a run in the order [`pipeline::run`] goes through them (the web surface's own
/// decoding, [`run_mixed`], comes first as [`Stage::Decoding`]). The page's progress bar gives
/// each an equal share; its stage names are the library's ([`Stage::name`]).
pub const STAGES: [Stage; 6] = [
    Stage::Decoding,
    Stage::Lens,
    Stage::Calibrating,
    Stage::Merging,
    Stage::Sky,
    Stage::Pictures,
];

/// Where `stage` comes in [`STAGES`]. The match has no wildcard, so a stage added to the library
/// stops this crate from compiling until it is placed here (and in [`STAGES`]: a test checks the
/// two agree).
const fn stage_position(stage: Stage) -> usize {
    match stage {
        Stage::Decoding => 0,
        Stage::Lens => 1,
        Stage::Calibrating => 2,
        Stage::Merging => 3,
        Stage::Sky => 4,
        Stage::Pictures => 5,
    }
}

/// A progress event as the page shows it: the stage's name, the fraction of it done and the
/// fraction of the whole run done.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StageProgress {
    /// The library's name of the stage ([`Stage::name`]: "decoding", "lens", …).
    pub stage: &'static str,
    /// Fraction of the stage done, `0..=1`.
    pub fraction: f64,
    /// Fraction of the run done, `0..=1`: the stages before this one in [`STAGES`], each an
    /// equal share, plus this one's fraction of its share.
    pub overall: f64,
}

impl StageProgress {
    /// The event for `fraction` (clamped to `0..=1`) of `stage`.
    pub fn new(stage: Stage, fraction: f64) -> StageProgress {
        let fraction = if fraction.is_nan() {
            0.0
        } else {
            fraction.clamp(0.0, 1.0)
        };
        StageProgress {
            stage: stage.name(),
            fraction,
            overall: (stage_position(stage) as f64 + fraction) / STAGES.len() as f64,
        }
    }

    fn to_json(self) -> String {
        // A struct of a string and two finite numbers always serialises.
        serde_json::to_string(&self).unwrap_or_default()
    }
}

/// The progress event (JSON `{stage, fraction, overall}`, see [`StageProgress`]) for `fraction`
/// of the decoding, which the merging worker reports while decoding workers decode a bracket
/// before its run.
#[wasm_bindgen]
pub fn decoding_progress(fraction: f64) -> String {
    StageProgress::new(Stage::Decoding, fraction).to_json()
}

/// Runs the pipeline on encoded photos. `times` (seconds, in the order of `frames`) overrides
/// EXIF when given. `progress` gets `(stage name, fraction)` and returns `true` to cancel.
pub fn run_frames(
    frames: Vec<EncodedFrame>,
    times: Option<Vec<f64>>,
    options: &Options,
    progress: &mut dyn FnMut(&str, f64) -> bool,
) -> Result<Dome, WebError> {
    run_input(Frames::Encoded(frames), times, options, &mut |stage, f| {
        progress(stage.name(), f)
    })
}

/// [`run_frames`] on photos some of which were decoded already by other workers
/// ([`decode_split`], then [`join_decoded`]); the rest are decoded here, in the same way
/// ([`skydome::bracket::decode`]). The photos keep the order given.
pub fn run_mixed(
    frames: Vec<Photo>,
    times: Option<Vec<f64>>,
    options: &Options,
    progress: &mut dyn FnMut(&str, f64) -> bool,
) -> Result<Dome, WebError> {
    run_photos(frames, times, options, &mut |stage, f| {
        progress(stage.name(), f)
    })
}

/// [`run_mixed`] with the progress callback given the stage itself.
fn run_photos(
    frames: Vec<Photo>,
    times: Option<Vec<f64>>,
    options: &Options,
    progress: &mut dyn FnMut(Stage, f64) -> bool,
) -> Result<Dome, WebError> {
    // None decoded yet: the pipeline decodes them itself, a few at once on the threaded core
    // (its own `decode_all`, the same decoder as below).
    if frames.iter().all(|f| matches!(f, Photo::Encoded(_))) {
        let encoded = frames
            .into_iter()
            .filter_map(|f| match f {
                Photo::Encoded(e) => Some(e),
                Photo::Decoded(_) => None,
            })
            .collect();
        return run_input(Frames::Encoded(encoded), times, options, progress);
    }
    let n = frames.len();
    let mut decoded = Vec::with_capacity(n);
    for (i, f) in frames.into_iter().enumerate() {
        if progress(Stage::Decoding, 0.99 * i as f64 / n as f64) {
            return Err(WebError::Pipeline(PipelineError::Cancelled));
        }
        decoded.push(match f {
            Photo::Decoded(d) => *d,
            Photo::Encoded(e) => {
                skydome::bracket::decode(&e.name, &e.bytes, &DecodeOptions::default())
                    .map_err(|err| WebError::Pipeline(err.into()))?
            }
        });
    }
    run_input(Frames::Decoded(decoded), times, options, progress)
}

fn run_input(
    frames: Frames,
    times: Option<Vec<f64>>,
    options: &Options,
    progress: &mut dyn FnMut(Stage, f64) -> bool,
) -> Result<Dome, WebError> {
    let input = Input {
        times,
        ..Input::new(frames)
    };
    let mut forward = |p: &Progress| match progress(p.stage, p.fraction) {
        true => ControlFlow::Break(()),
        false => ControlFlow::Continue(()),
    };
    pipeline::run(input, options, &mut forward).map_err(WebError::Pipeline)
}

/// One photo of a bracket as the page hands it over: its file's bytes, or decoded by a
/// decoding worker.
#[derive(Debug, Clone)]
pub enum Photo {
    /// The file's bytes (JPEG, PNG or TIFF), decoded in the run.
    Encoded(EncodedFrame),
    /// Decoded already ([`join_decoded`]).
    Decoded(Box<DecodedFrame>),
}

/// Everything of a decoded photo but its pixels, as it crosses from the Web Worker that decoded
/// it to the one that merges (the pixels travel apart, as bytes; see [`decode_split`]).
#[derive(Debug, Serialize, Deserialize)]
struct DecodedMeta {
    name: String,
    width: usize,
    height: usize,
    bits: u8,
    exif_time_s: Option<f64>,
    iso: Option<f64>,
    f_number: Option<f64>,
    info: CaptureInfo,
    non_srgb_icc: Option<String>,
}

/// Decodes one photo with the pipeline's own decoder ([`skydome::bracket::decode`], default
/// [`DecodeOptions`], as a run does) and splits it into its metadata as JSON and its samples as
/// bytes (8-bit samples as they are, 16-bit ones little-endian), for a decoding worker to hand
/// over without a copy. [`join_decoded`] puts it back together.
pub fn decode_split(name: &str, bytes: &[u8]) -> Result<(String, Vec<u8>), WebError> {
    let d = skydome::bracket::decode(name, bytes, &DecodeOptions::default())
        .map_err(|e| WebError::Pipeline(e.into()))?;
    let (bits, pixels) = match d.pixels {
        Pixels::U8(v) => (8, v),
        Pixels::U16(v) => (16, v.iter().flat_map(|s| s.to_le_bytes()).collect()),
    };
    let meta = DecodedMeta {
        name: d.name,
        width: d.width,
        height: d.height,
        bits,
        exif_time_s: d.exif_time_s,
        iso: d.iso,
        f_number: d.f_number,
        info: d.info,
        non_srgb_icc: d.non_srgb_icc,
    };
    let json = serde_json::to_string(&meta).map_err(|e| WebError::Encode(e.to_string()))?;
    Ok((json, pixels))
}

/// The decoded photo [`decode_split`] split. Errors when the parts do not belong together.
pub fn join_decoded(meta_json: &str, pixels: Vec<u8>) -> Result<DecodedFrame, WebError> {
    let m: DecodedMeta =
        serde_json::from_str(meta_json).map_err(|e| WebError::Options(e.to_string()))?;
    let expected = m
        .width
        .checked_mul(m.height)
        .and_then(|n| n.checked_mul(3 * usize::from(m.bits / 8)));
    if !matches!(m.bits, 8 | 16) || expected != Some(pixels.len()) {
        return Err(WebError::Options(format!(
            "{}: {} bytes of samples do not make a {}x{} {}-bit picture",
            m.name,
            pixels.len(),
            m.width,
            m.height,
            m.bits
        )));
    }
    let pixels = match m.bits {
        8 => Pixels::U8(pixels),
        _ => Pixels::U16(
            pixels
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect(),
        ),
    };
    Ok(DecodedFrame {
        name: m.name,
        width: m.width,
        height: m.height,
        pixels,
        exif_time_s: m.exif_time_s,
        iso: m.iso,
        f_number: m.f_number,
        info: m.info,
        non_srgb_icc: m.non_srgb_icc,
    })
}

/// A photo decoded in a decoding worker ([`decode_photo`]).
#[wasm_bindgen]
pub struct DecodedPhoto {
    meta: String,
    pixels: Vec<u8>,
}

#[wasm_bindgen]
impl DecodedPhoto {
    /// Its metadata, for [`Job::set_decoded`].
    pub fn meta_json(&self) -> String {
        self.meta.clone()
    }

    /// Its samples as bytes, for [`Job::set_decoded`]; moved out, so a second call is empty.
    pub fn take_pixels(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.pixels)
    }
}

/// Decodes one photo (JPEG, PNG or TIFF bytes; `name` is used in messages) in a decoding worker,
/// so the photos of a bracket decode on several cores; see [`decode_split`].
#[wasm_bindgen]
pub fn decode_photo(name: String, bytes: Vec<u8>) -> Result<DecodedPhoto, JsError> {
    let (meta, pixels) = decode_split(&name, &bytes)?;
    Ok(DecodedPhoto { meta, pixels })
}

/// A bracket being assembled by the page: photos are added one by one as files
/// ([`Job::add_frame`]); each may be decoded before the run, here ([`Job::decode`]) or by a
/// decoding worker ([`Job::set_decoded`]), so several decode at once; then [`Job::run`] runs the
/// pipeline.
#[wasm_bindgen]
#[derive(Default)]
pub struct Job {
    frames: Vec<Photo>,
}

#[wasm_bindgen]
impl Job {
    /// An empty job.
    #[wasm_bindgen(constructor)]
    pub fn new() -> Job {
        Job::default()
    }

    /// Adds one photo (JPEG, PNG or TIFF bytes); `name` is used in messages (the file name).
    pub fn add_frame(&mut self, name: String, bytes: Vec<u8>) {
        self.frames
            .push(Photo::Encoded(EncodedFrame { name, bytes }));
    }

    /// Decodes photo `index` (as added) here and now, so the run does not; a photo decoded
    /// already is left as it is. Errors name the photo, as the run's would.
    pub fn decode(&mut self, index: usize) -> Result<(), JsError> {
        let slot = self.slot(index)?;
        if let Photo::Encoded(e) = slot {
            let d = skydome::bracket::decode(&e.name, &e.bytes, &DecodeOptions::default())
                .map_err(|err| WebError::Pipeline(err.into()))?;
            *slot = Photo::Decoded(Box::new(d));
        }
        Ok(())
    }

    /// Replaces photo `index` (as added) by the same photo decoded by [`decode_photo`] in
    /// another worker (its [`DecodedPhoto::meta_json`] and [`DecodedPhoto::take_pixels`]).
    pub fn set_decoded(
        &mut self,
        index: usize,
        meta_json: &str,
        pixels: Vec<u8>,
    ) -> Result<(), JsError> {
        let d = join_decoded(meta_json, pixels)?;
        *self.slot(index)? = Photo::Decoded(Box::new(d));
        Ok(())
    }

    /// Whether a run of this job's photos (all as added, none decoded yet) with
    /// `options_json` ([`Options`] as JSON) reads them one at a time
    /// ([`pipeline::streams_input`]: the options' frame memory budget is below the photos'
    /// decoded size and the job is a plain crop to the dome), so the page should hand it the
    /// files rather than decode them beforehand (decoded beforehand, every photo would be in
    /// memory at once). Options that do not parse: `false` (the run reports them).
    pub fn streams(&mut self, options_json: &str) -> bool {
        let Ok(options) = parse_options(options_json) else {
            return false;
        };
        if !self.frames.iter().all(|f| matches!(f, Photo::Encoded(_))) {
            return false;
        }
        // The photos move to the input and back (no copy of their bytes).
        let encoded = std::mem::take(&mut self.frames)
            .into_iter()
            .filter_map(|f| match f {
                Photo::Encoded(e) => Some(e),
                Photo::Decoded(_) => None,
            })
            .collect();
        let input = Input::new(Frames::Encoded(encoded));
        let streams = pipeline::streams_input(&input, &options);
        if let Frames::Encoded(e) = input.frames {
            self.frames = e.into_iter().map(Photo::Encoded).collect();
        }
        streams
    }

    fn slot(&mut self, index: usize) -> Result<&mut Photo, JsError> {
        let n = self.frames.len();
        self.frames.get_mut(index).ok_or_else(|| {
            JsError::new(&format!(
                "There is no photo {index} of {n} in this bracket."
            ))
        })
    }

    /// Runs the pipeline with `options_json` ([`Options`] as JSON). `times` are exposure times
    /// in seconds in the order the photos were added (empty: from EXIF). `progress(event)` is
    /// called between steps with a [`StageProgress`] as JSON (`{stage, fraction, overall}`);
    /// returning `true` cancels. The photos go to the run (decoded ones take 3 bytes a pixel),
    /// so a second run needs a new job.
    ///
    /// Errors are JavaScript `Error`s named by their [`WebError::kind`].
    pub fn run(
        &mut self,
        options_json: &str,
        times: Vec<f64>,
        progress: &js_sys::Function,
    ) -> Result<Outcome, JsValue> {
        let options = parse_options(options_json).map_err(|e| e.to_js())?;
        let times = (!times.is_empty()).then_some(times);
        let mut cb = |stage: Stage, fraction: f64| {
            let event = StageProgress::new(stage, fraction).to_json();
            progress
                .call1(&JsValue::NULL, &JsValue::from_str(&event))
                .map(|v| v.is_truthy())
                .unwrap_or(false)
        };
        let dome = run_photos(std::mem::take(&mut self.frames), times, &options, &mut cb)
            .map_err(|e| e.to_js())?;
        Ok(Outcome { dome })
    }
}

/// The products of one run, encoded on demand.
#[wasm_bindgen]
pub struct Outcome {
    dome: Dome,
}

impl Outcome {
    /// Wraps a pipeline result (for native callers and tests).
    pub fn from_dome(dome: Dome) -> Outcome {
        Outcome { dome }
    }

    /// The pipeline's result.
    pub fn dome(&self) -> &Dome {
        &self.dome
    }

    fn radiance(&self, format: RadianceFormat) -> Result<Vec<u8>, WebError> {
        encode_radiance(&self.dome.radiance, &self.dome.meta, format)
            .map(|e| e.bytes)
            .map_err(|e| WebError::Encode(e.to_string()))
    }

    /// The radiance map as Radiance `.hdr` bytes (the library's encoder: `#SUN=`, `#NORTH=`,
    /// `CAPDATE=` lines).
    pub fn hdr_bytes(&self) -> Result<Vec<u8>, WebError> {
        self.radiance(RadianceFormat::Hdr)
    }

    /// The radiance map as OpenEXR (half, ZIP; float when values exceed half's range).
    pub fn exr_bytes(&self) -> Result<Vec<u8>, WebError> {
        self.radiance(RadianceFormat::Exr(ExrOptions::default()))
    }

    /// The equirectangular map as `.hdr`, when it was asked for.
    pub fn equirect_hdr_bytes(&self) -> Result<Vec<u8>, WebError> {
        let (img, meta) = self
            .dome
            .equirect
            .as_ref()
            .ok_or(WebError::Missing("the equirectangular map"))?;
        encode_radiance(img, meta, RadianceFormat::Hdr)
            .map(|e| e.bytes)
            .map_err(|e| WebError::Encode(e.to_string()))
    }

    /// The tone-mapped preview (or, with `overlay`, the overlay picture) as JPEG.
    pub fn picture_jpeg(&self, overlay: bool) -> Result<Vec<u8>, WebError> {
        // The overlay is made now when the run did not make it.
        let made;
        let (pic, what) = match overlay {
            true if self.dome.overlay.is_none() => {
                made = self.dome.overlay_picture().map_err(WebError::Pipeline)?;
                (&made, "the overlay picture")
            }
            true => (&self.dome.overlay, "the overlay picture"),
            false => (&self.dome.preview, "the preview"),
        };
        let pic = pic.as_ref().ok_or(WebError::Missing(what))?;
        encode_rgb8(
            pic,
            PictureFormat::Jpeg {
                quality: DEFAULT_JPEG_QUALITY,
            },
        )
        .map_err(|e| WebError::Encode(e.to_string()))
    }

    /// The input-photo pixel under output pixel `(x, y)`, as the library maps it
    /// ([`skydome::pipeline::GeometryReport::input_pixel`]). Without a lens the two are the
    /// same.
    pub fn input_pixel(&self, x: f64, y: f64) -> PixelPoint {
        let p = PixelPoint { x, y };
        match &self.dome.report.geometry {
            Some(g) => g.input_pixel(p).unwrap_or(p),
            None => p,
        }
    }
}

/// The dome's luminance over the sky (inside the 180° horizon when there is one), for the result
/// screen: cd/m² on an absolute dome (a meter reading was given), relative units otherwise.
/// Luminance is the library's (Rec. 709 weights of linear radiance, × 179 lm/W when
/// absolute, as Radiance's tools read it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LuminanceSummary {
    /// True when the values are cd/m².
    pub absolute: bool,
    /// Smallest positive luminance.
    pub min: f64,
    /// 1st percentile.
    pub p1: f64,
    /// Median.
    pub median: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest luminance (the sun when it is in the picture).
    pub max: f64,
}

impl Outcome {
    /// The circle the sky's figures are taken over: the 180° horizon in the output picture, when
    /// the run had a fish-eye lens.
    fn sky_mask(&self) -> Option<Circle> {
        self.dome.marks.as_ref().and_then(|m| m.horizon)
    }

    /// cd/m² per unit of the radiance map, when it is absolute.
    fn cd_per_unit(&self) -> Option<f64> {
        self.dome
            .meta
            .is_absolute()
            .then_some(skydome::image::RADIANCE_EFFICACY)
    }

    /// The sky's luminance range ([`LuminanceSummary`]).
    pub fn luminance_summary(&self) -> Result<LuminanceSummary, WebError> {
        let stats =
            skydome::tonemap::luminance_stats(&self.dome.radiance, self.sky_mask().as_ref())
                .map_err(|e| WebError::Encode(e.to_string()))?;
        let k = self.cd_per_unit().unwrap_or(1.0);
        Ok(LuminanceSummary {
            absolute: self.cd_per_unit().is_some(),
            min: stats.min * k,
            p1: stats.percentile(1.0) * k,
            median: stats.percentile(50.0) * k,
            p999: stats.percentile(99.9) * k,
            max: stats.max * k,
        })
    }

    /// The false-colour view of log luminance (the library's [`skydome::plot::false_colour`], as
    /// `skydome falsecolor` draws it): cd/m² on an absolute dome, with its labelled colour bar
    /// on the right, as JPEG.
    pub fn false_colour_bytes(&self) -> Result<Vec<u8>, WebError> {
        let pic = skydome::plot::false_colour(
            &self.dome.radiance,
            &skydome::plot::FalseColour {
                mask: self.sky_mask(),
                scale: self.cd_per_unit(),
                ..skydome::plot::FalseColour::default()
            },
        )
        .map_err(|e| WebError::Encode(e.to_string()))?;
        encode_rgb8(
            &pic,
            PictureFormat::Jpeg {
                quality: DEFAULT_JPEG_QUALITY,
            },
        )
        .map_err(|e| WebError::Encode(e.to_string()))
    }
}

#[wasm_bindgen]
impl Outcome {
    /// The sky's luminance range as JSON ([`LuminanceSummary`]).
    pub fn luminance_json(&self) -> Result<String, JsError> {
        let s = self.luminance_summary()?;
        Ok(serde_json::to_string(&s).map_err(|e| WebError::Encode(e.to_string()))?)
    }

    /// The false-colour view as JPEG ([`Outcome::false_colour_bytes`]).
    pub fn false_colour_jpeg(&self) -> Result<Vec<u8>, JsError> {
        Ok(self.false_colour_bytes()?)
    }

    /// The pipeline's report as JSON (frames, response, warnings, geometry, header metadata).
    pub fn report_json(&self) -> String {
        serde_json::to_string(&self.dome.report).unwrap_or_else(|_| "{}".to_string())
    }

    /// Width of the radiance map and the preview, pixels.
    pub fn width(&self) -> usize {
        self.dome.radiance.width
    }

    /// Height of the radiance map and the preview, pixels.
    pub fn height(&self) -> usize {
        self.dome.radiance.height
    }

    /// Radiance `.hdr` bytes.
    pub fn hdr(&self) -> Result<Vec<u8>, JsError> {
        Ok(self.hdr_bytes()?)
    }

    /// OpenEXR bytes.
    pub fn exr(&self) -> Result<Vec<u8>, JsError> {
        Ok(self.exr_bytes()?)
    }

    /// The equirectangular map as `.hdr` bytes.
    pub fn equirect_hdr(&self) -> Result<Vec<u8>, JsError> {
        Ok(self.equirect_hdr_bytes()?)
    }

    /// Preview JPEG bytes.
    pub fn preview_jpeg(&self) -> Result<Vec<u8>, JsError> {
        Ok(self.picture_jpeg(false)?)
    }

    /// The camera profile made by calibrating on this bracket, as the CLI's JSON; empty when
    /// a stored profile was used.
    pub fn camera_profile_json(&self) -> String {
        self.dome
            .camera_profile
            .as_ref()
            .map(CameraProfile::to_json)
            .unwrap_or_default()
    }

    /// The lens profile used, as the CLI's JSON; empty without a lens.
    pub fn lens_profile_json(&self) -> String {
        self.dome
            .lens_profile
            .as_ref()
            .and_then(|l| l.to_json().ok())
            .unwrap_or_default()
    }

    /// `[x, y]`: the input-photo pixel under output (preview) pixel `(x, y)`; see
    /// [`Outcome::input_pixel`].
    pub fn to_input_pixel(&self, x: f64, y: f64) -> Vec<f64> {
        let p = self.input_pixel(x, y);
        vec![p.x, p.y]
    }
}

/// Checks a camera profile file (the CLI's `camera.json`; `name` is the file's name, for the
/// message) and returns it re-serialised; the error names the file and what is wrong.
#[wasm_bindgen]
pub fn check_camera_profile(name: &str, json: &str) -> Result<String, JsError> {
    check_camera_profile_text(name, json).map_err(|m| JsError::new(&m))
}

/// [`check_camera_profile`]'s check, its refusal as the sentence the page shows.
pub fn check_camera_profile_text(name: &str, json: &str) -> Result<String, String> {
    let refused = |e: &dyn std::fmt::Display| {
        let e = WebError::Profile(format!("{name}: not a usable camera profile: {e}"));
        sentence(&e.to_string())
    };
    let p = CameraProfile::from_json(json).map_err(|e| refused(&e))?;
    p.response().map_err(|e| refused(&e))?;
    Ok(p.to_json())
}

/// Checks a lens profile file (the CLI's `lens.json`; `name` is the file's name, for the
/// message) and returns it re-serialised; the error names the file and what is wrong.
#[wasm_bindgen]
pub fn check_lens_profile(name: &str, json: &str) -> Result<String, JsError> {
    let refused = |e: &dyn std::fmt::Display| {
        WebError::Profile(format!("{name}: not a usable lens profile: {e}"))
    };
    let l = LensProfile::from_json(json)
        .and_then(|l| l.validate().map(|()| l))
        .map_err(|e| refused(&e))?;
    Ok(l.to_json().map_err(|e| refused(&e))?)
}

/// Marks for the live camera overlay, in the photo's displayed pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LiveMarks {
    /// The lens's visible circle.
    pub circle: Circle,
    /// The 180° horizon circle.
    pub horizon: Circle,
    /// Where true north meets the horizon, when a heading is known.
    pub north: Option<PixelPoint>,
}

/// The live overlay's marks for `lens` and a compass heading (azimuth of the phone's top edge,
/// degrees; `None` when unknown), for a phone lying screen-down, camera up, photo upright
/// (`SkyGeometry` with `DevicePose::ScreenDown`). For that pose the library's north point is
/// `(cx + R·sin h, cy − R·cos h)` with `R` the horizon radius: heading 0 puts north at the top
/// and east on the left (the mirror of a map, because the camera looks up).
pub fn live_marks(lens: &LensProfile, heading_deg: Option<f64>) -> Result<LiveMarks, WebError> {
    let geom = SkyGeometry::new(
        lens,
        heading_deg.unwrap_or(0.0),
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )
    .map_err(|e| WebError::Profile(e.to_string()))?;
    Ok(LiveMarks {
        circle: lens.circle,
        horizon: geom.horizon_circle(),
        north: heading_deg.map(|_| geom.north_point()),
    })
}

/// The live overlay's marks as JSON (`{circle, horizon, north}`) for a lens profile JSON, or —
/// when `lens_json` is empty — the nominal model `model` (`equidistant`, `stereographic`, …)
/// with full field of view `fov_deg` across `circle_json` (`{cx, cy, r}`). `heading_deg` NaN
/// means no compass.
#[wasm_bindgen]
pub fn live_overlay(
    lens_json: &str,
    circle_json: &str,
    model: &str,
    fov_deg: f64,
    heading_deg: f64,
) -> Result<String, JsError> {
    let lens = match lens_json.is_empty() {
        false => LensProfile::from_json(lens_json).map_err(|e| WebError::Profile(e.to_string()))?,
        true => {
            let circle: Circle =
                serde_json::from_str(circle_json).map_err(|e| WebError::Options(e.to_string()))?;
            let kind: LensKind = serde_json::from_value(serde_json::Value::String(model.into()))
                .map_err(|e| WebError::Options(e.to_string()))?;
            LensProfile::from_fov(circle, fov_deg, kind)
                .map_err(|e| WebError::Profile(e.to_string()))?
        }
    };
    let heading = heading_deg.is_finite().then_some(heading_deg);
    let marks = live_marks(&lens, heading)?;
    Ok(serde_json::to_string(&marks).map_err(|e| WebError::Encode(e.to_string()))?)
}

/// Detects the fish-eye image circle in one photo (e.g. a frame of the live camera as JPEG);
/// returns the fit as JSON (`{circle: {cx, cy, r}, residual_px, points, candidates}`).
#[wasm_bindgen]
pub fn detect_circle(name: String, bytes: Vec<u8>) -> Result<String, JsError> {
    let input = Input::new(Frames::Encoded(vec![EncodedFrame { name, bytes }]));
    let (fit, _) = pipeline::detect_lens_circle(input).map_err(WebError::Pipeline)?;
    Ok(serde_json::to_string(&fit).map_err(|e| WebError::Encode(e.to_string()))?)
}

/// What a photo's EXIF says about its exposure, as JSON (`{exif_time_s, iso, f_number, width,
/// height}`, unknown fields null): the capture screen reads it back after each shot to check that
/// the camera obeyed the requested exposure time.
#[wasm_bindgen]
pub fn photo_exposure(name: String, bytes: Vec<u8>) -> Result<String, JsError> {
    let d = skydome::bracket::decode(&name, &bytes, &skydome::bracket::DecodeOptions::default())
        .map_err(|e| WebError::Pipeline(e.into()))?;
    let v = serde_json::json!({
        "exif_time_s": d.exif_time_s,
        "iso": d.iso,
        "f_number": d.f_number,
        "width": d.width,
        "height": d.height,
    });
    Ok(v.to_string())
}

/// What a photo's EXIF says, read without decoding its pixels
/// ([`skydome::bracket::read_metadata`]), as JSON `{exposure_time_s, make, model}` (unknown
/// fields null): the page pre-fills the exposure-time field of each picked photo with it, and
/// names the camera a calibration's profile is stored under.
#[wasm_bindgen]
pub fn photo_metadata(bytes: Vec<u8>) -> String {
    let m = skydome::bracket::read_metadata(&bytes);
    serde_json::json!({
        "exposure_time_s": m.exposure_time_s,
        "make": m.info.make,
        "model": m.info.model,
    })
    .to_string()
}

/// Exposure times for photos without EXIF from a list file in the command line's
/// `--times-file` format (lines `FILE TIME` or `FILE TIME 1/TIME`, `#` comments; times as `0.004`
/// or `1/250`): the times of `names`, in that order, in seconds, matched as the command line
/// matches them ([`skydome::bracket::times_from_list`]).
pub fn times_from_list(
    list_name: &str,
    text: &str,
    names: &[String],
) -> Result<Vec<f64>, WebError> {
    skydome::bracket::times_from_list(list_name, text, names)
        .map_err(|e| WebError::Pipeline(e.into()))
}

/// [`times_from_list`] for the page.
#[wasm_bindgen]
pub fn list_times(list_name: &str, text: &str, names: Vec<String>) -> Result<Vec<f64>, JsError> {
    Ok(times_from_list(list_name, text, &names)?)
}

/// Runs the whole pipeline once on a tiny synthetic fish-eye bracket (`skydome::synth`,
/// `size`² pixels, JPEG frames) with the app's products (sky stage, preview, `.hdr` and JPEG
/// encoding).
///
/// Why: browsers compile WebAssembly twice, first quickly into slow code, then the functions
/// that turn out hot into optimised code, and a function switches only on its next call. The
/// pipeline calls each of its loops once per merge, so without this the first merge of a session
/// ran its big loops in the slow code (in Node's V8, 795 ms instead of 512 for 3 × 12 MP). The
/// worker calls this once after loading, while the user frames the shot.
pub fn warm_up(size: usize) -> Result<(), WebError> {
    use skydome::synth::{generate, SynthOptions};
    let b = generate(&SynthOptions {
        width: size,
        height: size,
        fisheye: true,
        jpeg_quality: None,
        ..SynthOptions::default()
    })
    .map_err(|e| WebError::Encode(e.to_string()))?;
    let mut frames = Vec::with_capacity(b.frames.len());
    let mut times = Vec::with_capacity(b.frames.len());
    for (i, f) in b.frames.into_iter().enumerate() {
        times.push(f.exposure.time_s);
        let Pixels::U8(data) = f.pixels else {
            return Err(WebError::Missing("an 8-bit synthetic frame"));
        };
        let img = skydome::image::RgbImage::from_vec(f.width, f.height, data)
            .ok_or(WebError::Missing("a synthetic frame of the stated size"))?;
        let bytes = encode_rgb8(
            &img,
            PictureFormat::Jpeg {
                quality: DEFAULT_JPEG_QUALITY,
            },
        )
        .map_err(|e| WebError::Encode(e.to_string()))?;
        frames.push(EncodedFrame {
            name: format!("warm-up {i}.jpg"),
            bytes,
        });
    }
    let options = parse_options(WARM_UP_OPTIONS)?;
    let outcome = Outcome::from_dome(run_frames(frames, Some(times), &options, &mut |_, _| {
        false
    })?);
    outcome.hdr_bytes()?;
    outcome.picture_jpeg(false)?;
    warm_up_sun(WARM_UP_SUN_SIDE, WARM_UP_SUN_ROUNDS)?;
    Ok(())
}

/// Side in pixels of the dome [`warm_up_sun`] searches.
const WARM_UP_SUN_SIDE: usize = 512;

/// How many times [`warm_up`] runs the sun search on its dome.
const WARM_UP_SUN_ROUNDS: usize = 8;

/// Runs the sun search ([`skydome::sky::find_sun`], with clipping flags as a merge passes them)
/// `rounds` times on a synthetic `side`² dome: a sky brightening downwards, a sun disc 6 px
/// across that clipped, and a broad aureole around it (some 3 500 pixels above half the
/// peak, so that the search's loops over the sun's blob run long enough). Returns whether the
/// last search found the sun.
///
/// Why: the merge calls the sun search once, so the browser's engine optimises it only after
/// the first call that spends its budget (V8: per function, spent as it runs) and that call
/// runs to its end in the baseline code. [`warm_up`]'s 256² merge did not spend it: V8's
/// compile trace (`web-tests/profile.mjs --trace`) showed `find_sun` optimised during the
/// first 12 MP merge (70–144 ms of compiling), its call in baseline code.
pub fn warm_up_sun(side: usize, rounds: usize) -> Result<bool, WebError> {
    let (img, clipped) = warm_up_dome(side);
    let geom = warm_up_geometry(side)?;
    let clues = skydome::sky::SunClues {
        clipped: Some(&clipped),
        prior: None,
    };
    let mut found = false;
    for _ in 0..rounds {
        found = skydome::sky::find_sun(&img, &geom, &clues)
            .map_err(|e| WebError::Pipeline(e.into()))?
            .is_some();
    }
    Ok(found)
}

/// The lens geometry of the warm-up domes: an equisolid 180° lens whose circle fills the
/// `side`² picture.
fn warm_up_geometry(side: usize) -> Result<SkyGeometry, WebError> {
    let half = side as f64 / 2.0;
    let lens = LensProfile::from_fov(
        Circle {
            cx: half,
            cy: half,
            r: half,
        },
        180.0,
        LensKind::Equisolid,
    )
    .map_err(|e| WebError::Pipeline(e.into()))?;
    SkyGeometry::new(&lens, 0.0, DevicePose::ScreenDown, ImageOrientation::Normal)
        .map_err(|e| WebError::Pipeline(e.into()))
}

/// A synthetic `side`² dome (linear radiance) and its clipping flags: a sky brightening
/// downwards, a sun disc 6 px across that clipped, and a broad aureole around it (some 3 500
/// pixels above half the peak at 512²).
fn warm_up_dome(side: usize) -> (skydome::HdrImage, Vec<bool>) {
    let mut img = skydome::HdrImage::new(side, side);
    let mut clipped = vec![false; side * side];
    let (sx, sy) = (0.6 * side as f64, 0.4 * side as f64);
    for (i, (px, clip)) in img.data.chunks_exact_mut(3).zip(&mut clipped).enumerate() {
        let (x, y) = ((i % side) as f64 + 0.5, (i / side) as f64 + 0.5);
        let d = (x - sx).hypot(y - sy);
        let sun = d <= 3.0;
        let aureole = 1.0e5 * (-(d / 40.0).powi(2)).exp();
        let v = if sun {
            1.0e5
        } else {
            (1.0 + 0.5 * y / side as f64 + aureole) as f32
        };
        px.fill(v);
        *clip = sun;
    }
    (img, clipped)
}

/// Side in pixels of the pictures [`warm_up_stages`] works on.
const WARM_UP_STAGES_SIDE: usize = 384;

/// How many times (idle steps of the worker, one round each) the page runs
/// [`warm_up_stages`].
pub const WARM_UP_STAGES_ROUNDS: usize = 4;

/// The stages [`warm_up_stages`] runs, in its report's order.
pub const WARM_UP_STAGES: [&str; 5] = [
    "lens circle",
    "preview tone map",
    "luminance statistics",
    "bracket checks, noise fit and merge",
    "the whole pipeline",
];

/// One round of the stages a merge calls once over a whole picture and that a small warm-up
/// merge does not run long enough, on `side`² synthetic pictures, through the functions the
/// merge itself calls: the lens circle's detection ([`skydome::fisheye::detect_circle`], on a
/// fish-eye photo's 8-bit RGB: a sky disc on a dark housing), the preview's tone map
/// ([`skydome::tonemap::tonemap_u8`] with the pipeline's default tone map) and the sky's
/// luminance statistics ([`skydome::tonemap::luminance_stats`], as the result's facts ask for
/// them), the latter two on a cropped dome with a sun, then the bracket checks, the noise fit
/// and the merge of a synthetic (`side` / 2)² bracket ([`warm_up_merge`]). Returns the names of
/// the stages that ran and gave what they should (the circle within 2 % of the drawn one, a
/// preview of `side`² pixels, statistics that see the sun, a merge of every frame with a fitted
/// noise model), from [`WARM_UP_STAGES`]. Nothing is kept: the pictures are synthetic and
/// dropped, and none of the user's photos is read.
///
/// Why: the browser's engine optimises a function only once it has spent a budget running
/// (V8: per function), and a running call keeps the code it started with. After [`warm_up`]'s
/// 256² merge (once or four times), V8's compile trace of the first 12 MP merge
/// (`web-tests/profile.mjs --trace`, `tools/wasm_compiles.py`) still showed these stages'
/// functions being optimised during it: the circle's blur (`Blurred::from_rows`, `blur_row`),
/// its fit (`kasa_fit`) and sorts, the tone map's statistics (`Acc::add_span`, `log2f`, their
/// parallel reduction), the bracket checks (`frames_that_inform`), the noise fit's sorts, the
/// merge's refinement (`Refine::new`), flags and warnings: 24 functions, 130–200 ms of
/// compiling, the code running in the baseline tier until then. After four rounds on 384²
/// pictures (0.15–0.25 s each on the 2-core test machine), 9 (20–30 ms), none of these.
pub fn warm_up_stages(side: usize) -> Result<Vec<&'static str>, WebError> {
    let mut ran = Vec::with_capacity(WARM_UP_STAGES.len());
    let half = side as f64 / 2.0;
    let drawn = 0.45 * side as f64;
    // A fish-eye photo: a sky disc brightening downwards, a little texture, a dark housing.
    let mut photo = Vec::with_capacity(3 * side * side);
    for y in 0..side {
        for x in 0..side {
            let d = (x as f64 + 0.5 - half).hypot(y as f64 + 0.5 - half);
            let t = ((x * 7919 + y * 104_729) % 7) as u8;
            if d <= drawn {
                let v = 110 + (100 * y / side) as u8 + t;
                photo.extend_from_slice(&[v / 2, v.saturating_sub(20), v]);
            } else {
                photo.extend_from_slice(&[4 + t, 4 + t, 5 + t]);
            }
        }
    }
    let photo = skydome::image::RgbImage::from_vec(side, side, photo)
        .ok_or(WebError::Missing("a warm-up photo of the stated size"))?;
    if let Ok(fit) = skydome::fisheye::detect_circle(&photo) {
        let c = fit.circle;
        if (c.cx - half)
            .abs()
            .max((c.cy - half).abs())
            .max((c.r - drawn).abs())
            <= 0.02 * drawn
        {
            ran.push(WARM_UP_STAGES[0]);
        }
    }
    drop(photo);
    // The dome as a merge crops it: nothing beyond the horizon.
    let (mut dome, _) = warm_up_dome(side);
    let horizon = Circle {
        cx: half,
        cy: half,
        r: half,
    };
    for (i, px) in dome.data.chunks_exact_mut(3).enumerate() {
        let (x, y) = ((i % side) as f64 + 0.5, (i / side) as f64 + 0.5);
        if (x - half).hypot(y - half) > half {
            px.fill(0.0);
        }
    }
    let preview = skydome::tonemap::tonemap_u8(&dome, &pipeline::default_tonemap(None))
        .map_err(|e| WebError::Encode(e.to_string()))?;
    if preview.width == side && preview.height == side {
        ran.push(WARM_UP_STAGES[1]);
    }
    let stats = skydome::tonemap::luminance_stats(&dome, Some(&horizon))
        .map_err(|e| WebError::Encode(e.to_string()))?;
    if stats.count > 0 && stats.max >= 1.0e4 {
        ran.push(WARM_UP_STAGES[2]);
    }
    drop(dome);
    if warm_up_merge(side / 2)? {
        ran.push(WARM_UP_STAGES[3]);
    }
    if warm_up_pipeline(side)? {
        ran.push(WARM_UP_STAGES[4]);
    }
    Ok(ran)
}

/// The app's options for a merge of a fish-eye bracket (the lens circle found, the dome
/// cropped, the sun found, the preview), as [`warm_up`] and [`warm_up_pipeline`] run them.
const WARM_UP_OPTIONS: &str = r#"{"lens": {"detect": {"model": "stereographic", "fov_deg": 235, "circle": null}},
    "sky": {"crop": true, "north_deg": 0, "sun": "auto"}, "products": {"preview": true}}"#;

/// The whole pipeline ([`skydome::pipeline::run`]) with the app's options ([`WARM_UP_OPTIONS`])
/// on a synthetic `side`² fish-eye bracket, its frames given decoded (the decoder has its own
/// warm-up, [`warm_up_decoding`]). Returns whether it made a dome and its preview.
///
/// Why: the stages above call the functions a merge spends most of its time in, but a merge
/// also runs passes of its own over whole pictures that nothing else calls: the best-exposed
/// frame's count, the shortest frame's ceiling pixels, the dome's crop, the sun's luminance
/// plane, the sky's statistics, the calibration's sample lattice. V8's compile trace of the first
/// 12 MP merge after the four stages' rounds (`web-tests/profile.mjs --trace`,
/// `tools/wasm_compiles.py`) still showed 21 functions optimised during it, these among them,
/// their first call running in the baseline code: the ceiling scan alone took 11.6 ms of CPU in
/// the first merge and too little to sample in the second. [`warm_up`]'s one 256² merge is too
/// small to spend their budgets; four rounds at 384² are not.
fn warm_up_pipeline(side: usize) -> Result<bool, WebError> {
    let (_, decoded) = synthetic_bracket(side)?;
    let times = decoded.iter().filter_map(|f| f.exif_time_s).collect();
    let options = parse_options(WARM_UP_OPTIONS)?;
    let dome = run_input(
        Frames::Decoded(decoded),
        Some(times),
        &options,
        &mut |_, _| false,
    )?;
    Ok(dome.radiance.width > 0 && dome.preview.is_some())
}

/// A synthetic `side`² fish-eye bracket (`skydome::synth`, lossless 8-bit frames) and its frames
/// as the decoder would hand them over (their times as if from EXIF); the bracket's own
/// `frames` are taken out (left empty).
fn synthetic_bracket(
    side: usize,
) -> Result<(skydome::synth::SynthBracket, Vec<DecodedFrame>), WebError> {
    use skydome::synth::{generate, SynthOptions};
    let mut b = generate(&SynthOptions {
        width: side,
        height: side,
        fisheye: true,
        jpeg_quality: None,
        ..SynthOptions::default()
    })
    .map_err(|e| WebError::Encode(e.to_string()))?;
    let decoded = std::mem::take(&mut b.frames)
        .into_iter()
        .map(|f| DecodedFrame {
            name: f.name,
            width: f.width,
            height: f.height,
            pixels: f.pixels,
            exif_time_s: Some(f.exposure.time_s),
            iso: None,
            f_number: None,
            info: CaptureInfo::default(),
            non_srgb_icc: None,
        })
        .collect();
    Ok((b, decoded))
}

/// The bracket checks, the noise model's fit and the noise-weighted merge of a synthetic
/// `side`² fish-eye bracket (three 8-bit frames, 2 EV apart, through their true response), as
/// the pipeline calls them ([`skydome::bracket::assemble`], [`skydome::noise::estimate`],
/// [`skydome::merge::merge`] with the fitted model, clipping flags, and the merge's warnings).
/// Returns whether all three frames were kept, the noise model was fitted and the merge gave a
/// radiance of the bracket's size.
fn warm_up_merge(side: usize) -> Result<bool, WebError> {
    let (b, decoded) = synthetic_bracket(side)?;
    let n = decoded.len();
    let br = skydome::bracket::assemble(decoded, None, Default::default())
        .map_err(|e| WebError::Pipeline(e.into()))?;
    let response = skydome::response::Response::from_curves(b.true_g)
        .map_err(|e| WebError::Encode(e.to_string()))?;
    let noise = skydome::noise::estimate(&br.frames, &response, 0, None);
    let merged = skydome::merge::merge(
        &br.frames,
        &response,
        &skydome::merge::MergeOptions {
            weighting: skydome::merge::Weighting::Noise,
            clipped_mask: true,
            noise: Some(noise.model),
            ..Default::default()
        },
    )
    .map_err(|e| WebError::Encode(e.to_string()))?;
    merged.warnings(b.circle.as_ref());
    Ok(br.frames.len() == n
        && noise.fitted
        && merged.radiance.width == side
        && merged.radiance.height == side)
}

/// [`warm_up_stages`] for the page, on `side`² pictures (0: [`WARM_UP_STAGES_SIDE`]): the
/// names of the stages that ran (call it [`WARM_UP_STAGES_ROUNDS`] times, each its own idle
/// step).
#[wasm_bindgen(js_name = warm_up_stages)]
pub fn warm_up_stages_js(side: usize) -> Result<Vec<String>, JsError> {
    let side = if side == 0 { WARM_UP_STAGES_SIDE } else { side };
    Ok(warm_up_stages(side)?
        .into_iter()
        .map(String::from)
        .collect())
}

/// [`WARM_UP_STAGES_ROUNDS`] for the page.
#[wasm_bindgen(js_name = warm_up_stages_rounds)]
pub fn warm_up_stages_rounds_js() -> usize {
    WARM_UP_STAGES_ROUNDS
}

/// Side in pixels of the pictures [`warm_up_decoding`] decodes.
const WARM_UP_JPEG_SIDE: u16 = 128;

/// Decodes two small JPEGs `rounds` times each, through the same decoder entry as a merge
/// (`skydome::bracket::decode`: header, EXIF reader, Huffman tables, MCU loop, IDCTs, colour
/// conversion): one with full-resolution colour (4:4:4, as `skydome synth` and some cameras
/// write) and one with subsampled colour (4:2:0, as phones write), both at quality 92. A
/// 128² picture; each round is a few milliseconds even in the browser's baseline code.
///
/// Why: the browser's WebAssembly engine optimises a function only after it has run a while
/// (V8: a budget per function, spent as it runs), and a running call keeps the code it
/// started with. The JPEG decoder decodes a whole photo in one call of its MCU loop, so a
/// first merge whose decoder was not made hot beforehand decodes its first photos entirely in
/// the slow code; [`warm_up`]'s 256² bracket (4:2:0 only, three frames) does not spend the
/// budgets of the 4:4:4 paths, of the header and Huffman table readers, or of the EXIF reader.
/// Many small decodes do, for a few tens of milliseconds (measured with
/// `web-tests/profile.mjs --trace`: which functions V8 optimises during the first merge).
pub fn warm_up_decoding(rounds: usize) -> Result<(), WebError> {
    let pictures = warm_up_jpegs()?;
    for _ in 0..rounds {
        for bytes in &pictures {
            skydome::bracket::decode("warm-up.jpg", bytes, &DecodeOptions::default())
                .map_err(|err| WebError::Pipeline(err.into()))?;
        }
    }
    Ok(())
}

/// The two JPEGs [`warm_up_decoding`] decodes: a [`WARM_UP_JPEG_SIDE`]² picture at quality 92,
/// 4:4:4 then 4:2:0.
pub fn warm_up_jpegs() -> Result<[Vec<u8>; 2], WebError> {
    let side = WARM_UP_JPEG_SIDE;
    let n = usize::from(side);
    // A smooth gradient with a little texture, so that the blocks have AC coefficients of
    // several sizes (Huffman codes of several lengths), as a photo of the sky has.
    let mut rgb = Vec::with_capacity(3 * n * n);
    for y in 0..n {
        for x in 0..n {
            let t = ((x * 7919 + y * 104_729) % 23) as u8;
            rgb.extend_from_slice(&[
                (x * 2) as u8 ^ t,
                (y * 2) as u8,
                ((x + y) as u8).wrapping_add(t * 3),
            ]);
        }
    }
    let encode = |sampling| -> Result<Vec<u8>, WebError> {
        let mut out = Vec::new();
        let mut enc = jpeg_encoder::Encoder::new(&mut out, DEFAULT_JPEG_QUALITY);
        enc.set_sampling_factor(sampling);
        enc.encode(&rgb, side, side, jpeg_encoder::ColorType::Rgb)
            .map_err(|e| WebError::Encode(e.to_string()))?;
        Ok(out)
    };
    Ok([
        encode(jpeg_encoder::SamplingFactor::F_1_1)?,
        encode(jpeg_encoder::SamplingFactor::F_2_2)?,
    ])
}

/// [`warm_up_decoding`] for the page.
#[wasm_bindgen(js_name = warm_up_decoding)]
pub fn warm_up_decoding_js(rounds: usize) -> Result<(), JsError> {
    Ok(warm_up_decoding(rounds)?)
}

/// Grows the core's heap by `bytes` (rounded up to whole pages), writes to every 4 KiB page of
/// it, and frees it again; returns the bytes so reserved (0 when the browser would not grant
/// them, which is not an error: a merge then grows the memory itself, as before).
///
/// Why: a WebAssembly memory only grows, page by page as the allocator asks, and the operating
/// system backs each new 4 KiB page on its first write. For a phone's 3 × 12 MP bracket the
/// core's memory grows from about 12 MiB to 185 MiB during the first merge, and on this project's
/// 2-core test machine growing and first-touching it took about 0.3 s of that merge's 1.3–1.5 s
/// (the second merge in the same page, whose memory is already there, 0.85–1.0 s; measured with
/// `web-tests/measure.mjs --again`). The allocator keeps what is freed here and hands it to the
/// next merge, so the worker calls this once after [`warm_up`], while the app waits for the
/// user, and the first merge starts on memory that is already there. The memory is not given
/// back (a WebAssembly memory never shrinks), as after any merge of that size: the tab holds
/// it from then on, which a merge that needs as much reaches anyway (a 3 × 12 MP merge's tab
/// peak is the same with and without it).
pub fn reserve_heap(bytes: usize) -> usize {
    /// The page size the operating system backs memory with (the smallest, 4 KiB).
    const OS_PAGE: usize = 4096;
    let mut block: Vec<u8> = Vec::new();
    if block.try_reserve_exact(bytes).is_err() {
        return 0;
    }
    for page in block.spare_capacity_mut().chunks_mut(OS_PAGE) {
        page[0].write(0);
    }
    block.capacity()
}

/// [`reserve_heap`] for the page, in MiB.
#[wasm_bindgen(js_name = reserve_heap)]
pub fn reserve_heap_js(mib: usize) -> usize {
    reserve_heap(mib.saturating_mul(1 << 20))
}

/// [`warm_up`] for the page: call once after loading (a 256² bracket takes about 0.1 s).
#[wasm_bindgen(js_name = warm_up)]
pub fn warm_up_js(size: usize) -> Result<(), JsError> {
    Ok(warm_up(size)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The warm-up's dome is one the sun search accepts (else it would not run the search's
    /// whole path, which is what it is for): the sun is found.
    #[test]
    fn the_sun_warm_up_finds_its_sun() {
        assert!(warm_up_sun(WARM_UP_SUN_SIDE, 1).expect("warm-up"));
    }

    /// Each stage of the stages' warm-up runs and gives what it should (the lens circle found
    /// where it was drawn, a preview of the picture's size, statistics that see the sun): if one
    /// stopped running, or ran a path that fails early, the warm-up would no longer make the
    /// merge's own code hot, and this fails.
    #[test]
    fn the_stages_warm_up_runs_every_stage() {
        assert_eq!(
            warm_up_stages(WARM_UP_STAGES_SIDE).expect("warm-up"),
            WARM_UP_STAGES.to_vec()
        );
        // Smaller pictures too (the circle's detection scales with them).
        assert_eq!(
            warm_up_stages(256).expect("warm-up"),
            WARM_UP_STAGES.to_vec()
        );
    }

    #[test]
    fn sentence_is_one_capitalised_line_with_a_full_stop() {
        assert_eq!(
            sentence("frame_0.jpg: cannot decode:\n  bad\tmarker"),
            "frame_0.jpg: cannot decode: bad marker."
        );
        assert_eq!(sentence("cancelled"), "Cancelled.");
        assert_eq!(sentence("done!"), "Done!");
        assert_eq!(sentence("calibration failed: x"), "Calibration failed: x.");
        assert_eq!(sentence(""), "Something went wrong.");
    }

    #[test]
    fn stages_are_listed_once_each_in_their_place() {
        for (i, s) in STAGES.iter().enumerate() {
            assert_eq!(stage_position(*s), i, "{s:?}");
        }
        let p = StageProgress::new(Stage::Merging, 0.5);
        assert_eq!(
            (p.stage, p.fraction, p.overall),
            ("merging", 0.5, 3.5 / 6.0)
        );
        assert_eq!(StageProgress::new(Stage::Pictures, 1.0).overall, 1.0);
        assert_eq!(StageProgress::new(Stage::Decoding, -1.0).overall, 0.0);
        assert_eq!(StageProgress::new(Stage::Lens, f64::NAN).fraction, 0.0);
        assert_eq!(
            decoding_progress(0.5),
            r#"{"stage":"decoding","fraction":0.5,"overall":0.08333333333333333}"#
        );
    }

    /// A run of the bundled fish-eye bracket with every stage goes through them in the order
    /// the page's progress bar counts them.
    #[test]
    fn a_run_reports_its_stages_in_the_listed_order() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo");
        let frames = (0..3)
            .map(|i| {
                let name = format!("frame_{i}.jpg");
                let bytes = std::fs::read(format!("{dir}/{name}")).expect("demo frame");
                Photo::Encoded(EncodedFrame { name, bytes })
            })
            .collect();
        let options = parse_options(
            r#"{"lens": {"detect": {"model": "stereographic", "fov_deg": 235, "circle": null}},
                "sky": {"crop": true, "north_deg": 0, "sun": "auto"}, "products": {"preview": true}}"#,
        )
        .expect("options");
        let mut seen = Vec::new();
        run_photos(
            frames,
            Some(vec![0.001, 0.004, 0.016]),
            &options,
            &mut |stage, _| {
                seen.push(stage_position(stage));
                false
            },
        )
        .expect("run");
        assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
        seen.dedup();
        assert_eq!(seen, (0..STAGES.len()).collect::<Vec<_>>());
    }

    /// The phone's words for what the command line words for a command-line user, and the
    /// kind the page offers a way out for.
    #[test]
    fn no_circle_and_bad_profiles_say_what_to_do_in_the_app() {
        let e = WebError::Pipeline(PipelineError::CircleNotFound {
            frame: "IMG_1.jpg".into(),
            reason: "no lens circle found (12 boundary points): use the best-exposed frame".into(),
        });
        assert_eq!(e.kind(), "no-circle");
        let text = sentence(&e.to_string());
        assert!(
            text.starts_with("IMG_1.jpg: no fish-eye picture circle"),
            "{text}"
        );
        assert!(!text.contains('('), "no nested parentheses: {text}");
        assert!(text.contains("ordinary photos"), "{text}");
        let p = check_camera_profile_text("camera.json", "{not json").expect_err("refused");
        assert!(!p.contains("skydome calibrate"), "{p}");
        assert!(p.contains("Settings"), "{p}");
        assert!(p.starts_with("camera.json: "), "{p}");
    }

    /// A lux reading makes the figures the page shows absolute: the dome's horizontal
    /// illuminance is the reading (to 1e-6), the luminance range is in cd/m² and 179 times the
    /// relative one's (Radiance's efficacy, to the percentiles' 1/32-stop resolution), and the false-colour view is a JPEG.
    #[test]
    fn a_lux_reading_makes_the_shown_figures_absolute() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo");
        let frames: Vec<EncodedFrame> = (0..3)
            .map(|i| {
                let name = format!("frame_{i}.jpg");
                let bytes = std::fs::read(format!("{dir}/{name}")).expect("demo frame");
                EncodedFrame { name, bytes }
            })
            .collect();
        let base = r#""lens": {"detect": {"model": "stereographic", "fov_deg": 235, "circle": null}},
            "sky": {"crop": true, "north_deg": 0, "sun": "none"}"#;
        let run = |json: &str| {
            let o = parse_options(json).expect("options");
            let dome = run_frames(
                frames.clone(),
                Some(vec![0.001, 0.004, 0.016]),
                &o,
                &mut |_, _| false,
            )
            .expect("run");
            Outcome::from_dome(dome)
        };
        let relative = run(&format!("{{{base}}}"));
        let absolute = run(&format!(
            "{{{base}, \"reference\": {{\"illuminance_lux\": 12000}}}}"
        ));
        let (r, a) = (
            relative.luminance_summary().expect("relative"),
            absolute.luminance_summary().expect("absolute"),
        );
        assert!(!r.absolute && a.absolute);
        let lux = absolute
            .dome()
            .report
            .photometry
            .and_then(|p| p.horizontal_illuminance_lux)
            .expect("illuminance");
        assert!((lux / 12000.0 - 1.0).abs() < 1e-6, "{lux}");
        assert!(a.p1 > 0.0 && a.p1 <= a.median && a.median <= a.p999 && a.p999 <= a.max);
        let scale = absolute.dome().report.photometry.expect("photometry").scale;
        let ratio = a.median / (r.median * scale);
        assert!((ratio / 179.0 - 1.0).abs() < 0.05, "cd/m² per unit {ratio}");
        let jpg = absolute.false_colour_bytes().expect("false colour");
        assert_eq!(jpg[..3], [0xff, 0xd8, 0xff]);
    }

    #[test]
    fn options_json_has_defaults_and_rejects_unknown_shapes() {
        let o = parse_options("{}").expect("empty options");
        assert_eq!(o, Options::default());
        assert!(parse_options("{\"sky\": {\"north_deg\": \"east\"}}").is_err());
    }

    /// The formula the app states on screen is the library's north point, for every heading and
    /// for lenses of several sizes.
    #[test]
    fn stated_north_formula_matches_the_library() {
        for (cx, cy, r, fov, kind) in [
            (512.0, 384.0, 300.0, 180.0, LensKind::Equidistant),
            (1224.0, 1224.0, 1180.0, 235.0, LensKind::Stereographic),
            (150.0, 150.0, 140.0, 200.0, LensKind::Equisolid),
        ] {
            let lens = LensProfile::from_fov(Circle { cx, cy, r }, fov, kind).expect("lens");
            for h in [0.0, 37.0, 90.0, 135.5, 180.0, 271.0, 359.0] {
                let m = live_marks(&lens, Some(h)).expect("marks");
                let n = m.north.expect("north");
                let rh = m.horizon.r;
                let (s, c) = f64::to_radians(h).sin_cos();
                assert!((n.x - (cx + rh * s)).abs() < 1e-6, "h {h}: x {}", n.x);
                assert!((n.y - (cy - rh * c)).abs() < 1e-6, "h {h}: y {}", n.y);
            }
            // East at heading 0 is on the left: the compass point at azimuth 90.
            let g = SkyGeometry::new(&lens, 0.0, DevicePose::ScreenDown, ImageOrientation::Normal)
                .expect("geometry");
            assert!(g.compass_point(90.0).x < cx - 0.5 * r);
        }
    }
}
