//! One function per fuzz target, each feeding arbitrary bytes to a parser that reads what a user
//! hands skydome. The fuzz targets (`fuzz_targets/*.rs`, nightly, libFuzzer) and the stable
//! replay test (`crates/skydome/tests/fuzz_corpus.rs`, which includes this file as a module) call
//! the same functions, so a corpus file that once crashed a target keeps being checked in CI.
//!
//! A function returns normally for every input, accepted or refused; a panic, a hang or an
//! allocation beyond the limits below is the bug the fuzzer looks for.
//!
//! Limits are smaller than the defaults (1 MP instead of 250 MP for photos, 100 MP for `.hdr`
//! and `.exr`) so that "allocates no more than the pixel limit allows" is checked at a size
//! libFuzzer's memory limit (`-rss_limit_mb`, `-malloc_limit_mb`) can see: a file that
//! announces a larger image must be refused before its pixels are allocated.

use skydome::bracket::{self, DecodeOptions, OrientationPolicy};
use skydome::camera::CameraProfile;
use skydome::fisheye::LensProfile;
use skydome::formats::{exr, rgbe};

/// The pixel limit of every image target: 1 MP.
pub const MAX_PIXELS: u64 = 1 << 20;

/// A bracket frame: JPEG, PNG or TIFF with its EXIF (exposure, orientation, GPS, capture time),
/// ICC profile and the truncated-JPEG check, then — when it decodes — a two-frame bracket of it
/// (orientation applied, the bracket's checks run).
pub fn decode_frame(data: &[u8]) {
    let opts = DecodeOptions {
        max_pixels: MAX_PIXELS,
    };
    let Ok(frame) = bracket::decode("fuzz", data, &opts) else {
        return;
    };
    assert_eq!(
        frame.pixels.len(),
        3 * frame.width * frame.height,
        "decoded samples do not match the size"
    );
    let _ = frame.info.capture_time();
    let _ = frame.info.header_times();
    let mut other = frame.clone();
    other.name = "fuzz-2".into();
    let _ = bracket::assemble(
        vec![frame, other],
        Some(&[0.01, 0.04]),
        OrientationPolicy::Apply,
    );
}

/// A DNG through our own reader (`bracket::dng::decode_dng`: the IFD walk, strips and tiles,
/// bit-packed samples, lossless JPEG, linearisation table, black and white levels, active area,
/// CFA, colour matrix, EXIF), then a two-frame RAW bracket of it; with the `raw-rawler` feature
/// the same bytes through rawler (`bracket::decode_with_rawler`), whose panics must be caught.
pub fn read_dng(data: &[u8]) {
    let opts = DecodeOptions {
        max_pixels: MAX_PIXELS,
    };
    if let Ok((frame, colour)) = bracket::dng::decode_dng("fuzz.dng", data, &opts) {
        check_raw_frame(&frame, &colour);
        let mut other = frame.clone();
        other.name = "fuzz-2.dng".into();
        let _ = bracket::assemble(
            vec![frame, other],
            Some(&[0.01, 0.04]),
            OrientationPolicy::Apply,
        );
    }
    #[cfg(feature = "raw-rawler")]
    if let Ok((frame, colour)) = bracket::decode_with_rawler("fuzz.raw", data, &opts) {
        check_raw_frame(&frame, &colour);
    }
}

/// What every decoded RAW frame must satisfy.
fn check_raw_frame(frame: &bracket::DecodedFrame, colour: &bracket::RawColour) {
    assert_eq!(
        frame.pixels.len(),
        3 * frame.width * frame.height,
        "decoded samples do not match the size"
    );
    assert!(
        (frame.width as u64) * (frame.height as u64) <= MAX_PIXELS,
        "a frame above the pixel limit was decoded"
    );
    assert!(
        colour
            .camera_to_rec709
            .iter()
            .flatten()
            .all(|v| v.is_finite()),
        "non-finite colour matrix {:?}",
        colour.camera_to_rec709
    );
    if let Some(p) = colour.cfa {
        assert!(p.iter().all(|&c| c < 3), "CFA {p:?}");
    }
}

/// A bare lossless JPEG stream (SOF3: every predictor, point transform, restart intervals, one
/// to four components) through `bracket::ljpeg`, our decoder of DNG tiles with two components,
/// asked for at most 4 Mi samples (a 1 MP CFA tile set): it must keep to that many.
pub fn ljpeg(data: &[u8]) {
    let max = 4 * MAX_PIXELS as usize;
    if let Ok(d) = bracket::ljpeg::decode(data, max) {
        assert!(d.samples.len() <= max, "more samples than asked for");
        assert!(
            d.samples.len() <= d.width * d.height * d.components,
            "more samples than the frame header announces"
        );
    }
}

/// A Radiance `.hdr` (RGBE or XYZE, flat or run-length encoded, any header), as `compare` and
/// `info` read it.
pub fn read_hdr(data: &[u8]) {
    let limits = rgbe::Limits {
        max_pixels: MAX_PIXELS,
        max_header_bytes: 1 << 16,
    };
    if let Ok(f) = rgbe::decode_rgbe(data, &limits) {
        assert_eq!(
            f.image.data.len(),
            3 * f.image.width * f.image.height,
            "decoded samples do not match the size"
        );
    }
}

/// An OpenEXR file (any compression the `exr` crate reads, grey or RGB, any windows), as
/// `compare` and `info` read it.
pub fn read_exr(data: &[u8]) {
    let limits = exr::Limits {
        max_pixels: MAX_PIXELS,
    };
    if let Ok(f) = exr::read_exr(data, &limits) {
        assert_eq!(
            f.image.data.len(),
            3 * f.image.width * f.image.height,
            "decoded samples do not match the size"
        );
    }
}

/// The exposure-time texts: a `--times` list, a times file (`FILE TIME` lines), one time, and
/// the date-time texts of `--time` and EXIF (`YYYY:MM:DD HH:MM:SS`, ISO 8601, UTC offsets).
pub fn times(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    if let Ok(ts) = bracket::parse_times(&text) {
        assert!(ts.iter().all(|t| t.is_finite() && *t > 0.0), "{ts:?}");
    }
    if let Ok(pairs) = bracket::parse_list_file("list.txt", &text) {
        assert!(pairs.iter().all(|(_, t)| t.is_finite() && *t > 0.0));
    }
    let _ = bracket::parse_time("fuzz", &text);
    let _ = bracket::parse_exif_datetime(&text);
    let _ = bracket::parse_utc_offset(&text);
    let _ = bracket::parse_iso8601(&text);
}

/// A camera profile (`calibrate`'s JSON), then the response it describes.
pub fn camera_profile(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = CameraProfile::from_json(text) {
        let r = p
            .response()
            .expect("a profile that parsed describes a response");
        let _ = r;
        // What `merge --profile` does next with it: written back, read again.
        let again = CameraProfile::from_json(&p.to_json());
        assert!(
            again.is_ok(),
            "a parsed profile does not read back: {again:?}"
        );
    }
}

/// A lens profile (`lens`'s JSON), then the radii of the horizon and the zenith.
pub fn lens_profile(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(l) = LensProfile::from_json(text) {
        for deg in [0.0, 30.0, 60.0, 90.0, l.fov_deg / 2.0] {
            let _ = l.radius_at_deg(deg);
        }
    }
}
