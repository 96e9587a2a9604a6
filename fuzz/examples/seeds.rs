//! Writes the fuzzers' seed files into `corpus/<target>/` (run once, from `fuzz/`:
//! `cargo run --example seeds`): small frames in every layout the bracket decoder reads, with
//! and without EXIF, `.hdr` and `.exr` files in every encoding skydome writes, time lists and
//! profiles. libFuzzer grows and minimises the corpus from them.

#[path = "../../crates/skydome/tests/common/dng.rs"]
mod dng;
#[path = "../../crates/skydome/tests/common/encode.rs"]
mod encode;

use std::path::Path;

use encode::{Exif, Layout};
use skydome::camera::CameraProfile;
use skydome::fisheye::LensKind;
use skydome::fisheye::LensProfile;
use skydome::formats::exr::{self, ExrCompression, ExrOptions, ExrPixelType};
use skydome::formats::{rgbe, HdrMeta, PixelPoint, SunMark};
use skydome::image::Circle;
use skydome::HdrImage;

fn put(target: &str, name: &str, bytes: &[u8]) {
    let dir = Path::new("corpus").join(target);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(format!("seed_{name}")), bytes).unwrap();
}

fn main() {
    let (w, h) = (16, 12);
    let rgb: Vec<u8> = (0..3 * w * h).map(|i| (i * 37 % 251) as u8).collect();
    let exif = Exif {
        time_s: Some(1.0 / 250.0),
        iso: Some(100),
        f_number: Some(2.8),
        orientation: Some(6),
    };
    put(
        "decode_frame",
        "exif.jpg",
        &encode::jpeg(&rgb, w, h, 90, Some(&exif)),
    );
    put(
        "decode_frame",
        "plain.jpg",
        &encode::jpeg(&rgb, w, h, 50, None),
    );
    put(
        "decode_frame",
        "cmyk.jpg",
        &encode::jpeg_cmyk(&rgb, w, h, Some(&exif)),
    );
    put(
        "decode_frame",
        "exif.png",
        &encode::png(&rgb, w, h, Layout::Rgb8, Some(&exif)),
    );
    for (name, layout) in [
        ("rgb16", Layout::Rgb16),
        ("grey8", Layout::Grey8),
        ("grey16", Layout::Grey16),
        ("rgba8", Layout::Rgba8),
    ] {
        put(
            "decode_frame",
            &format!("{name}.png"),
            &encode::png(&rgb, w, h, layout, None),
        );
    }
    for (name, layout) in [
        ("rgb8", Layout::Rgb8),
        ("rgb16", Layout::Rgb16),
        ("grey8", Layout::Grey8),
    ] {
        put(
            "decode_frame",
            &format!("{name}.tif"),
            &encode::tiff(&rgb, w, h, layout),
        );
    }

    let img = |w: usize, h: usize| HdrImage {
        width: w,
        height: h,
        data: (0..3 * w * h)
            .map(|i| (i % 17) as f32 * 0.37 + 1e-3)
            .collect(),
    };
    let meta = HdrMeta {
        exposure: Some(2.0),
        capdate: Some("2026:06:21 14:30:05".into()),
        sun: Some(SunMark {
            pixel: PixelPoint { x: 3.5, y: 2.5 },
            azimuth_deg: Some(120.0),
            elevation_deg: Some(40.0),
        }),
        north: Some(PixelPoint { x: 8.0, y: 0.0 }),
        ..HdrMeta::default()
    };
    put(
        "read_hdr",
        "flat.hdr",
        &rgbe::encode_rgbe(&img(5, 3), &meta).unwrap(),
    );
    put(
        "read_hdr",
        "rle.hdr",
        &rgbe::encode_rgbe(&img(40, 3), &meta).unwrap(),
    );
    for (c, cn) in [
        (ExrCompression::None, "none"),
        (ExrCompression::Rle, "rle"),
        (ExrCompression::Zips, "zips"),
        (ExrCompression::Zip, "zip"),
        (ExrCompression::Piz, "piz"),
    ] {
        for (t, tn) in [(ExrPixelType::Half, "half"), (ExrPixelType::Float, "float")] {
            let o = ExrOptions {
                pixel_type: t,
                compression: c,
            };
            put(
                "read_exr",
                &format!("{cn}_{tn}.exr"),
                &exr::encode_exr(&img(8, 6), &meta, o).unwrap(),
            );
        }
    }

    put("times", "list", b"1/400,1/100,1/25");
    put(
        "times",
        "file",
        b"# times\nframe_0.jpg 1/1000\nframe_1.jpg 0.004\n\nframe_2.jpg 2 # long\n",
    );
    put("times", "exif_date", b"2026:06:21 14:30:05");
    for (name, bytes) in dng::seeds() {
        put("read_dng", &format!("{name}.dng"), &bytes);
    }
    // Bare lossless JPEG streams for `bracket::ljpeg`: every predictor, a point transform,
    // restart intervals, one to three components, 8 to 16 bits.
    for (predictor, pt, restart_rows, comps, bits) in [
        (1, 0, 0, 1, 16),
        (2, 0, 0, 2, 14),
        (3, 0, 2, 2, 12),
        (4, 0, 0, 3, 8),
        (5, 1, 0, 2, 14),
        (6, 0, 3, 1, 12),
        (7, 2, 0, 2, 16),
    ] {
        let (lw, lh) = (6usize, 5usize);
        // Scattered codes within `bits`, multiples of 2^pt (what the point transform keeps).
        let mask = (((1u32 << bits) - 1) >> pt << pt) as usize;
        let samples: Vec<u16> = (0..lw * lh * comps)
            .map(|i: usize| ((i.wrapping_mul(2_654_435_761) >> 7) & mask) as u16)
            .collect();
        let coding = dng::Coding {
            predictor,
            pt,
            restart_rows,
        };
        put(
            "ljpeg",
            &format!("p{predictor}_pt{pt}_r{restart_rows}_c{comps}_{bits}bit.ljpeg"),
            &dng::ljpeg_with(&samples, lw, lh, comps, bits, coding),
        );
    }
    put("times", "iso8601", b"2026-06-21T14:30:05+02:00");

    let mut p = CameraProfile::linear();
    put("camera_profile", "linear.json", p.to_json().as_bytes());
    p.linear = false;
    p.g = std::array::from_fn(|c| {
        (0..256)
            .map(|z| {
                ((z as f64 + 0.5) / 255.0).powf(2.2 + 0.1 * c as f64).ln()
                    - (128.5f64 / 255.0).powf(2.2 + 0.1 * c as f64).ln()
            })
            .collect()
    });
    put("camera_profile", "curve.json", p.to_json().as_bytes());

    let circle = Circle {
        cx: 100.0,
        cy: 80.0,
        r: 75.0,
    };
    for (k, name) in [
        (LensKind::Equidistant, "equidistant"),
        (LensKind::Equisolid, "equisolid"),
        (LensKind::Stereographic, "stereographic"),
        (LensKind::Orthographic, "orthographic"),
    ] {
        let fov = if k == LensKind::Orthographic {
            180.0
        } else {
            200.0
        };
        let l = LensProfile::from_fov(circle, fov, k).unwrap();
        put(
            "lens_profile",
            &format!("{name}.json"),
            l.to_json().unwrap().as_bytes(),
        );
    }
}
