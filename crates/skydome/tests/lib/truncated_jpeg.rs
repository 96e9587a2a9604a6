//! A JPEG cut anywhere before its end-of-image marker is refused by name, never merged with a
//! grey or black remainder (the decoder alone fills the missing rows and says nothing).

use crate::common;
use skydome::bracket::{self, BracketError, DecodeOptions};

/// Cuts `bytes` at `offsets` and checks each cut is refused as a corrupt file named `name`.
fn refuses_every_cut(name: &str, bytes: &[u8], offsets: &[usize]) {
    let opts = DecodeOptions::default();
    bracket::decode(name, bytes, &opts).expect("the whole file decodes");
    for &n in offsets {
        let cut = &bytes[..n];
        match bracket::decode(name, cut, &opts) {
            Err(BracketError::Corrupt { file, reason }) => {
                assert_eq!(file, name);
                assert!(!reason.is_empty());
            }
            Err(BracketError::UnsupportedFormat { .. }) if n < 4 => {}
            other => panic!("{name} cut at {n} of {} bytes: {other:?}", bytes.len()),
        }
    }
}

/// Offsets from inside the header to a few bytes before the end marker.
fn offsets(len: usize) -> Vec<usize> {
    let mut v = vec![
        2, 20, 100, 600, 2_000, 10_000, 30_000, 60_000, 100_000, 150_000,
    ];
    v.extend([
        len / 3,
        len / 2,
        9 * len / 10,
        len - 1000,
        len - 100,
        len - 10,
        len - 3,
        len - 2,
    ]);
    v.retain(|&n| n >= 2 && n < len - 1);
    v.sort_unstable();
    v.dedup();
    v
}

#[test]
fn real_camera_jpegs_cut_anywhere_are_refused() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let dir = dir.join("frobisher_001");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .expect("frobisher_001")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("jpg")))
        .collect();
    names.sort();
    assert_eq!(names.len(), 3);
    for p in names {
        let bytes = std::fs::read(&p).expect("read");
        let offs = offsets(bytes.len());
        assert!(offs.len() >= 10, "{} offsets", offs.len());
        refuses_every_cut(&p.display().to_string(), &bytes, &offs);
    }
}

#[test]
fn bundled_demo_jpeg_cut_anywhere_is_refused() {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo/frame_1.jpg");
    let bytes = std::fs::read(p).expect("demo frame");
    let offs: Vec<usize> = (1..40).map(|k| k * (bytes.len() - 2) / 40).collect();
    refuses_every_cut("frame_1.jpg", &bytes, &offs);
}

#[test]
fn data_after_the_end_marker_is_accepted() {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo/frame_1.jpg");
    let mut bytes = std::fs::read(p).expect("demo frame");
    let whole = bracket::decode("a.jpg", &bytes, &DecodeOptions::default()).expect("decode");
    bytes.extend_from_slice(b"trailing maker data\xFF\x00\x01");
    let padded = bracket::decode("a.jpg", &bytes, &DecodeOptions::default()).expect("decode");
    assert_eq!(whole.pixels, padded.pixels);
}

#[test]
fn structure_check_on_hand_made_streams() {
    // SOI, a 4-byte APP0 segment, SOS with a 2-byte header, entropy data with a stuffed 0xFF00
    // and a restart marker, then EOI.
    let whole = [
        0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x04, 0x01, 0x02, 0xFF, 0xDA, 0x00, 0x02, 0x11, 0xFF, 0x00,
        0x22, 0xFF, 0xD0, 0x33, 0xFF, 0xD9,
    ];
    assert_eq!(bracket::check_jpeg_complete(&whole), Ok(()));
    for n in 0..whole.len() - 1 {
        assert!(
            bracket::check_jpeg_complete(&whole[..n]).is_err(),
            "cut at {n}"
        );
    }
    // A segment length pointing past the end.
    assert!(bracket::check_jpeg_complete(&[0xFF, 0xD8, 0xFF, 0xE1, 0x40, 0x00, 0x00]).is_err());
}
