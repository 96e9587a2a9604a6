//! The TIFF structure of an EXIF block: a lenient reader that re-encodes what it can read, and the
//! plain writer both it and [`crate::formats::exif`] use.
//!
//! Python's `piexif` (common on Raspberry Pi sky cameras) writes the Exif, GPS and Interop IFDs
//! *without* their 4-byte "next IFD" link — their values start right after the last entry — so
//! a strict reader (kamadak-exif: "Unexpected next IFD") takes the first value's bytes for a link
//! and stops, while Pillow, exifread and exiftool ignore sub-IFD links. [`relink`] reads IFD0,
//! the Exif IFD and the GPS IFD entry by entry, never following a sub-IFD's link, skips entries
//! that point outside the block, and writes the entries again in the plain layout of EXIF 2.32
//! (CIPA DC-008): a little-endian TIFF header, IFD0 with the pointers to the Exif IFD (tag
//! 0x8769) and the GPS IFD (0x8825), each IFD's entries sorted by tag, values over four bytes
//! after their IFD at even offsets, every next-IFD link 0 — which any reader takes. IFD1 (the
//! thumbnail), the Interop IFD and `MakerNote` are left out: nothing in skydome reads them.

/// TIFF type ASCII.
pub const ASCII: u16 = 2;
/// TIFF type SHORT.
pub const SHORT: u16 = 3;
/// TIFF type LONG.
pub const LONG: u16 = 4;
/// TIFF type RATIONAL.
pub const RATIONAL: u16 = 5;
/// TIFF type BYTE.
pub const BYTE: u16 = 1;

/// One IFD entry; `data` holds the value's bytes in little-endian order.
#[derive(Debug, Clone)]
pub struct Entry {
    /// The tag.
    pub tag: u16,
    /// The TIFF type (1 BYTE, 2 ASCII, 3 SHORT, 4 LONG, 5 RATIONAL, …).
    pub kind: u16,
    /// Number of values.
    pub count: u32,
    /// The values' bytes, little-endian.
    pub data: Vec<u8>,
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

/// Lays out a TIFF block: header (8 bytes) · IFD0 (`ifd0` and the pointers) · Exif IFD · GPS
/// IFD (when not empty), entries sorted by tag, every next-IFD link 0.
pub fn encode_ifds(mut ifd0: Vec<Entry>, mut exif: Vec<Entry>, mut gps: Vec<Entry>) -> Vec<u8> {
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
