//! Reproducible bytes: every writer of the library, run twice on the same input, writes the
//! same bytes (the batch runner's resume check and `scripts/same_bytes.sh` rely on it).

use skydome::camera::CameraProfile;
use skydome::fisheye::{LensKind, LensProfile};
use skydome::formats::exr::{encode_exr, ExrCompression, ExrOptions, ExrPixelType};
use skydome::formats::picture::{encode_rgb16, encode_rgb8, PictureFormat};
use skydome::formats::rgbe::encode_rgbe;
use skydome::formats::{HdrMeta, PixelPoint, SunMark};
use skydome::image::{Circle, HdrImage, RgbImage};
use skydome::plot;

/// A radiance map with a smooth ramp, a bright spot and some noise (xorshift, fixed seed).
fn sky(width: usize, height: usize) -> HdrImage {
    let mut img = HdrImage::new(width, height);
    let mut s = 0x2545_f491_4f6c_dd1du64;
    for y in 0..height {
        for x in 0..width {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let noise = (s >> 40) as f32 / (1u64 << 24) as f32;
            let base = 0.05 + (x + y) as f32 / (width + height) as f32;
            let sun = if (x as i64 - 20).pow(2) + (y as i64 - 12).pow(2) < 9 {
                3000.0
            } else {
                0.0
            };
            for c in 0..3 {
                img.data[3 * (y * width + x) + c] = base * (1.0 + 0.1 * c as f32) + noise + sun;
            }
        }
    }
    img
}

/// Every metadata field set: seven custom attributes in the EXR header, the ones whose order
/// used to change from run to run.
fn meta() -> HdrMeta {
    HdrMeta {
        exposure: Some(0.75),
        capdate: Some("2024:06:21 14:03:59".into()),
        gmt: Some("2024:06:21 12:03:59".into()),
        view: Some("-vta -vh 180 -vv 180".into()),
        sun: Some(SunMark {
            pixel: PixelPoint { x: 20.5, y: 12.5 },
            azimuth_deg: Some(201.5),
            elevation_deg: Some(12.345),
        }),
        north: Some(PixelPoint { x: 32.0, y: 0.5 }),
        software: None,
        other: vec!["# first line".into(), "second line".into()],
    }
}

fn rgb8(img: &HdrImage) -> RgbImage<u8> {
    RgbImage {
        width: img.width,
        height: img.height,
        data: img
            .data
            .iter()
            .map(|&v| (v.min(1.0) * 255.0).round() as u8)
            .collect(),
    }
}

/// Runs `write` twice (each run builds its input afresh) and asserts the bytes are the same.
fn twice<T: AsRef<[u8]>>(what: &str, write: impl Fn() -> T) {
    let (a, b) = (write(), write());
    let (a, b) = (a.as_ref(), b.as_ref());
    assert!(!a.is_empty(), "{what}: nothing written");
    if let Some(i) = a.iter().zip(b).position(|(x, y)| x != y) {
        panic!(
            "{what}: the two runs differ first at byte {i} of {} / {}",
            a.len(),
            b.len()
        );
    }
    assert_eq!(a.len(), b.len(), "{what}: lengths differ");
}

#[test]
fn radiance_writers_write_the_same_bytes_twice() {
    twice("RGBE .hdr", || encode_rgbe(&sky(64, 40), &meta()).unwrap());
    for pixel_type in [ExrPixelType::Half, ExrPixelType::Float] {
        for compression in [
            ExrCompression::None,
            ExrCompression::Rle,
            ExrCompression::Zips,
            ExrCompression::Zip,
            ExrCompression::Piz,
        ] {
            let opts = ExrOptions {
                pixel_type,
                compression,
            };
            // Several pairs: with a random hash seed per map, one pair could agree by chance.
            for _ in 0..4 {
                twice(&format!(".exr {pixel_type:?} {compression:?}"), || {
                    encode_exr(&sky(64, 40), &meta(), opts).unwrap()
                });
            }
        }
    }
}

#[test]
fn picture_writers_write_the_same_bytes_twice() {
    let img = sky(64, 40);
    twice("preview JPEG", || {
        encode_rgb8(&rgb8(&img), PictureFormat::Jpeg { quality: 92 }).unwrap()
    });
    twice("8-bit PNG", || {
        encode_rgb8(&rgb8(&img), PictureFormat::Png).unwrap()
    });
    twice("16-bit PNG", || {
        let data = img
            .data
            .iter()
            .map(|&v| (v.min(1.0) * 65535.0).round() as u16)
            .collect();
        let img16 = RgbImage {
            width: img.width,
            height: img.height,
            data,
        };
        encode_rgb16(&img16, PictureFormat::Png).unwrap()
    });
    twice("false colour PNG", || {
        let fc = plot::false_colour(&img, &plot::FalseColour::default()).unwrap();
        plot::encode_png_rgb8(&fc).unwrap()
    });
}

#[test]
fn profile_writers_write_the_same_json_twice() {
    twice("camera profile JSON", || CameraProfile::linear().to_json());
    let circle = Circle {
        cx: 150.2,
        cy: 141.1,
        r: 130.4,
    };
    for kind in [
        LensKind::Equidistant,
        LensKind::Equisolid,
        LensKind::Stereographic,
    ] {
        twice(&format!("{kind:?} lens profile JSON"), || {
            LensProfile::from_fov(circle, 235.0, kind)
                .unwrap()
                .to_json()
                .unwrap()
        });
    }
}

#[test]
fn plot_writers_write_the_same_bytes_twice() {
    let curve = |k: f64| (0..256).map(|z| k * (z as f64 + 1.0).ln() - 4.0).collect();
    let curves: [Vec<f64>; 3] = [curve(0.9), curve(1.0), curve(1.1)];
    let pts: Vec<(f64, u8)> = (0..50)
        .map(|i| (i as f64 * 0.1 - 3.0, i as u8 * 5))
        .collect();
    let samples = [&pts[..], &pts[..], &pts[..]];
    twice("response curves PNG", || {
        plot::response_curves_png(&curves, samples, (400, 300)).unwrap()
    });
    twice("response curves SVG", || {
        plot::response_curves_svg(&curves, samples, (400, 300)).unwrap()
    });
    twice("histogram PNG", || {
        plot::log_luminance_histogram_png(&sky(64, 40), None, (400, 300)).unwrap()
    });
}
