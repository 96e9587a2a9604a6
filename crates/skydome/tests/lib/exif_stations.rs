//! EXIF as sky-imaging stations write it: the same capture fields written by Python's `piexif`
//! (with and without a thumbnail) and by Pillow (`scripts/exif_fixtures.py` made the files in
//! `tests/data/exif/`) are all read: exposure time, f-number, ISO, capture time with sub-seconds
//! and UTC offset, GPS, camera.

use skydome::bracket;

fn fixture(name: &str) -> Vec<u8> {
    let p = format!("{}/tests/data/exif/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read(&p).unwrap_or_else(|e| panic!("{p}: {e}"))
}

const FILES: [&str; 3] = [
    "piexif_station.jpg",
    "piexif_thumbnail.jpg",
    "pillow_station.jpg",
];

#[test]
fn piexif_and_pillow_capture_fields_are_read() {
    for name in FILES {
        let m = bracket::read_metadata(&fixture(name));
        let t = m
            .exposure_time_s
            .unwrap_or_else(|| panic!("{name}: no exposure time"));
        assert!((t - 1.0 / 250.0).abs() < 1e-12, "{name}: {t}");
        let i = &m.info;
        assert_eq!(
            i.datetime_original.as_deref(),
            Some("2026:06:21 12:30:05"),
            "{name}"
        );
        assert_eq!(i.subsec_original.as_deref(), Some("25"), "{name}");
        assert_eq!(i.utc_offset.as_deref(), Some("+02:00"), "{name}");
        assert_eq!(i.make.as_deref(), Some("Raspberry Pi"), "{name}");
        assert_eq!(i.model.as_deref(), Some("RP_imx477"), "{name}");
        let lat = i
            .gps_latitude_deg
            .unwrap_or_else(|| panic!("{name}: no GPS"));
        let lon = i.gps_longitude_deg.unwrap();
        assert!(
            (lat - 47.5).abs() < 1e-9 && (lon - 8.25).abs() < 1e-9,
            "{name}: {lat} {lon}"
        );
        let utc = i.capture_time().unwrap().to_offset(time::UtcOffset::UTC);
        assert_eq!(
            (utc.hour(), utc.minute(), utc.second()),
            (10, 30, 5),
            "{name}"
        );
        let local = m.local_time().unwrap();
        assert_eq!(local.millisecond(), 250, "{name}");
    }
}

#[test]
fn piexif_and_pillow_frames_decode_with_their_exposure() {
    for name in FILES {
        let f = bracket::decode(name, &fixture(name), &Default::default()).unwrap();
        assert_eq!((f.width, f.height), (64, 64));
        assert_eq!(f.exif_time_s, Some(1.0 / 250.0), "{name}");
        assert_eq!(f.f_number, Some(2.8), "{name}");
        assert_eq!(f.iso, Some(100.0), "{name}");
    }
}

#[test]
fn a_strict_reader_refuses_piexif_and_takes_the_relinked_block() {
    use skydome::formats::exif::{jpeg_exif_block, relink};
    let bytes = fixture("piexif_station.jpg");
    let block = jpeg_exif_block(&bytes).unwrap();
    // Why the fix exists: kamadak-exif stops at piexif's Exif IFD, which has no next-IFD link.
    let strict = exif::Reader::new().read_raw(block.to_vec());
    assert!(
        strict
            .as_ref()
            .is_err_and(|e| e.to_string().contains("next IFD")),
        "{:?}",
        strict.map(|_| ())
    );
    let fixed = exif::Reader::new()
        .read_raw(relink(block).unwrap())
        .unwrap();
    let f = fixed
        .get_field(exif::Tag::DateTimeOriginal, exif::In::PRIMARY)
        .unwrap();
    assert_eq!(f.display_value().to_string(), "2026-06-21 12:30:05");
    // A block that reads well keeps its fields through relinking.
    let pillow = fixture("pillow_station.jpg");
    let block = jpeg_exif_block(&pillow).unwrap();
    let a = exif::Reader::new().read_raw(block.to_vec()).unwrap();
    let b = exif::Reader::new()
        .read_raw(relink(block).unwrap())
        .unwrap();
    for tag in [
        exif::Tag::DateTimeOriginal,
        exif::Tag::OffsetTimeOriginal,
        exif::Tag::GPSLatitude,
        exif::Tag::Make,
    ] {
        assert_eq!(
            a.get_field(tag, exif::In::PRIMARY)
                .map(|f| f.display_value().to_string()),
            b.get_field(tag, exif::In::PRIMARY)
                .map(|f| f.display_value().to_string()),
            "{tag}"
        );
    }
}
