//! `skydome merge a.dng b.dng c.dng`: a RAW bracket from the command line, with the standard
//! error as a float map and a picture, and the same radiance as the library gives.

use std::process::Command;

use skydome::formats::{encode_radiance, RadianceFormat};
use skydome::pipeline::{self, EncodedFrame, Frames, Input, Options};
use skydome::synth::{self, RawSynthOptions};

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

#[test]
fn merge_reads_a_dng_bracket_and_writes_the_standard_error() {
    let dir = tempfile::tempdir().unwrap();
    let c = skydome::image::Circle {
        cx: 48.0,
        cy: 48.0,
        r: 46.0,
    };
    let scene = synth::scene(96, 96, 7, Some(c));
    let files = synth::raw_bracket(&scene, &RawSynthOptions::default()).unwrap();
    let mut paths = Vec::new();
    for (name, bytes) in &files {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        paths.push(p.display().to_string());
    }
    let out = dir.path().join("sky.hdr");
    let se = dir.path().join("se.exr");
    let pic = dir.path().join("se.png");
    let o = Command::new(BIN)
        .arg("merge")
        .args(&paths)
        .args([
            "-o",
            out.to_str().unwrap(),
            "--confidence",
            se.to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["response"], "linear (RAW)");
    assert_eq!(report["raw"]["demosaic"], "bilinear");
    let median = report["standard_error"]["median_stops"].as_f64().unwrap();
    assert!(
        median > 0.0 && median < 0.2,
        "median standard error {median}"
    );
    // The float map: one value per pixel and channel, finite where measured.
    let exr = std::fs::read(&se).unwrap();
    let sigma = skydome::formats::exr::read_exr(&exr, &Default::default())
        .unwrap()
        .image;
    assert_eq!((sigma.width, sigma.height), (96, 96));
    assert!(sigma.data.iter().any(|v| v.is_finite() && *v > 0.0));
    // The same radiance as the library's, byte for byte.
    let frames = files
        .into_iter()
        .map(|(name, bytes)| EncodedFrame { name, bytes })
        .collect();
    let dome = pipeline::run(
        Input::new(Frames::Encoded(frames)),
        &Options::default(),
        &mut pipeline::no_progress,
    )
    .unwrap();
    let lib = encode_radiance(&dome.radiance, &dome.meta, RadianceFormat::Hdr)
        .unwrap()
        .bytes;
    assert_eq!(std::fs::read(&out).unwrap(), lib);
    // The picture with its scale bar.
    let o = Command::new(BIN)
        .arg("merge")
        .args(&paths)
        .args(["-o", dir.path().join("b.hdr").to_str().unwrap()])
        .args(["--confidence", pic.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(&pic).unwrap();
    assert_eq!(img.height(), 300, "padded to the scale bar's height");
    assert_eq!(img.width(), 96 + 150, "the map and its scale bar");
}

/// A camera RAW file in a build without the `raw-rawler` feature: one line naming the file and
/// saying how to read it, exit status 1, nothing written.
#[cfg(not(feature = "raw-rawler"))]
#[test]
fn merge_refuses_camera_raw_without_the_feature_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = synth::scene(32, 32, 7, None);
    let files = synth::raw_bracket(&scene, &RawSynthOptions::default()).unwrap();
    let mut paths = Vec::new();
    for (name, bytes) in &files {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        paths.push(p.display().to_string());
    }
    // The second frame a Canon CR2 (its signature is enough to be recognised).
    let mut cr2 = b"II*\0\x10\0\0\0CR\x02\0\0\0\0\0".to_vec();
    cr2.resize(256, 0);
    let cr2_path = dir.path().join("IMG_0002.CR2");
    std::fs::write(&cr2_path, &cr2).unwrap();
    paths[1] = cr2_path.display().to_string();
    let out = dir.path().join("sky.hdr");
    let o = Command::new(BIN)
        .arg("merge")
        .args(&paths)
        .args(["-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("IMG_0002.CR2") && err.contains("raw-rawler"),
        "{err}"
    );
    assert!(!out.exists());
}

/// The real RAW bracket (HDRMerge's Nikon D5000 DNGs, `scripts/fetch-raw-bracket.sh`) through
/// `skydome merge --align`, files in any order: the report states the EXIF times shortest
/// first, the file's colour, a fitted noise model and the hand-held shifts, and the radiance
/// written agrees with the middle (reference) frame's photosites at its exposure.
#[test]
fn merge_reads_the_real_raw_bracket() {
    use skydome::bracket::{self, dng, DecodeOptions, Pixels};
    let Some(src) = crate::common::required::raw_bracket() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sky.hdr");
    let paths: Vec<String> = ["sample1.dng", "sample3.dng", "sample2.dng"]
        .iter()
        .map(|f| src.join(f).display().to_string())
        .collect();
    let o = Command::new(BIN)
        .arg("merge")
        .args(&paths)
        .args(["-o", out.to_str().unwrap(), "--align", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["response"], "linear (RAW)");
    assert_eq!(
        (report["width"].as_u64(), report["height"].as_u64()),
        (Some(4310), Some(2868))
    );
    let frames = report["frames"].as_array().unwrap();
    let names: Vec<&str> = frames
        .iter()
        .map(|f| f["file"].as_str().unwrap().rsplit('/').next().unwrap())
        .collect();
    assert_eq!(names, ["sample2.dng", "sample1.dng", "sample3.dng"]);
    for (f, t) in frames.iter().zip([1.0 / 640.0, 1.0 / 160.0, 1.0 / 40.0]) {
        assert!(
            (f["time_s"].as_f64().unwrap() / t - 1.0).abs() < 1e-6,
            "{f}"
        );
    }
    assert_eq!(
        report["raw"]["colour"]["cfa"],
        serde_json::json!([1, 2, 0, 1])
    );
    assert_eq!(report["raw"]["colour"]["matrix_from"], "ColorMatrix1 (D65)");
    assert_eq!(report["raw"]["noise"]["fitted"], true);
    let a_green = report["raw"]["noise"]["a"][1].as_f64().unwrap();
    assert!((1500.0..20000.0).contains(&(1.0 / a_green)), "a {a_green}");
    let shifts = report["alignment"]["shifts"].as_array().unwrap();
    assert_eq!(
        shifts[1],
        serde_json::json!([0, 0]),
        "the middle frame is the reference"
    );
    assert!(shifts
        .iter()
        .flat_map(|s| s.as_array().unwrap())
        .any(|v| v != 0));
    // Even shifts: the frames keep the colour filter array's phase.
    assert!(
        shifts
            .iter()
            .flat_map(|s| s.as_array().unwrap())
            .all(|v| v.as_i64().is_some_and(|v| v % 2 == 0)),
        "{shifts:?}"
    );
    // The radiance written against the middle frame, photosite by photosite (every 9th row
    // and column), in camera RGB: within RGBE's rounding and the noise.
    let hdr = skydome::formats::read_radiance(&std::fs::read(&out).unwrap())
        .unwrap()
        .image;
    let bytes = std::fs::read(src.join("sample1.dng")).unwrap();
    let (f, colour) =
        bracket::decode_raw("sample1.dng", &bytes, &DecodeOptions::default()).unwrap();
    let colour = colour.unwrap();
    let Pixels::U16(v) = &f.pixels else {
        panic!("RAW frames are 16-bit")
    };
    let m = colour.camera_to_rec709.map(|r| r.map(f64::from));
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let inv = |i: usize, j: usize| {
        let (r0, r1, c0, c1) = ((j + 1) % 3, (j + 2) % 3, (i + 1) % 3, (i + 2) % 3);
        (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / det
    };
    let t = frames[1]["relative_exposure"].as_f64().unwrap();
    let mut d = Vec::new();
    for y in (0..f.height).step_by(9) {
        for x in (0..f.width).step_by(9) {
            let k = y * f.width + x;
            for c in (0..3).filter(|&c| colour.native(x, y, c)) {
                let Some(val) = dng::raw_value(v[3 * k + c]) else {
                    continue;
                };
                let e: f64 = (0..3)
                    .map(|j| inv(c, j) * f64::from(hdr.data[3 * k + j]))
                    .sum();
                if (0.05..0.8).contains(&val) && e > 0.0 {
                    d.push((f64::from(val) / t / e).log2().abs());
                }
            }
        }
    }
    d.sort_by(f64::total_cmp);
    let med = d[d.len() / 2];
    eprintln!(
        "real RAW bracket through the CLI: middle frame vs the radiance written, median {med:.4} stops over {} photosites; green noise {:.0} e- at white; shifts {}",
        d.len(),
        1.0 / a_green,
        report["alignment"]["shifts"]
    );
    assert!(
        d.len() > 50_000 && med < 0.04,
        "median |log2(v/t / E)| {med:.4} stops"
    );
}
