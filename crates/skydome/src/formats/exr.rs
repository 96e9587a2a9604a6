//! OpenEXR (`.exr`) writer and reader for RGB radiance maps, through the `exr` crate.
//!
//! # What is written
//!
//! One single-part scan-line image, channels `R`, `G`, `B` as 16-bit half or 32-bit float
//! ([`ExrPixelType`]), data window = display window = `(0, 0)…(W−1, H−1)`. Compression
//! ([`ExrCompression`]) is lossless: ZIP in blocks of 16 lines by default (OpenEXR's own
//! default, read by every implementation), or PIZ (wavelet, usually smaller and faster to
//! write for noisy photographic data), ZIPS (one line per block), RLE, or none.
//!
//! Blocks are compressed and decompressed on several threads when the `exr` crate's `rayon`
//! feature is on (the CLI turns it on; the library leaves it off so wasm builds stay
//! single-threaded).
//!
//! **Half precision.** Values are rounded to the nearest half (11-bit significand, relative
//! error ≤ 2⁻¹¹ for normal halves, i.e. ≥ 6.1·10⁻⁵). Finite values beyond ±65504 are clamped to
//! ±65504 rather than becoming infinite (a sun in absolute units can exceed that: use float);
//! NaN and ±∞ are kept. Float pixels are stored exactly.
//!
//! # Metadata mapping
//!
//! Standard OpenEXR attributes are used where one means the same thing; the rest are custom
//! string attributes prefixed `skydome:` (readers that do not know them ignore them).
//!
//! | [`HdrMeta`] field | attribute | type |
//! |---|---|---|
//! | `capdate` | `capDate` (standard: local time `YYYY:MM:DD HH:MM:SS`) | string |
//! | `gmt` | `skydome:gmt`, and standard `utcOffset` (seconds, UTC = local + offset) when `capdate` is also set | string, float |
//! | `software` (default `skydome <version>`) | `software` | string |
//! | `other` | `comments` (standard), the lines joined by `\n` | string |
//! | `exposure` | `skydome:exposure` (Radiance's multiplier; *not* `expTime`, which is a shutter time) | string |
//! | `view` | `skydome:view` (Radiance view options) | string |
//! | `sun` | `skydome:sun` = `-Y y +X x`, `skydome:sunAzimuth`, `skydome:sunElevation` (degrees, azimuth from north towards east) | strings |
//! | `north` | `skydome:north` = `-Y y +X x` | string |
//!
//! Pixel positions use the same convention as the `.hdr` header lines (see [`super::rgbe`]):
//! continuous coordinates, origin at the top-left corner, pixel centres at `+0.5`. Numbers are
//! written in shortest round-trip form, so [`read_exr`] gives back exactly the metadata that
//! [`encode_exr`] wrote. When a foreign file has `capDate` and `utcOffset` but no
//! `skydome:gmt`, `gmt` is computed from them.
//!
//! # Reading any EXR
//!
//! [`read_exr`] reads the first part (layer) that has `R`, `G` and `B` channels (any other
//! channels, e.g. `A`, are ignored; half, float and uint samples become `f32`), at its largest
//! resolution level (mip/rip-mapped and tiled files work). A part with only a `Y` channel is
//! read as grey (`R = G = B = Y`). Luminance/chroma files (`Y`, `RY`, `BY`, subsampled) and files
//! with neither are refused with an error that names the channels found.
//!
//! **Data window ≠ display window.** The returned image covers the *display window* (the frame
//! the picture was composed in, so pixel positions such as a sun mark refer to it); pixels of
//! the display window outside the data window are 0 and data outside the display window is
//! dropped. [`ExrFile::data_window`] tells where real data was. Both windows count against
//! [`Limits::max_pixels`] before any pixel is decoded.
//!
//! Header attributes are written in name order (as OpenEXR's own library writes them), so the
//! same image and metadata always give the same bytes.
//!
//! References: OpenEXR file layout and standard attributes,
//! <https://openexr.com/en/latest/OpenEXRFileLayout.html>,
//! <https://openexr.com/en/latest/StandardAttributes.html>.

use std::io::{Cursor, Write};

use ::exr::meta::attribute::{AttributeValue, IntegerBounds, Text};
use ::exr::meta::header::Header;
use ::exr::meta::MetaData;
use ::exr::prelude::{
    f16, Compression, Encoding, Image, Layer, LayerAttributes, LineOrder, ReadChannels, ReadLayers,
    ReadSpecificChannel, SpecificChannels, Vec2, WritableImage,
};

use super::rgbe::{fmt_num, validate_meta};
use super::{HdrMeta, PixelPoint, SunMark};
use crate::image::HdrImage;

/// Errors reading or writing OpenEXR files.
#[derive(Debug, thiserror::Error)]
pub enum ExrError {
    /// The underlying writer failed.
    #[error("could not write the .exr data: {0}")]
    Io(#[from] std::io::Error),
    /// The `exr` crate could not decode or encode the file.
    #[error("cannot process this OpenEXR file: {0}; the file is damaged or uses a feature that is not supported")]
    Exr(String),
    /// No part has `R`, `G`, `B` (or a lone `Y`) channels.
    #[error("the OpenEXR file has no R, G, B channels (channels found: {0}); export it as RGB")]
    NoRgb(String),
    /// Luminance/chroma files are refused.
    #[error("luminance/chroma OpenEXR files (Y, RY, BY) are not supported; convert to RGB first (e.g. `oiiotool in.exr -o out.exr`)")]
    LuminanceChroma,
    /// A window exceeds [`Limits::max_pixels`].
    #[error("the OpenEXR {window} window is {width}×{height} pixels, more than the limit of {max} pixels; raise Limits::max_pixels if the file is trusted")]
    TooLarge {
        /// `data` or `display`.
        window: &'static str,
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// The limit in pixels.
        max: u64,
    },
    /// The image to write is inconsistent.
    #[error("cannot write this image as .exr: {0}")]
    BadImage(String),
    /// The metadata cannot be written.
    #[error("cannot write this metadata into .exr attributes: {0}")]
    BadMeta(String),
}

impl From<::exr::error::Error> for ExrError {
    fn from(e: ::exr::error::Error) -> Self {
        match e {
            ::exr::error::Error::Io(io) => ExrError::Exr(io.to_string()),
            other => ExrError::Exr(other.to_string()),
        }
    }
}

/// Sample type of the written channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ExrPixelType {
    /// 16-bit half float: half the size, ~3 significant digits, range ±65504.
    #[default]
    Half,
    /// 32-bit float: exact.
    Float,
}

crate::named_enum!(ExrPixelType, "EXR pixel type", [Half => "half", Float => "float"]);

/// Lossless compression of the written blocks. Measured on a 6 MP synthetic merged sky-dome,
/// half float, 2 cores (the EXR part of `skydome merge --exr`): ZIP 8.0 MB in 0.54 s, PIZ
/// 7.4 MB in 0.31 s, RLE 16 MB in 0.22 s, none 36 MB in 0.27 s.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ExrCompression {
    /// No compression.
    None,
    /// Run-length encoding.
    Rle,
    /// Deflate, one scan line per block.
    Zips,
    /// Deflate, 16 scan lines per block (OpenEXR's default).
    #[default]
    Zip,
    /// Wavelet plus Huffman, 32 scan lines per block.
    Piz,
}

crate::named_enum!(ExrCompression, "EXR compression", [None => "none", Rle => "rle", Zips => "zips", Zip => "zip", Piz => "piz"]);

impl ExrCompression {
    fn to_exr(self) -> Compression {
        match self {
            ExrCompression::None => Compression::Uncompressed,
            ExrCompression::Rle => Compression::RLE,
            ExrCompression::Zips => Compression::ZIP1,
            ExrCompression::Zip => Compression::ZIP16,
            ExrCompression::Piz => Compression::PIZ,
        }
    }
}

/// How [`encode_exr`] writes: sample type and compression. An [`ExrPixelType`] converts into
/// options with the default compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExrOptions {
    /// Sample type of the channels.
    pub pixel_type: ExrPixelType,
    /// Block compression.
    pub compression: ExrCompression,
}

impl From<ExrPixelType> for ExrOptions {
    fn from(pixel_type: ExrPixelType) -> Self {
        Self {
            pixel_type,
            ..Self::default()
        }
    }
}

/// Decoding limits against hostile or damaged files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest accepted data or display window, in pixels (default 100 000 000).
    pub max_pixels: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_pixels: 100_000_000,
        }
    }
}

/// A pixel rectangle in OpenEXR's absolute coordinates (may be negative).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// Left column.
    pub x: i64,
    /// Top row.
    pub y: i64,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl From<IntegerBounds> for Window {
    fn from(b: IntegerBounds) -> Self {
        Window {
            x: i64::from(b.position.0),
            y: i64::from(b.position.1),
            width: b.size.0,
            height: b.size.1,
        }
    }
}

/// A decoded OpenEXR file.
#[derive(Debug, Clone, PartialEq)]
pub struct ExrFile {
    /// The display window's pixels (see the module doc), origin top-left.
    pub image: HdrImage,
    /// Metadata recovered from the attributes (see the mapping table in the module doc).
    pub meta: HdrMeta,
    /// Where the stored data lies, in absolute coordinates.
    pub data_window: Window,
    /// The display window, in absolute coordinates; `image` covers exactly this.
    pub display_window: Window,
    /// True when the file had only a `Y` channel and was read as grey.
    pub grey: bool,
    /// Every string attribute of the part that was read, as `(name, value)`, sorted by name.
    pub text_attributes: Vec<(String, String)>,
}

const ATTR_EXPOSURE: &str = "skydome:exposure";
const ATTR_GMT: &str = "skydome:gmt";
const ATTR_VIEW: &str = "skydome:view";
const ATTR_SUN: &str = "skydome:sun";
const ATTR_SUN_AZIMUTH: &str = "skydome:sunAzimuth";
const ATTR_SUN_ELEVATION: &str = "skydome:sunElevation";
const ATTR_NORTH: &str = "skydome:north";

fn text(name: &str, value: &str) -> Result<Text, ExrError> {
    Text::new_or_none(value).ok_or_else(|| {
        ExrError::BadMeta(format!(
            "{name} `{value}` has characters outside Latin-1, which OpenEXR text cannot hold"
        ))
    })
}

const DATE_FORMAT: &[time::format_description::BorrowedFormatItem<'static>] =
    time::macros::format_description!("[year]:[month]:[day] [hour]:[minute]:[second]");

/// `gmt − capdate` in seconds, when both parse.
fn utc_offset(capdate: &str, gmt: &str) -> Option<f32> {
    let local = time::PrimitiveDateTime::parse(capdate, DATE_FORMAT).ok()?;
    let utc = time::PrimitiveDateTime::parse(gmt, DATE_FORMAT).ok()?;
    let s = (utc - local).whole_seconds();
    // Real offsets are within ±26 h; anything else is a date typo, not an offset.
    (s.abs() <= 26 * 3600).then_some(s as f32)
}

fn gmt_from_offset(capdate: &str, offset: f32) -> Option<String> {
    let local = time::PrimitiveDateTime::parse(capdate, DATE_FORMAT).ok()?;
    if !offset.is_finite() || offset.abs() > 26.0 * 3600.0 {
        return None;
    }
    let utc = local + time::Duration::seconds(offset.round() as i64);
    utc.format(DATE_FORMAT).ok()
}

fn layer_attributes(meta: &HdrMeta) -> Result<LayerAttributes, ExrError> {
    let mut a = LayerAttributes::default();
    let software = meta
        .software
        .clone()
        .unwrap_or_else(|| format!("skydome {}", crate::VERSION));
    a.software_name = Some(text("SOFTWARE", &software)?);
    if let Some(d) = &meta.capdate {
        a.capture_date = Some(text("CAPDATE", d)?);
    }
    if !meta.other.is_empty() {
        a.comments = Some(text("extra header line", &meta.other.join("\n"))?);
    }
    let mut custom: Vec<(&str, String)> = Vec::new();
    if let Some(e) = meta.exposure {
        custom.push((ATTR_EXPOSURE, fmt_num(e)));
    }
    if let Some(g) = &meta.gmt {
        custom.push((ATTR_GMT, g.clone()));
        if let Some(c) = &meta.capdate {
            a.utc_offset = utc_offset(c, g);
        }
    }
    if let Some(v) = &meta.view {
        custom.push((ATTR_VIEW, v.clone()));
    }
    if let Some(s) = &meta.sun {
        custom.push((ATTR_SUN, s.pixel.to_string()));
        if let Some(az) = s.azimuth_deg {
            custom.push((ATTR_SUN_AZIMUTH, fmt_num(az)));
        }
        if let Some(el) = s.elevation_deg {
            custom.push((ATTR_SUN_ELEVATION, fmt_num(el)));
        }
    }
    if let Some(n) = &meta.north {
        custom.push((ATTR_NORTH, n.to_string()));
    }
    for (name, value) in custom {
        a.other
            .insert(Text::from(name), AttributeValue::Text(text(name, &value)?));
    }
    Ok(a)
}

/// Encodes `image` with `meta` as a complete OpenEXR file in memory (see the module doc).
/// Everything is validated first, so an error never leaves partial output.
pub fn encode_exr(
    image: &HdrImage,
    meta: &HdrMeta,
    opts: impl Into<ExrOptions>,
) -> Result<Vec<u8>, ExrError> {
    let opts = opts.into();
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return Err(ExrError::BadImage(format!("it is empty ({w}×{h} pixels)")));
    }
    if w.checked_mul(h).and_then(|n| n.checked_mul(3)) != Some(image.data.len()) {
        return Err(ExrError::BadImage(format!(
            "{w}×{h} pixels need {} samples but the buffer holds {}",
            3u128 * w as u128 * h as u128,
            image.data.len()
        )));
    }
    if w > i32::MAX as usize || h > i32::MAX as usize {
        return Err(ExrError::BadImage(format!(
            "{w}×{h} pixels exceed OpenEXR's 32-bit coordinates"
        )));
    }
    validate_meta(meta, w, h).map_err(ExrError::BadMeta)?;
    let attrs = layer_attributes(meta)?;
    let encoding = Encoding {
        compression: opts.compression.to_exr(),
        blocks: ::exr::prelude::Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let data = &image.data;
    let at = move |p: Vec2<usize>| {
        let i = 3 * (p.1 * w + p.0);
        (data[i], data[i + 1], data[i + 2])
    };
    let mut out = Cursor::new(Vec::with_capacity(image.data.len() * 2));
    match opts.pixel_type {
        ExrPixelType::Float => {
            let layer = Layer::new((w, h), attrs, encoding, SpecificChannels::rgb(at));
            Image::from_layer(layer).write().to_buffered(&mut out)?;
        }
        ExrPixelType::Half => {
            let half = |v: f32| {
                f16::from_f32(if v.is_finite() {
                    v.clamp(-65504.0, 65504.0)
                } else {
                    v
                })
            };
            let at_half = move |p: Vec2<usize>| {
                let (r, g, b) = at(p);
                (half(r), half(g), half(b))
            };
            let layer = Layer::new((w, h), attrs, encoding, SpecificChannels::rgb(at_half));
            Image::from_layer(layer).write().to_buffered(&mut out)?;
        }
    }
    let mut bytes = out.into_inner();
    sort_header_attributes(&mut bytes).map_err(ExrError::Exr)?;
    Ok(bytes)
}

/// Puts the attributes of a single-part file's header in name order, in place.
///
/// The `exr` crate keeps non-standard attributes (ours: `skydome:…`) in a `HashMap` with a
/// random seed and writes them in its iteration order, so two runs would write the same
/// attributes in different orders. OpenEXR's own library writes every header in name order
/// (its `Header` is a `std::map`); doing the same here makes the bytes reproducible. The
/// header keeps its length, so the offset table after it stays valid.
fn sort_header_attributes(bytes: &mut [u8]) -> Result<(), String> {
    const START: usize = 8; // magic number and version field
    let bad = || "internal: cannot parse the header just written".to_string();
    let flags = bytes.get(4..8).ok_or_else(bad)?;
    if flags[1] & 0x10 != 0 {
        return Err("internal: multi-part header written".into());
    }
    let cstr_end = |from: usize| -> Result<usize, String> {
        let rel = bytes
            .get(from..)
            .and_then(|b| b.iter().position(|&c| c == 0))
            .ok_or_else(bad)?;
        Ok(from + rel + 1)
    };
    // Each record: name\0 type\0 size (i32 LE) value; a lone \0 ends the header.
    let mut records: Vec<(usize, usize, usize)> = Vec::new(); // (start, name end, record end)
    let mut at = START;
    while *bytes.get(at).ok_or_else(bad)? != 0 {
        let name_end = cstr_end(at)?;
        let type_end = cstr_end(name_end)?;
        let size = bytes.get(type_end..type_end + 4).ok_or_else(bad)?;
        let size = i32::from_le_bytes([size[0], size[1], size[2], size[3]]);
        let size = usize::try_from(size).map_err(|_| bad())?;
        let end = type_end + 4 + size;
        if end > bytes.len() {
            return Err(bad());
        }
        records.push((at, name_end, end));
        at = end;
    }
    let mut sorted = records.clone();
    sorted.sort_by(|a, b| bytes[a.0..a.1].cmp(&bytes[b.0..b.1]));
    let header: Vec<u8> = sorted
        .iter()
        .flat_map(|&(s, _, e)| bytes[s..e].iter().copied())
        .collect();
    bytes[START..START + header.len()].copy_from_slice(&header);
    Ok(())
}

/// Writes `image` with `meta` as OpenEXR to `w` (see [`encode_exr`]); nothing is written
/// unless encoding succeeded.
pub fn write_exr<W: Write>(
    mut w: W,
    image: &HdrImage,
    meta: &HdrMeta,
    opts: impl Into<ExrOptions>,
) -> Result<(), ExrError> {
    let bytes = encode_exr(image, meta, opts)?;
    w.write_all(&bytes)?;
    w.flush()?;
    Ok(())
}

fn channel_names(h: &Header) -> Vec<String> {
    h.channels.list.iter().map(|c| c.name.to_string()).collect()
}

fn has(h: &Header, name: &str) -> bool {
    h.channels.list.iter().any(|c| c.name == *name)
}

fn text_attributes(h: &Header) -> Vec<(String, String)> {
    let mut v = Vec::new();
    let a = &h.own_attributes;
    for (name, t) in [
        ("capDate", &a.capture_date),
        ("comments", &a.comments),
        ("owner", &a.owner),
        ("software", &a.software_name),
    ] {
        if let Some(t) = t {
            v.push((name.to_owned(), t.to_string()));
        }
    }
    for (name, value) in a.other.iter().chain(h.shared_attributes.other.iter()) {
        if let AttributeValue::Text(t) = value {
            v.push((name.to_string(), t.to_string()));
        }
    }
    v.sort();
    v
}

fn meta_from_header(h: &Header, texts: &[(String, String)]) -> HdrMeta {
    let get = |k: &str| texts.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
    let num = |k: &str| {
        get(k)
            .and_then(|v| v.trim().parse::<f64>().ok())
            .filter(|v| v.is_finite())
    };
    let a = &h.own_attributes;
    let capdate = a.capture_date.as_ref().map(|t| t.to_string());
    let gmt = get(ATTR_GMT).or_else(|| {
        capdate
            .as_deref()
            .zip(a.utc_offset)
            .and_then(|(c, o)| gmt_from_offset(c, o))
    });
    let sun = get(ATTR_SUN)
        .and_then(|s| s.parse::<PixelPoint>().ok())
        .map(|pixel| SunMark {
            pixel,
            azimuth_deg: num(ATTR_SUN_AZIMUTH),
            elevation_deg: num(ATTR_SUN_ELEVATION),
        });
    HdrMeta {
        exposure: num(ATTR_EXPOSURE).filter(|e| *e > 0.0),
        capdate,
        gmt,
        view: get(ATTR_VIEW),
        sun,
        north: get(ATTR_NORTH).and_then(|s| s.parse::<PixelPoint>().ok()),
        software: a.software_name.as_ref().map(|t| t.to_string()),
        other: a
            .comments
            .as_ref()
            .map(|c| c.to_string().split('\n').map(str::to_owned).collect())
            .unwrap_or_default(),
    }
}

fn check_window(window: &'static str, b: &IntegerBounds, max: u64) -> Result<(), ExrError> {
    if (b.size.0 as u128) * (b.size.1 as u128) > u128::from(max) {
        return Err(ExrError::TooLarge {
            window,
            width: b.size.0,
            height: b.size.1,
            max,
        });
    }
    Ok(())
}

/// The decoded data window: its pixels, origin, size.
struct DataPixels {
    width: usize,
    data: Vec<f32>,
}

fn create<C>(size: Vec2<usize>, _: &C) -> DataPixels {
    DataPixels {
        width: size.0,
        data: vec![0.0; 3 * size.0 * size.1],
    }
}

/// Reads the first RGB (or grey `Y`) part of an OpenEXR file held in memory (see the module
/// doc for the rules).
pub fn read_exr(bytes: &[u8], limits: &Limits) -> Result<ExrFile, ExrError> {
    let meta_data = MetaData::read_from_buffered(Cursor::new(bytes), false)?;
    let rgb_part = meta_data
        .headers
        .iter()
        .position(|h| !h.deep && has(h, "R") && has(h, "G") && has(h, "B"));
    let (index, grey) = match rgb_part {
        Some(i) => (i, false),
        None => {
            if meta_data
                .headers
                .iter()
                .any(|h| has(h, "Y") && (has(h, "RY") || has(h, "BY")))
            {
                return Err(ExrError::LuminanceChroma);
            }
            match meta_data
                .headers
                .iter()
                .position(|h| !h.deep && has(h, "Y"))
            {
                Some(i) => (i, true),
                None => {
                    let names: Vec<String> =
                        meta_data.headers.iter().flat_map(channel_names).collect();
                    let names = if names.is_empty() {
                        "none".to_owned()
                    } else {
                        names.join(", ")
                    };
                    return Err(ExrError::NoRgb(names));
                }
            }
        }
    };
    let header = &meta_data.headers[index];
    let data_bounds = header.data_window();
    let display_bounds = header.shared_attributes.display_window;
    check_window("data", &data_bounds, limits.max_pixels)?;
    check_window("display", &display_bounds, limits.max_pixels)?;
    let texts = text_attributes(header);
    let meta = meta_from_header(header, &texts);

    let (pixels, position) = if grey {
        let set = |p: &mut DataPixels, pos: Vec2<usize>, (y,): (f32,)| {
            let i = 3 * (pos.1 * p.width + pos.0);
            p.data[i..i + 3].copy_from_slice(&[y, y, y]);
        };
        let img = ::exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .specific_channels()
            .required("Y")
            .collect_pixels(create, set)
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(bytes))?;
        (
            img.layer_data.channel_data.pixels,
            img.layer_data.attributes.layer_position,
        )
    } else {
        let set = |p: &mut DataPixels, pos: Vec2<usize>, (r, g, b): (f32, f32, f32)| {
            let i = 3 * (pos.1 * p.width + pos.0);
            p.data[i..i + 3].copy_from_slice(&[r, g, b]);
        };
        let img = ::exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .rgb_channels(create, set)
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(bytes))?;
        (
            img.layer_data.channel_data.pixels,
            img.layer_data.attributes.layer_position,
        )
    };

    let data_window = Window {
        x: i64::from(position.0),
        y: i64::from(position.1),
        width: pixels.width,
        height: if pixels.width == 0 {
            0
        } else {
            pixels.data.len() / (3 * pixels.width)
        },
    };
    let display_window = Window::from(display_bounds);
    let image = place_in_display_window(pixels, data_window, display_window);
    Ok(ExrFile {
        image,
        meta,
        data_window,
        display_window,
        grey,
        text_attributes: texts,
    })
}

fn place_in_display_window(px: DataPixels, data: Window, display: Window) -> HdrImage {
    if data == display {
        return HdrImage {
            width: display.width,
            height: display.height,
            data: px.data,
        };
    }
    let mut out = HdrImage::new(display.width, display.height);
    // Overlap of the two windows, in absolute coordinates.
    let x0 = data.x.max(display.x);
    let x1 = (data.x + data.width as i64).min(display.x + display.width as i64);
    let y0 = data.y.max(display.y);
    let y1 = (data.y + data.height as i64).min(display.y + display.height as i64);
    if x0 >= x1 || y0 >= y1 {
        return out;
    }
    let n = 3 * (x1 - x0) as usize;
    for y in y0..y1 {
        let src = 3 * ((y - data.y) as usize * data.width + (x0 - data.x) as usize);
        let dst = 3 * ((y - display.y) as usize * display.width + (x0 - display.x) as usize);
        out.data[dst..dst + n].copy_from_slice(&px.data[src..src + n]);
    }
    out
}
