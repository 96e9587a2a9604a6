//! A bracket: decoded frames of one still scene at different exposures.
//!
//! This module turns encoded photos (JPEG, PNG, TIFF; 8 or 16 bits per channel; grey is promoted
//! to RGB; DNG RAW files, see [`dng`]; camera RAW files with the opt-in `raw-rawler` feature, see
//! `rawler_reader`) into [`Frame`]s, reads their exposure from EXIF (or takes it from the caller), and
//! validates the set before anything downstream sees it:
//!
//! - at least two frames, all of the same size and bit depth;
//! - every frame has an exposure time (from EXIF `ExposureTime`, a `--times` list or a list file);
//! - no two frames closer than 1/6 stop in relative exposure `t · ISO / N²`;
//! - no two frames with (nearly) the same pixels although their metadata says the exposures
//!   differ — the "auto-ISO left on" / "legacy phone returned three identical shots" case;
//! - images above a pixel limit are refused before their pixels are decoded (decompression bombs).
//!
//! Frames are sorted by relative exposure, shortest first.
//!
//! **Orientation.** EXIF orientation is applied to the pixels when every frame carries the same
//! value, so frames come out the way a viewer shows them. When the frames disagree (a phone lying
//! flat often flips its orientation sensor between shots), applying each value would misalign
//! pixels that the sensor recorded aligned, so the bracket is refused unless the caller chooses
//! [`OrientationPolicy::Ignore`], which keeps the stored (sensor) pixel order for every frame.
//!
//! Pixel conventions are those of [`crate::image`]: origin top-left, `x` right, `y` down.

mod camera_raw;
mod checks;
mod decode;
pub mod dng;
mod exif;
pub mod ljpeg;
#[cfg(all(feature = "raw-rawler", not(target_arch = "wasm32")))]
pub mod rawler_reader;
pub mod tiff;
mod times;

pub use camera_raw::camera_raw_kind;
pub use checks::{assemble, assemble_for_measuring, assemble_with_black_level};
pub(crate) use checks::{assemble_thumbnails, every_7th_pixel};
pub(crate) use decode::orient;
pub use decode::{check_jpeg_complete, decode, decode_raw};
pub use dng::{is_dng, RawColour};
pub use exif::{
    format_exif_datetime, format_iso8601_utc, parse_exif_datetime, parse_iso8601, parse_utc_offset,
    read_metadata, FileMetadata,
};
#[cfg(all(feature = "raw-rawler", not(target_arch = "wasm32")))]
pub use rawler_reader::decode_with_rawler;
pub use times::{parse_list_file, parse_time, parse_times, times_from_list};

use thiserror::Error;

/// Pixel samples of one decoded frame: interleaved RGB, row-major, origin top-left.
#[derive(Debug, Clone, PartialEq)]
pub enum Pixels {
    /// 8 bits per channel, codes 0..=255.
    U8(Vec<u8>),
    /// 16 bits per channel, codes 0..=65535.
    U16(Vec<u16>),
}

impl Pixels {
    /// Keeps the first `len` samples and gives the rest of the buffer back to the allocator
    /// (with glibc, a large buffer shrinks in place and the freed pages leave the process).
    ///
    /// Unless `len` is 0 (everything goes), the cut is moved up to the next 2 MiB boundary of
    /// address, keeping at most 2 MiB more: where the kernel backs the buffer with transparent
    /// huge pages (as the command line asks), the freed part is then whole huge pages, returned
    /// at once, rather than the tail of one, which Linux holds until it splits the page later.
    ///
    /// On wasm32 only `len == 0` does anything: a WebAssembly memory never shrinks, and its
    /// allocator cannot shrink a large block in place, so a partial release would copy the part
    /// kept to a new block (in the browser it doubled the merge's time) and return nothing.
    pub(crate) fn release_from(&mut self, len: usize) {
        if cfg!(target_arch = "wasm32") && len != 0 {
            return;
        }
        fn release<T>(v: &mut Vec<T>, len: usize) {
            const HUGE_PAGE: usize = 2 << 20;
            let keep = if len == 0 {
                0
            } else {
                let start = v.as_ptr() as usize;
                let end = start + len * std::mem::size_of::<T>();
                let aligned = end.next_multiple_of(HUGE_PAGE) - start;
                (aligned / std::mem::size_of::<T>()).clamp(len, v.len().max(len))
            };
            v.truncate(keep);
            v.shrink_to_fit();
        }
        match self {
            Pixels::U8(v) => release(v, len),
            Pixels::U16(v) => release(v, len),
        }
    }

    /// Bits per channel (8 or 16).
    pub fn bit_depth(&self) -> u32 {
        match self {
            Pixels::U8(_) => 8,
            Pixels::U16(_) => 16,
        }
    }

    /// Number of samples (3 per pixel).
    pub fn len(&self) -> usize {
        match self {
            Pixels::U8(v) => v.len(),
            Pixels::U16(v) => v.len(),
        }
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sample `i` scaled to 0.0..=1.0.
    #[inline]
    fn unit(&self, i: usize) -> f32 {
        match self {
            Pixels::U8(v) => v[i] as f32 / 255.0,
            Pixels::U16(v) => v[i] as f32 / 65535.0,
        }
    }
}

/// Exposure settings of one frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Exposure {
    /// Shutter time Δt in seconds (> 0).
    pub time_s: f64,
    /// ISO speed, when known.
    pub iso: Option<f64>,
    /// Aperture f-number N, when known.
    pub f_number: Option<f64>,
}

impl Exposure {
    /// Relative exposure `t · ISO / N²` in "seconds at ISO 100, f/1" units (missing ISO counts as
    /// 100, missing f-number as 1), so a bracket that varies ISO or aperture still merges.
    /// Only ratios between frames of one bracket matter.
    pub fn relative(&self) -> f64 {
        let iso = self.iso.unwrap_or(100.0) / 100.0;
        let n = self.f_number.unwrap_or(1.0);
        self.time_s * iso / (n * n)
    }
}

/// One decoded frame of a bracket.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Where the frame came from (file name), for messages.
    pub name: String,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The samples.
    pub pixels: Pixels,
    /// Exposure settings.
    pub exposure: Exposure,
}

/// Capture metadata read from a frame's EXIF, as far as it is present.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CaptureInfo {
    /// Camera maker (`Make`).
    pub make: Option<String>,
    /// Camera model (`Model`).
    pub model: Option<String>,
    /// Local capture time `YYYY:MM:DD HH:MM:SS` (`DateTimeOriginal`).
    pub datetime_original: Option<String>,
    /// UTC offset of the capture time, `±HH:MM` (`OffsetTimeOriginal`, else `OffsetTime`).
    pub utc_offset: Option<String>,
    /// Fraction of a second of the capture time, as written (`SubSecTimeOriginal`: the digits
    /// after the decimal point, `"25"` = 0.25 s).
    #[serde(default)]
    pub subsec_original: Option<String>,
    /// Latitude in degrees, north positive (`GPSLatitude` + `GPSLatitudeRef`).
    pub gps_latitude_deg: Option<f64>,
    /// Longitude in degrees, east positive (`GPSLongitude` + `GPSLongitudeRef`).
    pub gps_longitude_deg: Option<f64>,
    /// EXIF `WhiteBalance` (0 auto, 1 manual).
    pub white_balance: Option<u32>,
    /// EXIF `Orientation` (1..=8), 1 when absent.
    pub orientation: u16,
}

impl CaptureInfo {
    /// The capture instant, when both `DateTimeOriginal` and a UTC offset are known.
    pub fn capture_time(&self) -> Option<time::OffsetDateTime> {
        let local = parse_exif_datetime(self.datetime_original.as_deref()?)?;
        let offset = parse_utc_offset(self.utc_offset.as_deref()?)?;
        Some(local.assume_offset(offset))
    }

    /// `CAPDATE=`/`GMT=` strings for a Radiance header (`YYYY:MM:DD HH:MM:SS`): local capture time
    /// when known, UTC when the offset is known too.
    pub fn header_times(&self) -> (Option<String>, Option<String>) {
        let local = self
            .datetime_original
            .as_deref()
            .and_then(parse_exif_datetime)
            .map(format_exif_datetime);
        let gmt = self.capture_time().map(|t| {
            let u = t.to_offset(time::UtcOffset::UTC);
            format_exif_datetime(time::PrimitiveDateTime::new(u.date(), u.time()))
        });
        (local, gmt)
    }
}

/// What to do with EXIF orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OrientationPolicy {
    /// Rotate/flip pixels as EXIF says when all frames agree; refuse when they disagree.
    #[default]
    Apply,
    /// Keep the stored pixel order of every frame.
    Ignore,
}

crate::named_enum!(OrientationPolicy, "orientation policy", [Apply => "apply", Ignore => "ignore"]);

/// Options for decoding frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecodeOptions {
    /// Largest accepted image, in pixels (width × height), checked before decoding.
    pub max_pixels: u64,
}

impl Default for DecodeOptions {
    fn default() -> Self {
        // 250 MP: above every phone sensor on the market, far below what exhausts memory.
        Self {
            max_pixels: 250_000_000,
        }
    }
}

/// A decoded file before validation: pixels in stored order, metadata, exposure if EXIF had it.
#[derive(Debug, Clone)]
pub struct DecodedFrame {
    /// File name for messages.
    pub name: String,
    /// Width in pixels (stored order, before orientation).
    pub width: usize,
    /// Height in pixels (stored order, before orientation).
    pub height: usize,
    /// Samples in stored order.
    pub pixels: Pixels,
    /// Exposure time from EXIF, if present and valid.
    pub exif_time_s: Option<f64>,
    /// ISO from EXIF.
    pub iso: Option<f64>,
    /// f-number from EXIF.
    pub f_number: Option<f64>,
    /// Other capture metadata.
    pub info: CaptureInfo,
    /// Description of an embedded ICC profile that is not sRGB (values are then not sRGB).
    pub non_srgb_icc: Option<String>,
}

impl DecodedFrame {
    /// A frame as a decoder hands it over before its metadata is read: no EXIF exposure,
    /// orientation 1 (stored order), no ICC profile; the EXIF reader fills in the rest.
    pub fn new(name: &str, width: usize, height: usize, pixels: Pixels) -> Self {
        DecodedFrame {
            name: name.to_string(),
            width,
            height,
            pixels,
            exif_time_s: None,
            iso: None,
            f_number: None,
            info: CaptureInfo {
                orientation: 1,
                ..CaptureInfo::default()
            },
            non_srgb_icc: None,
        }
    }
}

impl From<Frame> for DecodedFrame {
    /// The frame as a decoder would hand it over from a file whose EXIF gave its exposure
    /// (time, ISO, f-number) and no rotation (orientation 1): e.g. a simulated frame
    /// ([`crate::synth`]) on its way into [`crate::pipeline::run`].
    fn from(f: Frame) -> Self {
        DecodedFrame {
            name: f.name,
            width: f.width,
            height: f.height,
            pixels: f.pixels,
            exif_time_s: Some(f.exposure.time_s),
            iso: f.exposure.iso,
            f_number: f.exposure.f_number,
            info: CaptureInfo {
                orientation: 1,
                ..CaptureInfo::default()
            },
            non_srgb_icc: None,
        }
    }
}

/// A validated bracket, sorted by relative exposure (shortest first).
#[derive(Debug, Clone)]
pub struct Bracket {
    /// The frames, oriented and sorted.
    pub frames: Vec<Frame>,
    /// Capture metadata of the reference frame (the middle exposure).
    pub info: CaptureInfo,
    /// Things the user should know that do not stop the merge (one line each).
    pub warnings: Vec<String>,
    /// The EXIF orientation (1..=8) still in force on the pixels: 1 when it was applied by
    /// [`assemble`], the frames' stored value when it was ignored. Sky geometry needs it to
    /// know which way the sensor's top edge lies in the image.
    pub pixel_orientation: u16,
}

impl Bracket {
    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.frames.first().map_or(0, |f| f.width)
    }
    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.frames.first().map_or(0, |f| f.height)
    }
}

/// Why a file or a bracket was refused. Every message names the file when there is one.
#[derive(Debug, Error, PartialEq)]
pub enum BracketError {
    /// The bytes are empty.
    #[error("{file}: empty file (0 bytes)")]
    Empty {
        /// File name.
        file: String,
    },
    /// The format is not JPEG, PNG or TIFF.
    #[error(
        "{file}: unsupported or unrecognised image format (skydome reads JPEG, PNG, TIFF and DNG)"
    )]
    UnsupportedFormat {
        /// File name.
        file: String,
    },
    /// A camera RAW file (CR2, NEF, …) in a build without camera RAW support.
    #[error("{file}: a {kind} camera RAW file; this skydome was built without camera RAW support (build it with the `raw-rawler` feature, or convert the files to DNG, e.g. with dnglab or Adobe DNG Converter)")]
    CameraRawUnsupported {
        /// File name.
        file: String,
        /// The format (`"CR2"`, `"NEF"`, …).
        kind: String,
    },
    /// Some frames are RAW (DNG) and others are not.
    #[error("{file}: a bracket is all RAW (DNG) or all pictures (JPEG, PNG, TIFF); this frame is not like the first")]
    MixedRaw {
        /// File name.
        file: String,
    },
    /// The decoder failed (corrupt or truncated).
    #[error("{file}: cannot decode image: {reason}")]
    Corrupt {
        /// File name.
        file: String,
        /// The decoder's reason.
        reason: String,
    },
    /// The image is larger than the configured limit.
    #[error("{file}: image is {width}x{height} = {pixels} pixels, above the limit of {limit} (raise the pixel limit if the file is trusted)")]
    TooLarge {
        /// File name.
        file: String,
        /// Width.
        width: u64,
        /// Height.
        height: u64,
        /// Pixel count.
        pixels: u64,
        /// The limit.
        limit: u64,
    },
    /// An image too small to be a photo.
    #[error("{file}: image is only {width}x{height} pixels; a bracket frame needs at least 2x2")]
    TooSmall {
        /// File name.
        file: String,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// Fewer than two frames.
    #[error("a bracket needs at least 2 frames of different exposure, got {0}")]
    TooFewFrames(usize),
    /// Fewer than two frames left once the frames that add nothing (all black level or all
    /// clipped) were left out.
    #[error("{given} frames were given, but {} {} left out because almost every pixel is at the black level or clipped; a bracket needs at least 2 frames that show the scene: retake {} at an exposure that shows the scene", and_list(.left_out), were(.left_out), if .left_out.len() == 1 { "it" } else { "them" })]
    NothingToMerge {
        /// Frames given.
        given: usize,
        /// The frames left out, in exposure order.
        left_out: Vec<String>,
    },
    /// Frames of different sizes.
    #[error("{}: size differs from {first} ({w0}x{h0}); all frames must have the same size", and_list(&.files.iter().map(|(f, w, h)| format!("{f} ({w}x{h})")).collect::<Vec<_>>()))]
    SizeMismatch {
        /// Every file whose size differs from the first, with its width and height.
        files: Vec<(String, usize, usize)>,
        /// The first file.
        first: String,
        /// First width.
        w0: usize,
        /// First height.
        h0: usize,
    },
    /// Frames of different bit depths.
    #[error("{}: bit depth differs from {first} ({bits0}-bit samples); all frames must have the same bit depth", and_list(&.files.iter().map(|(f, b)| format!("{f} ({b}-bit samples)")).collect::<Vec<_>>()))]
    DepthMismatch {
        /// Every file whose depth differs from the first, with its depth.
        files: Vec<(String, u32)>,
        /// First file.
        first: String,
        /// First depth.
        bits0: u32,
    },
    /// No exposure time for a file.
    #[error("{}: no exposure time in EXIF; supply the exposure times", and_list(.files))]
    MissingExposure {
        /// Every file without one.
        files: Vec<String>,
    },
    /// A time that is not a positive finite number of seconds.
    #[error("{file}: invalid exposure time '{value}': expected a positive number of seconds such as 1/400, 0.0025 or 2")]
    BadTime {
        /// File name (or `--times`).
        file: String,
        /// The text given.
        value: String,
    },
    /// A frame that no line of a list file names.
    #[error("{file}: not listed in {list}; add a line '{base} TIME'")]
    NotListed {
        /// The frame as the caller named it.
        file: String,
        /// The list file.
        list: String,
        /// The frame's base name (what the missing line would start with).
        base: String,
    },
    /// A frame that two lines of a list file name with different times.
    #[error("{file}: listed twice in {list} with different times (lines {line} and {other_line}); keep one")]
    ListedTwice {
        /// The frame as the caller named it.
        file: String,
        /// The list file.
        list: String,
        /// First line naming it (1-based).
        line: usize,
        /// The other line naming it (1-based).
        other_line: usize,
    },
    /// A three-column list line whose third column is not 1/time.
    #[error("{list} line {line}: third column {inverse} is not 1/time for time {time} s (1/time = {expected}); correct one of them or drop the third column")]
    InverseTimeMismatch {
        /// The list file.
        list: String,
        /// Line number (1-based).
        line: usize,
        /// The time as written.
        time: String,
        /// The third column as written.
        inverse: String,
        /// 1/time, rounded for the message.
        expected: String,
    },
    /// Wrong number of `--times`.
    #[error(
        "{given} exposure times were given for {frames} frames; give one per frame, in frame order"
    )]
    TimesCount {
        /// Values given.
        given: usize,
        /// Files given.
        frames: usize,
    },
    /// Two frames with (almost) the same exposure.
    #[error("{}; every frame needs a different exposure (auto-ISO on?)", .pairs.iter().map(|p| format!("{}: exposure {} is within 1/6 stop of {} ({})", p.file, p.e1, p.other, p.e2)).collect::<Vec<_>>().join("; "))]
    DuplicateExposure {
        /// Every neighbouring pair (in exposure order) closer than 1/6 stop.
        pairs: Vec<NamedPair>,
    },
    /// Two frames whose pixels are (nearly) identical although metadata says otherwise.
    #[error("{}: pixels are nearly identical although their exposures differ by up to {stops:.2} stops; the camera probably ignored the bracket (auto-ISO or auto-exposure on): retake them, keep one of each group, or merge with the exposures measured from the photos", .groups.iter().map(|g| and_list(g)).collect::<Vec<_>>().join("; "))]
    IdenticalPixels {
        /// Runs of neighbouring frames (in exposure order) that carry the same picture.
        groups: Vec<Vec<String>>,
        /// The largest claimed difference within a group, in stops.
        stops: f64,
    },
    /// Frames whose bright and dark parts lie elsewhere than in their neighbours': photos of
    /// another scene (or another view) given with the bracket.
    #[error("{}", other_scene(.files, .others))]
    OtherScene {
        /// Every frame that does not show its neighbours' scene, in exposure order.
        files: Vec<String>,
        /// The frames they were compared with (their neighbours in exposure order).
        others: Vec<String>,
    },
    /// A frame exposed longer than another is darker at most pixels: the exposure times do not
    /// belong to the photos.
    #[error("{} at most pixels although {} exposed longer: the exposure times do not belong to these photos (swapped or mistyped); check them", .pairs.iter().map(|p| format!("{} ({}) is darker than {} ({})", p.file, p.e1, p.other, p.e2)).collect::<Vec<_>>().join("; "), if .pairs.len() == 1 { "it was" } else { "each was" })]
    DarkerWhenLonger {
        /// Every neighbouring pair (in exposure order) whose longer frame (`file`) is darker.
        pairs: Vec<NamedPair>,
    },
    /// EXIF orientations disagree.
    #[error("{}: EXIF orientation differs from {first} ({o0}); ignore EXIF orientation (keep the stored pixel order) to merge them", and_list(&.files.iter().map(|(f, o)| format!("{f} (orientation {o})")).collect::<Vec<_>>()))]
    OrientationMismatch {
        /// Every file whose orientation differs from the first, with its orientation.
        files: Vec<(String, u16)>,
        /// First file.
        first: String,
        /// First orientation.
        o0: u16,
    },
}

/// Two frames of a bracket named in a refusal, with their exposures as the message shows them:
/// `file` is the one exposed longer.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPair {
    /// The frame exposed longer (or, for equal exposures, the later in exposure order).
    pub file: String,
    /// Its exposure, formatted.
    pub e1: String,
    /// The other frame.
    pub other: String,
    /// Its exposure, formatted.
    pub e2: String,
}

/// `a`, `a and b`, `a, b and c`: file names for a message.
fn and_list<S: AsRef<str>>(names: &[S]) -> String {
    match names {
        [] => String::new(),
        [one] => one.as_ref().to_string(),
        [rest @ .., last] => format!(
            "{} and {}",
            rest.iter()
                .map(AsRef::as_ref)
                .collect::<Vec<_>>()
                .join(", "),
            last.as_ref()
        ),
    }
}

/// The sentence of [`BracketError::OtherScene`].
fn other_scene(files: &[String], others: &[String]) -> String {
    let one = files.len() == 1;
    let (it, its) = if one {
        ("it", "its")
    } else {
        ("them", "their")
    };
    if others.is_empty() {
        return format!(
            "{} do not show one scene: their bright and dark parts lie in different places (a photo of another scene or another view in the bracket); leave out the one that does not belong, or retake it",
            and_list(files)
        );
    }
    format!(
        "{} {} not show the scene of {}: {its} bright and dark parts lie elsewhere (a photo of another scene or another view in the bracket); leave {it} out or retake {it}",
        and_list(files),
        if one { "does" } else { "do" },
        and_list(others)
    )
}

fn were(names: &[String]) -> &'static str {
    if names.len() == 1 {
        "was"
    } else {
        "were"
    }
}

/// A 16-bit code → one of 256 levels, `round(v / 257)` (so `257 · z` maps to `z` exactly).
#[inline]
pub fn bin16(v: u16) -> u8 {
    ((u32::from(v) + 128) / 257) as u8
}

/// The frame with the most well-exposed samples (codes 20..=235, every 7th sample counted) as
/// an 8-bit image; 16-bit frames are binned with [`bin16`]. Empty for no frames. The lens
/// circle is detected on it.
pub fn best_exposed_u8(frames: &[Frame]) -> crate::image::RgbImage<u8> {
    let to8 = |p: &Pixels| -> Vec<u8> {
        match p {
            Pixels::U8(v) => v.clone(),
            Pixels::U16(v) => v.iter().map(|&x| bin16(x)).collect(),
        }
    };
    match best_exposed(frames) {
        Some(f) => crate::image::RgbImage {
            width: f.width,
            height: f.height,
            data: to8(&f.pixels),
        },
        None => crate::image::RgbImage {
            width: 0,
            height: 0,
            data: Vec::new(),
        },
    }
}

/// The frame [`best_exposed_u8`] copies, borrowed (`None` for no frames).
pub fn best_exposed(frames: &[Frame]) -> Option<&Frame> {
    // Every 7th sample, counted in parts of whole steps (the same samples as one pass; the
    // counts add up exactly in any order), in parallel with the `parallel` feature.
    const PART: usize = 7 << 16;
    fn count<T: Sync>(v: &[T], ok: impl Fn(&T) -> bool + Sync) -> usize {
        let part = |c: &[T]| c.iter().step_by(7).filter(|z| ok(z)).count();
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            v.par_chunks(PART).map(part).sum()
        }
        #[cfg(not(feature = "parallel"))]
        v.chunks(PART).map(part).sum()
    }
    let well = |p: &Pixels| -> usize {
        match p {
            Pixels::U8(v) => count(v, |&z| (20..=235).contains(&z)),
            Pixels::U16(v) => count(v, |&z| (20..=235).contains(&bin16(z))),
        }
    };
    let counts: Vec<usize> = frames.iter().map(|f| well(&f.pixels)).collect();
    frames
        .iter()
        .zip(&counts)
        .max_by_key(|(_, &n)| n)
        .map(|(f, _)| f)
}

#[cfg(test)]
mod tests {
    use super::decode::orient;
    use super::*;

    fn frame(name: &str, w: usize, h: usize, f: impl Fn(usize) -> u8, t: f64) -> DecodedFrame {
        DecodedFrame {
            name: name.into(),
            width: w,
            height: h,
            pixels: Pixels::U8((0..3 * w * h).map(f).collect()),
            exif_time_s: Some(t),
            iso: None,
            f_number: None,
            info: CaptureInfo {
                orientation: 1,
                ..Default::default()
            },
            non_srgb_icc: None,
        }
    }

    #[test]
    fn times_that_do_not_belong_to_the_photos_are_refused() {
        // A scene of codes 10..=250; the frame twice as long is twice as bright (clipped).
        let scene = |i: usize| 10 + (i * 7919 % 241) as u8;
        let short = |t| frame("short.jpg", 64, 64, scene, t);
        let long = |t| frame("long.jpg", 64, 64, |i| scene(i).saturating_mul(2), t);
        assert!(assemble(
            vec![short(0.01), long(0.02)],
            None,
            OrientationPolicy::Apply
        )
        .is_ok());
        // The times swapped: the brighter photo claims the shorter time.
        let e = assemble(
            vec![short(0.02), long(0.01)],
            None,
            OrientationPolicy::Apply,
        )
        .unwrap_err();
        assert!(matches!(e, BracketError::DarkerWhenLonger { .. }), "{e}");
        let msg = e.to_string();
        assert!(
            msg.starts_with("short.jpg (1/50 s") && msg.contains("long.jpg"),
            "{msg}"
        );
    }

    #[test]
    fn times_parse_fractions_and_decimals() {
        assert_eq!(parse_times("1/400, 0.5,2").unwrap(), vec![0.0025, 0.5, 2.0]);
        for bad in ["0", "-1/2", "1/0", "abc", "", "nan", "inf", "1e9"] {
            assert!(parse_time("x", bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn list_file_pairs_and_comments() {
        let l = parse_list_file("l.txt", "# c\na.jpg 1/8\n\nb.jpg 1  # x\n").unwrap();
        assert_eq!(l, vec![("a.jpg".into(), 0.125), ("b.jpg".into(), 1.0)]);
        assert!(parse_list_file("l.txt", "a.jpg\n").is_err());
    }

    #[test]
    fn frames_sort_by_relative_exposure_and_iso_counts() {
        let mut a = frame("a", 4, 4, |i| (i * 3 % 200) as u8 + 20, 1.0 / 100.0);
        a.iso = Some(100.0);
        let mut b = frame("b", 4, 4, |i| (i * 5 % 120) as u8, 1.0 / 100.0);
        b.iso = Some(50.0); // half the exposure of a (ISO 100 assumed when absent)
        let c = frame("c", 4, 4, |i| (i * 7 % 250) as u8, 1.0 / 25.0);
        let br = assemble(vec![a, b, c], None, OrientationPolicy::Apply).unwrap();
        let names: Vec<_> = br.frames.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["b", "a", "c"]);
        assert!(br.warnings.iter().any(|w| w.contains("ISO")));
    }

    #[test]
    fn identical_pixels_with_different_times_are_refused() {
        let a = frame("a", 16, 16, |i| (i % 180) as u8 + 30, 0.01);
        let b = frame("b", 16, 16, |i| (i % 180) as u8 + 30, 0.04);
        let e = assemble(vec![a, b], None, OrientationPolicy::Apply).unwrap_err();
        assert!(matches!(e, BracketError::IdenticalPixels { .. }), "{e}");
    }

    /// A film-scan-like pair: 95 % of the frame at the black level (code 16 ± 1), the rest a
    /// gradient one stop apart (through a gamma of 2.2).
    fn film_pair(t0: f64) -> (DecodedFrame, DecodedFrame) {
        let w = 64;
        let code = |i: usize, t: f64| -> u8 {
            let p = i / 3;
            if p % 100 < 95 {
                (15 + (i * 7 % 3)) as u8
            } else {
                let e = 0.05 + 0.4 * (p % 64) as f64 / 64.0;
                (16.0 + 224.0 * (e * t / t0).powf(1.0 / 2.2)).min(255.0) as u8
            }
        };
        (
            frame("short", w, w, move |i| code(i, t0), t0),
            frame("long", w, w, move |i| code(i, 2.0 * t0), 2.0 * t0),
        )
    }

    #[test]
    fn mostly_black_level_frames_one_stop_apart_are_accepted() {
        let (a, b) = film_pair(1.0 / 1024.0);
        let br = assemble(vec![a, b], None, OrientationPolicy::Apply).unwrap();
        assert_eq!(br.frames.len(), 2);
    }

    #[test]
    fn ignored_bracket_is_still_refused_at_a_black_level() {
        let (a, _) = film_pair(1.0 / 1024.0);
        let mut b = a.clone();
        b.name = "long".into();
        b.exif_time_s = Some(2.0 / 1024.0);
        let e = assemble(vec![a, b], None, OrientationPolicy::Apply).unwrap_err();
        assert!(matches!(e, BracketError::IdenticalPixels { .. }), "{e}");
    }

    #[test]
    fn a_frame_with_nothing_above_the_black_level_is_left_out_with_a_warning() {
        let (a, b) = film_pair(1.0 / 256.0);
        let dark = frame("dark", 64, 64, |i| (15 + (i * 7 % 3)) as u8, 1.0 / 4096.0);
        let br = assemble(vec![a, b, dark], None, OrientationPolicy::Apply).unwrap();
        let names: Vec<_> = br.frames.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["short", "long"]);
        assert!(br
            .warnings
            .iter()
            .any(|w| w.contains("dark") && w.contains("left out")));
        // Two black frames and one good one: too short once the black ones are out.
        let (a, _) = film_pair(1.0 / 256.0);
        let d1 = frame("d1", 64, 64, |_| 0, 1.0 / 4096.0);
        let d2 = frame("d2", 64, 64, |_| 0, 1.0 / 8192.0);
        let e = assemble(vec![a, d1, d2], None, OrientationPolicy::Apply).unwrap_err();
        assert_eq!(
            e,
            BracketError::NothingToMerge {
                given: 3,
                left_out: vec!["d2".into(), "d1".into()]
            }
        );
        assert_eq!(
            e.to_string(),
            "3 frames were given, but d2 and d1 were left out because almost every pixel is at the black level or clipped; a bracket needs at least 2 frames that show the scene: retake them at an exposure that shows the scene"
        );
    }

    #[test]
    fn capture_time_with_offset_gives_gmt() {
        let info = CaptureInfo {
            datetime_original: Some("2026:06:21 14:30:05".into()),
            utc_offset: Some("+02:00".into()),
            ..Default::default()
        };
        let (cap, gmt) = info.header_times();
        assert_eq!(cap.as_deref(), Some("2026:06:21 14:30:05"));
        assert_eq!(gmt.as_deref(), Some("2026:06:21 12:30:05"));
        let t = parse_iso8601("2026-06-21T14:30:05+02:00").unwrap();
        assert_eq!(t, info.capture_time().unwrap());
        assert_eq!(parse_iso8601("2026-06-21T12:30:05Z"), Some(t));
        assert!(parse_iso8601("2026-06-21T12:30:05").is_none());
        assert_eq!(
            parse_utc_offset("-0530"),
            time::UtcOffset::from_hms(-5, -30, 0).ok()
        );
    }

    #[test]
    fn orientation_6_rotates_clockwise() {
        // 2x1 image: left pixel 10, right pixel 20 -> after rotating 90° clockwise it is 1x2
        // with 10 on top.
        let (w, h, p) = orient(2, 1, Pixels::U8(vec![10, 10, 10, 20, 20, 20]), 6);
        assert_eq!((w, h), (1, 2));
        assert_eq!(p, Pixels::U8(vec![10, 10, 10, 20, 20, 20]));
        let (_, _, p) = orient(2, 1, Pixels::U8(vec![10, 10, 10, 20, 20, 20]), 8);
        assert_eq!(p, Pixels::U8(vec![20, 20, 20, 10, 10, 10]));
    }
}
