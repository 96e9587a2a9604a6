//! Radiance RGBE (`.hdr`, `.pic`) reader and writer.
//!
//! # The format
//!
//! A Radiance picture is an ASCII header, a blank line, a resolution line and binary scanlines
//! ([Ward, "Real Pixels", Graphics Gems II, 1991]; Radiance `color.c`, `header.c`, `resolu.c`).
//!
//! ```text
//! #?RADIANCE                      magic line (OpenCV writes `#?RGBE`; any `#?…` is accepted)
//! FORMAT=32-bit_rle_rgbe
//! SOFTWARE=skydome 0.1.0
//! EXPOSURE=0.5                    stored pixel = radiance × exposure; several lines multiply
//! CAPDATE=2024:06:21 12:00:00     local capture time
//! GMT=2024:06:21 10:00:00         capture time in UTC
//! VIEW= -vta -vh 180 -vv 180      Radiance view of a projected dome
//! #SUN=-Y 120.5 +X 300.25         skydome: the sun's centre (see below)
//! #SUN_DIRECTION= azimuth 123.45 elevation 34.56 (degrees, azimuth from north towards east)
//! #NORTH=-Y 10.5 +X 512.5         skydome: the north point on the horizon circle
//! …any other lines (HdrMeta::other), verbatim
//!                                 blank line ends the header
//! -Y 1024 +X 1024                 H scanlines from the top, each W pixels from the left
//! <scanlines>
//! ```
//!
//! Each pixel is four bytes `(r, g, b, e)`: three 8-bit mantissas sharing one exponent.
//!
//! **Scanline encodings.** *Flat*: `W` raw pixels. *Old-style RLE* (before 1991): a pixel
//! `(1, 1, 1, n)` repeats the previous pixel `n << s` times, where `s` grows by 8 for each
//! consecutive repeat marker. *New-style RLE*: for `8 ≤ W ≤ 32767` a scanline may start with
//! `(2, 2, W >> 8, W & 255)`, followed by the four components one after the other, each as
//! packets `128 + n, v` (a run of `n ≤ 127` copies of `v`) or `n, v₁…vₙ` (`n ≤ 128` literal
//! bytes). The reader accepts all three (per scanline, like Radiance's `freadcolrs`); the writer
//! emits new-style RLE with runs of at least 4 for `8 ≤ W ≤ 32767` and flat scanlines otherwise,
//! which is what every reader (Radiance, OpenCV, stb_image, OpenImageIO, `image`) expects.
//!
//! **Orientation.** The resolution line names the scanline axis first. The standard
//! `-Y H +X W` (rows top to bottom, pixels left to right) is what everybody writes; the reader
//! also transforms the seven other orientations (`+Y H +X W`, `-Y H -X W`, `+X W -Y H`, …) into
//! the crate's top-left-origin convention, so callers always get an upright image.
//!
//! # Conversion between floats and RGBE
//!
//! Writing a triple `(r, g, b)`:
//! 1. sanitise each channel: NaN and negative values become 0, `+∞` and anything above
//!    [`RGBE_MAX`] (= 255 · 2¹¹⁹ ≈ 1.69·10³⁸) becomes [`RGBE_MAX`];
//! 2. let `m = max(r, g, b)`; if `m <` [`RGBE_MIN`] (= 2⁻¹²⁸ ≈ 2.9·10⁻³⁹) the pixel is
//!    `(0, 0, 0, 0)` — below that the shared exponent byte cannot keep the error bound;
//! 3. `m = f · 2ᵉ` with `f ∈ [0.5, 1)` (`frexp`); the exponent byte is `e + 128`;
//! 4. each mantissa is `min(255, round(c · 2⁸⁻ᵉ))` — **round to nearest** (ties to even),
//!    not truncation.
//!
//! Reading: `c = mantissa · 2^(E − 136)` for exponent byte `E ≠ 0`, and 0 for `E = 0`.
//!
//! **Why this pair, and the error bound.** Radiance itself truncates on writing and decodes at
//! the bin centre (`mantissa + 0.5`); every other reader in use (OpenCV, stb_image, Bruce Walter's
//! `rgbe.c` inside OpenImageIO, the `image` crate) decodes at `mantissa` with no offset. A
//! truncating writer read by those tools is biased low by half a step on average (the `image`
//! crate's own encoder truncates: errors up to 1/128). Rounding to nearest makes our files
//! unbiased in all those readers, and our decoder agrees bit for bit with them. The bound:
//! the step is `2ᵉ⁻⁸` and `m ≥ 2ᵉ⁻¹ = 128` steps, so a rounded channel is off by at most
//! half a step `≤ m / 256`. When `m` rounds up to 256 steps the mantissa is clamped to 255
//! instead of bumping the exponent; then `m ∈ [255.5, 256)` steps and the error
//! `m − 255` steps is still `< m / 256`. Hence for every channel
//! `|decoded − c| ≤ max(r, g, b) / 256` (proved by a property test over 10⁻³⁰…10³⁰ and zeros).
//!
//! Worked example: `(0.3, 0.15, 0.0)`: `m = 0.3 = 0.6 · 2⁻¹`, so `e = −1`, byte 127, scale
//! `2⁹ = 512`: mantissas `round(153.6) = 154`, `round(76.8) = 77`, `0` → `(154, 77, 0, 127)`,
//! which decodes to `(0.30078, 0.15039, 0.0)`: errors 7.8·10⁻⁴ and 3.9·10⁻⁴, both below
//! `0.3 / 256 = 1.17·10⁻³`. Truncation would have given `(153, 76, 0)`, 2.6 times the error.
//!
//! # skydome's header lines
//!
//! `#SUN=-Y y +X x` and `#NORTH=-Y y +X x` hold a [`PixelPoint`] **unchanged**: continuous pixel
//! coordinates with the origin at the top-left *corner* of the image and pixel centres at
//! `+0.5`, so the centre of pixel column 10, row 20 is written `-Y 20.5 +X 10.5` (tools that
//! want integer indices take the floor). The sun's direction goes on its own comment line
//! `#SUN_DIRECTION= azimuth A elevation E (degrees, azimuth from north towards east)` (either
//! part may be missing). Numbers are written in Rust's shortest round-trip form, so reading back
//! what [`write_rgbe`] wrote gives exactly the same [`HdrMeta`].
//!
//! # Why our own encoder
//!
//! The `image` crate's `HdrEncoder` writes a fixed header (no `EXPOSURE`, `CAPDATE`, `#SUN` …),
//! truncates mantissas, and took 210–270 ms for a 6 MP image on this project's machines; this
//! encoder rounds, writes the full header and converts and compresses row bands in parallel
//! (see the `formats` benchmark for the ratio measured in the same run).
//!
//! # Hostile files
//!
//! [`Limits`] caps the pixel count and the header size; the reader never allocates more than the
//! file actually decodes to (it grows buffers as data arrives), reads at most the number of bytes
//! the worst-case encoding of the announced size needs, and reports truncation and corrupt runs
//! as errors, never panics.
//!
//! [Ward, "Real Pixels", Graphics Gems II, 1991]: https://www.graphicsgems.org/
//! [`PixelPoint`]: super::PixelPoint

use std::io::{BufRead, Read, Write};

use super::{HdrMeta, PixelPoint, SunMark};
use crate::image::HdrImage;

#[cfg(feature = "parallel")]
use rayon::prelude::*;

/// Largest value an RGBE pixel holds: mantissa 255 with exponent byte 255, i.e. `255 · 2¹¹⁹`
/// (≈ 1.69·10³⁸). Larger inputs and `+∞` are written as this value.
pub const RGBE_MAX: f32 = f32::from_bits((119 + 127) << 23) * 255.0;

/// Smallest largest-channel value that is stored (2⁻¹²⁸ ≈ 2.9·10⁻³⁹); pixels whose largest
/// channel is below it are written as black.
pub const RGBE_MIN: f32 = f32::from_bits(1 << 21);

/// Errors reading or writing Radiance `.hdr` files.
#[derive(Debug, thiserror::Error)]
pub enum RgbeError {
    /// The underlying reader or writer failed.
    #[error("could not read or write the .hdr data: {0}")]
    Io(#[from] std::io::Error),
    /// The file does not start with a `#?` magic line.
    #[error("not a Radiance .hdr file (it must start with `#?RADIANCE` or `#?RGBE`); check the file type")]
    NotRadiance,
    /// The header ended before the blank line and resolution line.
    #[error("the .hdr file ends inside its header; the file is truncated")]
    TruncatedHeader,
    /// The header is longer than [`Limits::max_header_bytes`].
    #[error("the .hdr header is longer than {0} bytes; the file is probably not a Radiance picture (raise Limits::max_header_bytes if it is)")]
    HeaderTooLong(usize),
    /// `FORMAT=` names something other than RGBE.
    #[error("unsupported pixel format `FORMAT={0}`; only 32-bit_rle_rgbe is supported (convert XYZE pictures with Radiance's `ra_xyze -r`)")]
    UnsupportedFormat(String),
    /// The resolution line could not be parsed.
    #[error("cannot parse the resolution line `{0}`; expected e.g. `-Y <height> +X <width>`")]
    BadResolution(String),
    /// The announced size exceeds [`Limits::max_pixels`].
    #[error("the image is {width}×{height} pixels, more than the limit of {max} pixels; raise Limits::max_pixels if the file is trusted")]
    TooLarge {
        /// Announced width in pixels.
        width: usize,
        /// Announced height in pixels.
        height: usize,
        /// The limit in pixels.
        max: u64,
    },
    /// The pixel data ended early.
    #[error("the pixel data ends in scanline {scanline} of {scanlines}; the file is truncated")]
    Truncated {
        /// Zero-based scanline where the data ran out.
        scanline: usize,
        /// Number of scanlines announced.
        scanlines: usize,
    },
    /// A scanline's run-length data is inconsistent.
    #[error("scanline {scanline} is corrupt: {reason}; the file is damaged")]
    Corrupt {
        /// Zero-based scanline.
        scanline: usize,
        /// What is wrong.
        reason: &'static str,
    },
    /// The image to write is inconsistent.
    #[error("cannot write this image as .hdr: {0}")]
    BadImage(String),
    /// The metadata to write cannot be represented or would not read back the same.
    #[error("cannot write this metadata into a .hdr header: {0}")]
    BadMeta(String),
}

/// Decoding limits against hostile or damaged files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest accepted `width × height` (default 100 000 000, i.e. 1.2 GB of `f32` RGB).
    pub max_pixels: u64,
    /// Largest accepted header, in bytes, up to the resolution line (default 1 MiB).
    pub max_header_bytes: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_pixels: 100_000_000,
            max_header_bytes: 1 << 20,
        }
    }
}

/// How the scanlines of a file are laid out, as given by its resolution line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Orientation {
    /// True when scanlines run along X (`±Y H ±X W`), false when transposed (`±X W ±Y H`).
    pub rows_are_scanlines: bool,
    /// True when successive scanlines go towards −Y (`-Y`, top to bottom) or −X.
    pub slow_decreasing: bool,
    /// True when pixels within a scanline go towards −X or −Y.
    pub fast_decreasing: bool,
}

impl Orientation {
    /// The standard `-Y H +X W`: rows top to bottom, pixels left to right.
    pub const STANDARD: Orientation = Orientation {
        rows_are_scanlines: true,
        slow_decreasing: true,
        fast_decreasing: false,
    };
}

/// A parsed `.hdr` header.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbeHeader {
    /// Metadata recovered from the header lines.
    pub meta: HdrMeta,
    /// Every header line as found (magic line first, without line ends, without the blank line).
    pub lines: Vec<String>,
    /// The resolution line as found (e.g. `-Y 512 +X 768`).
    pub resolution: String,
    /// Image width in pixels (after orientation is applied).
    pub width: usize,
    /// Image height in pixels (after orientation is applied).
    pub height: usize,
    /// The file's scanline layout.
    pub orientation: Orientation,
}

/// A decoded `.hdr` file.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbeFile {
    /// The pixels as stored (top-left origin); divide by `meta.exposure` for radiance.
    pub image: HdrImage,
    /// Header and metadata.
    pub header: RgbeHeader,
}

// ---------------------------------------------------------------------------------------------
// Pixel conversion

/// `2^(e − 136)` for every exponent byte `e` (0 for `e = 0`), exact in `f32` (subnormal below
/// `e = 10`), so decoding is one multiply per channel.
const EXP_TABLE: [f32; 256] = {
    let mut t = [0.0f32; 256];
    let mut e = 1;
    while e < 256 {
        let p = e as i32 - 136;
        t[e] = if p >= -126 {
            f32::from_bits(((p + 127) as u32) << 23)
        } else {
            f32::from_bits(1u32 << (p + 149))
        };
        e += 1;
    }
    t
};

/// Converts a linear RGB triple to RGBE with the rounding and clamping rules of the module doc
/// (relative error ≤ 1/256 of the largest channel; NaN/negative → 0; +∞ → [`RGBE_MAX`]).
#[inline]
pub fn float_to_rgbe(rgb: [f32; 3]) -> [u8; 4] {
    // Sanitising, the maximum and `frexp` work on the IEEE bit patterns (monotonic for
    // non-negative floats; `frexp`'s exponent is the exponent field), so there is no libm call
    // and every step is exact.
    #[inline(always)]
    fn sanitise(v: f32) -> u32 {
        let b = v.to_bits();
        // Keeps (0, +∞] (bit patterns 1..=0x7f80_0000); zero, negatives (sign bit, including
        // negative NaNs) and +NaN become 0. Written as a select so it compiles branch-free.
        let keep = b.wrapping_sub(1) < 0x7f80_0000;
        if keep {
            b.min(RGBE_MAX_BITS)
        } else {
            0
        }
    }
    let [r, g, b] = rgb.map(sanitise);
    let m = r.max(g).max(b);
    if m < RGBE_MIN_BITS {
        return [0; 4];
    }
    let e_field = m >> 23;
    if e_field < 7 {
        // The largest channel is below 2⁻¹²⁰, where 2^(8−e) overflows an f32: rare, use f64.
        return float_to_rgbe_f64([r, g, b].map(f32::from_bits));
    }
    // 2^(8−e) with e = e_field − 126; multiplying by a power of two is exact.
    let scale = f32::from_bits((261 - e_field) << 23);
    // Adding 2²³ rounds x ∈ [0, 256) to the nearest integer (ties to even) in a single
    // IEEE rounding and leaves that integer in the low significand bits.
    const MAGIC: f32 = 8_388_608.0;
    let q =
        |c: u32| ((f32::from_bits(c) * scale + MAGIC).to_bits() - MAGIC.to_bits()).min(255) as u8;
    // frexp exponent e = e_field − 126, stored as e + 128.
    [q(r), q(g), q(b), (e_field + 2) as u8]
}

/// The same conversion through `f64` (`frexp` from the f64 exponent field), which covers f32
/// subnormals; inputs must already be sanitised and their maximum ≥ [`RGBE_MIN`].
fn float_to_rgbe_f64([r, g, b]: [f32; 3]) -> [u8; 4] {
    let m = r.max(g).max(b);
    let e = ((f64::from(m).to_bits() >> 52) & 0x7ff) as i32 - 1022;
    let scale = f64::from_bits(((1023 + 8 - e) as u64) << 52);
    let q = |v: f32| ((f64::from(v) * scale).round_ties_even() as u32).min(255) as u8;
    [q(r), q(g), q(b), (e + 128) as u8]
}

const RGBE_MAX_BITS: u32 = RGBE_MAX.to_bits();
const RGBE_MIN_BITS: u32 = RGBE_MIN.to_bits();

/// Converts an RGBE pixel to linear RGB: `mantissa · 2^(e − 136)`, black for `e = 0`.
#[inline]
pub fn rgbe_to_float(p: [u8; 4]) -> [f32; 3] {
    let s = EXP_TABLE[p[3] as usize];
    [
        f32::from(p[0]) * s,
        f32::from(p[1]) * s,
        f32::from(p[2]) * s,
    ]
}

// ---------------------------------------------------------------------------------------------
// Writing

/// Encodes `image` with `meta` into a complete `.hdr` file in memory.
///
/// The pixels are written as given (they are the *stored* values: `meta.exposure` is recorded,
/// not applied). Everything is validated first, so an error never leaves partial output.
pub fn encode_rgbe(image: &HdrImage, meta: &HdrMeta) -> Result<Vec<u8>, RgbeError> {
    let header = header_text(image, meta)?;
    let bands = encode_bands(image);
    let total = header.len() + bands.iter().map(Vec::len).sum::<usize>();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(header.as_bytes());
    for b in &bands {
        out.extend_from_slice(b);
    }
    Ok(out)
}

/// Writes `image` with `meta` as a `.hdr` file to `w` (see [`encode_rgbe`]).
///
/// Nothing is written unless the image and metadata are valid; an I/O error can still leave a
/// partial file, which is why callers write to a temporary file and rename it.
pub fn write_rgbe<W: Write>(mut w: W, image: &HdrImage, meta: &HdrMeta) -> Result<(), RgbeError> {
    let header = header_text(image, meta)?;
    let bands = encode_bands(image);
    w.write_all(header.as_bytes())?;
    for b in &bands {
        w.write_all(b)?;
    }
    w.flush()?;
    Ok(())
}

fn validate_image(image: &HdrImage) -> Result<(), RgbeError> {
    if image.width == 0 || image.height == 0 {
        return Err(RgbeError::BadImage(format!(
            "it is empty ({}×{} pixels)",
            image.width, image.height
        )));
    }
    let expected = image
        .width
        .checked_mul(image.height)
        .and_then(|n| n.checked_mul(3));
    if expected != Some(image.data.len()) {
        return Err(RgbeError::BadImage(format!(
            "{}×{} pixels need {} samples but the buffer holds {}",
            image.width,
            image.height,
            3u128 * image.width as u128 * image.height as u128,
            image.data.len()
        )));
    }
    Ok(())
}

/// Shortest text that parses back to exactly `x`; plain decimals for everyday magnitudes.
pub(crate) use crate::image::fmt_num;

/// True for `YYYY:MM:DD HH:MM:SS`.
pub(crate) fn is_exif_datetime(s: &str) -> bool {
    let b = s.as_bytes();
    b.len() == 19
        && b.iter().enumerate().all(|(i, &c)| match i {
            4 | 7 => c == b':',
            10 => c == b' ',
            13 | 16 => c == b':',
            _ => c.is_ascii_digit(),
        })
}

/// Checks the parts of `meta` shared by the `.hdr` and `.exr` writers; `width`/`height` bound
/// the marks. Returns a one-line reason on failure.
pub(crate) fn validate_meta(meta: &HdrMeta, width: usize, height: usize) -> Result<(), String> {
    if let Some(e) = meta.exposure {
        if !(e.is_finite() && e > 0.0) {
            return Err(format!(
                "EXPOSURE must be a positive finite number, got {e}"
            ));
        }
    }
    for (name, v) in [("CAPDATE", &meta.capdate), ("GMT", &meta.gmt)] {
        if let Some(v) = v {
            if !is_exif_datetime(v) {
                return Err(format!(
                    "{name} must be formatted YYYY:MM:DD HH:MM:SS, got `{}`",
                    v.escape_debug()
                ));
            }
        }
    }
    for (name, v) in [("VIEW", &meta.view), ("SOFTWARE", &meta.software)] {
        if let Some(v) = v {
            if v.is_empty() || v.trim() != v || v.contains(['\n', '\r']) {
                return Err(format!(
                    "{name} must be one non-empty line without leading or trailing spaces, got `{}`",
                    v.escape_debug()
                ));
            }
        }
    }
    let check_point = |what: &str, p: &PixelPoint| {
        let (w, h) = (width as f64, height as f64);
        let inside = p.x.is_finite()
            && p.y.is_finite()
            && (-w..=2.0 * w).contains(&p.x)
            && (-h..=2.0 * h).contains(&p.y);
        if !inside {
            return Err(format!(
                "the {what} mark ({}, {}) is not a finite point within one image size of the {width}×{height} image",
                p.x, p.y
            ));
        }
        Ok(())
    };
    if let Some(s) = &meta.sun {
        check_point("sun", &s.pixel)?;
        if let Some(a) = s.azimuth_deg {
            if !(a.is_finite() && (-360.0..=360.0).contains(&a)) {
                return Err(format!(
                    "the sun's azimuth must be within ±360 degrees, got {a}"
                ));
            }
        }
        if let Some(e) = s.elevation_deg {
            if !(e.is_finite() && (-90.0..=90.0).contains(&e)) {
                return Err(format!(
                    "the sun's elevation must be within ±90 degrees, got {e}"
                ));
            }
        }
    }
    if let Some(n) = &meta.north {
        check_point("north", n)?;
    }
    for line in &meta.other {
        if line.is_empty() || line.contains(['\n', '\r']) {
            return Err(format!(
                "extra header line `{}` must be one non-empty line",
                line.escape_debug()
            ));
        }
        match classify(line) {
            Line::Other => {}
            Line::SunDirection(..) if meta.sun.is_none() => {}
            _ => {
                return Err(format!(
                    "extra header line `{}` would be read back as a structured field; set the matching HdrMeta field instead",
                    line.escape_debug()
                ))
            }
        }
    }
    Ok(())
}

fn header_text(image: &HdrImage, meta: &HdrMeta) -> Result<String, RgbeError> {
    validate_image(image)?;
    validate_meta(meta, image.width, image.height).map_err(RgbeError::BadMeta)?;
    let mut h = String::with_capacity(256);
    h.push_str("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n");
    let software = meta
        .software
        .clone()
        .unwrap_or_else(|| format!("skydome {}", crate::VERSION));
    h.push_str(&format!("SOFTWARE={software}\n"));
    if let Some(e) = meta.exposure {
        h.push_str(&format!("EXPOSURE={}\n", fmt_num(e)));
    }
    if let Some(d) = &meta.capdate {
        h.push_str(&format!("CAPDATE={d}\n"));
    }
    if let Some(d) = &meta.gmt {
        h.push_str(&format!("GMT={d}\n"));
    }
    if let Some(v) = &meta.view {
        h.push_str(&format!("VIEW= {v}\n"));
    }
    if let Some(s) = &meta.sun {
        h.push_str(&format!("#SUN={}\n", s.pixel));
        if let Some(d) = sun_direction_text(s) {
            h.push_str(&format!("#SUN_DIRECTION={d}\n"));
        }
    }
    if let Some(n) = &meta.north {
        h.push_str(&format!("#NORTH={n}\n"));
    }
    for line in &meta.other {
        h.push_str(line);
        h.push('\n');
    }
    h.push_str(&format!("\n-Y {} +X {}\n", image.height, image.width));
    Ok(h)
}

fn sun_direction_text(s: &SunMark) -> Option<String> {
    if s.azimuth_deg.is_none() && s.elevation_deg.is_none() {
        return None;
    }
    // Micro-degrees: far below any measurement's accuracy, and the same text whichever
    // platform's sin/cos computed the angle (the phone's wasm build and the laptop agree).
    let deg = |x: f64| fmt_num((x * 1e6).round() / 1e6 + 0.0);
    let mut t = String::new();
    if let Some(a) = s.azimuth_deg {
        t.push_str(&format!(" azimuth {}", deg(a)));
    }
    if let Some(e) = s.elevation_deg {
        t.push_str(&format!(" elevation {}", deg(e)));
    }
    t.push_str(" (degrees, azimuth from north towards east)");
    Some(t)
}

/// Rows per parallel work item: big enough to amortise scheduling, small enough to balance.
const BAND_ROWS: usize = 32;

fn encode_bands(image: &HdrImage) -> Vec<Vec<u8>> {
    let w = image.width;
    let band_samples = 3 * w * BAND_ROWS;
    let encode = |band: &[f32]| {
        let mut out = Vec::with_capacity(band.len() / 3 * 4 + 64);
        let mut planes = vec![0u8; 4 * w];
        for row in band.chunks_exact(3 * w) {
            encode_row(row, w, &mut planes, &mut out);
        }
        out
    };
    #[cfg(feature = "parallel")]
    {
        image.data.par_chunks(band_samples).map(encode).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        image.data.chunks(band_samples).map(encode).collect()
    }
}

fn encode_row(row: &[f32], w: usize, planes: &mut [u8], out: &mut Vec<u8>) {
    if !(8..=32767).contains(&w) {
        for px in row.chunks_exact(3) {
            out.extend_from_slice(&float_to_rgbe([px[0], px[1], px[2]]));
        }
        return;
    }
    let (r, rest) = planes.split_at_mut(w);
    let (g, rest) = rest.split_at_mut(w);
    let (b, e) = rest.split_at_mut(w);
    convert_row_planar(row, r, g, b, e);
    out.extend_from_slice(&[2, 2, (w >> 8) as u8, (w & 255) as u8]);
    for plane in [&*r, &*g, &*b, &*e] {
        rle_component(plane, out);
    }
}

/// [`float_to_rgbe`] for a whole row into four planes, written without branches so the
/// compiler vectorises it; the rare pixels whose largest channel is below 2⁻¹²⁰ (where the
/// `f32` scale factor would overflow) are redone by the scalar function afterwards.
fn convert_row_planar(row: &[f32], r: &mut [u8], g: &mut [u8], b: &mut [u8], e: &mut [u8]) {
    const MAGIC: f32 = 8_388_608.0;
    let mut tiny = 0u32;
    let planes = r
        .iter_mut()
        .zip(g.iter_mut())
        .zip(b.iter_mut().zip(e.iter_mut()));
    for (px, ((r, g), (b, e))) in row.chunks_exact(3).zip(planes) {
        let sanitise = |v: f32| {
            let bits = v.to_bits();
            let keep = bits.wrapping_sub(1) < 0x7f80_0000;
            if keep {
                bits.min(RGBE_MAX_BITS)
            } else {
                0
            }
        };
        let (cr, cg, cb) = (sanitise(px[0]), sanitise(px[1]), sanitise(px[2]));
        let m = cr.max(cg).max(cb);
        let e_field = m >> 23;
        let black = m < RGBE_MIN_BITS;
        tiny |= u32::from(!black & (e_field < 7));
        // Clamped so the bit pattern stays a valid power of two; such lanes are redone below.
        let scale = f32::from_bits((261 - e_field.max(7)) << 23);
        let q = |c: u32| {
            let v = ((f32::from_bits(c) * scale + MAGIC).to_bits() - MAGIC.to_bits()).min(255);
            if black {
                0
            } else {
                v as u8
            }
        };
        *r = q(cr);
        *g = q(cg);
        *b = q(cb);
        *e = if black { 0 } else { (e_field + 2) as u8 };
    }
    if tiny != 0 {
        let planes = r
            .iter_mut()
            .zip(g.iter_mut())
            .zip(b.iter_mut().zip(e.iter_mut()));
        for (px, ((r, g), (b, e))) in row.chunks_exact(3).zip(planes) {
            let p = float_to_rgbe([px[0], px[1], px[2]]);
            (*r, *g, *b, *e) = (p[0], p[1], p[2], p[3]);
        }
    }
}

/// Shortest run worth a run packet: a run of 4 costs 2 bytes instead of 4 (Radiance's MINRUN).
const MIN_RUN: usize = 4;

/// New-style RLE of one component plane.
fn rle_component(data: &[u8], out: &mut Vec<u8>) {
    let n = data.len();
    let mut lit_start = 0;
    let mut i = 0;
    while i + MIN_RUN <= n {
        // A run of MIN_RUN starting at i, i+1 or i+2 needs data[i+2] == data[i+3]: on noisy
        // data this skips three bytes per comparison instead of one.
        if data[i + 2] != data[i + 3] {
            i += 3;
            continue;
        }
        let v = data[i];
        if data[i + 1] != v || data[i + 2] != v {
            i += 1;
            continue;
        }
        let mut j = i + 3;
        while j < n && data[j] == v && j - i < 127 {
            j += 1;
        }
        flush_literals(&data[lit_start..i], out);
        out.push(128 + (j - i) as u8);
        out.push(v);
        lit_start = j;
        i = j;
    }
    flush_literals(&data[lit_start..n], out);
}

fn flush_literals(mut lit: &[u8], out: &mut Vec<u8>) {
    while !lit.is_empty() {
        let k = lit.len().min(128);
        out.push(k as u8);
        out.extend_from_slice(&lit[..k]);
        lit = &lit[k..];
    }
}

// ---------------------------------------------------------------------------------------------
// Header parsing

/// How one header line is understood.
enum Line {
    Format(String),
    Exposure(f64),
    Software(String),
    Capdate(String),
    Gmt(String),
    View(String),
    Sun(PixelPoint),
    SunDirection(Option<f64>, Option<f64>),
    North(PixelPoint),
    Other,
}

fn parse_sun_direction(s: &str) -> Option<(Option<f64>, Option<f64>)> {
    let mut az = None;
    let mut el = None;
    let mut it = s.split_whitespace();
    while let Some(tok) = it.next() {
        if tok.starts_with('(') {
            // The trailing explanation `(degrees, azimuth from north towards east)`.
            break;
        }
        let slot = match tok {
            "azimuth" => &mut az,
            "elevation" => &mut el,
            _ => continue,
        };
        let v = it.next()?.parse::<f64>().ok()?;
        if !v.is_finite() {
            return None;
        }
        *slot = Some(v);
    }
    (az.is_some() || el.is_some()).then_some((az, el))
}

fn classify(line: &str) -> Line {
    let value = |key: &str| line.strip_prefix(key).map(str::trim);
    if let Some(v) = value("FORMAT=") {
        return Line::Format(v.to_owned());
    }
    if let Some(v) = value("EXPOSURE=") {
        return match v.parse::<f64>() {
            Ok(e) if e.is_finite() && e > 0.0 => Line::Exposure(e),
            _ => Line::Other,
        };
    }
    let text = |v: &str, f: fn(String) -> Line| {
        if v.is_empty() {
            Line::Other
        } else {
            f(v.to_owned())
        }
    };
    if let Some(v) = value("SOFTWARE=") {
        return text(v, Line::Software);
    }
    if let Some(v) = value("CAPDATE=") {
        return text(v, Line::Capdate);
    }
    if let Some(v) = value("GMT=") {
        return text(v, Line::Gmt);
    }
    if let Some(v) = value("VIEW=") {
        return text(v, Line::View);
    }
    if let Some(v) = value("#SUN=") {
        return v.parse::<PixelPoint>().ok().map_or(Line::Other, Line::Sun);
    }
    if let Some(v) = value("#SUN_DIRECTION=") {
        return parse_sun_direction(v).map_or(Line::Other, |(a, e)| Line::SunDirection(a, e));
    }
    if let Some(v) = value("#NORTH=") {
        return v
            .parse::<PixelPoint>()
            .ok()
            .map_or(Line::Other, Line::North);
    }
    Line::Other
}

/// Reads one `\n`-terminated line of at most `budget` bytes; `None` at end of input.
fn read_line<R: BufRead>(
    r: &mut R,
    budget: &mut usize,
    limit: usize,
) -> Result<Option<String>, RgbeError> {
    let mut buf = Vec::new();
    let n = r
        .by_ref()
        .take(*budget as u64 + 1)
        .read_until(b'\n', &mut buf)?;
    if n == 0 {
        return Ok(None);
    }
    if n > *budget {
        return Err(RgbeError::HeaderTooLong(limit));
    }
    *budget -= n;
    if buf.last() != Some(&b'\n') {
        return Err(RgbeError::TruncatedHeader);
    }
    buf.pop();
    // Tolerate headers edited on Windows.
    if buf.last() == Some(&b'\r') {
        buf.pop();
    }
    Ok(Some(String::from_utf8_lossy(&buf).into_owned()))
}

fn parse_resolution(line: &str) -> Option<(usize, usize, Orientation)> {
    let t: Vec<&str> = line.split_whitespace().collect();
    let [a1, n1, a2, n2] = t.as_slice() else {
        return None;
    };
    let axis = |a: &str| -> Option<(bool, char)> {
        let mut c = a.chars();
        let sign = match c.next()? {
            '-' => true,
            '+' => false,
            _ => return None,
        };
        let ax = c.next()?;
        (c.next().is_none() && (ax == 'X' || ax == 'Y')).then_some((sign, ax))
    };
    let (dec1, ax1) = axis(a1)?;
    let (dec2, ax2) = axis(a2)?;
    if ax1 == ax2 {
        return None;
    }
    let n1: usize = n1.parse().ok()?;
    let n2: usize = n2.parse().ok()?;
    if n1 == 0 || n2 == 0 {
        return None;
    }
    let rows = ax1 == 'Y';
    let (w, h) = if rows { (n2, n1) } else { (n1, n2) };
    Some((
        w,
        h,
        Orientation {
            rows_are_scanlines: rows,
            slow_decreasing: dec1,
            fast_decreasing: dec2,
        },
    ))
}

/// Reads a `.hdr` header up to and including the resolution line, leaving `r` at the first
/// scanline. Fails on a missing magic line, a non-RGBE `FORMAT=`, a bad resolution line, or a
/// size over `limits`.
pub fn read_header<R: BufRead>(r: &mut R, limits: &Limits) -> Result<RgbeHeader, RgbeError> {
    let mut budget = limits.max_header_bytes;
    let limit = limits.max_header_bytes;
    let magic = read_line(r, &mut budget, limit)?.ok_or(RgbeError::NotRadiance)?;
    if !magic.starts_with("#?") {
        return Err(RgbeError::NotRadiance);
    }
    let mut lines = vec![magic];
    let mut meta = HdrMeta::default();
    let mut sun_px = None;
    let mut sun_dir: Option<(Option<f64>, Option<f64>, String)> = None;
    loop {
        let line = read_line(r, &mut budget, limit)?.ok_or(RgbeError::TruncatedHeader)?;
        if line.is_empty() {
            break;
        }
        match classify(&line) {
            Line::Format(f) => {
                if f != "32-bit_rle_rgbe" {
                    return Err(RgbeError::UnsupportedFormat(f));
                }
            }
            Line::Exposure(e) => meta.exposure = Some(meta.exposure.unwrap_or(1.0) * e),
            Line::Software(s) => meta.software = Some(s),
            Line::Capdate(s) => meta.capdate = Some(s),
            Line::Gmt(s) => meta.gmt = Some(s),
            Line::View(s) => meta.view = Some(s),
            Line::Sun(p) => sun_px = Some(p),
            Line::SunDirection(a, e) => sun_dir = Some((a, e, line.clone())),
            Line::North(p) => meta.north = Some(p),
            Line::Other => meta.other.push(line.clone()),
        }
        lines.push(line);
    }
    match (sun_px, sun_dir) {
        (Some(pixel), dir) => {
            meta.sun = Some(SunMark {
                pixel,
                azimuth_deg: dir.as_ref().and_then(|d| d.0),
                elevation_deg: dir.as_ref().and_then(|d| d.1),
            })
        }
        // A direction without a position cannot fill a SunMark: keep the line verbatim.
        (None, Some((_, _, line))) => meta.other.push(line),
        (None, None) => {}
    }
    let resolution = read_line(r, &mut budget, limit)?.ok_or(RgbeError::TruncatedHeader)?;
    let (width, height, orientation) = parse_resolution(&resolution)
        .ok_or_else(|| RgbeError::BadResolution(resolution.clone()))?;
    if (width as u128) * (height as u128) > u128::from(limits.max_pixels) {
        return Err(RgbeError::TooLarge {
            width,
            height,
            max: limits.max_pixels,
        });
    }
    Ok(RgbeHeader {
        meta,
        lines,
        resolution,
        width,
        height,
        orientation,
    })
}

// ---------------------------------------------------------------------------------------------
// Pixel decoding

/// Why a scanline failed, before the scanline number is attached.
enum ScanError {
    Truncated,
    Corrupt(&'static str),
}

/// Reads a `.hdr` file: header, metadata and pixels (see the module doc for what is accepted).
pub fn read_rgbe<R: BufRead>(mut r: R, limits: &Limits) -> Result<RgbeFile, RgbeError> {
    let header = read_header(&mut r, limits)?;
    let (n_scan, scan_len) = if header.orientation.rows_are_scanlines {
        (header.height, header.width)
    } else {
        (header.width, header.height)
    };
    // The worst case of any encoding (new-style RLE of incompressible data plus its markers);
    // reading more would only let a hostile stream make us buffer garbage.
    let per_scan = 4 + 4 * (scan_len as u64 + scan_len as u64 / 128 + 1);
    let max_bytes = (n_scan as u64).saturating_mul(per_scan);
    let mut data = Vec::new();
    r.take(max_bytes).read_to_end(&mut data)?;
    decode_pixels(&data, header)
}

/// Reads a `.hdr` file from memory (see [`read_rgbe`]), decoding the pixels in place rather
/// than through a copy of the file.
pub fn decode_rgbe(bytes: &[u8], limits: &Limits) -> Result<RgbeFile, RgbeError> {
    let mut rest = bytes;
    let header = read_header(&mut rest, limits)?;
    decode_pixels(rest, header)
}

/// Decodes the pixel data that follows `header`.
fn decode_pixels(data: &[u8], header: RgbeHeader) -> Result<RgbeFile, RgbeError> {
    let (n_scan, scan_len) = if header.orientation.rows_are_scanlines {
        (header.height, header.width)
    } else {
        (header.width, header.height)
    };
    let rgbe = decode_scanlines(data, n_scan, scan_len)?;
    let image = to_float(&rgbe, &header);
    Ok(RgbeFile { image, header })
}

fn decode_scanlines(src: &[u8], n_scan: usize, len: usize) -> Result<Vec<u8>, RgbeError> {
    // Grow with the data actually decoded rather than trusting the header's size up front.
    let total = n_scan.saturating_mul(len).saturating_mul(4);
    let mut out = Vec::with_capacity(total.min(src.len().saturating_mul(4)).max(4 * len));
    let mut pos = 0;
    for s in 0..n_scan {
        let start = out.len();
        out.resize(start + 4 * len, 0);
        decode_scanline(src, &mut pos, &mut out[start..]).map_err(|e| match e {
            ScanError::Truncated => RgbeError::Truncated {
                scanline: s,
                scanlines: n_scan,
            },
            ScanError::Corrupt(reason) => RgbeError::Corrupt {
                scanline: s,
                reason,
            },
        })?;
    }
    Ok(out)
}

fn decode_scanline(src: &[u8], pos: &mut usize, line: &mut [u8]) -> Result<(), ScanError> {
    let len = line.len() / 4;
    let first = src.get(*pos..*pos + 4).ok_or(ScanError::Truncated)?;
    let first = [first[0], first[1], first[2], first[3]];
    if (8..=32767).contains(&len) && first[0] == 2 && first[1] == 2 && first[2] & 0x80 == 0 {
        if (usize::from(first[2]) << 8 | usize::from(first[3])) != len {
            return Err(ScanError::Corrupt(
                "its run-length marker announces a different width",
            ));
        }
        *pos += 4;
        for plane in line.chunks_exact_mut(len) {
            decode_component(src, pos, plane)?;
        }
        return Ok(());
    }
    decode_old(src, pos, line, len)
}

fn decode_component(src: &[u8], pos: &mut usize, plane: &mut [u8]) -> Result<(), ScanError> {
    let len = plane.len();
    let mut x = 0;
    while x < len {
        let code = *src.get(*pos).ok_or(ScanError::Truncated)?;
        *pos += 1;
        if code > 128 {
            let n = usize::from(code - 128);
            let v = *src.get(*pos).ok_or(ScanError::Truncated)?;
            *pos += 1;
            if x + n > len {
                return Err(ScanError::Corrupt(
                    "a run goes past the end of the scanline",
                ));
            }
            plane[x..x + n].fill(v);
            x += n;
        } else {
            let n = usize::from(code);
            if x + n > len {
                return Err(ScanError::Corrupt(
                    "literal bytes go past the end of the scanline",
                ));
            }
            let lit = src.get(*pos..*pos + n).ok_or(ScanError::Truncated)?;
            *pos += n;
            plane[x..x + n].copy_from_slice(lit);
            x += n;
        }
    }
    Ok(())
}

/// Flat or old-style RLE scanline, written into the scanline's four component planes.
fn decode_old(src: &[u8], pos: &mut usize, line: &mut [u8], len: usize) -> Result<(), ScanError> {
    let mut x = 0;
    let mut shift = 0u32;
    while x < len {
        let p = src.get(*pos..*pos + 4).ok_or(ScanError::Truncated)?;
        *pos += 4;
        if p[0] == 1 && p[1] == 1 && p[2] == 1 {
            if x == 0 {
                return Err(ScanError::Corrupt(
                    "it starts with a repeat marker (old-style RLE)",
                ));
            }
            if shift > 24 {
                return Err(ScanError::Corrupt("too many consecutive repeat markers"));
            }
            let n = (usize::from(p[3])) << shift;
            if x + n > len {
                return Err(ScanError::Corrupt(
                    "an old-style run goes past the end of the scanline",
                ));
            }
            for plane in line.chunks_exact_mut(len) {
                let prev = plane[x - 1];
                plane[x..x + n].fill(prev);
            }
            x += n;
            shift += 8;
        } else {
            for (c, plane) in line.chunks_exact_mut(len).enumerate() {
                plane[x] = p[c];
            }
            x += 1;
            shift = 0;
        }
    }
    Ok(())
}

/// Converts planar scanlines (`R…, G…, B…, E…` per scanline) to the interleaved float image,
/// applying the file's orientation.
fn to_float(planes: &[u8], h: &RgbeHeader) -> HdrImage {
    let (w, ht) = (h.width, h.height);
    let mut data = vec![0.0f32; 3 * w * ht];
    if h.orientation == Orientation::STANDARD {
        let convert = |(dst, src): (&mut [f32], &[u8])| {
            for (row, line) in dst.chunks_exact_mut(3 * w).zip(src.chunks_exact(4 * w)) {
                let (r, rest) = line.split_at(w);
                let (g, rest) = rest.split_at(w);
                let (b, e) = rest.split_at(w);
                for (i, px) in row.chunks_exact_mut(3).enumerate() {
                    px.copy_from_slice(&rgbe_to_float([r[i], g[i], b[i], e[i]]));
                }
            }
        };
        let rows = 64;
        #[cfg(feature = "parallel")]
        data.par_chunks_mut(3 * w * rows)
            .zip(planes.par_chunks(4 * w * rows))
            .for_each(convert);
        #[cfg(not(feature = "parallel"))]
        data.chunks_mut(3 * w * rows)
            .zip(planes.chunks(4 * w * rows))
            .for_each(convert);
    } else {
        let o = h.orientation;
        let (n_scan, len) = if o.rows_are_scanlines {
            (ht, w)
        } else {
            (w, ht)
        };
        for (s, line) in planes.chunks_exact(4 * len).enumerate() {
            let c1 = if o.slow_decreasing { n_scan - 1 - s } else { s };
            for i in 0..len {
                let c2 = if o.fast_decreasing { len - 1 - i } else { i };
                // Radiance coordinates: X from the left, Y from the bottom.
                let (xc, yc) = if o.rows_are_scanlines {
                    (c2, c1)
                } else {
                    (c1, c2)
                };
                let (x, y) = (xc, ht - 1 - yc);
                let v =
                    rgbe_to_float([line[i], line[len + i], line[2 * len + i], line[3 * len + i]]);
                data[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&v);
            }
        }
    }
    HdrImage {
        width: w,
        height: ht,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worked_example_in_module_doc_holds() {
        assert_eq!(float_to_rgbe([0.3, 0.15, 0.0]), [154, 77, 0, 127]);
        let d = rgbe_to_float([154, 77, 0, 127]);
        assert_eq!(d, [154.0 / 512.0, 77.0 / 512.0, 0.0]);
        assert_eq!(float_to_rgbe([1.0, 0.5, 0.25]), [128, 64, 32, 129]);
        assert_eq!(rgbe_to_float([128, 64, 32, 129]), [1.0, 0.5, 0.25]);
    }

    #[test]
    fn bit_pattern_conversion_equals_f64_reference() {
        let mut s = 0x1234_5678_9abc_def1u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for i in 0..1_000_000 {
            let bits = next();
            // Mix raw bit patterns with channels close to each other (the common case).
            let px = if i % 2 == 0 {
                [bits as u32, (bits >> 32) as u32, (bits >> 16) as u32].map(f32::from_bits)
            } else {
                let m = f32::from_bits((bits as u32) & 0x7fff_ffff);
                [m, m * 0.37, m * ((bits >> 40) as f32 / 16_777_216.0)]
            };
            let clean = px.map(|v| if v > 0.0 { v.min(RGBE_MAX) } else { 0.0 });
            let expected = if clean[0].max(clean[1]).max(clean[2]) < RGBE_MIN {
                [0; 4]
            } else {
                float_to_rgbe_f64(clean)
            };
            assert_eq!(float_to_rgbe(px), expected, "{px:?}");
        }
    }

    #[test]
    fn vectorised_row_conversion_equals_scalar_for_any_bits() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let w = 4096;
        let row: Vec<f32> = (0..3 * w)
            .map(|i| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                match i % 4 {
                    0 => f32::from_bits(s as u32),
                    1 => f32::from_bits((s as u32) & 0x03ff_ffff), // tiny and subnormal
                    _ => (s >> 40) as f32 * 1e-3,
                }
            })
            .collect();
        let mut planes = vec![0u8; 4 * w];
        let (r, rest) = planes.split_at_mut(w);
        let (g, rest) = rest.split_at_mut(w);
        let (b, e) = rest.split_at_mut(w);
        convert_row_planar(&row, r, g, b, e);
        for (i, px) in row.chunks_exact(3).enumerate() {
            assert_eq!(
                [r[i], g[i], b[i], e[i]],
                float_to_rgbe([px[0], px[1], px[2]]),
                "{px:?}"
            );
        }
    }

    #[test]
    fn exponent_table_is_exact_powers_of_two() {
        for (e, &v) in EXP_TABLE.iter().enumerate().skip(1) {
            assert_eq!(f64::from(v), 2f64.powi(e as i32 - 136), "e = {e}");
        }
        assert_eq!(EXP_TABLE[0], 0.0);
    }

    #[test]
    fn limits_are_the_documented_constants() {
        assert_eq!(f64::from(RGBE_MAX), 255.0 * 2f64.powi(119));
        assert_eq!(f64::from(RGBE_MIN), 2f64.powi(-128));
        assert_eq!(rgbe_to_float(float_to_rgbe([RGBE_MAX; 3])), [RGBE_MAX; 3]);
        assert_eq!(float_to_rgbe([RGBE_MIN, 0.0, 0.0]), [128, 0, 0, 1]);
    }

    #[test]
    fn mantissa_that_rounds_to_256_is_clamped_within_bound() {
        // 255.75 steps of exponent 0 (m = 0.99902…): rounding would give 256.
        let m = 255.75f32 / 256.0;
        let q = float_to_rgbe([m, 0.0, m / 2.0]);
        assert_eq!(q[0], 255);
        let d = rgbe_to_float(q);
        assert!(f64::from((d[0] - m).abs()) <= f64::from(m) / 256.0);
    }

    #[test]
    fn rle_packets_decode_back_to_the_plane() {
        let plane: Vec<u8> = (0..1000u32)
            .map(|i| {
                if (i / 37) % 2 == 0 {
                    7
                } else {
                    (i * 31 % 251) as u8
                }
            })
            .collect();
        let mut enc = Vec::new();
        rle_component(&plane, &mut enc);
        let mut back = vec![0u8; plane.len()];
        let mut pos = 0;
        assert!(decode_component(&enc, &mut pos, &mut back).is_ok());
        assert_eq!(pos, enc.len());
        assert_eq!(back, plane);
        assert!(enc.len() < plane.len(), "runs must compress");
    }
}
