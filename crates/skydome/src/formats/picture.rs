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
///
/// Pictures of more than one [strip](jpeg_strip_rows) are encoded strip by strip (in parallel
/// with the `parallel` feature) and joined with restart markers into one baseline JPEG; the
/// strips depend only on the size, so the bytes are the same on any number of threads.
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
    if u16::try_from(img.width).is_err() || u16::try_from(img.height).is_err() {
        return Err(err(format!(
            "{}×{} is larger than JPEG's 65535×65535",
            img.width, img.height
        )));
    }
    if img.width == 0 || img.height == 0 {
        return Err(err("the picture is empty".into()));
    }
    let quality = quality.clamp(1, 100);
    let rows = jpeg_strip_rows(img.width);
    if img.height <= rows {
        return encode_jpeg_plain(&img.data, img.width, img.height, quality);
    }
    let strip_bytes = 3 * img.width * rows;
    let encode = |strip: &[u8]| {
        let h = strip.len() / (3 * img.width);
        encode_jpeg_plain(strip, img.width, h, quality)
    };
    #[cfg(feature = "parallel")]
    let strips: Vec<Result<Vec<u8>, PictureError>> = {
        use rayon::prelude::*;
        img.data.par_chunks(strip_bytes).map(encode).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let strips: Vec<Result<Vec<u8>, PictureError>> =
        img.data.chunks(strip_bytes).map(encode).collect();
    let strips = strips.into_iter().collect::<Result<Vec<_>, _>>()?;
    let interval = (img.width.div_ceil(JPEG_MCU) * rows / JPEG_MCU) as u16;
    join_jpeg_strips(&strips, img.height as u16, interval)
        .ok_or_else(|| err("the strip encoder wrote an unexpected stream".into()))
}

/// The side of a 4:2:0 MCU, in pixels.
const JPEG_MCU: usize = 16;

/// Rows per strip of [`encode_jpeg`] for pictures `width` pixels wide: whole MCU rows, about
/// 2¹⁸ pixels a strip (enough strips to share among threads, few enough that the restart
/// markers cost nothing), and at most 65535 MCUs, the largest restart interval.
fn jpeg_strip_rows(width: usize) -> usize {
    let per_mcu_row = width.div_ceil(JPEG_MCU);
    let wanted = (1usize << 18).div_ceil(JPEG_MCU * width.max(1));
    let most = (usize::from(u16::MAX) / per_mcu_row).max(1);
    JPEG_MCU * wanted.clamp(1, most)
}

/// One baseline 4:2:0 JPEG of `data` (`width × height` RGB, sizes already checked).
fn encode_jpeg_plain(
    data: &[u8],
    width: usize,
    height: usize,
    quality: u8,
) -> Result<Vec<u8>, PictureError> {
    // Compressed size is well under a byte per pixel at preview qualities.
    let mut out = Vec::with_capacity(width * height / 2);
    let mut enc = jpeg_encoder::Encoder::new(&mut out, quality);
    enc.set_sampling_factor(jpeg_encoder::SamplingFactor::F_2_2);
    enc.encode(
        data,
        width as u16,
        height as u16,
        jpeg_encoder::ColorType::Rgb,
    )
    .map_err(|e| PictureError::Encode {
        format: "JPEG",
        reason: e.to_string(),
    })?;
    Ok(out)
}

/// Joins separately encoded strips (same width, quality and tables; all but the last
/// `interval` MCUs long) into one JPEG of `height` rows: the first strip's headers with its
/// frame height set to `height` and a restart interval (DRI) added, then each strip's entropy
/// coded data, separated by the restart markers RST0…RST7 in turn (ITU-T T.81). At a restart
/// a decoder resets the DC predictors, which is where each strip's encoder started; each
/// strip's data already ends on a byte boundary padded with ones, as a restart needs.
///
/// Written by hand because no JPEG encoder crate encodes on several threads. `None` when a
/// strip is not the stream `jpeg-encoder` writes (SOI, segments, SOS, data, EOI).
fn join_jpeg_strips(strips: &[Vec<u8>], height: u16, interval: u16) -> Option<Vec<u8>> {
    const SOF0: u8 = 0xC0;
    const SOS: u8 = 0xDA;
    /// The offset of the SOS marker and of the entropy-coded data after its header.
    fn split(jpeg: &[u8]) -> Option<(usize, usize)> {
        if jpeg.get(..2)? != [0xFF, 0xD8] || jpeg.get(jpeg.len().checked_sub(2)?..)? != [0xFF, 0xD9]
        {
            return None;
        }
        let mut at = 2;
        loop {
            let (&ff, &marker) = (jpeg.get(at)?, jpeg.get(at + 1)?);
            let len = usize::from(u16::from_be_bytes([*jpeg.get(at + 2)?, *jpeg.get(at + 3)?]));
            if ff != 0xFF || len < 2 {
                return None;
            }
            if marker == SOS {
                return Some((at, at + 2 + len));
            }
            at += 2 + len;
        }
    }
    let (first, rest) = strips.split_first()?;
    let (sos, data) = split(first)?;
    let total: usize = strips.iter().map(Vec::len).sum();
    let mut out = Vec::with_capacity(total + 6 + 2 * strips.len());
    out.extend_from_slice(&first[..sos]);
    // The frame header's height: SOF0, length, precision, then the height.
    let mut at = 2;
    let mut patched = false;
    while at + 7 <= sos {
        let len = usize::from(u16::from_be_bytes([out[at + 2], out[at + 3]]));
        if out[at + 1] == SOF0 {
            out[at + 5..at + 7].copy_from_slice(&height.to_be_bytes());
            patched = true;
        }
        at += 2 + len;
    }
    if !patched {
        return None;
    }
    out.extend_from_slice(&[0xFF, 0xDD, 0x00, 0x04]);
    out.extend_from_slice(&interval.to_be_bytes());
    out.extend_from_slice(&first[sos..data]);
    out.extend_from_slice(&first[data..first.len() - 2]);
    for (i, strip) in rest.iter().enumerate() {
        out.extend_from_slice(&[0xFF, 0xD0 + (i % 8) as u8]);
        let (_, data) = split(strip)?;
        out.extend_from_slice(&strip[data..strip.len() - 2]);
    }
    out.extend_from_slice(&[0xFF, 0xD9]);
    Some(out)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth colour ramp with a noise texture, `w × h`.
    fn picture(w: usize, h: usize) -> RgbImage<u8> {
        let mut img = RgbImage::<u8>::new(w, h);
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        for y in 0..h {
            for x in 0..w {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let n = (state % 24) as usize;
                let i = 3 * (y * w + x);
                img.data[i] = ((x * 200 / w) + n) as u8;
                img.data[i + 1] = ((y * 200 / h) + n) as u8;
                img.data[i + 2] = (((x + y) * 100 / (w + h)) + 2 * n) as u8;
            }
        }
        img
    }

    fn decode(jpeg: &[u8]) -> (u32, u32, Vec<u8>) {
        let img = image::load_from_memory_with_format(jpeg, image::ImageFormat::Jpeg)
            .expect("decodes")
            .to_rgb8();
        (img.width(), img.height(), img.into_raw())
    }

    #[test]
    fn strips_joined_with_restart_markers_decode_like_one_encode() {
        // Heights: one MCU row short of a strip, several strips with an uneven last one
        // (more than 8, so the RST markers wrap), and an odd width.
        for (w, h) in [(640, 100), (640, 4000), (333, 9000)] {
            let img = picture(w, h);
            let rows = jpeg_strip_rows(w);
            let strips = h.div_ceil(rows);
            let joined = encode_rgb8(&img, PictureFormat::Jpeg { quality: 92 }).unwrap();
            let plain = encode_jpeg_plain(&img.data, w, h, 92).unwrap();
            assert_eq!(joined == plain, strips == 1, "{w}×{h}: {strips} strips");
            let (jw, jh, jd) = decode(&joined);
            let (pw, ph, pd) = decode(&plain);
            assert_eq!((jw, jh), (w as u32, h as u32));
            assert_eq!((pw, ph), (w as u32, h as u32));
            assert!(jd == pd, "{w}×{h}: the joined strips decode differently");
            // One restart marker between each two strips.
            let markers = joined
                .windows(2)
                .filter(|p| p[0] == 0xFF && (0xD0..=0xD7).contains(&p[1]))
                .count();
            assert_eq!(markers, strips - 1, "{w}×{h}");
        }
    }

    #[test]
    fn strip_rows_are_whole_mcus_within_the_restart_limit() {
        for w in [1, 15, 16, 17, 640, 2448, 4032, 20_000, 65_535] {
            let rows = jpeg_strip_rows(w);
            assert!(
                rows >= JPEG_MCU && rows.is_multiple_of(JPEG_MCU),
                "{w}: {rows}"
            );
            assert!(
                w.div_ceil(JPEG_MCU) * rows / JPEG_MCU <= usize::from(u16::MAX),
                "{w}"
            );
        }
        assert_eq!(jpeg_strip_rows(2448), 112);
    }

    #[test]
    fn a_stream_that_is_not_a_jpeg_is_not_joined() {
        let img = picture(64, 64);
        let good = encode_jpeg_plain(&img.data, 64, 64, 90).unwrap();
        assert!(join_jpeg_strips(&[good.clone(), good.clone()], 128, 4).is_some());
        assert!(join_jpeg_strips(&[good.clone(), vec![0xFF, 0xD8, 0xFF, 0xD9]], 128, 4).is_none());
        assert!(join_jpeg_strips(&[good[..good.len() - 2].to_vec()], 64, 4).is_none());
        assert!(join_jpeg_strips(&[], 64, 4).is_none());
    }
}
