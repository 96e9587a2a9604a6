//! Display pictures: 8-bit RGB as JPEG or PNG, 16-bit RGB as PNG, and grey maps.
//!
//! These are the encoders behind every preview, overlay, confidence map and plot skydome writes,
//! so the command line and the web app produce the same bytes from the same pixels.

use crate::image::RgbImage;

/// Errors while encoding a picture.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PictureError {
    /// The encoder failed (or the size does not fit the format).
    #[error("cannot encode {format}: {reason}")]
    Encode {
        /// "JPEG" or "PNG".
        format: &'static str,
        /// What the encoder said.
        reason: String,
    },
    /// A picture format that cannot hold what was asked (e.g. 16 bits in JPEG).
    #[error("cannot write {what} as {format}; use {instead}")]
    Unsupported {
        /// What was to be written.
        what: &'static str,
        /// The format asked for.
        format: &'static str,
        /// What works instead.
        instead: &'static str,
    },
    /// Pixel values whose count does not match the size.
    #[error("{len} values do not fill a {width}×{height} picture")]
    Size {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Number of values given.
        len: usize,
    },
}

/// A display-picture file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PictureFormat {
    /// Baseline JPEG, 4:2:0, 8 bits, at a quality in 1..=100.
    Jpeg {
        /// JPEG quality 1..=100.
        quality: u8,
    },
    /// PNG, lossless, 8 or 16 bits.
    Png,
}

/// JPEG quality of previews and overlays.
pub const DEFAULT_JPEG_QUALITY: u8 = 92;

impl PictureFormat {
    /// The format for a file extension (`jpg`, `jpeg`, `png`; any case), JPEG at
    /// [`DEFAULT_JPEG_QUALITY`]; `None` for anything else.
    pub fn from_extension(ext: &str) -> Option<Self> {
        match ext.to_ascii_lowercase().as_str() {
            "jpg" | "jpeg" => Some(Self::Jpeg {
                quality: DEFAULT_JPEG_QUALITY,
            }),
            "png" => Some(Self::Png),
            _ => None,
        }
    }

    /// The format's name for messages.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Jpeg { .. } => "JPEG",
            Self::Png => "PNG",
        }
    }

    /// The MIME type (`image/jpeg`, `image/png`).
    pub fn mime(&self) -> &'static str {
        match self {
            Self::Jpeg { .. } => "image/jpeg",
            Self::Png => "image/png",
        }
    }
}

/// Encodes an 8-bit RGB picture.
pub fn encode_rgb8(img: &RgbImage<u8>, format: PictureFormat) -> Result<Vec<u8>, PictureError> {
    match format {
        PictureFormat::Png => encode_png(
            &img.data,
            img.width,
            img.height,
            image::ExtendedColorType::Rgb8,
        ),
        PictureFormat::Jpeg { quality } => encode_jpeg(img, quality),
    }
}

/// Baseline 4:2:0 JPEG through the `jpeg-encoder` crate. Chosen by measurement over `image`'s
/// encoder (which is 4× slower on a 6 MP preview here; `cargo bench --bench tonemap`,
/// group `preview_6mp`): it has an AVX2 path picked at run time and plain Rust elsewhere, so it
/// builds for wasm32 too.
fn encode_jpeg(img: &RgbImage<u8>, quality: u8) -> Result<Vec<u8>, PictureError> {
    let err = |reason: String| PictureError::Encode {
        format: "JPEG",
        reason,
    };
    if img.data.len() != 3 * img.width * img.height {
        return Err(PictureError::Size {
            width: img.width,
            height: img.height,
            len: img.data.len(),
        });
    }
    // JPEG stores sizes in 16 bits.
    let (Ok(w), Ok(h)) = (u16::try_from(img.width), u16::try_from(img.height)) else {
        return Err(err(format!(
            "{}×{} is larger than JPEG's 65535×65535",
            img.width, img.height
        )));
    };
    if w == 0 || h == 0 {
        return Err(err("the picture is empty".into()));
    }
    // Compressed size is well under a byte per pixel at preview qualities.
    let mut out = Vec::with_capacity(img.width * img.height / 2);
    let mut enc = jpeg_encoder::Encoder::new(&mut out, quality.clamp(1, 100));
    enc.set_sampling_factor(jpeg_encoder::SamplingFactor::F_2_2);
    enc.encode(&img.data, w, h, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| err(e.to_string()))?;
    Ok(out)
}

/// Encodes a 16-bit RGB picture; only PNG holds 16 bits.
pub fn encode_rgb16(img: &RgbImage<u16>, format: PictureFormat) -> Result<Vec<u8>, PictureError> {
    if format != PictureFormat::Png {
        return Err(PictureError::Unsupported {
            what: "16-bit pictures",
            format: format.name(),
            instead: "PNG",
        });
    }
    // The `image` encoder takes native-endian samples and writes PNG's big-endian itself.
    let bytes: Vec<u8> = img.data.iter().flat_map(|v| v.to_ne_bytes()).collect();
    encode_png(
        &bytes,
        img.width,
        img.height,
        image::ExtendedColorType::Rgb16,
    )
}

/// A grey 8-bit RGB picture of per-pixel values in `0..=1` (e.g. merge confidence), row-major,
/// origin top-left; values outside are clamped.
pub fn grey_picture(
    width: usize,
    height: usize,
    values: &[f32],
) -> Result<RgbImage<u8>, PictureError> {
    let data = values
        .iter()
        .flat_map(|v| {
            let g = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
            [g, g, g]
        })
        .collect();
    RgbImage::from_vec(width, height, data).ok_or(PictureError::Size {
        width,
        height,
        len: values.len(),
    })
}

fn encode_png(
    data: &[u8],
    w: usize,
    h: usize,
    ct: image::ExtendedColorType,
) -> Result<Vec<u8>, PictureError> {
    use image::ImageEncoder;
    let err = |reason: String| PictureError::Encode {
        format: "PNG",
        reason,
    };
    let (Ok(w32), Ok(h32)) = (u32::try_from(w), u32::try_from(h)) else {
        return Err(err(format!("{w}×{h} is too large")));
    };
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(data, w32, h32, ct)
        .map_err(|e| err(e.to_string()))?;
    Ok(out)
}
