//! DNG (Digital Negative, the RAW format of Android's camera API and Apple ProRAW) frames:
//! the sensor's linear values, the black and white levels, the colour filter array (CFA) and
//! the colour matrix, read from the file.
//!
//! **What is read.** The raw image is the IFD (IFD0 or one of its SubIFDs) with
//! `NewSubFileType` 0 and `PhotometricInterpretation` 32803 (CFA, a 2 × 2 RGB pattern such as
//! RGGB) or 34892 (LinearRaw, three samples per pixel, already demosaiced); strips or tiles,
//! uncompressed (8, 16 or bit-packed 10–14 bits per sample, rows starting on a byte) or
//! lossless JPEG (compression 7, the "LJ92" of most DNGs, decoded by the `jpeg-decoder`
//! crate: 1, 3 or 4 components per stream; the two-component streams of the Adobe DNG
//! Converter's Bayer tiles, which it refuses, by our own [`super::ljpeg`]).
//! `LinearizationTable`, `BlackLevel` (per CFA position), `WhiteLevel`, `ActiveArea`,
//! `ColorMatrix1/2` with their illuminants and `AsShotNeutral` are applied; exposure time, ISO
//! and f-number come from EXIF as for every frame. Other compressions (deflate, lossy JPEG, JPEG XL) are refused with a message.
//!
//! **Why the IFD walk is our own.** The `tiff` crate (0.11) refuses to open a file whose first
//! image is a CFA (`UnsupportedError(UnknownInterpretation)` from `Decoder::new`), and no
//! MIT/Apache crate reads DNG's tags; the lenient IFD reader of [`super::tiff`] already reads
//! every entry bounds-checked, so a hostile file can at worst give an error. The `tiff` crate
//! does write the synthetic DNGs of the tests.
//!
//! **Values.** Each photosite becomes `v = (raw − black) / (white − black)` (1 = the white
//! level). A photosite at or above [`CLIP_FRACTION`] of the white level is *clipped*.
//! Demosaicing is **bilinear** (each missing colour is the mean of the nearest photosites of
//! that colour in the 3 × 3 neighbourhood — for a Bayer pattern the classic bilinear
//! interpolation); a value that used a clipped photosite is itself clipped, so clipping is
//! excluded per channel. The frame stays in **camera RGB** (no white balance yet): the merge of
//! linear frames is done per camera channel ([`crate::merge::merge_linear`]) and
//! [`RawColour::camera_to_rec709`] is applied to the merged radiance.
//!
//! **Encoding in a [`Frame`](super::Frame).** So that lens detection, alignment and the checks
//! of the bracket see a 16-bit picture, `v` is stored as the 16-bit code
//! `RAW_PEDESTAL + v · (RAW_FULL − RAW_PEDESTAL)` (clamped; the pedestal keeps the noise
//! below black), and a clipped value as [`RAW_CLIPPED`]. Only [`crate::merge::merge_linear`]
//! reads these codes as numbers; [`raw_value`] undoes the encoding. Pixels stay in sensor
//! order (EXIF orientation is not applied to RAW frames): the CFA's phase must stay known.

use super::tiff::read_ifd;
use super::{BracketError, DecodeOptions, DecodedFrame, Pixels};

/// The 16-bit code of a raw value 0 (the black level).
pub const RAW_PEDESTAL: u16 = 2048;
/// The 16-bit code of a raw value 1 (the white level).
pub const RAW_FULL: u16 = 65534;
/// The 16-bit code of a clipped value.
pub const RAW_CLIPPED: u16 = 65535;
/// A photosite at or above this fraction of the white level (after the black level) is
/// treated as clipped: sensors leave the linear range a little below their white level.
pub const CLIP_FRACTION: f32 = 0.98;

/// The raw value `v` (1 = white level) of a code of a RAW frame, `None` when clipped.
#[inline]
pub fn raw_value(code: u16) -> Option<f32> {
    (code != RAW_CLIPPED)
        .then(|| (f32::from(code) - f32::from(RAW_PEDESTAL)) / f32::from(RAW_FULL - RAW_PEDESTAL))
}

/// The 16-bit code of raw value `v` (see the module docs).
#[inline]
fn raw_code(v: f32, clipped: bool) -> u16 {
    if clipped {
        return RAW_CLIPPED;
    }
    let c = f32::from(RAW_PEDESTAL) + v * f32::from(RAW_FULL - RAW_PEDESTAL);
    c.round().clamp(0.0, f32::from(RAW_FULL)) as u16
}

/// The colour of a RAW bracket, read from its (first) DNG.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RawColour {
    /// The 2 × 2 CFA pattern in row-major order from the top-left photosite (0 red, 1 green,
    /// 2 blue), `None` for LinearRaw (every pixel measured in all three channels).
    pub cfa: Option<[u8; 4]>,
    /// Camera RGB (black-subtracted, 1 = white level) to linear Rec.709/sRGB primaries, white
    /// balance included: `rgb = M · cam`, rows R, G, B.
    pub camera_to_rec709: [[f32; 3]; 3],
    /// The white balance applied, as the camera's `AsShotNeutral` (camera values of a neutral
    /// surface, green 1); `[1, 1, 1]` when the file has none.
    pub as_shot_neutral: [f32; 3],
    /// Where the matrix came from, for the report (`"ColorMatrix2 (D65)"`, `"identity"`, …).
    pub matrix_from: String,
    /// Black and white level of the first frame (raw sensor units).
    pub black_level: f32,
    /// White level (raw sensor units).
    pub white_level: f32,
}

impl RawColour {
    /// True when channel `c` was measured (not interpolated) at pixel `(x, y)`.
    #[inline]
    pub fn native(&self, x: usize, y: usize, c: usize) -> bool {
        match self.cfa {
            Some(p) => usize::from(p[(y & 1) * 2 + (x & 1)]) == c,
            None => true,
        }
    }
}

/// True when `bytes` is a DNG: a TIFF whose IFD0 has the `DNGVersion` tag.
pub fn is_dng(bytes: &[u8]) -> bool {
    let Some((big, ifd0)) = header(bytes) else {
        return false;
    };
    read_ifd(bytes, ifd0, big)
        .iter()
        .any(|e| e.tag == DNG_VERSION)
}

const NEW_SUBFILE_TYPE: u16 = 254;
const WIDTH: u16 = 256;
const HEIGHT: u16 = 257;
const BITS: u16 = 258;
const COMPRESSION: u16 = 259;
const PHOTOMETRIC: u16 = 262;
const STRIP_OFFSETS: u16 = 273;
const SAMPLES: u16 = 277;
const ROWS_PER_STRIP: u16 = 278;
const STRIP_BYTES: u16 = 279;
const TILE_WIDTH: u16 = 322;
const TILE_LENGTH: u16 = 323;
const TILE_OFFSETS: u16 = 324;
const TILE_BYTES: u16 = 325;
const SUB_IFDS: u16 = 330;
const CFA_DIM: u16 = 33421;
const CFA_PATTERN: u16 = 33422;
const DNG_VERSION: u16 = 50706;
const LINEARIZATION: u16 = 50712;
const BLACK_DIM: u16 = 50713;
const BLACK_LEVEL: u16 = 50714;
const WHITE_LEVEL: u16 = 50717;
const COLOR_MATRIX_1: u16 = 50721;
const COLOR_MATRIX_2: u16 = 50722;
const AS_SHOT_NEUTRAL: u16 = 50728;
const ILLUMINANT_1: u16 = 50778;
const ILLUMINANT_2: u16 = 50779;
const ACTIVE_AREA: u16 = 50829;

const PHOTOMETRIC_CFA: u64 = 32803;
const PHOTOMETRIC_LINEAR_RAW: u64 = 34892;

/// Byte order and IFD0 offset of a TIFF.
fn header(bytes: &[u8]) -> Option<(bool, usize)> {
    let big = match bytes.get(..4)? {
        b"II*\0" => false,
        b"MM\0*" => true,
        _ => return None,
    };
    let o = bytes.get(4..8)?;
    let o = if big {
        u32::from_be_bytes([o[0], o[1], o[2], o[3]])
    } else {
        u32::from_le_bytes([o[0], o[1], o[2], o[3]])
    };
    Some((big, o as usize))
}

/// One IFD's entries with typed access (values are little-endian after [`read_ifd`]).
struct Ifd(Vec<super::tiff::Entry>);

impl Ifd {
    fn get(&self, tag: u16) -> Option<&super::tiff::Entry> {
        self.0.iter().find(|e| e.tag == tag)
    }

    /// Unsigned integer values (BYTE, SHORT, LONG).
    fn uints(&self, tag: u16) -> Option<Vec<u64>> {
        let e = self.get(tag)?;
        let d = &e.data;
        Some(match e.kind {
            1 | 7 => d.iter().map(|&b| u64::from(b)).collect(),
            3 => d
                .chunks_exact(2)
                .map(|c| u64::from(u16::from_le_bytes([c[0], c[1]])))
                .collect(),
            4 | 13 => d
                .chunks_exact(4)
                .map(|c| u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])))
                .collect(),
            _ => return None,
        })
    }

    fn uint(&self, tag: u16) -> Option<u64> {
        self.uints(tag)?.first().copied()
    }

    /// Numeric values of any numeric type as `f64`.
    fn nums(&self, tag: u16) -> Option<Vec<f64>> {
        let e = self.get(tag)?;
        let d = &e.data;
        let w4 = |c: &[u8]| [c[0], c[1], c[2], c[3]];
        Some(match e.kind {
            1 | 3 | 4 | 7 | 13 => self.uints(tag)?.into_iter().map(|v| v as f64).collect(),
            6 => d.iter().map(|&b| f64::from(b as i8)).collect(),
            8 => d
                .chunks_exact(2)
                .map(|c| f64::from(i16::from_le_bytes([c[0], c[1]])))
                .collect(),
            9 => d
                .chunks_exact(4)
                .map(|c| f64::from(i32::from_le_bytes(w4(c))))
                .collect(),
            5 => d
                .chunks_exact(8)
                .map(|c| {
                    f64::from(u32::from_le_bytes(w4(&c[..4])))
                        / f64::from(u32::from_le_bytes(w4(&c[4..])))
                })
                .collect(),
            10 => d
                .chunks_exact(8)
                .map(|c| {
                    f64::from(i32::from_le_bytes(w4(&c[..4])))
                        / f64::from(i32::from_le_bytes(w4(&c[4..])))
                })
                .collect(),
            11 => d
                .chunks_exact(4)
                .map(|c| f64::from(f32::from_le_bytes(w4(c))))
                .collect(),
            12 => d
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
            _ => return None,
        })
    }
}

/// The raw image's IFD: IFD0 or a SubIFD (one level down, as DNG writes them) that is a
/// full-resolution (`NewSubFileType` 0) CFA or LinearRaw image; the widest wins.
fn raw_ifd(bytes: &[u8], big: bool, ifd0: usize) -> Option<Ifd> {
    let first = Ifd(read_ifd(bytes, ifd0, big));
    let mut candidates = Vec::new();
    for &sub in first.uints(SUB_IFDS).unwrap_or_default().iter().take(16) {
        let ifd = Ifd(read_ifd(bytes, sub as usize, big));
        // A SubIFD's own SubIFDs (rare) are one level further.
        for &s2 in ifd.uints(SUB_IFDS).unwrap_or_default().iter().take(16) {
            candidates.push(Ifd(read_ifd(bytes, s2 as usize, big)));
        }
        candidates.push(ifd);
    }
    candidates.push(first);
    candidates
        .into_iter()
        .filter(|i| i.uint(NEW_SUBFILE_TYPE).unwrap_or(0) & 1 == 0)
        .filter(|i| {
            matches!(
                i.uint(PHOTOMETRIC),
                Some(PHOTOMETRIC_CFA | PHOTOMETRIC_LINEAR_RAW)
            )
        })
        .max_by_key(|i| i.uint(WIDTH).unwrap_or(0))
}

/// Decodes a DNG into a frame of camera-RGB codes (see the module docs) and its colour. The
/// caller reads EXIF (exposure, capture time) from the same bytes.
pub fn decode_dng(
    name: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<(DecodedFrame, RawColour), BracketError> {
    let bad = |reason: String| BracketError::Corrupt {
        file: name.to_string(),
        reason,
    };
    let (big, ifd0) = header(bytes).ok_or_else(|| bad("not a TIFF/DNG file".into()))?;
    let first = Ifd(read_ifd(bytes, ifd0, big));
    let ifd = raw_ifd(bytes, big, ifd0)
        .ok_or_else(|| bad("DNG without a readable raw image (no CFA or LinearRaw IFD)".into()))?;
    let w = ifd.uint(WIDTH).unwrap_or(0);
    let h = ifd.uint(HEIGHT).unwrap_or(0);
    let pixels = w.saturating_mul(h);
    if pixels > opts.max_pixels {
        return Err(BracketError::TooLarge {
            file: name.to_string(),
            width: w,
            height: h,
            pixels,
            limit: opts.max_pixels,
        });
    }
    let (w, h) = (w as usize, h as usize);
    if w < 4 || h < 4 {
        return Err(BracketError::TooSmall {
            file: name.to_string(),
            width: w,
            height: h,
        });
    }
    let linear_raw = ifd.uint(PHOTOMETRIC) == Some(PHOTOMETRIC_LINEAR_RAW);
    let spp = ifd.uint(SAMPLES).unwrap_or(1) as usize;
    let want_spp = if linear_raw { 3 } else { 1 };
    if spp != want_spp {
        return Err(bad(format!(
            "DNG raw image with {spp} samples per pixel (expected {want_spp})"
        )));
    }
    let cfa = if linear_raw {
        None
    } else {
        Some(cfa_pattern(&ifd).map_err(|r| bad(r.into()))?)
    };
    let raw = read_samples(bytes, &ifd, big, w, h, spp).map_err(bad)?;
    let levels = Levels::of(&ifd, spp).map_err(|r| bad(r.into()))?;
    // ActiveArea: top, left, bottom, right.
    let (x0, y0, aw, ah) = match ifd.uints(ACTIVE_AREA).filter(|a| a.len() == 4) {
        Some(a) if a[0] < a[2] && a[1] < a[3] && a[2] as usize <= h && a[3] as usize <= w => {
            // Keep the CFA phase: the area starts on an even photosite.
            let (t, l) = (a[0] as usize, a[1] as usize);
            (l, t, a[3] as usize - l, a[2] as usize - t)
        }
        _ => (0, 0, w, h),
    };
    let cfa = cfa.map(|p| shift_cfa(p, x0, y0));
    if aw < 4 || ah < 4 {
        return Err(bad("DNG active area below 4 × 4 pixels".into()));
    }
    // Normalised values, spp per pixel.
    let mut v = vec![0f32; aw * ah * spp];
    for y in 0..ah {
        for x in 0..aw {
            for s in 0..spp {
                let r = raw[((y + y0) * w + x + x0) * spp + s];
                let lin = levels.linearise(r);
                let plane = if linear_raw { s } else { 0 };
                let (black, white) = levels.at(x + x0, y + y0, plane);
                v[(y * aw + x) * spp + s] = (lin - black) / (white - black).max(1e-6);
            }
        }
    }
    let (matrix, from) = camera_matrix(&first, &ifd);
    let sensor = SensorImage {
        width: aw,
        height: ah,
        values: v,
        cfa,
        matrix,
        matrix_from: from,
        as_shot_neutral: as_shot_neutral(&first, &ifd),
        black_level: levels.black.first().copied().unwrap_or(0.0),
        white_level: levels.white.first().copied().unwrap_or(0.0),
    };
    let (mut frame, colour) = sensor.develop(name);
    super::exif::read_exif(bytes, &mut frame);
    // Sensor order: the CFA phase must survive (see the module docs).
    frame.info.orientation = 1;
    Ok((frame, colour))
}

/// A RAW image as a reader hands it over, before demosaicing: the active area's photosites
/// normalised to `v = (raw − black) / (white − black)`, and the colour metadata. Both readers
/// (this module's DNG reader and, under the `raw-rawler` feature, `rawler` for camera formats)
/// end here, so every RAW frame is clipped, demosaiced and encoded the same way.
pub(super) struct SensorImage {
    /// Width of the active area in photosites.
    pub width: usize,
    /// Height of the active area in photosites.
    pub height: usize,
    /// Normalised values, row-major from the top-left photosite: one per photosite for a CFA
    /// image, three (camera R, G, B) per pixel for LinearRaw.
    pub values: Vec<f32>,
    /// The 2 × 2 pattern from the top-left photosite of the active area (0 R, 1 G, 2 B), `None`
    /// for LinearRaw.
    pub cfa: Option<[u8; 4]>,
    /// The XYZ → camera matrix (rows camera R, G, B), `None` when the file has none.
    pub matrix: Option<[[f64; 3]; 3]>,
    /// Where the matrix came from, for the report.
    pub matrix_from: String,
    /// The camera's as-shot neutral (camera values of a neutral surface, green 1).
    pub as_shot_neutral: [f32; 3],
    /// Black level (raw sensor units), for the report.
    pub black_level: f32,
    /// White level (raw sensor units), for the report.
    pub white_level: f32,
}

impl SensorImage {
    /// Clipping ([`CLIP_FRACTION`]), bilinear demosaicing of a CFA image and the 16-bit codes
    /// of the module docs; the colour from the matrix and the white balance. The frame has no
    /// EXIF yet (the caller reads it) and orientation 1 (sensor order).
    pub(super) fn develop(self, name: &str) -> (DecodedFrame, RawColour) {
        let clip: Vec<bool> = self.values.iter().map(|&n| n >= CLIP_FRACTION).collect();
        let (w, h) = (self.width, self.height);
        let rgb = match self.cfa {
            Some(p) => demosaic_bilinear(&self.values, &clip, w, h, p),
            None => self
                .values
                .iter()
                .zip(&clip)
                .map(|(&v, &c)| raw_code(v, c))
                .collect(),
        };
        let colour = RawColour {
            cfa: self.cfa,
            camera_to_rec709: camera_to_rec709(self.matrix.as_ref(), self.as_shot_neutral),
            as_shot_neutral: self.as_shot_neutral,
            matrix_from: self.matrix_from,
            black_level: self.black_level,
            white_level: self.white_level,
        };
        (DecodedFrame::new(name, w, h, Pixels::U16(rgb)), colour)
    }
}

/// The 2 × 2 CFA pattern (0 R, 1 G, 2 B); other sizes and colours are refused.
fn cfa_pattern(ifd: &Ifd) -> Result<[u8; 4], &'static str> {
    let dim = ifd.uints(CFA_DIM).unwrap_or_else(|| vec![2, 2]);
    if dim != [2, 2] {
        return Err("DNG CFA pattern other than 2 × 2 (X-Trans and others are not supported)");
    }
    let p = ifd
        .uints(CFA_PATTERN)
        .ok_or("DNG CFA image without a CFAPattern tag")?;
    if p.len() != 4 || p.iter().any(|&c| c > 2) {
        return Err("DNG CFAPattern is not a 2 × 2 pattern of red, green and blue");
    }
    let p = [p[0] as u8, p[1] as u8, p[2] as u8, p[3] as u8];
    if !(0..3).all(|c| p.contains(&c)) {
        return Err("DNG CFAPattern lacks one of red, green, blue");
    }
    Ok(p)
}

/// The pattern as seen from photosite `(x0, y0)`.
fn shift_cfa(p: [u8; 4], x0: usize, y0: usize) -> [u8; 4] {
    let at = |x: usize, y: usize| p[((y + y0) & 1) * 2 + ((x + x0) & 1)];
    [at(0, 0), at(1, 0), at(0, 1), at(1, 1)]
}

/// Black and white levels, and the linearisation table.
struct Levels {
    lut: Option<Vec<f32>>,
    /// Black level per repeat position (`BlackLevelRepeatDim` rows × cols × planes).
    black: Vec<f32>,
    black_dim: (usize, usize),
    white: Vec<f32>,
    planes: usize,
}

impl Levels {
    fn of(ifd: &Ifd, spp: usize) -> Result<Self, &'static str> {
        let lut: Option<Vec<f32>> = ifd
            .nums(LINEARIZATION)
            .filter(|t| !t.is_empty())
            .map(|t| t.into_iter().map(|v| v as f32).collect());
        let dim = ifd
            .uints(BLACK_DIM)
            .filter(|d| d.len() == 2 && d[0] >= 1 && d[1] >= 1 && d[0] * d[1] <= 64)
            .map_or((1, 1), |d| (d[0] as usize, d[1] as usize));
        let mut black: Vec<f32> = ifd
            .nums(BLACK_LEVEL)
            .unwrap_or_else(|| vec![0.0])
            .into_iter()
            .map(|v| v as f32)
            .collect();
        let want = dim.0 * dim.1 * spp;
        if black.len() != want {
            let b0 = black.first().copied().unwrap_or(0.0);
            black = vec![b0; want];
        }
        let bits = ifd.uint(BITS).unwrap_or(16).clamp(1, 16);
        let default_white = match &lut {
            Some(t) => t.iter().copied().fold(0.0, f32::max),
            None => ((1u32 << bits) - 1) as f32,
        };
        let mut white: Vec<f32> = ifd
            .nums(WHITE_LEVEL)
            .map(|v| v.into_iter().map(|v| v as f32).collect())
            .unwrap_or_else(|| vec![default_white]);
        if white.len() != spp {
            white = vec![white.first().copied().unwrap_or(default_white); spp];
        }
        if black.iter().chain(&white).any(|v| !v.is_finite())
            || white.iter().zip(0..).any(|(&wl, s)| {
                let b = black[s % black.len()];
                wl <= b
            })
        {
            return Err("DNG white level not above its black level");
        }
        Ok(Self {
            lut,
            black,
            black_dim: dim,
            white,
            planes: spp,
        })
    }

    #[inline]
    fn linearise(&self, raw: u16) -> f32 {
        match &self.lut {
            Some(t) => t[usize::from(raw).min(t.len() - 1)],
            None => f32::from(raw),
        }
    }

    /// Black and white level at photosite `(x, y)`, plane `s`.
    #[inline]
    fn at(&self, x: usize, y: usize, s: usize) -> (f32, f32) {
        let (rows, cols) = self.black_dim;
        let b = self.black[((y % rows) * cols + x % cols) * self.planes + s];
        (b, self.white[s])
    }
}

/// Every sample of the raw image, row-major, `spp` per pixel.
fn read_samples(
    bytes: &[u8],
    ifd: &Ifd,
    big: bool,
    w: usize,
    h: usize,
    spp: usize,
) -> Result<Vec<u16>, String> {
    let bits = ifd.uint(BITS).unwrap_or(1) as usize;
    if !(8..=16).contains(&bits) {
        return Err(format!(
            "DNG with {bits} bits per sample (8 to 16 are read)"
        ));
    }
    let compression = ifd.uint(COMPRESSION).unwrap_or(1);
    if compression != 1 && compression != 7 {
        return Err(format!(
            "DNG compression {compression} is not supported (uncompressed and lossless JPEG are)"
        ));
    }
    // Chunks: (x, y, width, height) in pixels and their bytes.
    let (offsets, counts, cw, ch) = match (ifd.uints(TILE_OFFSETS), ifd.uints(TILE_BYTES)) {
        (Some(o), Some(c)) => {
            let tw = ifd.uint(TILE_WIDTH).unwrap_or(0) as usize;
            let th = ifd.uint(TILE_LENGTH).unwrap_or(0) as usize;
            (o, c, tw, th)
        }
        _ => {
            let o = ifd
                .uints(STRIP_OFFSETS)
                .ok_or("DNG raw image without strip or tile offsets")?;
            let c = ifd
                .uints(STRIP_BYTES)
                .ok_or("DNG raw image without strip byte counts")?;
            let rps = ifd.uint(ROWS_PER_STRIP).unwrap_or(h as u64) as usize;
            (o, c, w, rps.min(h))
        }
    };
    if cw == 0 || ch == 0 {
        return Err("DNG tile or strip of zero size".into());
    }
    // A chunk's samples are allocated before they are decoded: a tile far larger than the image
    // (a damaged TileWidth/TileLength) must not reserve gigabytes.
    if cw.saturating_mul(ch) > w.saturating_mul(h).saturating_mul(4).max(65_536) {
        return Err(format!(
            "DNG tile of {cw} × {ch} pixels for a {w} × {h} image (damaged tile size?)"
        ));
    }
    let across = w.div_ceil(cw);
    let down = h.div_ceil(ch);
    if offsets.len() < across * down || counts.len() < offsets.len() {
        return Err(format!(
            "DNG has {} data chunks, {} needed for {w} × {h} pixels",
            offsets.len().min(counts.len()),
            across * down
        ));
    }
    let mut out = vec![0u16; w * h * spp];
    for (i, (&off, &len)) in offsets.iter().zip(&counts).take(across * down).enumerate() {
        let data = (off as usize)
            .checked_add(len as usize)
            .and_then(|end| bytes.get(off as usize..end))
            .ok_or("DNG data chunk beyond the end of the file (truncated?)")?;
        let (cx, cy) = ((i % across) * cw, (i / across) * ch);
        let samples = match compression {
            7 => lossless_jpeg(data, cw, ch, spp)?,
            _ => unpack(data, cw, ch.min(h - cy), spp, bits, big)?,
        };
        let rows = samples.len() / (cw * spp);
        for r in 0..rows.min(h - cy) {
            let n = (w - cx).min(cw) * spp;
            let src = &samples[r * cw * spp..r * cw * spp + n];
            let d = ((cy + r) * w + cx) * spp;
            out[d..d + n].copy_from_slice(src);
        }
    }
    Ok(out)
}

/// Uncompressed samples of one chunk: 8 or 16 bits, or packed big-endian bit fields with each
/// row starting on a byte.
fn unpack(
    data: &[u8],
    cw: usize,
    rows: usize,
    spp: usize,
    bits: usize,
    big: bool,
) -> Result<Vec<u16>, String> {
    let per_row = cw * spp;
    let row_bytes = (per_row * bits).div_ceil(8);
    if data.len() < row_bytes * rows {
        return Err(format!(
            "DNG strip holds {} bytes, {} needed (truncated?)",
            data.len(),
            row_bytes * rows
        ));
    }
    let mut out = Vec::with_capacity(per_row * rows);
    for r in 0..rows {
        let row = &data[r * row_bytes..(r + 1) * row_bytes];
        match bits {
            8 => out.extend(row.iter().map(|&b| u16::from(b))),
            16 => out.extend(row.chunks_exact(2).map(|c| match big {
                true => u16::from_be_bytes([c[0], c[1]]),
                false => u16::from_le_bytes([c[0], c[1]]),
            })),
            _ => {
                let (mut acc, mut have, mut at) = (0u32, 0usize, 0usize);
                for _ in 0..per_row {
                    while have < bits {
                        acc = (acc << 8) | u32::from(row[at]);
                        at += 1;
                        have += 8;
                    }
                    have -= bits;
                    out.push(((acc >> have) & ((1 << bits) - 1)) as u16);
                }
            }
        }
    }
    Ok(out)
}

/// One lossless-JPEG chunk (compression 7) as `cw × ch × spp` samples in raster order. The
/// JPEG's own width × components may differ from the chunk's (DNG writers often code two
/// photosites as one two-component pixel); only the sample count has to agree.
fn lossless_jpeg(data: &[u8], cw: usize, ch: usize, spp: usize) -> Result<Vec<u16>, String> {
    // The decoder is third-party code fed with untrusted bytes: a panic in it must not take
    // the process down.
    let want = cw * ch * spp;
    let decoded = std::panic::catch_unwind(|| {
        let mut d = jpeg_decoder::Decoder::new(data);
        // The decoder allocates what its frame header announces (up to 65535 × 65535 pixels);
        // a header announcing more samples than the chunk holds is damage, refused before that.
        // (After a failed `read_info` the decoder cannot start again: its error is the answer,
        // a two-component stream's included.)
        if let Err(e) = d.read_info() {
            return Ok((Err(e), None));
        }
        if let Some(i) = d.info() {
            let comps = match i.pixel_format {
                jpeg_decoder::PixelFormat::L8 | jpeg_decoder::PixelFormat::L16 => 1,
                jpeg_decoder::PixelFormat::RGB24 => 3,
                _ => 4,
            };
            let announced = usize::from(i.width) * usize::from(i.height) * comps;
            if announced > want {
                return Err(announced);
            }
        }
        let px = d.decode();
        Ok((px, d.info()))
    });
    let (px, info) = decoded
        .map_err(|_| "the lossless JPEG decoder failed on this DNG".to_string())?
        .map_err(|n| {
            format!("DNG lossless JPEG announces {n} samples for a chunk of {want} (damaged?)")
        })?;
    let px = match px {
        // Two-component streams (the Adobe DNG Converter's Bayer tiles): our own decoder.
        Err(jpeg_decoder::Error::Unsupported(
            jpeg_decoder::UnsupportedFeature::ComponentCount(2),
        )) => {
            let d = super::ljpeg::decode(data, want).map_err(|e| format!("DNG {e}"))?;
            if d.samples.len() < want
                && (!d.samples.len().is_multiple_of(cw * spp) || d.samples.is_empty())
            {
                return Err(format!(
                    "DNG lossless JPEG holds {} samples, {want} expected",
                    d.samples.len()
                ));
            }
            return Ok(d.samples);
        }
        px => px.map_err(|e| format!("DNG lossless JPEG: {e}"))?,
    };
    let info = info.ok_or("DNG lossless JPEG without a frame header")?;
    if info.coding_process != jpeg_decoder::CodingProcess::Lossless {
        return Err("DNG tile is a lossy JPEG (only lossless JPEG is read)".into());
    }
    let comps = match info.pixel_format {
        jpeg_decoder::PixelFormat::L8 | jpeg_decoder::PixelFormat::L16 => 1,
        jpeg_decoder::PixelFormat::RGB24 => 3,
        _ => 4,
    };
    let n = usize::from(info.width) * usize::from(info.height) * comps;
    let samples: Vec<u16> = if n > 0 && px.len() == 2 * n {
        px.chunks_exact(2)
            .map(|c| u16::from_ne_bytes([c[0], c[1]]))
            .collect()
    } else {
        px.iter().map(|&b| u16::from(b)).collect()
    };
    if samples.len() < want {
        // The last strip of an image may be short.
        if !samples.len().is_multiple_of(cw * spp) || samples.is_empty() {
            return Err(format!(
                "DNG lossless JPEG holds {} samples, {want} expected",
                samples.len()
            ));
        }
    }
    Ok(samples.into_iter().take(want).collect())
}

/// Bilinear demosaicing of normalised photosites `v` (clipped where `clip`): each missing
/// colour is the mean of the photosites of that colour in the 3 × 3 neighbourhood; a value
/// that used a clipped photosite is clipped. Returns RGB codes (see the module docs).
fn demosaic_bilinear(v: &[f32], clip: &[bool], w: usize, h: usize, cfa: [u8; 4]) -> Vec<u16> {
    let colour = |x: usize, y: usize| cfa[(y & 1) * 2 + (x & 1)] as usize;
    let mut out = vec![0u16; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let own = colour(x, y);
            let mut sum = [0f32; 3];
            let mut n = [0u32; 3];
            let mut clipped = [false; 3];
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let c = colour(xx, yy);
                    if c == own && (xx != x || yy != y) {
                        continue;
                    }
                    let k = yy * w + xx;
                    sum[c] += v[k];
                    n[c] += 1;
                    clipped[c] |= clip[k];
                }
            }
            for c in 0..3 {
                let val = if n[c] > 0 { sum[c] / n[c] as f32 } else { 0.0 };
                out[(y * w + x) * 3 + c] = raw_code(val, clipped[c] || n[c] == 0);
            }
        }
    }
    out
}

/// The XYZ → camera matrix to use: `ColorMatrix2` when its illuminant is D65 (21), else
/// `ColorMatrix1` when its illuminant is D65, else `ColorMatrix2` (DNG writes the warmer
/// illuminant first), else `ColorMatrix1`; `None` when the file has none (or a bad one).
fn camera_matrix(first: &Ifd, raw: &Ifd) -> (Option<[[f64; 3]; 3]>, String) {
    let find = |tag: u16| raw.nums(tag).or_else(|| first.nums(tag));
    let ill = |tag: u16| raw.uint(tag).or_else(|| first.uint(tag));
    let m1 = find(COLOR_MATRIX_1);
    let m2 = find(COLOR_MATRIX_2);
    let (i1, i2) = (ill(ILLUMINANT_1), ill(ILLUMINANT_2));
    let pick = match (&m1, &m2) {
        (_, Some(m)) if i2 == Some(21) => Some((m, "ColorMatrix2 (D65)")),
        (Some(m), _) if i1 == Some(21) => Some((m, "ColorMatrix1 (D65)")),
        (_, Some(m)) => Some((m, "ColorMatrix2")),
        (Some(m), _) => Some((m, "ColorMatrix1")),
        _ => None,
    };
    match pick {
        Some((m, from)) if m.len() == 9 && m.iter().all(|v| v.is_finite()) => (
            Some([[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]]),
            from.to_string(),
        ),
        _ => (None, "identity (the DNG has no colour matrix)".into()),
    }
}

/// `AsShotNeutral`, green 1; `[1, 1, 1]` when absent or unusable.
fn as_shot_neutral(first: &Ifd, raw: &Ifd) -> [f32; 3] {
    let n = raw
        .nums(AS_SHOT_NEUTRAL)
        .or_else(|| first.nums(AS_SHOT_NEUTRAL));
    match n {
        Some(n) if n.len() == 3 && n.iter().all(|v| v.is_finite() && *v > 0.0) => {
            let g = n[1];
            [(n[0] / g) as f32, 1.0, (n[2] / g) as f32]
        }
        _ => [1.0; 3],
    }
}

/// Linear sRGB (Rec.709 primaries, D65) to XYZ.
const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.412_456_4, 0.357_576_1, 0.180_437_5],
    [0.212_672_9, 0.715_152_2, 0.072_175_0],
    [0.019_333_9, 0.119_192_0, 0.950_304_1],
];

/// Camera RGB → linear Rec.709 with white balance, the way dcraw and LibRaw do it:
/// `cam_rgb = ColorMatrix · RGB_TO_XYZ`, each row normalised to sum 1 (so Rec.709 white
/// gives equal camera values), inverted; then the as-shot white balance (each camera channel
/// divided by its `AsShotNeutral` value) is applied before it. Without a colour matrix: the
/// white balance alone.
pub fn camera_to_rec709(matrix: Option<&[[f64; 3]; 3]>, neutral: [f32; 3]) -> [[f32; 3]; 3] {
    let wb = neutral.map(|n| 1.0 / f64::from(n));
    let rgb_cam = matrix.and_then(|m| {
        let mut cam_rgb = [[0f64; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                cam_rgb[i][j] = (0..3).map(|k| m[i][k] * RGB_TO_XYZ[k][j]).sum();
            }
            let s: f64 = cam_rgb[i].iter().sum();
            if s.abs() < 1e-9 {
                return None;
            }
            cam_rgb[i].iter_mut().for_each(|v| *v /= s);
        }
        invert3(&cam_rgb)
    });
    let rgb_cam = rgb_cam.unwrap_or([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    let mut out = [[0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (rgb_cam[i][j] * wb[j]) as f32;
        }
    }
    out
}

/// The inverse of a 3 × 3 matrix, `None` when it is (nearly) singular.
fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c =
        |r0: usize, c0: usize, r1: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let det = m[0][0] * c(1, 1, 2, 2) - m[0][1] * c(1, 0, 2, 2) + m[0][2] * c(1, 0, 2, 1);
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    let inv = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    Some(inv.map(|r| r.map(|v| v / det)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn inverse_of_a_matrix_times_itself_is_identity() {
        let m = [[2.0, 1.0, 0.5], [0.3, 1.5, 0.2], [0.1, 0.4, 3.0]];
        let i = invert3(&m).unwrap();
        for r in 0..3 {
            for c in 0..3 {
                let v: f64 = (0..3).map(|k| m[r][k] * i[k][c]).sum();
                assert!((v - f64::from(u8::from(r == c))).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn white_maps_to_white_after_white_balance() {
        // Any colour matrix: camera values equal to the neutral give equal Rec.709 values.
        let m = [[0.9, -0.3, -0.1], [-0.4, 1.2, 0.2], [-0.05, 0.15, 0.6]];
        let n = [0.5f32, 1.0, 0.7];
        let t = camera_to_rec709(Some(&m), n);
        let out: Vec<f32> = (0..3)
            .map(|i| (0..3).map(|j| t[i][j] * n[j]).sum())
            .collect();
        for v in &out {
            assert!((v - out[1]).abs() < 1e-5, "{out:?}");
        }
    }

    #[test]
    fn packed_12_bit_rows_unpack() {
        // 0xABC, 0x123 packed big-endian in 3 bytes.
        let v = unpack(&[0xAB, 0xC1, 0x23], 2, 1, 1, 12, false).unwrap();
        assert_eq!(v, [0xABC, 0x123]);
    }

    #[test]
    fn codes_round_trip_to_raw_values() {
        for v in [0.0f32, 0.25, 0.9, 1.0] {
            assert!((raw_value(raw_code(v, false)).unwrap() - v).abs() < 2e-5);
        }
        assert_eq!(raw_value(raw_code(0.5, true)), None);
    }
}
