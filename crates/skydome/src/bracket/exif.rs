//! Metadata read from a photo's EXIF, and the EXIF date-time and UTC-offset formats.

use std::io::Cursor;

use super::DecodedFrame;

/// Parses an EXIF date-time `YYYY:MM:DD HH:MM:SS` (also accepts `-` in the date and a `T`).
pub fn parse_exif_datetime(s: &str) -> Option<time::PrimitiveDateTime> {
    let s = s.trim();
    let (d, t) = s.split_once([' ', 'T'])?;
    let d: Vec<&str> = d.split([':', '-']).collect();
    let t: Vec<&str> = t.split(':').collect();
    if d.len() != 3 || t.len() < 2 {
        return None;
    }
    let month = time::Month::try_from(d[1].parse::<u8>().ok()?).ok()?;
    let date =
        time::Date::from_calendar_date(d[0].parse().ok()?, month, d[2].parse().ok()?).ok()?;
    let sec: f64 = t.get(2).map_or(Some(0.0), |x| x.parse().ok())?;
    let time =
        time::Time::from_hms(t[0].parse().ok()?, t[1].parse().ok()?, sec.floor() as u8).ok()?;
    Some(time::PrimitiveDateTime::new(date, time))
}

/// Parses a UTC offset `±HH:MM`, `±HHMM`, `±HH` or `Z`.
pub fn parse_utc_offset(s: &str) -> Option<time::UtcOffset> {
    let s = s.trim();
    if s == "Z" || s == "z" {
        return Some(time::UtcOffset::UTC);
    }
    let (sign, rest) = match s.as_bytes().first()? {
        b'+' => (1i8, &s[1..]),
        b'-' => (-1i8, &s[1..]),
        _ => return None,
    };
    let digits: String = rest.chars().filter(|c| *c != ':').collect();
    if !digits.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let (h, m) = match digits.len() {
        2 => (digits.parse::<i8>().ok()?, 0),
        4 => (
            digits[..2].parse::<i8>().ok()?,
            digits[2..].parse::<i8>().ok()?,
        ),
        _ => return None,
    };
    time::UtcOffset::from_hms(sign * h, sign * m, 0).ok()
}

/// Parses an ISO 8601 instant with offset, e.g. `2026-06-21T12:30:00+02:00` or `…Z`.
pub fn parse_iso8601(s: &str) -> Option<time::OffsetDateTime> {
    let s = s.trim();
    let split = s
        .char_indices()
        .skip(11)
        .find(|(_, c)| matches!(c, '+' | '-' | 'Z' | 'z'))
        .map(|(i, _)| i)?;
    let local = parse_exif_datetime(&s[..split])?;
    Some(local.assume_offset(parse_utc_offset(&s[split..])?))
}

/// A date and time as EXIF writes it, `YYYY:MM:DD HH:MM:SS` (local time, no offset).
pub fn format_exif_datetime(t: time::PrimitiveDateTime) -> String {
    format!(
        "{:04}:{:02}:{:02} {:02}:{:02}:{:02}",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second()
    )
}

/// An instant as ISO 8601 in UTC, `YYYY-MM-DDTHH:MM:SSZ` (whole seconds).
pub fn format_iso8601_utc(t: time::OffsetDateTime) -> String {
    let u = t.to_offset(time::UtcOffset::UTC);
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}Z",
        u.year(),
        u8::from(u.month()),
        u.day(),
        u.hour(),
        u.minute(),
        u.second()
    )
}

/// A file's EXIF exposure and capture metadata, read without decoding its pixels (what a batch
/// needs to group a folder of frames into captures).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FileMetadata {
    /// Exposure time in seconds, when EXIF has a valid one.
    pub exposure_time_s: Option<f64>,
    /// Capture metadata (time, offset, GPS, camera).
    pub info: super::CaptureInfo,
}

impl FileMetadata {
    /// The capture's local clock reading with its fraction of a second
    /// (`DateTimeOriginal` + `SubSecTimeOriginal`), when EXIF has the time.
    pub fn local_time(&self) -> Option<time::PrimitiveDateTime> {
        let t = parse_exif_datetime(self.info.datetime_original.as_deref()?)?;
        let frac = self
            .info
            .subsec_original
            .as_deref()
            .map(str::trim)
            .filter(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|s| format!("0.{s}").parse::<f64>().ok())
            .unwrap_or(0.0);
        Some(t + time::Duration::seconds_f64(frac))
    }
}

/// Reads a file's EXIF (JPEG, PNG, TIFF bytes; the head of a JPEG is enough) without decoding
/// its pixels. A file without readable EXIF gives empty metadata.
pub fn read_metadata(bytes: &[u8]) -> FileMetadata {
    let mut frame = DecodedFrame::new("", 0, 0, super::Pixels::U8(Vec::new()));
    read_exif(bytes, &mut frame);
    FileMetadata {
        exposure_time_s: frame.exif_time_s,
        info: frame.info,
    }
}

/// Parses the file's EXIF; when the strict reader refuses it, the block re-encoded by
/// [`super::tiff::relink`] (EXIF written by Python's `piexif` has sub-IFDs without
/// their next-IFD link, which kamadak-exif stops at while Pillow, exifread and exiftool read
/// on): what can be read is read.
fn parse(bytes: &[u8]) -> Option<exif::Exif> {
    match exif::Reader::new().read_from_container(&mut Cursor::new(bytes)) {
        Ok(ex) => Some(ex),
        Err(_) => {
            let block = super::tiff::jpeg_exif_block(bytes)?;
            let fixed = super::tiff::relink(block)?;
            exif::Reader::new().read_raw(fixed).ok()
        }
    }
}

/// Fills exposure and capture metadata from the file's EXIF, when it has any.
pub(super) fn read_exif(bytes: &[u8], frame: &mut DecodedFrame) {
    use exif::{In, Tag, Value};
    let Some(ex) = parse(bytes) else {
        return;
    };
    let get = |tag| ex.get_field(tag, In::PRIMARY).map(|f| &f.value);
    let num = |tag| -> Option<f64> {
        let v = match get(tag)? {
            Value::Rational(r) => r.first().map(|r| r.to_f64()),
            Value::SRational(r) => r.first().map(|r| r.to_f64()),
            Value::Short(s) => s.first().map(|&s| f64::from(s)),
            Value::Long(s) => s.first().map(|&s| f64::from(s)),
            // Pillow writes Python floats as DOUBLE.
            Value::Double(d) => d.first().copied(),
            Value::Float(f) => f.first().map(|&f| f64::from(f)),
            _ => None,
        }?;
        (v.is_finite() && v > 0.0).then_some(v)
    };
    let text = |tag| -> Option<String> {
        match get(tag)? {
            Value::Ascii(v) => v
                .first()
                .map(|s| {
                    String::from_utf8_lossy(s)
                        .trim_end_matches('\0')
                        .trim()
                        .to_string()
                })
                .filter(|s| !s.is_empty()),
            _ => None,
        }
    };
    let dms = |tag, reftag| -> Option<f64> {
        let Value::Rational(r) = get(tag)? else {
            return None;
        };
        if r.len() < 3 {
            return None;
        }
        let v = r[0].to_f64() + r[1].to_f64() / 60.0 + r[2].to_f64() / 3600.0;
        let sign = match text(reftag).as_deref() {
            Some("S") | Some("W") => -1.0,
            _ => 1.0,
        };
        v.is_finite().then_some(sign * v)
    };
    frame.exif_time_s = num(Tag::ExposureTime).filter(|&t| t <= 86_400.0);
    frame.f_number = num(Tag::FNumber);
    frame.iso = num(Tag::PhotographicSensitivity);
    let info = &mut frame.info;
    info.make = text(Tag::Make);
    info.model = text(Tag::Model);
    info.datetime_original = text(Tag::DateTimeOriginal);
    info.utc_offset = text(Tag::OffsetTimeOriginal).or_else(|| text(Tag::OffsetTime));
    info.subsec_original = text(Tag::SubSecTimeOriginal);
    info.gps_latitude_deg = dms(Tag::GPSLatitude, Tag::GPSLatitudeRef);
    info.gps_longitude_deg = dms(Tag::GPSLongitude, Tag::GPSLongitudeRef);
    info.white_balance = get(Tag::WhiteBalance).and_then(|v| v.get_uint(0));
    info.orientation = get(Tag::Orientation)
        .and_then(|v| v.get_uint(0))
        .and_then(|o| u16::try_from(o).ok())
        .filter(|o| (1..=8).contains(o))
        .unwrap_or(1);
}
