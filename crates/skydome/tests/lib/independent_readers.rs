//! Our `.hdr` and `.exr` files, read back by two independent implementations (OpenCV and
//! OpenImageIO) through `scripts/independent_readers.py`.
//!
//! Skipped when `python3 -c "import cv2, OpenImageIO"` fails, unless
//! `SKYDOME_REQUIRE_INDEPENDENT_READERS=1` (CI), in which case that is a failure. The Python
//! interpreter is `$SKYDOME_PYTHON` (default `python3`).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::independent_readers;
use skydome::formats::exr::{
    encode_exr, read_exr, ExrCompression, ExrOptions, ExrPixelType, Limits as ExrLimits,
};
use skydome::formats::rgbe::{decode_rgbe, encode_rgbe, Limits};
use skydome::formats::{HdrMeta, PixelPoint, SunMark};
use skydome::HdrImage;

/// A sky-like image spanning `stops` stops: a dim-to-bright gradient, a sun disc, noise.
fn sky(width: usize, height: usize, stops: f64, seed: u64) -> HdrImage {
    let mut img = HdrImage::new(width, height);
    let mut s = seed | 1;
    for y in 0..height {
        for x in 0..width {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let u = (s >> 40) as f64 / (1u64 << 24) as f64;
            let t = (x + y * width) as f64 / (width * height) as f64;
            let mut v = 2f64.powf(t * (stops - 4.0) - (stops - 4.0) / 2.0);
            let (dx, dy) = (
                x as f64 - width as f64 * 0.7,
                y as f64 - height as f64 * 0.3,
            );
            if dx * dx + dy * dy < 4.0 {
                v = 2f64.powf(stops / 2.0);
            }
            let row_kind = y % 7;
            let px = match row_kind {
                0 => [0.0; 3],
                1 => [0.25, 0.5, 1.0],
                _ => [v * (0.8 + 0.2 * u), v, v * (1.2 - 0.2 * u)],
            };
            img.set_pixel(x, y, px.map(|c| c as f32));
        }
    }
    img
}

fn meta(width: usize, height: usize) -> HdrMeta {
    HdrMeta {
        exposure: Some(0.5),
        capdate: Some("2024:06:21 14:03:59".into()),
        gmt: Some("2024:06:21 12:03:59".into()),
        view: Some("-vta -vh 180 -vv 180".into()),
        sun: Some(SunMark {
            pixel: PixelPoint {
                x: width as f64 * 0.7 + 0.5,
                y: height as f64 * 0.3 + 0.5,
            },
            azimuth_deg: Some(135.25),
            elevation_deg: Some(40.5),
        }),
        north: Some(PixelPoint {
            x: width as f64 / 2.0,
            y: 0.5,
        }),
        software: None,
        other: vec!["# written by skydome's independent_readers test".into()],
    }
}

fn dump(path: &Path, data: &[f32]) {
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn opencv_and_openimageio_read_our_hdr_and_exr_files() {
    let Some(py) = independent_readers() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        // ≥ 16 stops (20 here) with a sun disc 2^10 above the mid level.
        ("wide_range_20_stops", sky(640, 48, 20.0, 7)),
        // Narrower than 8: flat scanlines.
        ("narrow_flat_scanlines", sky(5, 9, 16.0, 11)),
        ("runs_and_noise", sky(300, 40, 8.0, 13)),
    ];
    let mut manifest = Vec::new();
    for (name, img) in &cases {
        let m = meta(img.width, img.height);
        let hdr = encode_rgbe(img, &m).unwrap();
        std::fs::write(dir.path().join(format!("{name}.hdr")), &hdr).unwrap();
        // What the .hdr holds is the RGBE-quantised image: our own decode of our own output.
        let decoded = decode_rgbe(&hdr, &Limits::default()).unwrap();
        dump(
            &dir.path().join(format!("{name}.hdr.f32")),
            &decoded.image.data,
        );
        let mut files = vec![serde_json::json!({
            "file": format!("{name}.hdr"), "expect": format!("{name}.hdr.f32"), "kind": "hdr"
        })];
        let variants = [
            (ExrPixelType::Half, "half", ExrCompression::Zip),
            (ExrPixelType::Float, "float", ExrCompression::Zip),
            (ExrPixelType::Half, "half", ExrCompression::Piz),
            (ExrPixelType::Float, "float", ExrCompression::Piz),
            (ExrPixelType::Half, "half", ExrCompression::Rle),
            (ExrPixelType::Float, "float", ExrCompression::Zips),
            (ExrPixelType::Half, "half", ExrCompression::None),
        ];
        for (t, kind, compression) in variants {
            let opts = ExrOptions {
                pixel_type: t,
                compression,
            };
            let exr = encode_exr(img, &m, opts).unwrap();
            let comp = format!("{compression:?}").to_lowercase();
            let file = format!("{name}.{kind}.{comp}.exr");
            std::fs::write(dir.path().join(&file), &exr).unwrap();
            let stored = read_exr(&exr, &ExrLimits::default()).unwrap().image.data;
            if t == ExrPixelType::Float {
                assert_eq!(stored, img.data);
            }
            dump(&dir.path().join(format!("{file}.f32")), &stored);
            files.push(serde_json::json!({
                "file": file, "expect": format!("{file}.f32"), "kind": kind
            }));
        }
        let sun = m.sun.unwrap().pixel;
        let north = m.north.unwrap();
        manifest.push(serde_json::json!({
            "name": name,
            "width": img.width,
            "height": img.height,
            "files": files,
            "attrs": {
                "sun": format!("-Y {} +X {}", sun.y, sun.x),
                "north": format!("-Y {} +X {}", north.y, north.x),
                "capdate": m.capdate,
                "software": format!("skydome {}", skydome::VERSION),
                "comments": m.other.join("\n"),
                "exposure": m.exposure,
            }
        }));
    }
    std::fs::write(
        dir.path().join("manifest.json"),
        serde_json::to_vec_pretty(&serde_json::json!({ "cases": manifest })).unwrap(),
    )
    .unwrap();

    let script: PathBuf =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/independent_readers.py");
    let out = Command::new(&py)
        .arg(&script)
        .arg(dir.path())
        .output()
        .expect("running the independent readers script");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("{stdout}{stderr}");
    assert!(
        out.status.success(),
        "independent readers disagree with our files:\n{stdout}{stderr}"
    );
    // The script must be able to fail: one sample off by 1% in an expectation is a mismatch.
    let (name, img) = &cases[1];
    let mut wrong = img.data.clone();
    wrong[46] = wrong[46] * 1.01 + 0.01;
    let expect = dir.path().join(format!("{name}.float.zip.exr.f32"));
    let original = std::fs::read(&expect).unwrap();
    dump(&expect, &wrong);
    let out = Command::new(&py)
        .arg(&script)
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "a wrong expectation must fail the script"
    );
    std::fs::write(&expect, original).unwrap();

    // The --check mode (for CLI outputs) must accept our .exr against its sibling .hdr.
    let (name, _) = &cases[0];
    let hdr = dir.path().join(format!("{name}.hdr"));
    let exr = dir.path().join(format!("{name}.exr"));
    std::fs::copy(dir.path().join(format!("{name}.half.zip.exr")), &exr).unwrap();
    let out = Command::new(&py)
        .arg(&script)
        .arg("--check")
        .arg(&hdr)
        .arg(&exr)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{text}");
    assert!(out.status.success(), "--check failed:\n{text}");
    assert!(text.contains("agree within RGBE precision"), "{text}");
}

/// A preview-sized JPEG written in strips joined by restart markers decodes in OpenCV and
/// OpenImageIO (both libjpeg-based) to what our own decoder (zune-jpeg, through `image`) sees:
/// a broken join would shift or garble everything after the first strip.
#[test]
fn opencv_and_openimageio_decode_our_strip_encoded_jpeg() {
    let Some(py) = independent_readers() else {
        return;
    };
    use skydome::formats::picture::{encode_rgb8, PictureFormat};
    use skydome::tonemap::{tonemap_u8, ToneMap};
    // A tone-mapped sky 700 × 5000: many strips, an uneven last one, more than 8 restarts.
    let img = sky(700, 5000, 14.0, 11);
    let rgb = tonemap_u8(&img, &ToneMap::default()).unwrap();
    let jpeg = encode_rgb8(&rgb, PictureFormat::Jpeg { quality: 92 }).unwrap();
    let restarts = jpeg
        .windows(2)
        .filter(|p| p[0] == 0xFF && (0xD0..=0xD7).contains(&p[1]))
        .count();
    assert!(restarts > 8, "{restarts} restart markers");
    let ours = image::load_from_memory(&jpeg).unwrap().to_rgb8().into_raw();
    let dir = tempfile::tempdir().unwrap();
    let (jp, raw) = (dir.path().join("strips.jpg"), dir.path().join("ours.rgb"));
    std::fs::write(&jp, &jpeg).unwrap();
    std::fs::write(&raw, &ours).unwrap();
    let script = r#"
import sys, numpy as np, cv2, OpenImageIO as oiio
jp, raw, w, h = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
ours = np.fromfile(raw, np.uint8).reshape(h, w, 3).astype(int)
cv = cv2.imread(jp, cv2.IMREAD_COLOR)[:, :, ::-1].astype(int)
inp = oiio.ImageInput.open(jp)
oi = np.asarray(inp.read_image(0, 0, 0, 3, "uint8")).astype(int)
inp.close()
for name, got in (("OpenCV", cv), ("OpenImageIO", oi)):
    d = np.abs(got - ours)
    # libjpeg upsamples chroma differently from zune-jpeg (a few codes at colour edges, 0.19
    # on average here); per band of 16 rows, a misplaced restart shows as a band far off.
    worst_band = max(d[y:y + 16].mean() for y in range(0, h, 16))
    print(f"{name}: max {d.max()}, mean {d.mean():.4f}, worst 16-row band mean {worst_band:.3f}")
    if got.shape != ours.shape or worst_band > 3.0 or d.mean() > 0.5:
        sys.exit(1)
"#;
    let out = Command::new(&py)
        .arg("-c")
        .arg(script)
        .arg(&jp)
        .arg(&raw)
        .arg(rgb.width.to_string())
        .arg(rgb.height.to_string())
        .output()
        .expect("running python");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{text}");
    assert!(out.status.success(), "{text}");
}
