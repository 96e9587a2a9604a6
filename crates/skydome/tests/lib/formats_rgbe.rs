//! Radiance RGBE `.hdr`: conversion accuracy, round trips, header metadata, foreign files and
//! hostile input.

use crate::common::data_dir;
use std::path::{Path, PathBuf};

use proptest::prelude::*;
use skydome::formats::rgbe::{
    decode_rgbe, encode_rgbe, float_to_rgbe, read_header, rgbe_to_float, write_rgbe, Limits,
    RgbeError, RGBE_MAX, RGBE_MIN,
};
use skydome::formats::{HdrMeta, PixelPoint, SunMark};
use skydome::HdrImage;

/// Deterministic xorshift so every run tests the same "noise".
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Rows of extreme ranges, all-zero rows, long runs and noise.
fn test_image(width: usize, height: usize, seed: u64) -> HdrImage {
    let mut rng = Rng(seed | 1);
    let mut img = HdrImage::new(width, height);
    for y in 0..height {
        for x in 0..width {
            let v = match y % 6 {
                5 => {
                    // Largest channel in [2^-128, 2^-120): the encoder's scalar fallback.
                    let t = 2f32.powi(-128) * (1.0 + 250.0 * rng.unit() as f32);
                    [t, t * 0.5, 0.0]
                }
                0 => [0.0; 3],
                1 => {
                    let run = (x / 13) as f32;
                    [run, run * 0.5, 1e-3]
                }
                2 => {
                    let e = rng.unit() * 60.0 - 30.0;
                    let base = 10f64.powf(e) as f32;
                    [base, base * rng.unit() as f32, base * 1e-3]
                }
                3 => [rng.unit() as f32, rng.unit() as f32, rng.unit() as f32],
                _ => {
                    let e = (x as f64 / width.max(2) as f64) * 70.0 - 35.0;
                    let v = 10f64.powf(e) as f32;
                    [v, v, v]
                }
            };
            img.set_pixel(x, y, v);
        }
    }
    img
}

fn quantised(img: &HdrImage) -> Vec<f32> {
    img.pixels()
        .flat_map(|p| rgbe_to_float(float_to_rgbe(p)))
        .collect()
}

fn assert_within_rgbe_bound(input: [f32; 3], decoded: [f32; 3]) {
    let s = input.map(|v| if v > 0.0 { v.min(RGBE_MAX) } else { 0.0 });
    let m = f64::from(s[0].max(s[1]).max(s[2]));
    if m < f64::from(RGBE_MIN) {
        assert_eq!(decoded, [0.0; 3], "below the smallest value must be black");
        return;
    }
    for c in 0..3 {
        let err = (f64::from(decoded[c]) - f64::from(s[c])).abs();
        assert!(
            err <= m / 256.0,
            "channel {c} of {input:?} decoded to {decoded:?}: error {err:e} > max/256 = {:e}",
            m / 256.0
        );
    }
}

fn channel() -> impl Strategy<Value = f32> {
    prop_oneof![
        1 => Just(0.0f32),
        6 => (-30.0f64..30.0).prop_map(|e| 10f64.powf(e) as f32),
        1 => 0.0f32..1.0,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]
    #[test]
    fn rgbe_error_is_within_one_256th_of_largest_channel(r in channel(), g in channel(), b in channel()) {
        assert_within_rgbe_bound([r, g, b], rgbe_to_float(float_to_rgbe([r, g, b])));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3_000))]
    #[test]
    fn rgbe_error_bound_holds_for_any_bit_pattern(r in any::<u32>(), g in any::<u32>(), b in any::<u32>()) {
        let px = [f32::from_bits(r), f32::from_bits(g), f32::from_bits(b)];
        assert_within_rgbe_bound(px, rgbe_to_float(float_to_rgbe(px)));
    }
}

#[test]
fn worst_case_error_measured_over_a_sweep_stays_below_bound() {
    let mut rng = Rng(0x5eed);
    let mut worst: f64 = 0.0;
    for _ in 0..200_000 {
        let m = 10f64.powf(rng.unit() * 60.0 - 30.0) as f32;
        let px = [m, m * rng.unit() as f32, m * rng.unit() as f32];
        let d = rgbe_to_float(float_to_rgbe(px));
        for c in 0..3 {
            worst = worst.max((f64::from(d[c]) - f64::from(px[c])).abs() / f64::from(m));
        }
    }
    eprintln!(
        "worst relative error over 200k pixels: {worst:.3e} (bound {:.3e})",
        1.0 / 256.0
    );
    assert!(worst <= 1.0 / 256.0);
    // Rounding (not truncation) must actually be in use: truncation's worst case is ~1/128.
    assert!(worst > 1.0 / 600.0, "sweep too small to exercise rounding");
}

#[test]
fn special_values_map_as_documented() {
    assert_eq!(float_to_rgbe([f32::NAN, -1.0, 0.0]), [0, 0, 0, 0]);
    assert_eq!(float_to_rgbe([RGBE_MIN * 0.99, 0.0, 0.0]), [0, 0, 0, 0]);
    assert_eq!(float_to_rgbe([1e-45, 1e-40, 0.0]), [0, 0, 0, 0]);
    assert_eq!(
        rgbe_to_float(float_to_rgbe([f32::INFINITY, 0.0, 1.0])),
        [RGBE_MAX, 0.0, 0.0]
    );
    assert_eq!(rgbe_to_float(float_to_rgbe([f32::MAX; 3])), [RGBE_MAX; 3]);
    assert_eq!(
        rgbe_to_float(float_to_rgbe([f32::NAN, 2.0, -5.0])),
        [0.0, 2.0, 0.0]
    );
}

#[test]
fn round_trip_matches_quantisation_for_all_widths() {
    for (w, h) in [
        (1, 9),
        (7, 11),
        (8, 10),
        (300, 17),
        (32767, 2),
        (32768, 1),
        (40001, 1),
    ] {
        let img = test_image(w, h, w as u64 * 7919);
        let bytes = encode_rgbe(&img, &HdrMeta::default()).unwrap();
        let back = decode_rgbe(&bytes, &Limits::default()).unwrap();
        assert_eq!((back.image.width, back.image.height), (w, h));
        assert_eq!(back.image.data, quantised(&img), "width {w}");
        for (a, b) in img.pixels().zip(back.image.pixels()) {
            assert_within_rgbe_bound(a, b);
        }
        // Re-encoding what was decoded must reproduce the very same file.
        let again = encode_rgbe(&back.image, &back.header.meta).unwrap();
        assert_eq!(again, bytes, "width {w}: decode → encode is not idempotent");
    }
}

fn pixel_data_offset(bytes: &[u8]) -> usize {
    let end = bytes.windows(2).position(|w| w == b"\n\n").unwrap() + 2;
    end + bytes[end..].iter().position(|&b| b == b'\n').unwrap() + 1
}

#[test]
fn narrow_and_very_wide_images_use_flat_scanlines() {
    for w in [1usize, 7, 32768] {
        let img = test_image(w, 3, 3);
        let bytes = encode_rgbe(&img, &HdrMeta::default()).unwrap();
        let off = pixel_data_offset(&bytes);
        assert_eq!(bytes.len() - off, 4 * w * 3, "width {w} must be flat");
    }
}

#[test]
fn widths_8_to_32767_use_new_rle_and_compress_runs() {
    for w in [8usize, 300, 32767] {
        let img = HdrImage::from_vec(w, 4, vec![0.25; 3 * w * 4]).unwrap();
        let bytes = encode_rgbe(&img, &HdrMeta::default()).unwrap();
        let off = pixel_data_offset(&bytes);
        assert_eq!(
            &bytes[off..off + 4],
            &[2, 2, (w >> 8) as u8, (w & 255) as u8]
        );
        assert!(
            bytes.len() - off < 4 * w * 4 / 2,
            "a constant image must compress"
        );
    }
}

fn full_meta() -> HdrMeta {
    HdrMeta {
        exposure: Some(0.123456789012345),
        capdate: Some("2024:06:21 14:03:59".into()),
        gmt: Some("2024:06:21 12:03:59".into()),
        view: Some("-vta -vh 180 -vv 180".into()),
        sun: Some(SunMark {
            pixel: PixelPoint {
                x: 12.456789,
                y: 1.5,
            },
            azimuth_deg: Some(123.45),
            // Sun angles are written to micro-degrees (the same text on every platform).
            elevation_deg: Some(34.560001),
        }),
        north: Some(PixelPoint { x: 15.5, y: 0.5 }),
        software: Some("skydome-test 9.9".into()),
        other: vec![
            "# a comment".into(),
            "PRIMARIES= 0.640 0.330 0.300 0.600 0.150 0.060 0.3127 0.3290".into(),
        ],
    }
}

#[test]
fn metadata_round_trips_exactly() {
    let img = test_image(300, 20, 1);
    let metas = [
        full_meta(),
        HdrMeta::default(),
        HdrMeta {
            sun: Some(SunMark {
                pixel: PixelPoint { x: 300.0, y: 0.0 },
                azimuth_deg: None,
                elevation_deg: Some(-0.25),
            }),
            exposure: Some(3.0e-20),
            ..HdrMeta::default()
        },
        HdrMeta {
            sun: Some(SunMark {
                pixel: PixelPoint { x: 1.0, y: 2.0 },
                azimuth_deg: None,
                elevation_deg: None,
            }),
            ..HdrMeta::default()
        },
    ];
    for meta in metas {
        let bytes = encode_rgbe(&img, &meta).unwrap();
        let back = decode_rgbe(&bytes, &Limits::default()).unwrap();
        let mut expected = meta.clone();
        expected
            .software
            .get_or_insert_with(|| format!("skydome {}", skydome::VERSION));
        assert_eq!(back.header.meta, expected);
    }
}

#[test]
fn header_lines_are_written_as_specified() {
    let img = test_image(8, 2, 1);
    let mut meta = full_meta();
    meta.software = None;
    let bytes = encode_rgbe(&img, &meta).unwrap();
    let text = String::from_utf8_lossy(&bytes[..pixel_data_offset(&bytes)]).into_owned();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "#?RADIANCE");
    for expected in [
        "FORMAT=32-bit_rle_rgbe",
        &format!("SOFTWARE=skydome {}", skydome::VERSION),
        "EXPOSURE=0.123456789012345",
        "CAPDATE=2024:06:21 14:03:59",
        "GMT=2024:06:21 12:03:59",
        "VIEW= -vta -vh 180 -vv 180",
        "#SUN=-Y 1.5 +X 12.456789",
        "#SUN_DIRECTION= azimuth 123.45 elevation 34.560001 (degrees, azimuth from north towards east)",
        "#NORTH=-Y 0.5 +X 15.5",
        "# a comment",
    ] {
        assert!(lines.contains(&expected), "missing `{expected}` in\n{text}");
    }
    assert_eq!(&lines[lines.len() - 2..], &["", "-Y 2 +X 8"]);
}

#[test]
fn invalid_metadata_is_refused_before_anything_is_written() {
    let img = test_image(10, 2, 1);
    let bad = [
        HdrMeta {
            exposure: Some(f64::NAN),
            ..HdrMeta::default()
        },
        HdrMeta {
            exposure: Some(0.0),
            ..HdrMeta::default()
        },
        HdrMeta {
            capdate: Some("21.6.2024 14:00".into()),
            ..HdrMeta::default()
        },
        HdrMeta {
            view: Some("-vta\n-vh 180".into()),
            ..HdrMeta::default()
        },
        HdrMeta {
            other: vec!["EXPOSURE=2".into()],
            ..HdrMeta::default()
        },
        HdrMeta {
            other: vec![String::new()],
            ..HdrMeta::default()
        },
        HdrMeta {
            north: Some(PixelPoint {
                x: f64::INFINITY,
                y: 0.0,
            }),
            ..HdrMeta::default()
        },
        HdrMeta {
            sun: Some(SunMark {
                pixel: PixelPoint { x: 1.0, y: 1.0 },
                azimuth_deg: None,
                elevation_deg: Some(91.0),
            }),
            ..HdrMeta::default()
        },
    ];
    for meta in bad {
        let mut out = Vec::new();
        let err = write_rgbe(&mut out, &img, &meta).unwrap_err();
        assert!(matches!(err, RgbeError::BadMeta(_)), "{meta:?} gave {err}");
        assert!(out.is_empty(), "partial output written for {meta:?}");
        assert!(!err.to_string().contains('\n'));
    }
    let mut out = Vec::new();
    let broken = HdrImage {
        width: 4,
        height: 4,
        data: vec![0.0; 5],
    };
    assert!(matches!(
        write_rgbe(&mut out, &broken, &HdrMeta::default()),
        Err(RgbeError::BadImage(_))
    ));
    assert!(matches!(
        write_rgbe(&mut out, &HdrImage::new(0, 3), &HdrMeta::default()),
        Err(RgbeError::BadImage(_))
    ));
    assert!(out.is_empty());
}

fn flat_file(header: &str, resolution: &str, pixels: &[[u8; 4]]) -> Vec<u8> {
    let mut v = format!("{header}\n\n{resolution}\n").into_bytes();
    for p in pixels {
        v.extend_from_slice(p);
    }
    v
}

#[test]
fn multiple_exposure_lines_multiply_and_rgbe_magic_is_accepted() {
    let px = [[128, 64, 32, 129]; 6];
    let bytes = flat_file(
        "#?RGBE\nEXPOSURE= 2.0\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=0.25\n#Generated by a test",
        "-Y 2 +X 3",
        &px,
    );
    let f = decode_rgbe(&bytes, &Limits::default()).unwrap();
    assert_eq!(f.header.meta.exposure, Some(0.5));
    assert_eq!(f.header.meta.other, vec!["#Generated by a test".to_owned()]);
    assert_eq!(f.header.lines[0], "#?RGBE");
    assert_eq!(f.image.pixel(2, 1), [1.0, 0.5, 0.25]);
}

#[test]
fn every_orientation_is_transformed_to_top_left_origin() {
    // A 3×2 image with distinct pixels; `code(x, y)` is its mantissa.
    let (w, h) = (3usize, 2usize);
    let code = |x: usize, y: usize| (10 * (y + 1) + x) as u8;
    for res in [
        "-Y 2 +X 3",
        "-Y 2 -X 3",
        "+Y 2 +X 3",
        "+Y 2 -X 3",
        "+X 3 +Y 2",
        "+X 3 -Y 2",
        "-X 3 +Y 2",
        "-X 3 -Y 2",
    ] {
        let t: Vec<&str> = res.split_whitespace().collect();
        let rows = t[0].ends_with('Y');
        let (n1, n2) = if rows { (h, w) } else { (w, h) };
        let mut px = Vec::new();
        for s in 0..n1 {
            for i in 0..n2 {
                let c1 = if t[0].starts_with('-') { n1 - 1 - s } else { s };
                let c2 = if t[2].starts_with('-') { n2 - 1 - i } else { i };
                let (xc, yc) = if rows { (c2, c1) } else { (c1, c2) };
                let (x, y) = (xc, h - 1 - yc);
                px.push([code(x, y), 0, 0, 136]);
            }
        }
        let f = decode_rgbe(&flat_file("#?RADIANCE", res, &px), &Limits::default()).unwrap();
        assert_eq!((f.image.width, f.image.height), (w, h), "{res}");
        for y in 0..h {
            for x in 0..w {
                assert_eq!(
                    f.image.pixel(x, y)[0],
                    f32::from(code(x, y)),
                    "{res} at ({x},{y})"
                );
            }
        }
    }
}

#[test]
fn old_style_rle_repeats_previous_pixel_with_growing_shift() {
    // Pixel A, then repeat 3 (→ 4 A's), then B, then repeat 1 and repeat 1 (1 + 256 B's).
    let a = [128, 0, 0, 129];
    let b = [0, 128, 0, 129];
    let px = [a, [1, 1, 1, 3], b, [1, 1, 1, 1], [1, 1, 1, 1]];
    let f = decode_rgbe(
        &flat_file("#?RADIANCE", "-Y 1 +X 262", &px),
        &Limits::default(),
    )
    .unwrap();
    assert!((0..4).all(|x| f.image.pixel(x, 0) == [1.0, 0.0, 0.0]));
    assert!((4..262).all(|x| f.image.pixel(x, 0) == [0.0, 1.0, 0.0]));
}

fn assert_clean_error(r: Result<impl std::fmt::Debug, RgbeError>) -> RgbeError {
    let e = r.expect_err("expected an error");
    let msg = e.to_string();
    assert!(!msg.is_empty() && !msg.contains('\n'), "message `{msg}`");
    e
}

#[test]
fn corrupt_input_gives_errors_not_panics() {
    let lim = Limits::default();
    assert!(matches!(
        assert_clean_error(decode_rgbe(b"", &lim)),
        RgbeError::NotRadiance
    ));
    assert!(matches!(
        assert_clean_error(decode_rgbe(b"\x89PNG\r\n\x1a\n garbage", &lim)),
        RgbeError::NotRadiance
    ));
    assert!(matches!(
        assert_clean_error(decode_rgbe(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", &lim)),
        RgbeError::TruncatedHeader
    ));
    assert!(matches!(
        assert_clean_error(decode_rgbe(
            b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n\0\0\0\0",
            &lim
        )),
        RgbeError::UnsupportedFormat(_)
    ));
    for res in [
        "-Y 0 +X 5",
        "-Y 5 +Y 5",
        "Y 5 X 5",
        "-Y -5 +X 5",
        "-Y 5 +X",
        "hello",
    ] {
        let bytes = flat_file("#?RADIANCE", res, &[]);
        assert!(
            matches!(
                assert_clean_error(decode_rgbe(&bytes, &lim)),
                RgbeError::BadResolution(_)
            ),
            "{res}"
        );
    }
    let absurd = flat_file("#?RADIANCE", "-Y 100000000 +X 100000000", &[[1, 2, 3, 128]]);
    assert!(matches!(
        assert_clean_error(decode_rgbe(&absurd, &lim)),
        RgbeError::TooLarge { .. }
    ));
    // Within the pixel limit but almost no data: must fail as truncated without allocating
    // the announced 10⁸ pixels up front.
    let big = flat_file("#?RADIANCE", "-Y 10000 +X 10000", &[[1, 2, 3, 128]]);
    assert!(matches!(
        assert_clean_error(decode_rgbe(&big, &lim)),
        RgbeError::Truncated { scanline: 0, .. }
    ));
    let long = format!("#?RADIANCE\n{}\n", "x".repeat(2 << 20));
    assert!(matches!(
        assert_clean_error(decode_rgbe(long.as_bytes(), &lim)),
        RgbeError::HeaderTooLong(_)
    ));
    // New-style RLE whose run overruns the scanline, and a wrong width marker.
    let mut overrun = flat_file("#?RADIANCE", "-Y 1 +X 8", &[[2, 2, 0, 8]]);
    overrun.extend_from_slice(&[128 + 9, 5]);
    assert!(matches!(
        assert_clean_error(decode_rgbe(&overrun, &lim)),
        RgbeError::Corrupt { .. }
    ));
    let wrong = flat_file("#?RADIANCE", "-Y 1 +X 8", &[[2, 2, 0, 9]]);
    assert!(matches!(
        assert_clean_error(decode_rgbe(&wrong, &lim)),
        RgbeError::Corrupt { .. }
    ));
}

#[test]
fn every_truncation_of_a_valid_file_is_an_error() {
    let img = test_image(37, 6, 11);
    let bytes = encode_rgbe(&img, &full_meta()).unwrap();
    for n in 0..bytes.len() {
        assert_clean_error(decode_rgbe(&bytes[..n], &Limits::default()));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]
    #[test]
    fn mutated_files_never_panic(edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..8)) {
        let img = test_image(20, 5, 5);
        let mut bytes = encode_rgbe(&img, &full_meta()).unwrap();
        for (i, v) in edits {
            let n = bytes.len();
            bytes[i % n] = v;
        }
        let _ = decode_rgbe(&bytes, &Limits { max_pixels: 1 << 20, ..Limits::default() });
    }
}

#[test]
fn header_only_reader_stops_at_the_pixels() {
    let img = test_image(16, 4, 2);
    let bytes = encode_rgbe(&img, &full_meta()).unwrap();
    let mut r = &bytes[..];
    let h = read_header(&mut r, &Limits::default()).unwrap();
    assert_eq!((h.width, h.height), (16, 4));
    assert_eq!(h.resolution, "-Y 4 +X 16");
    assert_eq!(r.len(), bytes.len() - pixel_data_offset(&bytes));
}

// ---------------------------------------------------------------------------------------------
// Real files written by other software

fn hdr_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.join("hdr_files")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "hdr") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

fn image_crate_decode(bytes: &[u8]) -> Option<(u32, u32, Vec<f32>)> {
    use image::ImageDecoder;
    let d = image::codecs::hdr::HdrDecoder::with_strictness(bytes, false).ok()?;
    let (w, h) = d.dimensions();
    let mut buf = vec![0u8; d.total_bytes() as usize];
    d.read_image(&mut buf).ok()?;
    let f = buf
        .chunks_exact(4)
        .map(|c| f32::from_ne_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Some((w, h, f))
}

#[test]
fn real_hdr_files_match_the_image_crate_decoder() {
    let Some(dir) = data_dir() else { return };
    let files = hdr_files(&dir);
    assert!(
        files.len() >= 14,
        "expected the shared .hdr files, found {files:?}"
    );
    let mut compared = 0;
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let bytes = std::fs::read(path).unwrap();
        let ours =
            decode_rgbe(&bytes, &Limits::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let img = &ours.image;
        assert!(
            img.data.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{name}"
        );
        match image_crate_decode(&bytes) {
            Some((w, h, theirs)) => {
                assert_eq!((img.width, img.height), (w as usize, h as usize), "{name}");
                let diff = img.data.iter().zip(&theirs).filter(|(a, b)| a != b).count();
                assert_eq!(
                    diff, 0,
                    "{name}: {diff} samples differ from image's decoder"
                );
                compared += 1;
            }
            None => eprintln!("{name}: the image crate cannot decode it; checking plausibility"),
        }
        // Re-encoding and decoding our reading must be lossless (it is already quantised).
        let again = decode_rgbe(
            &encode_rgbe(img, &ours.header.meta).unwrap(),
            &Limits::default(),
        )
        .unwrap();
        assert_eq!(again.image, *img, "{name}: re-encode changed pixels");
        assert_eq!(again.header.meta.other, ours.header.meta.other, "{name}");
        eprintln!(
            "{name}: {}×{} ok, header {:?}",
            img.width, img.height, ours.header.lines
        );
    }
    eprintln!("{compared} of {} files compared pixel-exactly", files.len());
    assert!(compared >= 13);
}

#[test]
fn known_properties_of_real_hdr_files_are_recovered() {
    let Some(dir) = data_dir() else { return };
    let read = |rel: &str| {
        let bytes = std::fs::read(dir.join("hdr_files").join(rel)).unwrap();
        decode_rgbe(&bytes, &Limits::default()).unwrap()
    };
    let old = read("image_rs_tests/old-rle.hdr");
    assert_eq!((old.image.width, old.image.height), (551, 276));
    assert!(old.header.meta.other[0].contains("anachronistic"));
    let nonzero = old.image.data.iter().filter(|v| **v > 0.0).count();
    assert!(
        nonzero > old.image.data.len() / 2,
        "old-rle.hdr decoded mostly black"
    );

    let scale = read("image_rs_tests/scale.hdr");
    let pos: Vec<f32> = scale
        .image
        .data
        .iter()
        .copied()
        .filter(|v| *v > 0.0)
        .collect();
    let (lo, hi) = pos
        .iter()
        .fold((f32::MAX, 0f32), |(l, h), v| (l.min(*v), h.max(*v)));
    assert!(lo < 1e-40 && hi > 1e38, "scale.hdr spans {lo:e}..{hi:e}");

    let cv = read("qhan1028_memorial_debevec_radiance.hdr");
    assert_eq!(cv.header.lines[0], "#?RGBE");
    assert_eq!((cv.image.width, cv.image.height), (512, 768));

    let church = read("banterle_Oxford_Church.hdr");
    assert_eq!(church.header.meta.exposure, Some(1.0));
    assert_eq!(
        church.header.meta.other,
        vec!["#Generated by the HDR Toolbox by Francesco Banterle".to_owned()]
    );
    let probe = read("probulator_latlong/wells.hdr");
    assert_eq!((probe.image.width, probe.image.height), (256, 128));
    assert_eq!(
        probe.header.meta.other,
        vec!["# Written by stb_image_write.h".to_owned()]
    );
}
