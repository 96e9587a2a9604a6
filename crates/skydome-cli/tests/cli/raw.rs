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
