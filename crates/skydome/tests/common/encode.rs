//! Encoding test frames the way cameras and scanners hand them over: JPEG, PNG and TIFF at 8
//! and 16 bits, grey, with alpha, CMYK JPEG, and EXIF (exposure time, ISO, f-number,
//! orientation) embedded as a camera writes it (JPEG `APP1 Exif`, PNG `eXIf`).
//!
//! Included by path in the library's test binary (`tests/lib/main.rs`) and in
//! `fuzz/examples/seeds.rs`, which writes the fuzzers' seed files with it.
#![allow(dead_code)]

use std::io::Cursor;

use exif::{experimental::Writer, Field, In, Rational, Tag, Value};

/// EXIF fields to embed; `None` fields are left out.
#[derive(Debug, Clone, Copy, Default)]
pub struct Exif {
    /// `ExposureTime` in seconds (written as a rational `1/n` below 1 s, `n/1000` above).
    pub time_s: Option<f64>,
    /// `PhotographicSensitivity`.
    pub iso: Option<u16>,
    /// `FNumber`.
    pub f_number: Option<f64>,
    /// `Orientation` (1..=8).
    pub orientation: Option<u16>,
}

fn rational(v: f64) -> Rational {
    if v < 1.0 {
        Rational {
            num: 1,
            denom: (1.0 / v).round() as u32,
        }
    } else {
        Rational {
            num: (v * 1000.0).round() as u32,
            denom: 1000,
        }
    }
}

/// The EXIF block as a little-endian TIFF structure (what follows `Exif\0\0` in a JPEG).
pub fn exif_tiff(e: &Exif) -> Vec<u8> {
    let mut fields = Vec::new();
    if let Some(t) = e.time_s {
        fields.push(Field {
            tag: Tag::ExposureTime,
            ifd_num: In::PRIMARY,
            value: Value::Rational(vec![rational(t)]),
        });
    }
    if let Some(n) = e.f_number {
        fields.push(Field {
            tag: Tag::FNumber,
            ifd_num: In::PRIMARY,
            value: Value::Rational(vec![Rational {
                num: (n * 10.0).round() as u32,
                denom: 10,
            }]),
        });
    }
    if let Some(iso) = e.iso {
        fields.push(Field {
            tag: Tag::PhotographicSensitivity,
            ifd_num: In::PRIMARY,
            value: Value::Short(vec![iso]),
        });
    }
    if let Some(o) = e.orientation {
        fields.push(Field {
            tag: Tag::Orientation,
            ifd_num: In::PRIMARY,
            value: Value::Short(vec![o]),
        });
    }
    let mut w = Writer::new();
    for f in &fields {
        w.push_field(f);
    }
    let mut out = Cursor::new(Vec::new());
    w.write(&mut out, true).expect("EXIF of plain fields");
    out.into_inner()
}

/// A JPEG of interleaved 8-bit RGB at `quality`, with `exif` in an `APP1` segment after SOI.
pub fn jpeg(rgb: &[u8], w: usize, h: usize, quality: u8, exif: Option<&Exif>) -> Vec<u8> {
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, quality)
        .encode(rgb, w as u16, h as u16, jpeg_encoder::ColorType::Rgb)
        .expect("JPEG encoding");
    match exif {
        Some(e) => with_jpeg_exif(&out, e),
        None => out,
    }
}

/// A CMYK JPEG (as prepress software saves one) of the same picture: `C = 255 − R`,
/// `M = 255 − G`, `Y = 255 − B`, `K = 0` (the encoder writes Adobe's inverted convention).
pub fn jpeg_cmyk(rgb: &[u8], w: usize, h: usize, exif: Option<&Exif>) -> Vec<u8> {
    let cmyk: Vec<u8> = rgb
        .chunks_exact(3)
        .flat_map(|p| [255 - p[0], 255 - p[1], 255 - p[2], 0])
        .collect();
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, 95)
        .encode(&cmyk, w as u16, h as u16, jpeg_encoder::ColorType::Cmyk)
        .expect("CMYK JPEG encoding");
    match exif {
        Some(e) => with_jpeg_exif(&out, e),
        None => out,
    }
}

/// `jpeg` with an `APP1 Exif` segment inserted after its start-of-image marker.
pub fn with_jpeg_exif(jpeg: &[u8], e: &Exif) -> Vec<u8> {
    let tiff = exif_tiff(e);
    let len = (2 + 6 + tiff.len()) as u16;
    let mut out = Vec::with_capacity(jpeg.len() + len as usize + 2);
    out.extend_from_slice(&jpeg[..2]);
    out.extend_from_slice(&[0xFF, 0xE1]);
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(b"Exif\0\0");
    out.extend_from_slice(&tiff);
    out.extend_from_slice(&jpeg[2..]);
    out
}

/// Pixel layouts a PNG or TIFF can be written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// 8-bit RGB.
    Rgb8,
    /// 16-bit RGB (each 8-bit code `z` written as `257 z`).
    Rgb16,
    /// 8-bit grey (the green channel).
    Grey8,
    /// 16-bit grey (the green channel, `257 z`).
    Grey16,
    /// 8-bit RGB plus an opaque alpha channel.
    Rgba8,
}

fn dynamic(rgb: &[u8], w: usize, h: usize, layout: Layout) -> image::DynamicImage {
    let (w, h) = (w as u32, h as u32);
    let wide = |v: u8| u16::from(v) * 257;
    match layout {
        Layout::Rgb8 => image::RgbImage::from_raw(w, h, rgb.to_vec()).map(Into::into),
        Layout::Rgb16 => image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(
            w,
            h,
            rgb.iter().map(|&v| wide(v)).collect(),
        )
        .map(Into::into),
        Layout::Grey8 => {
            image::GrayImage::from_raw(w, h, rgb.chunks_exact(3).map(|p| p[1]).collect())
                .map(Into::into)
        }
        Layout::Grey16 => image::ImageBuffer::<image::Luma<u16>, _>::from_raw(
            w,
            h,
            rgb.chunks_exact(3).map(|p| wide(p[1])).collect(),
        )
        .map(Into::into),
        Layout::Rgba8 => image::RgbaImage::from_raw(
            w,
            h,
            rgb.chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
        )
        .map(Into::into),
    }
    .expect("buffer matches the size")
}

/// A PNG of the picture in `layout`, with `exif` in an `eXIf` chunk before the image data.
pub fn png(rgb: &[u8], w: usize, h: usize, layout: Layout, exif: Option<&Exif>) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    dynamic(rgb, w, h, layout)
        .write_to(&mut out, image::ImageFormat::Png)
        .expect("PNG encoding");
    let png = out.into_inner();
    match exif {
        Some(e) => with_png_chunk(&png, b"eXIf", &exif_tiff(e)),
        None => png,
    }
}

/// A TIFF of the picture in `layout` (no EXIF: a scanner's or a RAW converter's TIFF).
pub fn tiff(rgb: &[u8], w: usize, h: usize, layout: Layout) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    dynamic(rgb, w, h, layout)
        .write_to(&mut out, image::ImageFormat::Tiff)
        .expect("TIFF encoding");
    out.into_inner()
}

/// `png` with a chunk inserted right after `IHDR` (which is always first, 8 + 25 bytes in).
pub fn with_png_chunk(png: &[u8], kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let at = 8 + 25;
    let mut chunk = Vec::with_capacity(data.len() + 12);
    chunk.extend_from_slice(&(data.len() as u32).to_be_bytes());
    chunk.extend_from_slice(kind);
    chunk.extend_from_slice(data);
    let crc = crc32(&chunk[4..]);
    chunk.extend_from_slice(&crc.to_be_bytes());
    let mut out = png[..at].to_vec();
    out.extend_from_slice(&chunk);
    out.extend_from_slice(&png[at..]);
    out
}

/// CRC-32 (ISO 3309, as PNG uses), bit by bit: the test frames are small.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}
