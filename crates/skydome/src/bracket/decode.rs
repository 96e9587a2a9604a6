//! Decoding one encoded photo into stored-order pixels and metadata, and applying its EXIF
//! orientation.

use std::io::Cursor;

use super::{exif::read_exif, BracketError, DecodeOptions, DecodedFrame, Pixels, RawColour};

/// Decodes one encoded image (JPEG, PNG, TIFF or DNG; camera RAW with the `raw-rawler` feature)
/// and reads its EXIF.
///
/// Pixels stay in stored order; [`assemble`](super::assemble) applies orientation once the whole
/// bracket is known. A DNG gives its demosaiced camera-RGB codes ([`super::dng`]); use
/// [`decode_raw`] to have its colour too.
pub fn decode(
    name: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<DecodedFrame, BracketError> {
    decode_raw(name, bytes, opts).map(|(f, _)| f)
}

/// As [`decode`], with the colour of a RAW frame (DNG, or camera RAW with the `raw-rawler`
/// feature; `None` for every other format). Camera RAW files are recognised by
/// [`super::camera_raw_kind`]; without the feature they are refused with a message saying so.
pub fn decode_raw(
    name: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<(DecodedFrame, Option<RawColour>), BracketError> {
    if bytes.is_empty() {
        return Err(BracketError::Empty {
            file: name.to_string(),
        });
    }
    if super::dng::is_dng(bytes) {
        return super::dng::decode_dng(name, bytes, opts).map(|(f, c)| (f, Some(c)));
    }
    if let Some(kind) = super::camera_raw::camera_raw_kind(name, bytes) {
        #[cfg(all(feature = "raw-rawler", not(target_arch = "wasm32")))]
        {
            let _ = kind;
            return super::rawler_reader::decode_with_rawler(name, bytes, opts)
                .map(|(f, c)| (f, Some(c)));
        }
        #[cfg(not(all(feature = "raw-rawler", not(target_arch = "wasm32"))))]
        return Err(BracketError::CameraRawUnsupported {
            file: name.to_string(),
            kind: kind.to_string(),
        });
    }
    decode_picture(name, bytes, opts).map(|f| (f, None))
}

/// Decodes a JPEG, PNG or TIFF through the `image` crate.
fn decode_picture(
    name: &str,
    bytes: &[u8],
    opts: &DecodeOptions,
) -> Result<DecodedFrame, BracketError> {
    use image::{ImageDecoder, ImageFormat};
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
    let mut frame = DecodedFrame::new(name, w as usize, h as usize, pixels);
    frame.non_srgb_icc = icc.as_deref().and_then(non_srgb_description);
    read_exif(bytes, &mut frame);
    Ok(frame)
}

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

pub(crate) fn orient(w: usize, h: usize, pixels: Pixels, o: u16) -> (usize, usize, Pixels) {
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
