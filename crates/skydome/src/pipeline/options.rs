//! What [`run`](super::run)(super::run) is told: the frames ([`Input`]) and everything else
//! ([`Options`]), serialisable so a web page can pass it as JSON.

use serde::{Deserialize, Serialize};

use crate::bracket::{DecodeOptions, DecodedFrame, OrientationPolicy};
use crate::camera::CameraProfile;
use crate::exposures::ExposureSource;
use crate::fisheye::{LensKind, LensProfile};
use crate::image::{Circle, PixelPoint};
use crate::merge::Weighting;
use crate::photometry::Reference;
use crate::reproject::Ground;
use crate::response::CalibrateOptions;
use crate::sky::{DevicePose, Level};

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
    /// Encoded photos, decoded by [`run`](super::run) (in parallel with the `parallel` feature).
    Encoded(Vec<EncodedFrame>),
    /// Frames decoded by [`crate::bracket::decode`].
    Decoded(Vec<DecodedFrame>),
}

/// What [`run`](super::run) reads.
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
    pub level: Option<Level>,
    /// How the sun is found.
    pub sun: SunMode,
    /// Capture time, ISO 8601 with a UTC offset; default: EXIF `DateTimeOriginal` + offset.
    pub time: Option<String>,
    /// The UTC offset (`+02:00`, `-05:00`, `Z`) EXIF's `DateTimeOriginal` is read in, for
    /// cameras that write no `OffsetTimeOriginal`; when given it wins over EXIF's offset.
    pub time_zone: Option<String>,
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
            time_zone: None,
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

/// Which products [`run`](super::run) makes besides the radiance map.
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

/// Everything [`run`](super::run) is told besides the frames. Serialisable, so a web page can pass it as
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
    /// Which exposures calibrate and merge: the listed times (EXIF or [`Input::times`],
    /// checked against the photos: a frame more than 1/3 stop off is named in a warning), or
    /// the exposures measured from the photos ([`crate::exposures`]), anchored on the listed
    /// time of the frame that agrees best with the others; frames that carry the same picture
    /// are then one exposure, and one of each is merged. Not for RAW brackets (their listed
    /// times are used and checked).
    pub exposures: ExposureSource,
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
    pub reference: Reference,
    /// Where an absolute scale comes from when no measurement is given (a measurement in
    /// [`Options::reference`] always wins).
    pub absolute: AbsoluteMode,
    /// The most memory, in bytes, the bracket's photos may take decoded at once: a resource
    /// policy, not an image decision (the output is the same bytes either way). `None` (the
    /// default, the command line's and Python's): no limit, every photo is decoded whole,
    /// the fastest way. With a budget, a bracket of encoded 8-bit photos whose decoded size
    /// (frames × width × height × 3 bytes, from the files' headers) exceeds it is read one
    /// photo at a time when the job allows ([`super::streams`]: a plain crop to the dome),
    /// at the cost of decoding each photo twice; a web page sets one (a phone's browser tab
    /// is killed near 1 GB; nine 12 MP photos are 324 MB decoded). See
    /// [`super::streams_input`].
    pub frame_memory_budget: Option<u64>,
}

/// Where the absolute scale comes from without a meter reading.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AbsoluteMode {
    /// The camera profile's absolute constant ([`crate::camera::AbsoluteConstant`]) with the
    /// frames' EXIF time, ISO and f-number, when the profile has one; else relative.
    #[default]
    Profile,
    /// The reflected-light meter equation (`K` = 12.5) with the frames' EXIF time, ISO and
    /// f-number: an estimate within ±30 %, labelled so in the header and the report.
    Exif,
    /// Relative radiance, even with a profile's constant.
    None,
}

crate::named_enum!(AbsoluteMode, "absolute mode", [
    Profile => "profile",
    Exif => "exif",
    None => "none"
]);
