//! Time and site for the ephemeris and the header, and where each came from (issue 22 part 4):
//! EXIF `DateTimeOriginal` + `OffsetTimeOriginal` and GPS with no option, the time zone given
//! for a camera that writes no offset, a given time and site winning over EXIF.

use skydome::bracket::{self, CaptureInfo, DecodedFrame};
use skydome::fisheye::LensKind;
use skydome::image::Circle;
use skydome::pipeline::{self, Frames, Input, LensSource, Options, Provenance, SkyOptions};

/// The demo bracket with the capture information a station's camera writes.
fn demo(info: &CaptureInfo) -> Vec<DecodedFrame> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo");
    (0..3)
        .map(|i| {
            let name = format!("frame_{i}.jpg");
            let bytes = std::fs::read(format!("{dir}/{name}")).expect("demo frame");
            let mut d = bracket::decode(&name, &bytes, &Default::default()).expect("decode");
            d.info = info.clone();
            d
        })
        .collect()
}

fn run(info: &CaptureInfo, sky: SkyOptions) -> pipeline::Dome {
    let input = Input {
        times: Some(vec![0.001, 0.004, 0.016]),
        ..Input::new(Frames::Decoded(demo(info)))
    };
    let o = Options {
        lens: LensSource::Detect {
            model: LensKind::Equidistant,
            fov_deg: 235.0,
            circle: Some(Circle {
                cx: 200.0,
                cy: 200.0,
                r: 192.0,
            }),
        },
        sky: SkyOptions {
            crop: true,
            north_deg: Some(0.0),
            ..sky
        },
        ..Options::default()
    };
    pipeline::run(input, &o, &mut pipeline::no_progress).expect("run")
}

fn station() -> CaptureInfo {
    CaptureInfo {
        orientation: 1,
        datetime_original: Some("2026:06:21 09:00:00".into()),
        utc_offset: Some("+02:00".into()),
        gps_latitude_deg: Some(47.05),
        gps_longitude_deg: Some(8.31),
        ..CaptureInfo::default()
    }
}

#[test]
fn exif_time_and_gps_feed_the_ephemeris_and_the_header_with_no_option() {
    let dome = run(&station(), SkyOptions::default());
    let c = &dome.report.capture;
    assert_eq!(c.time_utc.as_deref(), Some("2026-06-21T07:00:00Z"));
    assert_eq!(
        (c.time_from, c.site_from),
        (Provenance::Exif, Provenance::Exif)
    );
    assert_eq!((c.latitude_deg, c.longitude_deg), (Some(47.05), Some(8.31)));
    assert_eq!(dome.meta.capdate.as_deref(), Some("2026:06:21 09:00:00"));
    assert_eq!(dome.meta.gmt.as_deref(), Some("2026:06:21 07:00:00"));
    assert!(
        dome.meta
            .other
            .iter()
            .any(|l| l.starts_with("#SITE= 47.050000 8.310000") && l.ends_with("from exif)")),
        "{:?}",
        dome.meta.other
    );
    // The ephemeris ran: 07:00 UTC at 47° N on the solstice puts the sun in the east, ~40° up.
    let e = dome
        .report
        .geometry
        .as_ref()
        .unwrap()
        .sun_ephemeris
        .expect("ephemeris sun");
    assert!((80.0..100.0).contains(&e.azimuth_deg), "{e:?}");
    assert!((30.0..45.0).contains(&e.elevation_deg), "{e:?}");
    // The header written to bytes carries the lines.
    let hdr = skydome::formats::encode_radiance(
        &dome.radiance,
        &dome.meta,
        skydome::formats::RadianceFormat::Hdr,
    )
    .unwrap()
    .bytes;
    let head = String::from_utf8_lossy(&hdr[..400.min(hdr.len())]).to_string();
    assert!(
        head.contains("GMT=2026:06:21 07:00:00") || head.contains("GMT= 2026:06:21 07:00:00"),
        "{head}"
    );
    assert!(head.contains("#SITE= 47.050000 8.310000"), "{head}");
}

#[test]
fn a_given_time_zone_reads_the_cameras_clock() {
    // A camera that writes no offset: the time is unknown without a zone, known with one.
    let info = CaptureInfo {
        utc_offset: None,
        ..station()
    };
    let none = run(&info, SkyOptions::default());
    assert_eq!(none.report.capture.time_from, Provenance::None);
    assert_eq!(none.report.capture.time_utc, None);
    assert_eq!(none.meta.gmt, None);
    assert_eq!(none.meta.capdate.as_deref(), Some("2026:06:21 09:00:00"));
    let zoned = run(
        &info,
        SkyOptions {
            time_zone: Some("-05:00".into()),
            ..SkyOptions::default()
        },
    );
    let c = &zoned.report.capture;
    assert_eq!(c.time_from, Provenance::ExifClockGivenZone);
    assert_eq!(c.time_utc.as_deref(), Some("2026-06-21T14:00:00Z"));
    // The zone wins over EXIF's own offset when both are there.
    let both = run(
        &station(),
        SkyOptions {
            time_zone: Some("Z".into()),
            ..SkyOptions::default()
        },
    );
    assert_eq!(
        both.report.capture.time_utc.as_deref(),
        Some("2026-06-21T09:00:00Z")
    );
}

#[test]
fn given_time_and_site_win_over_exif_and_say_so() {
    let dome = run(
        &station(),
        SkyOptions {
            time: Some("2026-06-21T12:00:00+00:00".into()),
            latitude_deg: Some(-33.9),
            longitude_deg: Some(18.4),
            ..SkyOptions::default()
        },
    );
    let c = &dome.report.capture;
    assert_eq!(
        (c.time_from, c.site_from),
        (Provenance::Given, Provenance::Given)
    );
    assert_eq!(c.time_utc.as_deref(), Some("2026-06-21T12:00:00Z"));
    assert_eq!(c.latitude_deg, Some(-33.9));
    let json = serde_json::to_value(&dome.report).unwrap();
    assert_eq!(json["capture"]["time_from"], "flag");
    assert_eq!(json["capture"]["site_from"], "flag");
    // Nothing known: none, and no header lines.
    let bare = run(&CaptureInfo::default(), SkyOptions::default());
    assert_eq!(bare.report.capture.site_from, Provenance::None);
    assert!(!bare.meta.other.iter().any(|l| l.starts_with("#SITE=")));
    // A bad zone is a one-line error naming it.
    let input = Input {
        times: Some(vec![0.001, 0.004, 0.016]),
        ..Input::new(Frames::Decoded(demo(&station())))
    };
    let o = Options {
        sky: SkyOptions {
            time_zone: Some("CEST".into()),
            ..SkyOptions::default()
        },
        ..Options::default()
    };
    let e = pipeline::run(input, &o, &mut pipeline::no_progress).unwrap_err();
    assert!(e.to_string().contains("time zone 'CEST'"), "{e}");
}
