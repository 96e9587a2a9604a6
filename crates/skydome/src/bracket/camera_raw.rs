//! Recognising camera RAW files (CR2, CR3, NEF, ARW, RAF, ORF, RW2, …) without decoding them.
//!
//! Every build recognises them: without the `raw-rawler` feature a camera RAW file is refused
//! with a message that says how to read it (instead of, as a plain TIFF reader would, decoding
//! the small preview some of them carry in their first IFD as if it were the photo); with the
//! feature it is handed to [`super::rawler`].
//!
//! **How.** By content where the format has a signature of its own (CR2, CR3, RAF, ORF, RW2,
//! MRW, CRW, X3F); by the file name's extension for the formats whose container is a plain TIFF
//! (NEF, ARW, PEF, SRW, …: nothing in the first bytes tells them from a TIFF a user exported).
//! DNG is not a camera RAW here: it is read by [`super::dng`] in every build.

/// The camera RAW format of a file, as an upper-case name (`"CR2"`, `"NEF"`, …), `None` for
/// anything else (JPEG, PNG, TIFF, DNG, unknown bytes).
pub fn camera_raw_kind(name: &str, bytes: &[u8]) -> Option<&'static str> {
    if let Some(kind) = by_signature(bytes) {
        return Some(kind);
    }
    // JPEG and PNG are never camera RAW, whatever they are called.
    if bytes.starts_with(&[0xFF, 0xD8]) || bytes.starts_with(b"\x89PNG") {
        return None;
    }
    if super::dng::is_dng(bytes) {
        return None;
    }
    let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
    TIFF_LIKE
        .iter()
        .find(|(e, _)| *e == ext)
        .map(|&(_, kind)| kind)
}

/// Formats recognised by their first bytes.
fn by_signature(b: &[u8]) -> Option<&'static str> {
    let tiff = b.starts_with(b"II*\0") || b.starts_with(b"MM\0*");
    if tiff && b.get(8..10) == Some(b"CR") {
        return Some("CR2");
    }
    if b.get(4..8) == Some(b"ftyp") && b.get(8..12) == Some(b"crx ") {
        return Some("CR3");
    }
    if b.starts_with(b"FUJIFILMCCD-RAW") {
        return Some("RAF");
    }
    if b.starts_with(b"IIRO") || b.starts_with(b"IIRS") || b.starts_with(b"MMOR") {
        return Some("ORF");
    }
    if b.starts_with(b"IIU\0") {
        return Some("RW2");
    }
    if b.starts_with(b"\0MRM") {
        return Some("MRW");
    }
    if b.get(6..14) == Some(b"HEAPCCDR") {
        return Some("CRW");
    }
    if b.starts_with(b"FOVb") {
        return Some("X3F");
    }
    None
}

/// Camera RAW formats in a TIFF container, by lower-case extension.
const TIFF_LIKE: [(&str, &str); 17] = [
    ("nef", "NEF"),
    ("nrw", "NRW"),
    ("arw", "ARW"),
    ("srf", "SRF"),
    ("sr2", "SR2"),
    ("pef", "PEF"),
    ("srw", "SRW"),
    ("erf", "ERF"),
    ("kdc", "KDC"),
    ("dcr", "DCR"),
    ("dcs", "DCS"),
    ("3fr", "3FR"),
    ("fff", "FFF"),
    ("iiq", "IIQ"),
    ("mos", "MOS"),
    ("mef", "MEF"),
    ("rwl", "RWL"),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signatures_and_extensions() {
        assert_eq!(
            camera_raw_kind("a.cr2", b"II*\0\x10\0\0\0CR\x02\0"),
            Some("CR2")
        );
        assert_eq!(
            camera_raw_kind("x", b"\0\0\0\x18ftypcrx \0\0\0\x01"),
            Some("CR3")
        );
        assert_eq!(camera_raw_kind("x", b"FUJIFILMCCD-RAW 0201"), Some("RAF"));
        assert_eq!(camera_raw_kind("x.NEF", b"MM\0*\0\0\0\x08"), Some("NEF"));
        // A TIFF called .tif, a JPEG called .nef: not camera RAW.
        assert_eq!(camera_raw_kind("x.tif", b"MM\0*\0\0\0\x08"), None);
        assert_eq!(camera_raw_kind("x.nef", b"\xFF\xD8\xFF\xE0"), None);
        assert_eq!(camera_raw_kind("noext", b"II*\0\x08\0\0\0"), None);
    }
}
