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
//! **Reading what strict readers refuse** ([`relink`]): Python's `piexif` (common on Raspberry Pi
//! sky cameras) writes the Exif, GPS and Interop IFDs *without* their 4-byte "next IFD" link —
//! their values start right after the last entry — so a strict reader (kamadak-exif: "Unexpected
//! next IFD") takes the first value's bytes for a link and stops, while Pillow, exifread and
//! exiftool ignore sub-IFD links. [`relink`] reads IFD0, the Exif IFD and the GPS IFD entry by
//! entry, never following a sub-IFD's link, skips entries that point outside the block, and
//! writes the entries again in the layout above (values converted to little-endian), which any
//! reader takes. IFD1 (the thumbnail), the Interop IFD and `MakerNote` are left out: nothing in
//! skydome reads them.

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

const ASCII: u16 = 2;
const SHORT: u16 = 3;
const LONG: u16 = 4;
const RATIONAL: u16 = 5;
const BYTE: u16 = 1;

/// One IFD entry; `data` holds the value's bytes in little-endian order.
#[derive(Debug, Clone)]
struct Entry {
    tag: u16,
    kind: u16,
    count: u32,
    data: Vec<u8>,
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

/// Serialises one IFD at `offset` (its value area follows it); `next` is the next-IFD link.
fn ifd_bytes(entries: &[Entry], offset: u32, next: u32) -> Vec<u8> {
    let head = 2 + 12 * entries.len() + 4;
    let mut out = Vec::new();
    let mut values = Vec::new();
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for e in entries {
        out.extend_from_slice(&e.tag.to_le_bytes());
        out.extend_from_slice(&e.kind.to_le_bytes());
        out.extend_from_slice(&e.count.to_le_bytes());
        if e.data.len() <= 4 {
            let mut v = e.data.clone();
            v.resize(4, 0);
            out.extend_from_slice(&v);
        } else {
            let at = offset + (head + values.len()) as u32;
            out.extend_from_slice(&at.to_le_bytes());
            values.extend_from_slice(&e.data);
            if values.len() % 2 == 1 {
                values.push(0);
            }
        }
    }
    out.extend_from_slice(&next.to_le_bytes());
    out.extend_from_slice(&values);
    out
}

fn ifd_len(entries: &[Entry]) -> u32 {
    let values: usize = entries
        .iter()
        .filter(|e| e.data.len() > 4)
        .map(|e| e.data.len().next_multiple_of(2))
        .sum();
    (2 + 12 * entries.len() + 4 + values) as u32
}

fn pointer(tag: u16, at: u32) -> Entry {
    Entry {
        tag,
        kind: LONG,
        count: 1,
        data: at.to_le_bytes().to_vec(),
    }
}

/// The EXIF block as TIFF bytes (`II*\0` …), without the `Exif\0\0` prefix.
pub fn encode_tiff(f: &ExifFields) -> Result<Vec<u8>, ExifWriteError> {
    let mut exif = Vec::new();
    if let Some(t) = f.exposure_time_s.filter(|t| t.is_finite() && *t > 0.0) {
        exif.push(rationals(0x829A, &[time_rational(t)]));
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

/// Lays out a TIFF block: header (8 bytes) · IFD0 (`ifd0` and the pointers) · Exif IFD · GPS
/// IFD (when not empty), entries sorted by tag, every next-IFD link 0.
fn encode_ifds(mut ifd0: Vec<Entry>, mut exif: Vec<Entry>, mut gps: Vec<Entry>) -> Vec<u8> {
    for v in [&mut ifd0, &mut exif, &mut gps] {
        v.sort_by_key(|e| e.tag);
        v.dedup_by_key(|e| e.tag);
    }
    let pointers = 1 + usize::from(!gps.is_empty());
    let mut sized = ifd0.clone();
    sized.extend((0..pointers).map(|_| pointer(0, 0)));
    let exif_at = 8 + ifd_len(&sized);
    let gps_at = exif_at + ifd_len(&exif);
    ifd0.push(pointer(0x8769, exif_at));
    if !gps.is_empty() {
        ifd0.push(pointer(0x8825, gps_at));
    }
    ifd0.sort_by_key(|e| e.tag);
    let mut out = b"II*\0".to_vec();
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend(ifd_bytes(&ifd0, 8, 0));
    out.extend(ifd_bytes(&exif, exif_at, 0));
    if !gps.is_empty() {
        out.extend(ifd_bytes(&gps, gps_at, 0));
    }
    out
}

/// Bytes per element of a TIFF type, `None` for unknown types.
fn type_size(kind: u16) -> Option<usize> {
    match kind {
        1 | 2 | 6 | 7 => Some(1),
        3 | 8 => Some(2),
        4 | 9 | 11 => Some(4),
        5 | 10 | 12 => Some(8),
        _ => None,
    }
}

/// Reads one IFD leniently: its entries (values converted to little-endian) and nothing else —
/// no link is followed. Entries of unknown type or pointing outside `tiff` are skipped.
fn read_ifd(tiff: &[u8], at: usize, big: bool) -> Vec<Entry> {
    let u16_at = |o: usize| -> Option<u16> {
        let b = tiff.get(o..o + 2)?;
        Some(if big {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        })
    };
    let u32_at = |o: usize| -> Option<u32> {
        let b = tiff.get(o..o + 4)?;
        Some(if big {
            u32::from_be_bytes([b[0], b[1], b[2], b[3]])
        } else {
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        })
    };
    let Some(n) = u16_at(at) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for i in 0..usize::from(n).min(1000) {
        let e = at + 2 + 12 * i;
        let (Some(tag), Some(kind), Some(count)) = (u16_at(e), u16_at(e + 2), u32_at(e + 4)) else {
            break;
        };
        let Some(size) = type_size(kind) else {
            continue;
        };
        let Some(len) = (count as usize)
            .checked_mul(size)
            .filter(|l| *l <= tiff.len())
        else {
            continue;
        };
        let bytes = if len <= 4 {
            tiff.get(e + 8..e + 8 + len)
        } else {
            u32_at(e + 8).and_then(|o| tiff.get(o as usize..o as usize + len))
        };
        let Some(bytes) = bytes else {
            continue;
        };
        let mut data = bytes.to_vec();
        // Rationals are two 4-byte numbers; everything else swaps per element.
        let unit = if matches!(kind, 5 | 10) { 4 } else { size };
        if big && unit > 1 {
            data.chunks_exact_mut(unit).for_each(<[u8]>::reverse);
        }
        out.push(Entry {
            tag,
            kind,
            count,
            data,
        });
    }
    out
}

/// A TIFF-structured EXIF block (`II`/`MM` …) read leniently and written again in the plain
/// layout of [`encode_tiff`] (see the module docs): IFD0, the Exif IFD and the GPS IFD with
/// every entry that could be read. `None` when `tiff` has no TIFF header.
pub fn relink(tiff: &[u8]) -> Option<Vec<u8>> {
    let big = match tiff.get(..4)? {
        b"II*\0" => false,
        b"MM\0*" => true,
        _ => return None,
    };
    let b = tiff.get(4..8)?;
    let ifd0_at = if big {
        u32::from_be_bytes([b[0], b[1], b[2], b[3]])
    } else {
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    } as usize;
    let ifd0 = read_ifd(tiff, ifd0_at, big);
    let sub = |tag: u16| -> Vec<Entry> {
        ifd0.iter()
            .find(|e| e.tag == tag && e.kind == LONG && e.data.len() == 4)
            .map(|e| {
                let at = u32::from_le_bytes([e.data[0], e.data[1], e.data[2], e.data[3]]);
                read_ifd(tiff, at as usize, big)
            })
            .unwrap_or_default()
    };
    let exif: Vec<Entry> = sub(0x8769)
        .into_iter()
        .filter(|e| !matches!(e.tag, 0xA005 | 0x927C))
        .collect();
    let gps = sub(0x8825);
    let ifd0: Vec<Entry> = ifd0
        .into_iter()
        .filter(|e| !matches!(e.tag, 0x8769 | 0x8825 | 0x014A))
        .collect();
    Some(encode_ifds(ifd0, exif, gps))
}

/// The TIFF block of a JPEG's EXIF `APP1` segment (after `Exif\0\0`), when it has one.
pub fn jpeg_exif_block(jpeg: &[u8]) -> Option<&[u8]> {
    if !jpeg.starts_with(&[0xFF, 0xD8]) {
        return None;
    }
    let mut i = 2;
    while let Some(&[0xFF, marker, hi, lo]) = jpeg.get(i..i + 4) {
        if marker == 0xDA || marker == 0xD9 {
            return None;
        }
        let len = usize::from(u16::from_be_bytes([hi, lo]));
        let body = jpeg.get(i + 4..i + 2 + len)?;
        if marker == 0xE1 && body.starts_with(b"Exif\0\0") {
            return Some(&body[6..]);
        }
        i += 2 + len;
    }
    None
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
        assert!(insert_into_jpeg(b"PNG", &f).is_err());
        assert!(ascii(1, "x", "é").is_err());
    }
}
