//! A bracket: decoded frames of one still scene at different exposures.
//!
//! (Decoding, EXIF and validation are being filled in; the types below are the contract that
//! calibration and merging consume.)

/// Pixel samples of one decoded frame: interleaved RGB, row-major, origin top-left.
#[derive(Debug, Clone, PartialEq)]
pub enum Pixels {
    /// 8 bits per channel, codes 0..=255.
    U8(Vec<u8>),
    /// 16 bits per channel, codes 0..=65535.
    U16(Vec<u16>),
}

impl Pixels {
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
