//! EXIF as sky-imaging stations write it.
//!
//! **Writing** ([`encode_tiff`], [`insert_into_jpeg`]): the capture fields a station records
//! (exposure time, capture time with sub-seconds and UTC offset, GPS position) as a JPEG `APP1`
//! segment, so that synthetic station days (`skydome synth --captures`) and tests carry the
//! metadata real cameras write; skydome never rewrites a user's photo. The layout is the plain one
//! of EXIF 2.32 (CIPA DC-008): a little-endian TIFF header, IFD0 with `Orientation` and the
//! pointers to the Exif IFD (tag 0x8769) and the GPS IFD (0x8825), each IFD's entries sorted by
//! tag, values over four bytes stored after their IFD at even offsets, every "next IFD" link 0.
//! Example: a 1/250 s frame taken at 2026-06-21 12:30:05.25 +02:00 writes `ExposureTime` = 1/250
//! (RATIONAL), `DateTimeOriginal` = `2026:06:21 12:30:05`, `SubSecTimeOriginal` = `25`,
//! `OffsetTimeOriginal` = `+02:00`.
//!
//! The TIFF layout and the lenient reader for blocks strict readers refuse (piexif's) are
//! [`crate::bracket::tiff`]'s.

use crate::bracket::tiff::{encode_ifds, Entry, ASCII, BYTE, RATIONAL, SHORT};
pub use crate::bracket::tiff::{jpeg_exif_block, relink};

/// The fields written; `None` fields are left out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExifFields {
    /// Exposure time, seconds (written as `1/n` when `1/t` is a whole number, else in
    /// microseconds).
    pub exposure_time_s: Option<f64>,
    /// Local capture time `YYYY:MM:DD HH:MM:SS` (`DateTimeOriginal`).
    pub datetime_original: Option<String>,
    /// Digits of the fraction of a second (`SubSecTimeOriginal`, e.g. `"25"` for 0.25 s).
    pub subsec_original: Option<String>,
    /// UTC offset `±HH:MM` (`OffsetTimeOriginal`).
    pub offset_time_original: Option<String>,
    /// Latitude and longitude, degrees (north and east positive).
    pub gps_deg: Option<(f64, f64)>,
    /// ISO speed (`PhotographicSensitivity`, a whole number 1..=65535).
    pub iso: Option<f64>,
    /// Aperture f-number (`FNumber`, written in 1/100).
    pub f_number: Option<f64>,
}

/// Errors of [`insert_into_jpeg`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExifWriteError {
    /// The bytes are not a JPEG (no start-of-image marker).
    #[error("not a JPEG file (no start-of-image marker); EXIF is written into JPEGs only")]
    NotJpeg,
    /// A text field that EXIF cannot hold (not ASCII, or too long).
    #[error("EXIF field {0} must be ASCII text of at most 64 characters")]
    BadText(&'static str),
}

fn ascii(tag: u16, name: &'static str, s: &str) -> Result<Entry, ExifWriteError> {
    if !s.is_ascii() || s.len() > 64 {
        return Err(ExifWriteError::BadText(name));
    }
    let mut data = s.as_bytes().to_vec();
    data.push(0);
    Ok(Entry {
        tag,
        kind: ASCII,
        count: data.len() as u32,
        data,
    })
}

fn rationals(tag: u16, v: &[(u32, u32)]) -> Entry {
    let mut data = Vec::with_capacity(8 * v.len());
    for (n, d) in v {
        data.extend_from_slice(&n.to_le_bytes());
        data.extend_from_slice(&d.to_le_bytes());
    }
    Entry {
        tag,
        kind: RATIONAL,
        count: v.len() as u32,
        data,
    }
}

/// A shutter time as a rational: `1/n` when `1/t` is whole, else microseconds.
fn time_rational(t: f64) -> (u32, u32) {
    let inv = 1.0 / t;
    if t < 1.0 && (inv - inv.round()).abs() < 1e-6 * inv {
        (1, inv.round() as u32)
    } else if t >= 1.0 && (t - t.round()).abs() < 1e-9 {
        (t.round() as u32, 1)
    } else {
        ((t * 1e6).round().min(u32::MAX as f64) as u32, 1_000_000)
    }
}

/// Degrees as EXIF's degrees, minutes, seconds (seconds in 1/10000).
fn dms(v: f64) -> [(u32, u32); 3] {
    let v = v.abs();
    let d = v.floor();
    let m = ((v - d) * 60.0).floor();
    let s = ((v - d) * 60.0 - m) * 60.0;
    [
        (d as u32, 1),
        (m as u32, 1),
        ((s * 10_000.0).round() as u32, 10_000),
    ]
}

/// The EXIF block as TIFF bytes (`II*\0` …), without the `Exif\0\0` prefix.
pub fn encode_tiff(f: &ExifFields) -> Result<Vec<u8>, ExifWriteError> {
    let mut exif = Vec::new();
    if let Some(t) = f.exposure_time_s.filter(|t| t.is_finite() && *t > 0.0) {
        exif.push(rationals(0x829A, &[time_rational(t)]));
    }
    if let Some(n) = f
        .f_number
        .filter(|n| n.is_finite() && *n > 0.0 && *n < 10_000.0)
    {
        exif.push(rationals(0x829D, &[((n * 100.0).round() as u32, 100)]));
    }
    if let Some(iso) = f.iso.filter(|s| s.is_finite() && *s >= 1.0) {
        exif.push(Entry {
            tag: 0x8827,
            kind: SHORT,
            count: 1,
            data: (iso.round().min(65535.0) as u16).to_le_bytes().to_vec(),
        });
    }
    exif.push(Entry {
        tag: 0x9000,
        kind: 7,
        count: 4,
        data: b"0232".to_vec(),
    });
    if let Some(s) = &f.datetime_original {
        exif.push(ascii(0x9003, "DateTimeOriginal", s)?);
    }
    if let Some(s) = &f.offset_time_original {
        exif.push(ascii(0x9011, "OffsetTimeOriginal", s)?);
    }
    if let Some(s) = &f.subsec_original {
        exif.push(ascii(0x9291, "SubSecTimeOriginal", s)?);
    }
    let gps: Vec<Entry> = match f.gps_deg {
        Some((lat, lon)) => vec![
            Entry {
                tag: 0x0000,
                kind: BYTE,
                count: 4,
                data: vec![2, 3, 0, 0],
            },
            ascii(0x0001, "GPSLatitudeRef", if lat < 0.0 { "S" } else { "N" })?,
            rationals(0x0002, &dms(lat)),
            ascii(0x0003, "GPSLongitudeRef", if lon < 0.0 { "W" } else { "E" })?,
            rationals(0x0004, &dms(lon)),
        ],
        None => Vec::new(),
    };
    let orientation = Entry {
        tag: 0x0112,
        kind: SHORT,
        count: 1,
        data: 1u16.to_le_bytes().to_vec(),
    };
    Ok(encode_ifds(vec![orientation], exif, gps))
}

/// `jpeg` with an EXIF `APP1` segment holding `f` right after the start-of-image marker (an
/// existing EXIF segment is kept after it; readers take the first).
pub fn insert_into_jpeg(jpeg: &[u8], f: &ExifFields) -> Result<Vec<u8>, ExifWriteError> {
    if !jpeg.starts_with(&[0xFF, 0xD8]) {
        return Err(ExifWriteError::NotJpeg);
    }
    let tiff = encode_tiff(f)?;
    let len = (2 + 6 + tiff.len()) as u16;
    let mut out = Vec::with_capacity(jpeg.len() + len as usize + 2);
    out.extend_from_slice(&[0xFF, 0xD8, 0xFF, 0xE1]);
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(b"Exif\0\0");
    out.extend(tiff);
    out.extend_from_slice(&jpeg[2..]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shutter_times_as_rationals() {
        assert_eq!(time_rational(1.0 / 250.0), (1, 250));
        assert_eq!(time_rational(2.0), (2, 1));
        assert_eq!(time_rational(0.0123), (12_300, 1_000_000));
        let [d, m, s] = dms(-47.5042);
        assert_eq!((d, m), ((47, 1), (30, 1)));
        assert!((s.0 as f64 / s.1 as f64 - 15.12).abs() < 1e-3);
    }

    #[test]
    fn written_fields_read_back_with_kamadak_exif() {
        use ::exif::{In, Tag};
        let f = ExifFields {
            exposure_time_s: Some(1.0 / 250.0),
            datetime_original: Some("2026:06:21 12:30:05".into()),
            subsec_original: Some("25".into()),
            offset_time_original: Some("+02:00".into()),
            gps_deg: Some((47.5, -8.25)),
            iso: Some(64.0),
            f_number: Some(1.8),
        };
        let ex = ::exif::Reader::new()
            .read_raw(encode_tiff(&f).unwrap())
            .unwrap();
        let text = |t| {
            ex.get_field(t, In::PRIMARY)
                .unwrap()
                .display_value()
                .to_string()
        };
        assert_eq!(text(Tag::ExposureTime), "1/250");
        assert_eq!(text(Tag::DateTimeOriginal), "2026-06-21 12:30:05");
        assert_eq!(text(Tag::SubSecTimeOriginal), "\"25\"");
        assert_eq!(text(Tag::OffsetTimeOriginal), "\"+02:00\"");
        assert_eq!(text(Tag::GPSLongitudeRef), "W");
        assert_eq!(text(Tag::PhotographicSensitivity), "64");
        assert_eq!(text(Tag::FNumber), "1.8");
        assert!(insert_into_jpeg(b"PNG", &f).is_err());
        assert!(ascii(1, "x", "é").is_err());
    }
}
