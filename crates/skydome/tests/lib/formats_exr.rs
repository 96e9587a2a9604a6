//! OpenEXR: round trips (half/float), metadata mapping, real files from other software compared
//! with the `exr` crate's generic reader, and hostile input.

use crate::common::data_dir;
use std::path::{Path, PathBuf};

use exr::prelude::{f16, ReadChannels, ReadLayers};
use skydome::formats::exr::{
    encode_exr, read_exr, write_exr, ExrCompression, ExrError, ExrOptions, ExrPixelType, Limits,
};
use skydome::formats::{HdrMeta, PixelPoint, SunMark};
use skydome::HdrImage;

fn test_image(width: usize, height: usize) -> HdrImage {
    let mut img = HdrImage::new(width, height);
    let mut s = 0x9e3779b97f4a7c15u64;
    for y in 0..height {
        for x in 0..width {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let u = (s >> 40) as f32 / (1u64 << 24) as f32;
            let v = match y % 4 {
                0 => [0.0; 3],
                1 => [u, u * 0.5, 1.0 - u],
                2 => {
                    let e = (x as f32 / width.max(2) as f32) * 60.0 - 30.0;
                    let v = 10f32.powf(e);
                    [v, v * u, -v]
                }
                _ => [1e5 * u, 65504.0, 1e-9],
            };
            img.set_pixel(x, y, v);
        }
    }
    img
}

fn meta() -> HdrMeta {
    HdrMeta {
        exposure: Some(0.75),
        capdate: Some("2024:06:21 14:03:59".into()),
        gmt: Some("2024:06:21 12:03:59".into()),
        view: Some("-vta -vh 180 -vv 180".into()),
        sun: Some(SunMark {
            pixel: PixelPoint { x: 10.25, y: 3.5 },
            azimuth_deg: Some(201.5),
            elevation_deg: Some(12.3456789),
        }),
        north: Some(PixelPoint { x: 5.5, y: 0.5 }),
        software: None,
        other: vec!["# first line".into(), "second line".into()],
    }
}

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn float_exr_round_trips_pixels_bit_exactly() {
    for (w, h) in [(1, 5), (7, 3), (300, 17)] {
        let mut img = test_image(w, h);
        img.data[0] = f32::NAN;
        img.data[1] = f32::INFINITY;
        let bytes = encode_exr(&img, &HdrMeta::default(), ExrPixelType::Float).unwrap();
        let back = read_exr(&bytes, &Limits::default()).unwrap();
        assert_eq!((back.image.width, back.image.height), (w, h));
        assert!(same_bits(&back.image.data, &img.data), "{w}×{h}");
        assert!(!back.grey);
    }
}

#[test]
fn every_compression_round_trips_losslessly_and_is_what_the_file_says() {
    use exr::prelude::Compression;
    let img = test_image(300, 70);
    for (c, want) in [
        (ExrCompression::None, Compression::Uncompressed),
        (ExrCompression::Rle, Compression::RLE),
        (ExrCompression::Zips, Compression::ZIP1),
        (ExrCompression::Zip, Compression::ZIP16),
        (ExrCompression::Piz, Compression::PIZ),
    ] {
        for pixel_type in [ExrPixelType::Half, ExrPixelType::Float] {
            let opts = ExrOptions {
                pixel_type,
                compression: c,
            };
            let bytes = encode_exr(&img, &HdrMeta::default(), opts).unwrap();
            let back = read_exr(&bytes, &Limits::default()).unwrap();
            let plain = encode_exr(&img, &HdrMeta::default(), pixel_type).unwrap();
            let reference = read_exr(&plain, &Limits::default()).unwrap();
            assert!(
                same_bits(&back.image.data, &reference.image.data),
                "{c:?} {pixel_type:?}"
            );
            if pixel_type == ExrPixelType::Float {
                assert!(same_bits(&back.image.data, &img.data), "{c:?}");
            }
            // The file itself names the compression (checked with the exr crate's own reader).
            let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(&bytes), false)
                .unwrap();
            assert_eq!(meta.headers[0].compression, want);
        }
    }
}

#[test]
fn half_exr_holds_nearest_half_and_clamps_overflow_to_65504() {
    let mut img = test_image(300, 9);
    img.data[3] = 1e9;
    img.data[4] = -1e9;
    img.data[5] = f32::NAN;
    let bytes = encode_exr(&img, &HdrMeta::default(), ExrPixelType::Half).unwrap();
    let back = read_exr(&bytes, &Limits::default()).unwrap();
    let expected: Vec<f32> = img
        .data
        .iter()
        .map(|&v| {
            f16::from_f32(if v.is_finite() {
                v.clamp(-65504.0, 65504.0)
            } else {
                v
            })
            .to_f32()
        })
        .collect();
    assert!(same_bits(&back.image.data, &expected));
    assert_eq!(&back.image.data[3..5], &[65504.0, -65504.0]);
    assert!(back.image.data[5].is_nan());
    // Relative error of normal halves is at most 2^-11.
    let mut worst = 0f64;
    for (a, b) in img.data.iter().zip(&back.image.data) {
        let a = f64::from(*a);
        if a.is_finite() && (6.2e-5..=65504.0).contains(&a.abs()) {
            worst = worst.max((f64::from(*b) - a).abs() / a.abs());
        }
    }
    eprintln!(
        "worst half relative error: {worst:.3e} (bound {:.3e})",
        2f64.powi(-11)
    );
    assert!(worst <= 2f64.powi(-11) && worst > 0.0);
}

#[test]
fn metadata_round_trips_exactly_in_half_and_float() {
    let img = test_image(20, 8);
    for t in [ExrPixelType::Half, ExrPixelType::Float] {
        for m in [meta(), HdrMeta::default()] {
            let bytes = encode_exr(&img, &m, t).unwrap();
            let back = read_exr(&bytes, &Limits::default()).unwrap();
            let mut expected = m.clone();
            expected
                .software
                .get_or_insert_with(|| format!("skydome {}", skydome::VERSION));
            assert_eq!(back.meta, expected, "{t:?}");
        }
    }
}

#[test]
fn standard_attributes_carry_capture_date_offset_and_comments() {
    let img = test_image(20, 8);
    let bytes = encode_exr(&img, &meta(), ExrPixelType::Half).unwrap();
    let m = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(&bytes), true).unwrap();
    let a = &m.headers[0].own_attributes;
    assert_eq!(
        a.capture_date.as_ref().unwrap().to_string(),
        "2024:06:21 14:03:59"
    );
    // UTC = local + utcOffset.
    assert_eq!(a.utc_offset, Some(-7200.0));
    assert_eq!(
        a.comments.as_ref().unwrap().to_string(),
        "# first line\nsecond line"
    );
    assert_eq!(
        a.software_name.as_ref().unwrap().to_string(),
        format!("skydome {}", skydome::VERSION)
    );
    let back = read_exr(&bytes, &Limits::default()).unwrap();
    let names: Vec<&str> = back
        .text_attributes
        .iter()
        .map(|(n, _)| n.as_str())
        .collect();
    for n in [
        "capDate",
        "comments",
        "software",
        "skydome:exposure",
        "skydome:gmt",
        "skydome:north",
        "skydome:sun",
        "skydome:sunAzimuth",
        "skydome:sunElevation",
        "skydome:view",
    ] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
}

#[test]
fn gmt_is_computed_from_capdate_and_utc_offset_of_foreign_files() {
    use exr::prelude::*;
    let attrs = LayerAttributes {
        capture_date: Some(Text::from("2023:12:31 23:30:00")),
        utc_offset: Some(3600.0),
        ..Default::default()
    };
    let layer = Layer::new(
        (4, 2),
        attrs,
        Encoding::UNCOMPRESSED,
        SpecificChannels::rgb(|_p: Vec2<usize>| (0.5f32, 0.25f32, 1.0f32)),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .unwrap();
    let back = read_exr(bytes.get_ref(), &skydome::formats::exr::Limits::default()).unwrap();
    assert_eq!(back.meta.gmt.as_deref(), Some("2024:01:01 00:30:00"));
    assert_eq!(back.image.pixel(3, 1), [0.5, 0.25, 1.0]);
}

#[test]
fn invalid_input_is_refused_before_anything_is_written() {
    let img = test_image(8, 2);
    let mut out = Vec::new();
    let m = HdrMeta {
        other: vec!["température ☀".into()],
        ..HdrMeta::default()
    };
    assert!(matches!(
        write_exr(&mut out, &img, &m, ExrPixelType::Half),
        Err(ExrError::BadMeta(_))
    ));
    let m = HdrMeta {
        exposure: Some(-1.0),
        ..HdrMeta::default()
    };
    assert!(matches!(
        write_exr(&mut out, &img, &m, ExrPixelType::Float),
        Err(ExrError::BadMeta(_))
    ));
    let broken = HdrImage {
        width: 3,
        height: 3,
        data: vec![1.0; 4],
    };
    assert!(matches!(
        write_exr(&mut out, &broken, &HdrMeta::default(), ExrPixelType::Float),
        Err(ExrError::BadImage(_))
    ));
    assert!(out.is_empty());
}

fn clean_err<T: std::fmt::Debug>(r: Result<T, ExrError>) -> ExrError {
    let e = r.expect_err("expected an error");
    let s = e.to_string();
    assert!(!s.is_empty() && !s.contains('\n'), "message `{s}`");
    e
}

#[test]
fn corrupt_and_hostile_files_give_errors_not_panics() {
    let lim = Limits::default();
    clean_err(read_exr(b"", &lim));
    clean_err(read_exr(b"#?RADIANCE\nnot an exr at all", &lim));
    let img = test_image(40, 12);
    let bytes = encode_exr(&img, &meta(), ExrPixelType::Half).unwrap();
    for n in (0..bytes.len()).step_by(7) {
        clean_err(read_exr(&bytes[..n], &lim));
    }
    // Announce a 10⁸ × 10⁸ data window in an otherwise valid file.
    let key = b"dataWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
    let mut hostile = bytes.clone();
    hostile[at + 8..at + 12].copy_from_slice(&99_999_999i32.to_le_bytes());
    hostile[at + 12..at + 16].copy_from_slice(&99_999_999i32.to_le_bytes());
    let e = clean_err(read_exr(&hostile, &lim));
    assert!(
        matches!(e, ExrError::TooLarge { .. } | ExrError::Exr(_)),
        "unexpected {e}"
    );
    // Flipping bytes anywhere must not panic either.
    for i in (0..bytes.len()).step_by(3) {
        let mut b = bytes.clone();
        b[i] ^= 0xa5;
        let _ = read_exr(
            &b,
            &Limits {
                max_pixels: 1 << 20,
            },
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Real files written by other software

fn exr_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.join("exr_files")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "exr") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// R, G, B (or Y) of the first valid layer through the `exr` crate's generic channel reader.
/// Width, height, data-window origin and channel samples.
type Direct = (usize, usize, i32, i32, Vec<Vec<f32>>);

fn direct(path: &Path) -> Option<Direct> {
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .ok()?;
    let l = &img.layer_data;
    let find = |n: &str| {
        l.channel_data
            .list
            .iter()
            .find(|c| c.name == *n)
            .map(|c| c.sample_data.values_as_f32().collect::<Vec<f32>>())
    };
    let chans = match (find("R"), find("G"), find("B")) {
        (Some(r), Some(g), Some(b)) => vec![r, g, b],
        _ => vec![find("Y")?],
    };
    Some((
        l.size.0,
        l.size.1,
        l.attributes.layer_position.0,
        l.attributes.layer_position.1,
        chans,
    ))
}

#[test]
fn real_exr_files_match_the_exr_crate_channel_reader() {
    let Some(dir) = data_dir() else { return };
    let files = exr_files(&dir);
    assert!(
        files.len() >= 18,
        "expected the shared .exr files, found {}",
        files.len()
    );
    let mut compared = 0;
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let bytes = std::fs::read(path).unwrap();
        let ours = read_exr(&bytes, &Limits::default());
        match name.as_str() {
            // Despite its name this file stores only Y (no RY/BY): it is read as grey.
            "LuminanceChroma_Garden.exr" => {
                assert!(
                    ours.as_ref().is_ok_and(|f| f.grey),
                    "{name} must read as grey"
                );
            }
            "TestImages_WideFloatRange.exr" => {
                let e = ours.err();
                assert!(
                    matches!(&e, Some(ExrError::NoRgb(c)) if c == "G"),
                    "{name}: a G-only file has no RGB, got {e:?}"
                );
                continue;
            }
            _ => {}
        }
        let ours = ours.unwrap_or_else(|e| panic!("{name}: {e}"));
        let (w, h, x0, y0, chans) =
            direct(path).unwrap_or_else(|| panic!("{name}: exr crate cannot read it"));
        assert_eq!(ours.grey, chans.len() == 1, "{name}");
        assert_eq!(
            (
                ours.data_window.x,
                ours.data_window.y,
                ours.data_window.width,
                ours.data_window.height
            ),
            (i64::from(x0), i64::from(y0), w, h),
            "{name}"
        );
        let disp = ours.display_window;
        assert_eq!(
            (ours.image.width, ours.image.height),
            (disp.width, disp.height)
        );
        let mut mismatches = 0;
        let mut outside_nonzero = 0;
        for y in 0..disp.height {
            for x in 0..disp.width {
                let (ax, ay) = (disp.x + x as i64, disp.y + y as i64);
                let got = ours.image.pixel(x, y);
                let (dx, dy) = (ax - i64::from(x0), ay - i64::from(y0));
                if dx < 0 || dy < 0 || dx >= w as i64 || dy >= h as i64 {
                    outside_nonzero += usize::from(got != [0.0; 3]);
                    continue;
                }
                let i = dy as usize * w + dx as usize;
                let want = if chans.len() == 3 {
                    [chans[0][i], chans[1][i], chans[2][i]]
                } else {
                    [chans[0][i]; 3]
                };
                if !same_bits(&got, &want) {
                    mismatches += 1;
                }
            }
        }
        assert_eq!(mismatches, 0, "{name}: pixels differ from the exr crate");
        assert_eq!(
            outside_nonzero, 0,
            "{name}: outside the data window must be 0"
        );
        compared += 1;
        eprintln!(
            "{name}: {}×{} display, data {}×{} at ({x0},{y0}){} ok",
            disp.width,
            disp.height,
            w,
            h,
            if ours.grey { ", grey" } else { "" }
        );
    }
    assert!(compared >= 16, "only {compared} compared");
}

#[test]
fn known_properties_of_real_exr_files_are_recovered() {
    let Some(dir) = data_dir() else { return };
    let read = |rel: &str| {
        read_exr(
            &std::fs::read(dir.join("exr_files").join(rel)).unwrap(),
            &Limits::default(),
        )
        .unwrap()
    };
    let crop = read("image_rs_cropping_datawindow_differs.exr");
    assert_eq!((crop.image.width, crop.image.height), (1920, 1920));
    assert_eq!((crop.data_window.x, crop.data_window.y), (1012, 1097));
    assert_eq!(
        (crop.data_window.width, crop.data_window.height),
        (315, 100)
    );

    let rings = read("openexr_images/TestImages_BrightRingsNanInf.exr");
    assert!(rings.image.data.iter().any(|v| v.is_nan()));
    assert!(rings.image.data.iter().any(|v| v.is_infinite()));

    let desk = read("openexr_images/ScanLines_Desk.exr");
    let max = desk
        .image
        .data
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0f32, f32::max);
    assert!(
        (200.0..300.0).contains(&max),
        "ScanLines_Desk max {max} (README: ~234)"
    );

    let env = read("openexr_images/MultiResolution_KernerEnvLatLong.exr");
    assert_eq!((env.image.width, env.image.height), (1024, 512));

    let ramps = read("openexr_images/TestImages_GrayRampsHorizontal.exr");
    assert!(ramps.grey);
    assert!(ramps.image.pixels().all(|p| p[0] == p[1] && p[1] == p[2]));
}

fn exr_with_channels(names: &[&str]) -> Vec<u8> {
    use exr::prelude::*;
    let list = names
        .iter()
        .map(|n| AnyChannel::new(*n, FlatSamples::F32(vec![0.5; 6])))
        .collect();
    let mut out = std::io::Cursor::new(Vec::new());
    Image::from_channels((3, 2), AnyChannels::sort(list))
        .write()
        .to_buffered(&mut out)
        .unwrap();
    out.into_inner()
}

#[test]
fn luminance_chroma_and_channel_less_files_are_refused_clearly() {
    let lim = Limits::default();
    let e = clean_err(read_exr(&exr_with_channels(&["BY", "RY", "Y"]), &lim));
    assert!(matches!(e, ExrError::LuminanceChroma), "{e}");
    let e = clean_err(read_exr(&exr_with_channels(&["Z", "depth"]), &lim));
    assert!(
        matches!(&e, ExrError::NoRgb(c) if c.contains('Z') && c.contains("depth")),
        "{e}"
    );
    let grey = read_exr(&exr_with_channels(&["Y"]), &lim).unwrap();
    assert!(grey.grey && grey.image.data.iter().all(|v| *v == 0.5));
}
