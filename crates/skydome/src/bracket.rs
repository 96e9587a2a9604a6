//! A bracket: decoded frames of one still scene at different exposures.
//!
//! This module turns encoded photos (JPEG, PNG, TIFF; 8 or 16 bits per channel; grey is promoted
//! to RGB) into [`Frame`]s, reads their exposure from EXIF (or takes it from the caller), and
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

use std::io::Cursor;

#[cfg(feature = "parallel")]
use rayon::prelude::*;
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

/// Parses an EXIF date-time `YYYY:MM:DD HH:MM:SS` (also accepts `-` in the date and a `T`).
pub fn parse_exif_datetime(s: &str) -> Option<time::PrimitiveDateTime> {
    let s = s.trim();
    let (d, t) = s.split_once([' ', 'T'])?;
    let d: Vec<&str> = d.split([':', '-']).collect();
    let t: Vec<&str> = t.split(':').collect();
    if d.len() != 3 || t.len() < 2 {
        return None;
    }
    let month = time::Month::try_from(d[1].parse::<u8>().ok()?).ok()?;
    let date =
        time::Date::from_calendar_date(d[0].parse().ok()?, month, d[2].parse().ok()?).ok()?;
    let sec: f64 = t.get(2).map_or(Some(0.0), |x| x.parse().ok())?;
    let time =
        time::Time::from_hms(t[0].parse().ok()?, t[1].parse().ok()?, sec.floor() as u8).ok()?;
    Some(time::PrimitiveDateTime::new(date, time))
}

/// Parses a UTC offset `±HH:MM`, `±HHMM`, `±HH` or `Z`.
pub fn parse_utc_offset(s: &str) -> Option<time::UtcOffset> {
    let s = s.trim();
    if s == "Z" || s == "z" {
        return Some(time::UtcOffset::UTC);
    }
    let (sign, rest) = match s.as_bytes().first()? {
        b'+' => (1i8, &s[1..]),
        b'-' => (-1i8, &s[1..]),
        _ => return None,
    };
    let digits: String = rest.chars().filter(|c| *c != ':').collect();
    if !digits.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let (h, m) = match digits.len() {
        2 => (digits.parse::<i8>().ok()?, 0),
        4 => (
            digits[..2].parse::<i8>().ok()?,
            digits[2..].parse::<i8>().ok()?,
        ),
        _ => return None,
    };
    time::UtcOffset::from_hms(sign * h, sign * m, 0).ok()
}

/// Parses an ISO 8601 instant with offset, e.g. `2026-06-21T12:30:00+02:00` or `…Z`.
pub fn parse_iso8601(s: &str) -> Option<time::OffsetDateTime> {
    let s = s.trim();
    let split = s
        .char_indices()
        .skip(11)
        .find(|(_, c)| matches!(c, '+' | '-' | 'Z' | 'z'))
        .map(|(i, _)| i)?;
    let local = parse_exif_datetime(&s[..split])?;
    Some(local.assume_offset(parse_utc_offset(&s[split..])?))
}

fn format_exif_datetime(t: time::PrimitiveDateTime) -> String {
    format!(
        "{:04}:{:02}:{:02} {:02}:{:02}:{:02}",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second()
    )
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
    #[error("{file}: unsupported or unrecognised image format (skydome reads JPEG, PNG and TIFF)")]
    UnsupportedFormat {
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
    /// Frames of different sizes.
    #[error(
        "{file}: size {w}x{h} differs from {first} ({w0}x{h0}); all frames must have the same size"
    )]
    SizeMismatch {
        /// Offending file.
        file: String,
        /// Its width.
        w: usize,
        /// Its height.
        h: usize,
        /// The first file.
        first: String,
        /// First width.
        w0: usize,
        /// First height.
        h0: usize,
    },
    /// Frames of different bit depths.
    #[error("{file}: {bits}-bit samples, but {first} has {bits0}-bit; all frames must have the same bit depth")]
    DepthMismatch {
        /// Offending file.
        file: String,
        /// Its depth.
        bits: u32,
        /// First file.
        first: String,
        /// First depth.
        bits0: u32,
    },
    /// No exposure time for a file.
    #[error("{file}: no exposure time in EXIF; supply the exposure times")]
    MissingExposure {
        /// File name.
        file: String,
    },
    /// A time that is not a positive finite number of seconds.
    #[error("{file}: invalid exposure time '{value}': expected a positive number of seconds such as 1/400, 0.0025 or 2")]
    BadTime {
        /// File name (or `--times`).
        file: String,
        /// The text given.
        value: String,
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
    #[error("{file}: exposure {e1} is within 1/6 stop of {other} ({e2}); every frame needs a different exposure (auto-ISO on?)")]
    DuplicateExposure {
        /// File name.
        file: String,
        /// Its exposure, formatted.
        e1: String,
        /// The other file.
        other: String,
        /// Its exposure, formatted.
        e2: String,
    },
    /// Two frames whose pixels are (nearly) identical although metadata says otherwise.
    #[error("{file}: pixels are nearly identical to {other} although their exposures differ by {stops:.2} stops; the camera probably ignored the bracket (auto-ISO or auto-exposure on)")]
    IdenticalPixels {
        /// File name.
        file: String,
        /// The other file.
        other: String,
        /// Claimed difference in stops.
        stops: f64,
    },
    /// A frame exposed longer than another is darker at most pixels: the exposure times do not
    /// belong to the photos.
    #[error("{file} ({e1}) is darker than {other} ({e2}) at most pixels although it was exposed longer: the exposure times do not belong to these photos (swapped or mistyped); check them")]
    DarkerWhenLonger {
        /// The frame exposed longer.
        file: String,
        /// Its exposure, formatted.
        e1: String,
        /// The frame exposed shorter.
        other: String,
        /// Its exposure, formatted.
        e2: String,
    },
    /// EXIF orientations disagree.
    #[error("{file}: EXIF orientation {o} differs from {first} ({o0}); ignore EXIF orientation (keep the stored pixel order) to merge them")]
    OrientationMismatch {
        /// File name.
        file: String,
        /// Its orientation.
        o: u16,
        /// First file.
        first: String,
        /// First orientation.
        o0: u16,
    },
}

/// Parses one exposure time in seconds: `1/400`, `0.0025`, `2`, `1/2.5`. `file` names the source
/// for the error message. Refuses zero, negatives, NaN/infinity and times above 24 hours.
pub fn parse_time(file: &str, text: &str) -> Result<f64, BracketError> {
    let bad = || BracketError::BadTime {
        file: file.to_string(),
        value: text.to_string(),
    };
    let t = text.trim();
    let v = match t.split_once('/') {
        Some((n, d)) => {
            let n: f64 = n.trim().parse().map_err(|_| bad())?;
            let d: f64 = d.trim().parse().map_err(|_| bad())?;
            n / d
        }
        None => t.parse().map_err(|_| bad())?,
    };
    if v.is_finite() && v > 0.0 && v <= 86_400.0 {
        Ok(v)
    } else {
        Err(bad())
    }
}

/// Parses a comma-separated `--times` list (e.g. `1/400,1/100,1/25`).
pub fn parse_times(text: &str) -> Result<Vec<f64>, BracketError> {
    text.split(',')
        .map(|t| parse_time("exposure times", t))
        .collect()
}

/// Parses a list file: one `FILE TIME` pair per line (whitespace separated; `#` starts a
/// comment; blank lines ignored). `list_name` is used in error messages. Returns the pairs in
/// file order; file names are as written (the caller resolves them).
pub fn parse_list_file(list_name: &str, text: &str) -> Result<Vec<(String, f64)>, BracketError> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut parts = line.split_whitespace();
        let (Some(file), Some(time), None) = (parts.next(), parts.next(), parts.next()) else {
            return Err(BracketError::BadTime {
                file: format!("{list_name} line {}", n + 1),
                value: line.to_string(),
            });
        };
        out.push((
            file.to_string(),
            parse_time(&format!("{list_name} line {}", n + 1), time)?,
        ));
    }
    Ok(out)
}

/// Decodes one encoded image (JPEG, PNG or TIFF) and reads its EXIF.
///
/// Pixels stay in stored order; [`assemble`] applies orientation once the whole bracket is known.
pub fn decode(
    name: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<DecodedFrame, BracketError> {
    use image::{ImageDecoder, ImageFormat};
    if bytes.is_empty() {
        return Err(BracketError::Empty {
            file: name.to_string(),
        });
    }
    let corrupt = |e: &dyn std::fmt::Display| BracketError::Corrupt {
        file: name.to_string(),
        reason: e.to_string(),
    };
    let reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| corrupt(&e))?;
    match reader.format() {
        Some(ImageFormat::Jpeg | ImageFormat::Png | ImageFormat::Tiff) => {}
        _ => {
            return Err(BracketError::UnsupportedFormat {
                file: name.to_string(),
            })
        }
    }
    if reader.format() == Some(ImageFormat::Jpeg) {
        check_jpeg_complete(bytes).map_err(|reason| BracketError::Corrupt {
            file: name.to_string(),
            reason: reason.to_string(),
        })?;
    }
    let mut decoder = reader.into_decoder().map_err(|e| corrupt(&e))?;
    let (w, h) = decoder.dimensions();
    let pixels = u64::from(w) * u64::from(h);
    if pixels > opts.max_pixels {
        return Err(BracketError::TooLarge {
            file: name.to_string(),
            width: w.into(),
            height: h.into(),
            pixels,
            limit: opts.max_pixels,
        });
    }
    if w < 2 || h < 2 {
        return Err(BracketError::TooSmall {
            file: name.to_string(),
            width: w as usize,
            height: h as usize,
        });
    }
    let mut limits = image::Limits::default();
    // Room for the decoded image as 16-bit RGBA plus the decoder's own buffers.
    limits.max_alloc = Some(pixels.saturating_mul(8).saturating_add(64 << 20));
    decoder.set_limits(limits).map_err(|e| corrupt(&e))?;
    let icc = decoder.icc_profile().ok().flatten();
    let sixteen = matches!(
        decoder.color_type(),
        image::ColorType::L16
            | image::ColorType::La16
            | image::ColorType::Rgb16
            | image::ColorType::Rgba16
            | image::ColorType::Rgb32F
            | image::ColorType::Rgba32F
    );
    let img = image::DynamicImage::from_decoder(decoder).map_err(|e| corrupt(&e))?;
    let pixels = if sixteen {
        Pixels::U16(img.into_rgb16().into_raw())
    } else {
        Pixels::U8(img.into_rgb8().into_raw())
    };
    let mut frame = DecodedFrame {
        name: name.to_string(),
        width: w as usize,
        height: h as usize,
        pixels,
        exif_time_s: None,
        iso: None,
        f_number: None,
        info: CaptureInfo {
            orientation: 1,
            ..CaptureInfo::default()
        },
        non_srgb_icc: icc.as_deref().and_then(non_srgb_description),
    };
    read_exif(bytes, &mut frame);
    Ok(frame)
}

/// A file's EXIF exposure and capture metadata, read without decoding its pixels (what a batch
/// needs to group a folder of frames into captures).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FileMetadata {
    /// Exposure time in seconds, when EXIF has a valid one.
    pub exposure_time_s: Option<f64>,
    /// Capture metadata (time, offset, GPS, camera).
    pub info: CaptureInfo,
}

impl FileMetadata {
    /// The capture's local clock reading with its fraction of a second
    /// (`DateTimeOriginal` + `SubSecTimeOriginal`), when EXIF has the time.
    pub fn local_time(&self) -> Option<time::PrimitiveDateTime> {
        let t = parse_exif_datetime(self.info.datetime_original.as_deref()?)?;
        let frac = self
            .info
            .subsec_original
            .as_deref()
            .map(str::trim)
            .filter(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|s| format!("0.{s}").parse::<f64>().ok())
            .unwrap_or(0.0);
        Some(t + time::Duration::seconds_f64(frac))
    }
}

/// Reads a file's EXIF (JPEG, PNG, TIFF bytes) without decoding its pixels. A file without
/// readable EXIF gives empty metadata.
pub fn read_metadata(bytes: &[u8]) -> FileMetadata {
    let mut frame = DecodedFrame {
        name: String::new(),
        width: 0,
        height: 0,
        pixels: Pixels::U8(Vec::new()),
        exif_time_s: None,
        iso: None,
        f_number: None,
        info: CaptureInfo {
            orientation: 1,
            ..CaptureInfo::default()
        },
        non_srgb_icc: None,
    };
    read_exif(bytes, &mut frame);
    FileMetadata {
        exposure_time_s: frame.exif_time_s,
        info: frame.info,
    }
}

/// Fills exposure and capture metadata from the file's EXIF, when it has any.
/// Checks that a JPEG stream is whole: every marker segment fits in the file and the scans end
/// with the end-of-image marker.
///
/// Written by hand because the decoders do not say so: `image`'s JPEG decoder (zune-jpeg) fills
/// the rows missing from a truncated file with grey and returns `Ok`, which would merge the
/// missing part of a frame as if it were picture. Bytes after the end-of-image marker (some
/// phones append data there) are allowed.
pub fn check_jpeg_complete(bytes: &[u8]) -> Result<(), &'static str> {
    const TRUNCATED: &str = "truncated JPEG (the file ends before its end-of-image marker)";
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return Err("not a JPEG stream (no start-of-image marker)");
    }
    let mut i = 2;
    loop {
        // Markers may be preceded by any number of 0xFF fill bytes.
        if bytes.get(i) != Some(&0xFF) {
            return Err(match i < bytes.len() {
                true => "corrupt JPEG (a marker was expected)",
                false => TRUNCATED,
            });
        }
        while bytes.get(i) == Some(&0xFF) {
            i += 1;
        }
        let Some(&marker) = bytes.get(i) else {
            return Err(TRUNCATED);
        };
        i += 1;
        match marker {
            0xD9 => return Ok(()),
            // Stand-alone markers: restart markers, TEM, a stray SOI.
            0xD0..=0xD8 | 0x01 => continue,
            _ => {}
        }
        let len = match bytes.get(i..i + 2) {
            Some(l) => usize::from(u16::from_be_bytes([l[0], l[1]])),
            None => return Err(TRUNCATED),
        };
        if len < 2 {
            return Err("corrupt JPEG (a marker segment has a length below 2)");
        }
        i += len;
        if i > bytes.len() {
            return Err(TRUNCATED);
        }
        if marker == 0xDA {
            // Entropy-coded data runs to the next marker that is not a stuffed 0xFF00 or a
            // restart marker.
            loop {
                match bytes.get(i..i + 2) {
                    None => return Err(TRUNCATED),
                    Some([0xFF, m]) if *m != 0x00 && !(0xD0..=0xD7).contains(m) && *m != 0xFF => {
                        break
                    }
                    _ => i += 1,
                }
            }
        }
    }
}

fn read_exif(bytes: &[u8], frame: &mut DecodedFrame) {
    use exif::{In, Tag, Value};
    let Ok(ex) = exif::Reader::new().read_from_container(&mut Cursor::new(bytes)) else {
        return;
    };
    let get = |tag| ex.get_field(tag, In::PRIMARY).map(|f| &f.value);
    let num = |tag| -> Option<f64> {
        let v = match get(tag)? {
            Value::Rational(r) => r.first().map(|r| r.to_f64()),
            Value::SRational(r) => r.first().map(|r| r.to_f64()),
            Value::Short(s) => s.first().map(|&s| f64::from(s)),
            Value::Long(s) => s.first().map(|&s| f64::from(s)),
            _ => None,
        }?;
        (v.is_finite() && v > 0.0).then_some(v)
    };
    let text = |tag| -> Option<String> {
        match get(tag)? {
            Value::Ascii(v) => v
                .first()
                .map(|s| {
                    String::from_utf8_lossy(s)
                        .trim_end_matches('\0')
                        .trim()
                        .to_string()
                })
                .filter(|s| !s.is_empty()),
            _ => None,
        }
    };
    let dms = |tag, reftag| -> Option<f64> {
        let Value::Rational(r) = get(tag)? else {
            return None;
        };
        if r.len() < 3 {
            return None;
        }
        let v = r[0].to_f64() + r[1].to_f64() / 60.0 + r[2].to_f64() / 3600.0;
        let sign = match text(reftag).as_deref() {
            Some("S") | Some("W") => -1.0,
            _ => 1.0,
        };
        v.is_finite().then_some(sign * v)
    };
    frame.exif_time_s = num(Tag::ExposureTime).filter(|&t| t <= 86_400.0);
    frame.f_number = num(Tag::FNumber);
    frame.iso = num(Tag::PhotographicSensitivity);
    let info = &mut frame.info;
    info.make = text(Tag::Make);
    info.model = text(Tag::Model);
    info.datetime_original = text(Tag::DateTimeOriginal);
    info.utc_offset = text(Tag::OffsetTimeOriginal).or_else(|| text(Tag::OffsetTime));
    info.subsec_original = text(Tag::SubSecTimeOriginal);
    info.gps_latitude_deg = dms(Tag::GPSLatitude, Tag::GPSLatitudeRef);
    info.gps_longitude_deg = dms(Tag::GPSLongitude, Tag::GPSLongitudeRef);
    info.white_balance = get(Tag::WhiteBalance).and_then(|v| v.get_uint(0));
    info.orientation = get(Tag::Orientation)
        .and_then(|v| v.get_uint(0))
        .and_then(|o| u16::try_from(o).ok())
        .filter(|o| (1..=8).contains(o))
        .unwrap_or(1);
}

/// The description of an ICC profile when it is not an sRGB profile, `None` for sRGB.
///
/// Written by hand because only the profile's description tag is needed: a full colour-management
/// crate (lcms2, qcms) would pull C code or a large dependency into the wasm build for one string.
fn non_srgb_description(icc: &[u8]) -> Option<String> {
    let desc = icc_description(icc).unwrap_or_else(|| "unnamed ICC profile".to_string());
    let lower = desc.to_ascii_lowercase();
    (!(lower.contains("srgb") || lower.contains("iec61966-2"))).then_some(desc)
}

/// Reads the `desc` tag of an ICC profile (v2 `desc` ASCII or v4 `mluc` UTF-16BE).
fn icc_description(icc: &[u8]) -> Option<String> {
    let be32 = |o: usize| -> Option<usize> {
        icc.get(o..o + 4)
            .map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let count = be32(128)?;
    for i in 0..count.min(1024) {
        let e = 132 + 12 * i;
        if icc.get(e..e + 4)? != b"desc" {
            continue;
        }
        let (off, size) = (be32(e + 4)?, be32(e + 8)?);
        let tag = icc.get(off..off.checked_add(size)?)?;
        return match tag.get(0..4)? {
            b"desc" => {
                let n = u32::from_be_bytes(tag.get(8..12)?.try_into().ok()?) as usize;
                let s = tag.get(12..12 + n.min(tag.len().saturating_sub(12)))?;
                Some(
                    String::from_utf8_lossy(s)
                        .trim_end_matches('\0')
                        .to_string(),
                )
            }
            b"mluc" => {
                let len = u32::from_be_bytes(tag.get(20..24)?.try_into().ok()?) as usize;
                let off = u32::from_be_bytes(tag.get(24..28)?.try_into().ok()?) as usize;
                let s = tag.get(off..off.checked_add(len)?)?;
                let units: Vec<u16> = s
                    .chunks_exact(2)
                    .map(|c| u16::from_be_bytes([c[0], c[1]]))
                    .collect();
                Some(String::from_utf16_lossy(&units))
            }
            _ => None,
        };
    }
    None
}

/// Validates decoded frames and turns them into a sorted [`Bracket`].
///
/// `times`, when given, are exposure times in seconds in the order of `decoded` and override
/// EXIF; otherwise every frame needs an EXIF `ExposureTime`.
pub fn assemble(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
) -> Result<Bracket, BracketError> {
    if decoded.len() < 2 {
        return Err(BracketError::TooFewFrames(decoded.len()));
    }
    if let Some(t) = times {
        if t.len() != decoded.len() {
            return Err(BracketError::TimesCount {
                given: t.len(),
                frames: decoded.len(),
            });
        }
        for &v in t {
            if !(v.is_finite() && v > 0.0) {
                return Err(BracketError::BadTime {
                    file: "exposure times".into(),
                    value: v.to_string(),
                });
            }
        }
    }
    let first = &decoded[0];
    for d in &decoded[1..] {
        if (d.width, d.height) != (first.width, first.height) {
            return Err(BracketError::SizeMismatch {
                file: d.name.clone(),
                w: d.width,
                h: d.height,
                first: first.name.clone(),
                w0: first.width,
                h0: first.height,
            });
        }
        if d.pixels.bit_depth() != first.pixels.bit_depth() {
            return Err(BracketError::DepthMismatch {
                file: d.name.clone(),
                bits: d.pixels.bit_depth(),
                first: first.name.clone(),
                bits0: first.pixels.bit_depth(),
            });
        }
        if orientation == OrientationPolicy::Apply && d.info.orientation != first.info.orientation {
            return Err(BracketError::OrientationMismatch {
                file: d.name.clone(),
                o: d.info.orientation,
                first: first.name.clone(),
                o0: first.info.orientation,
            });
        }
    }

    let mut warnings = Vec::new();
    differing(&decoded, "ISO", |d| d.iso, &mut warnings);
    differing(
        &decoded,
        "aperture (f-number)",
        |d| d.f_number,
        &mut warnings,
    );
    differing(
        &decoded,
        "white balance mode",
        |d| d.info.white_balance.map(f64::from),
        &mut warnings,
    );
    if let Some(p) = decoded.iter().find_map(|d| d.non_srgb_icc.as_ref()) {
        warnings.push(format!(
            "embedded ICC profile '{p}' is not sRGB: pixel values are not sRGB (the response calibration absorbs the tone curve, but colours stay in that profile's primaries)"
        ));
    }

    let mut frames = Vec::with_capacity(decoded.len());
    let mut infos = Vec::with_capacity(decoded.len());
    for (i, d) in decoded.into_iter().enumerate() {
        let time_s = match times {
            Some(t) => t[i],
            None => d.exif_time_s.ok_or_else(|| BracketError::MissingExposure {
                file: d.name.clone(),
            })?,
        };
        let exposure = Exposure {
            time_s,
            iso: d.iso,
            f_number: d.f_number,
        };
        let (width, height, pixels) = match orientation {
            OrientationPolicy::Apply if d.info.orientation != 1 => {
                orient(d.width, d.height, d.pixels, d.info.orientation)
            }
            _ => (d.width, d.height, d.pixels),
        };
        infos.push(d.info);
        frames.push(Frame {
            name: d.name,
            width,
            height,
            pixels,
            exposure,
        });
    }
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by(|&a, &b| {
        frames[a]
            .exposure
            .relative()
            .total_cmp(&frames[b].exposure.relative())
    });
    let mut slots: Vec<Option<Frame>> = frames.into_iter().map(Some).collect();
    let frames: Vec<Frame> = order.iter().filter_map(|&i| slots[i].take()).collect();
    let info = infos[order[order.len() / 2]].clone();

    for pair in frames.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let stops = (b.exposure.relative() / a.exposure.relative()).log2();
        if stops < 1.0 / 6.0 {
            return Err(BracketError::DuplicateExposure {
                file: b.name.clone(),
                e1: describe(&b.exposure),
                other: a.name.clone(),
                e2: describe(&a.exposure),
            });
        }
    }
    // Only informative values judge the frames: neither at the bracket's black level nor
    // clipped. A frame with (almost) none — all black level or all white — adds nothing and is
    // left out with a warning, as long as two frames remain.
    let floor = black_floor(&frames);
    let total = frames.len();
    // Every frame's informative samples and every neighbouring pair's comparison in one go (in
    // parallel with the `parallel` feature): each is a pass over frames too big for the cache,
    // so they are run side by side rather than one after another. The pairs are compared again
    // only when a frame is left out (rare), which makes new neighbours.
    let compare_all = |frames: &[Frame]| -> Vec<PairCheck> {
        let pairs: Vec<(&Frame, &Frame)> = frames.windows(2).map(|p| (&p[0], &p[1])).collect();
        #[cfg(feature = "parallel")]
        let checks = pairs
            .par_iter()
            .map(|&(a, b)| compare_pair(a, b, floor))
            .collect();
        #[cfg(not(feature = "parallel"))]
        let checks = pairs
            .iter()
            .map(|&(a, b)| compare_pair(a, b, floor))
            .collect();
        checks
    };
    let count_all = |frames: &[Frame]| -> Vec<usize> {
        #[cfg(feature = "parallel")]
        let counts = frames
            .par_iter()
            .map(|f| informative_count(f, floor))
            .collect();
        #[cfg(not(feature = "parallel"))]
        let counts = frames.iter().map(|f| informative_count(f, floor)).collect();
        counts
    };
    #[cfg(feature = "parallel")]
    let (counts, checks) = rayon::join(|| count_all(&frames), || compare_all(&frames));
    #[cfg(not(feature = "parallel"))]
    let (counts, checks) = (count_all(&frames), compare_all(&frames));
    let mut kept = Vec::with_capacity(total);
    for (f, count) in frames.into_iter().zip(counts) {
        if count < informative_needed(&f) {
            warnings.push(format!(
                "{}: almost every pixel is at the black level or clipped, so the frame adds nothing to the bracket; it was left out",
                f.name
            ));
        } else {
            kept.push(f);
        }
    }
    if kept.len() < 2 {
        return Err(BracketError::TooFewFrames(kept.len()));
    }
    let frames = kept;
    let checks = match frames.len() == total {
        true => checks,
        false => compare_all(&frames),
    };
    for (pair, check) in frames.windows(2).zip(&checks) {
        let (a, b) = (&pair[0], &pair[1]);
        if check.identical {
            return Err(BracketError::IdenticalPixels {
                file: b.name.clone(),
                other: a.name.clone(),
                stops: (b.exposure.relative() / a.exposure.relative()).log2(),
            });
        }
    }
    for (pair, check) in frames.windows(2).zip(&checks) {
        let (a, b) = (&pair[0], &pair[1]);
        if check.darker_when_longer {
            return Err(BracketError::DarkerWhenLonger {
                file: b.name.clone(),
                e1: describe(&b.exposure),
                other: a.name.clone(),
                e2: describe(&a.exposure),
            });
        }
    }
    let pixel_orientation = match orientation {
        OrientationPolicy::Apply => 1,
        OrientationPolicy::Ignore => info.orientation,
    };
    Ok(Bracket {
        frames,
        info,
        warnings,
        pixel_orientation,
    })
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
    let well = |p: &Pixels| -> usize {
        match p {
            Pixels::U8(v) => v
                .iter()
                .step_by(7)
                .filter(|&&z| (20..=235).contains(&z))
                .count(),
            Pixels::U16(v) => v
                .iter()
                .step_by(7)
                .filter(|&&z| (20..=235).contains(&bin16(z)))
                .count(),
        }
    };
    frames.iter().max_by_key(|f| well(&f.pixels))
}

fn describe(e: &Exposure) -> String {
    let t = if e.time_s < 1.0 {
        format!("1/{:.0} s", 1.0 / e.time_s)
    } else {
        format!("{} s", e.time_s)
    };
    let mut s = t;
    if let Some(iso) = e.iso {
        s += &format!(" ISO {iso}");
    }
    if let Some(n) = e.f_number {
        s += &format!(" f/{n}");
    }
    s
}

fn differing(
    decoded: &[DecodedFrame],
    what: &str,
    key: impl Fn(&DecodedFrame) -> Option<f64>,
    warnings: &mut Vec<String>,
) {
    let vals: Vec<(String, f64)> = decoded
        .iter()
        .filter_map(|d| key(d).map(|v| (d.name.clone(), v)))
        .collect();
    if let Some((n0, v0)) = vals.first() {
        if let Some((n, v)) = vals.iter().find(|(_, v)| (v - v0).abs() > 1e-9 * v0.abs()) {
            warnings.push(format!(
                "{what} differs between frames ({n0}: {v0}, {n}: {v}); exposure accounts for it as t·ISO/N², but check the bracket was shot as intended"
            ));
        }
    }
}

/// Values (full scale 1) at most this far above the bracket's black level count as black.
const BLACK_MARGIN: f32 = 0.03;
/// Values above this count as clipped.
const CLIP_UNIT: f32 = 0.98;

/// The bracket's black level on the unit scale: the 0.5th percentile of every 21st sample of
/// every frame. 0 for most photos (a black housing or shadows); ≈ 16/255 for a film scan or a
/// camera that lifts its blacks, where "black" pixels are not 0.
fn black_floor(frames: &[Frame]) -> f32 {
    // The same percentile from a histogram of the codes (one pass, no copy or selection of
    // millions of samples): frames of one bit depth, as a bracket's are.
    fn by_histogram<T: Copy + Into<usize>>(
        frames: &[Frame],
        codes: impl Fn(&Pixels) -> Option<&[T]>,
        bins: usize,
        full: f32,
    ) -> Option<f32> {
        let mut hist = vec![0usize; bins];
        let mut len = 0usize;
        for f in frames {
            for &c in codes(&f.pixels)?.iter().step_by(21) {
                hist[c.into()] += 1;
                len += 1;
            }
        }
        if len == 0 {
            return Some(0.0);
        }
        let k = len / 200;
        let mut seen = 0usize;
        let code = hist.iter().position(|&n| {
            seen += n;
            seen > k
        })?;
        Some(code as f32 / full)
    }
    fn u8s(p: &Pixels) -> Option<&[u8]> {
        match p {
            Pixels::U8(v) => Some(v),
            Pixels::U16(_) => None,
        }
    }
    fn u16s(p: &Pixels) -> Option<&[u16]> {
        match p {
            Pixels::U16(v) => Some(v),
            Pixels::U8(_) => None,
        }
    }
    if let Some(v) = by_histogram(frames, u8s, 1 << 8, 255.0)
        .or_else(|| by_histogram(frames, u16s, 1 << 16, 65535.0))
    {
        return v;
    }
    let mut v: Vec<f32> = frames
        .iter()
        .flat_map(|f| (0..f.pixels.len()).step_by(21).map(|i| f.pixels.unit(i)))
        .collect();
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 200;
    v.select_nth_unstable_by(k, f32::total_cmp);
    v[k]
}

/// Whether a unit value informs: above the black level by a margin and below clipping.
#[inline]
fn informative(v: f32, floor: f32) -> bool {
    v > floor + BLACK_MARGIN && v < CLIP_UNIT
}

/// Informative values among every 21st sample of a frame.
fn informative_count(f: &Frame, floor: f32) -> usize {
    (0..f.pixels.len())
        .step_by(21)
        .filter(|&i| informative(f.pixels.unit(i), floor))
        .count()
}

/// A frame with fewer informative samples (of every 21st) than this adds nothing: 0.05 % of
/// them, and at least 10; a frame too small to judge (under 100 such samples) needs none.
fn informative_needed(f: &Frame) -> usize {
    let sampled = f.pixels.len().div_ceil(21);
    if sampled < 100 {
        0
    } else {
        sampled / 2000 + 10
    }
}

/// What comparing two neighbouring frames of a bracket (`a` exposed shorter than `b`) found.
struct PairCheck {
    /// The two frames carry (nearly) the same picture: over the values informative in both
    /// (neither at the black level nor clipped), the mean brightness differs by less than 2 %
    /// and the mean absolute difference is below 1.5 % of full scale. Frames that genuinely
    /// differ by ≥ 1/6 stop differ by ≥ 12 % in linear terms, which even a strong tone curve
    /// does not squeeze below 2 %. Judging only informative values matters: a mostly black frame
    /// (a film scan's black level, a short exposure at night) is identical to its neighbour
    /// *where both are black*, which says nothing about the exposure.
    identical: bool,
    /// `b`, exposed longer, is clearly darker at most samples where the two differ clearly (by
    /// more than 3 % of the code range): a code never falls as exposure grows, so the times
    /// must belong to other photos. Noise, JPEG and a little motion make a few samples darker
    /// in any real bracket; a majority needs swapped times.
    darker_when_longer: bool,
}

/// Compares two frames on the samples of every 7th pixel, in one pass over both.
fn compare_pair(a: &Frame, b: &Frame, floor: f32) -> PairCheck {
    let n = a.pixels.len().min(b.pixels.len());
    let (mut sa, mut sb, mut sad, mut count) = (0f64, 0f64, 0f64, 0usize);
    let (mut darker, mut brighter) = (0usize, 0usize);
    let mut i = 0;
    while i + 2 < n {
        for c in 0..3 {
            let (va, vb) = (a.pixels.unit(i + c), b.pixels.unit(i + c));
            let d = vb - va;
            if d < -0.03 {
                darker += 1;
            } else if d > 0.03 {
                brighter += 1;
            }
            if informative(va, floor) && informative(vb, floor) {
                sa += f64::from(va);
                sb += f64::from(vb);
                sad += f64::from((va - vb).abs());
                count += 1;
            }
        }
        i += 21;
    }
    // Too few usable samples (frames almost all black or white): nothing to compare.
    let identical = count >= n / 21 / 100 + 10 && {
        let (ma, mb) = (sa / count as f64, sb / count as f64);
        (ma - mb).abs() < 0.02 * ma.max(mb) && sad / (count as f64) < 0.015
    };
    PairCheck {
        identical,
        darker_when_longer: darker >= 100 && darker > brighter,
    }
}

/// Applies EXIF orientation `o` (2..=8) to interleaved RGB samples.
fn orient(w: usize, h: usize, pixels: Pixels, o: u16) -> (usize, usize, Pixels) {
    fn go<T: Copy + Default>(w: usize, h: usize, src: &[T], o: u16) -> (usize, usize, Vec<T>) {
        let swap = o >= 5;
        let (ow, oh) = if swap { (h, w) } else { (w, h) };
        let mut dst = vec![T::default(); src.len()];
        for y in 0..h {
            for x in 0..w {
                // Destination of stored pixel (x, y) for each EXIF orientation (CIPA DC-008).
                let (dx, dy) = match o {
                    2 => (w - 1 - x, y),
                    3 => (w - 1 - x, h - 1 - y),
                    4 => (x, h - 1 - y),
                    5 => (y, x),
                    6 => (h - 1 - y, x),
                    7 => (h - 1 - y, w - 1 - x),
                    8 => (y, w - 1 - x),
                    _ => (x, y),
                };
                let s = 3 * (y * w + x);
                let d = 3 * (dy * ow + dx);
                dst[d..d + 3].copy_from_slice(&src[s..s + 3]);
            }
        }
        (ow, oh, dst)
    }
    match pixels {
        Pixels::U8(v) => {
            let (ow, oh, d) = go(w, h, &v, o);
            (ow, oh, Pixels::U8(d))
        }
        Pixels::U16(v) => {
            let (ow, oh, d) = go(w, h, &v, o);
            (ow, oh, Pixels::U16(d))
        }
    }
}

#[cfg(test)]
mod tests {
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
        assert_eq!(e, BracketError::TooFewFrames(1));
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
