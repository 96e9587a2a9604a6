//! File formats: one module per format, each over `Read`/`Write` (never paths) so the
//! command line and the web app share them.
//!
//! - [`rgbe`]: Radiance RGBE `.hdr` (reader: flat, old-style and new-style RLE, `#?RADIANCE`
//!   and `#?RGBE`; writer: new-style RLE with skydome's header lines).
//! - [`exr`]: OpenEXR RGB half/float with the same metadata as string attributes.
//! - The JSON of a camera profile and a lens profile is read and written by the profiles'
//!   own `to_json`/`from_json` ([`crate::camera::CameraProfile`],
//!   [`crate::fisheye::LensProfile`]).
//! - [`exif`]: EXIF as stations write it: a writer for the capture fields (synthetic days) and a
//!   lenient re-encoder for blocks that strict readers refuse (piexif's sub-IFDs).
//! - [`picture`]: 8-bit JPEG/PNG and 16-bit PNG display pictures (previews, overlays, maps).

use crate::image::HdrImage;

pub mod exif;
pub mod exr;
pub mod picture;
pub mod rgbe;

pub use crate::image::PixelPoint;

/// The sun as marked in an output file.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SunMark {
    /// Where the sun's centre is in the image.
    pub pixel: PixelPoint,
    /// Azimuth in degrees from true north towards east (0 = N, 90 = E), when known.
    pub azimuth_deg: Option<f64>,
    /// Elevation above the horizon in degrees, when known.
    pub elevation_deg: Option<f64>,
}

/// Metadata that skydome writes into (and reads back from) `.hdr` and `.exr` files.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HdrMeta {
    /// Radiance's `EXPOSURE=`: stored pixel = radiance × exposure. `None` means 1.
    pub exposure: Option<f64>,
    /// `CAPDATE=` local capture time, formatted `YYYY:MM:DD HH:MM:SS`.
    pub capdate: Option<String>,
    /// `GMT=` capture time in UTC, formatted `YYYY:MM:DD HH:MM:SS`.
    pub gmt: Option<String>,
    /// `VIEW=` Radiance view options for projected domes (e.g. `-vta -vh 180 -vv 180`).
    pub view: Option<String>,
    /// The sun (`#SUN=` line and an azimuth/elevation comment).
    pub sun: Option<SunMark>,
    /// The north point on the horizon circle (`#NORTH=` line).
    pub north: Option<PixelPoint>,
    /// `SOFTWARE=` line; writers fill in `skydome <version>` when `None`.
    pub software: Option<String>,
    /// Any other header lines, verbatim (without the trailing newline).
    pub other: Vec<String>,
}

/// The header comment that marks absolute radiance (Radiance's W·sr⁻¹·m⁻²), as
/// [`crate::pipeline`] writes it after a luminance or illuminance reading.
pub const ABSOLUTE_UNITS_LINE: &str = "#UNITS= absolute";

impl HdrMeta {
    /// True when the header says the values are absolute Radiance units (an
    /// [`ABSOLUTE_UNITS_LINE`]): luminance is then `179 × (0.265 R + 0.670 G + 0.065 B)` cd/m².
    pub fn is_absolute(&self) -> bool {
        self.other
            .iter()
            .any(|l| l.starts_with(ABSOLUTE_UNITS_LINE))
    }
}

/// A radiance-map file format skydome writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RadianceFormat {
    /// Radiance RGBE `.hdr`, new-style RLE.
    Hdr,
    /// OpenEXR, with the given channel type and compression.
    Exr(exr::ExrOptions),
}

impl RadianceFormat {
    /// The format for a file extension: `hdr`, `pic`, `rgbe` → RGBE; `exr` → OpenEXR with
    /// `exr_options`; `None` for anything else.
    pub fn from_extension(ext: &str, exr_options: exr::ExrOptions) -> Option<Self> {
        match ext.to_ascii_lowercase().as_str() {
            "hdr" | "pic" | "rgbe" => Some(Self::Hdr),
            "exr" => Some(Self::Exr(exr_options)),
            _ => None,
        }
    }
}

/// Errors reading or writing a radiance map in either format.
#[derive(Debug, thiserror::Error)]
pub enum RadianceError {
    /// Radiance RGBE.
    #[error(transparent)]
    Rgbe(#[from] rgbe::RgbeError),
    /// OpenEXR.
    #[error(transparent)]
    Exr(#[from] exr::ExrError),
    /// Neither format's signature.
    #[error("not a Radiance .hdr or OpenEXR file (unrecognised first bytes)")]
    Unrecognised,
}

/// An encoded radiance map and what the encoder had to decide.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodedRadiance {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// Things the caller should tell the user (e.g. a switch from half to float).
    pub warnings: Vec<String>,
}

/// Largest finite half-float value.
pub const HALF_MAX: f32 = 65504.0;

/// Encodes `image` with `meta` as `format`. OpenEXR half channels turn values above
/// [`HALF_MAX`] into infinity, so when the image holds such values the channels are written as
/// 32-bit float instead, with a warning.
pub fn encode_radiance(
    image: &HdrImage,
    meta: &HdrMeta,
    format: RadianceFormat,
) -> Result<EncodedRadiance, RadianceError> {
    match format {
        RadianceFormat::Hdr => Ok(EncodedRadiance {
            bytes: rgbe::encode_rgbe(image, meta)?,
            warnings: Vec::new(),
        }),
        RadianceFormat::Exr(mut o) => {
            let mut warnings = Vec::new();
            if o.pixel_type == exr::ExrPixelType::Half {
                let max = image
                    .data
                    .iter()
                    .copied()
                    .filter(|v| v.is_finite())
                    .fold(0.0f32, f32::max);
                if max > HALF_MAX {
                    o.pixel_type = exr::ExrPixelType::Float;
                    warnings.push(format!(
                        "values up to {max:.3e} exceed half-float range; writing 32-bit float channels"
                    ));
                }
            }
            Ok(EncodedRadiance {
                bytes: exr::encode_exr(image, meta, o)?,
                warnings,
            })
        }
    }
}

/// A radiance map read by [`read_radiance`].
#[derive(Debug, Clone, PartialEq)]
pub struct RadianceFile {
    /// Radiance: the stored values divided by the file's `EXPOSURE` (Radiance's rule).
    pub image: HdrImage,
    /// Metadata from the header.
    pub meta: HdrMeta,
    /// Header lines (`.hdr`) or `name = value` attributes (`.exr`).
    pub header: Vec<String>,
    /// "Radiance RGBE" or "OpenEXR".
    pub format: &'static str,
}

/// Reads a Radiance `.hdr` or OpenEXR file, recognised by its first bytes (not its name), with
/// the formats' default limits. Values are divided by `EXPOSURE` when the header has one.
pub fn read_radiance(bytes: &[u8]) -> Result<RadianceFile, RadianceError> {
    let (mut image, meta, header, format) = if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        let f = exr::read_exr(bytes, &exr::Limits::default())?;
        let header = f
            .text_attributes
            .iter()
            .map(|(k, v)| format!("{k} = {v}"))
            .collect();
        (f.image, f.meta, header, "OpenEXR")
    } else if bytes.starts_with(b"#?") {
        let f = rgbe::decode_rgbe(bytes, &rgbe::Limits::default())?;
        (f.image, f.header.meta, f.header.lines, "Radiance RGBE")
    } else {
        return Err(RadianceError::Unrecognised);
    };
    if let Some(e) = meta
        .exposure
        .filter(|e| e.is_finite() && *e > 0.0 && *e != 1.0)
    {
        let k = (1.0 / e) as f32;
        image.data.iter_mut().for_each(|v| *v *= k);
    }
    Ok(RadianceFile {
        image,
        meta,
        header,
        format,
    })
}
