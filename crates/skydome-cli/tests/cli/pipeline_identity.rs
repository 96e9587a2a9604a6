//! The command line is a shell over `skydome::pipeline::run`: for a full fish-eye merge (lens
//! detection, crop, north, the sun detected and from the ephemeris, equirectangular map,
//! preview, overlay) the files `skydome merge` writes are byte-identical to the pipeline called
//! directly and encoded with the library's encoders.

use std::path::Path;
use std::process::Command;

use skydome::fisheye::LensKind;
use skydome::formats::picture::{self, PictureFormat};
use skydome::formats::{encode_radiance, RadianceFormat};
use skydome::pipeline::{
    self, EncodedFrame, EquirectOptions, Frames, Input, LensSource, Options, Products, SkyOptions,
    SunMode,
};

const BIN: &str = env!("CARGO_BIN_EXE_skydome");
const TIMES: [f64; 3] = [0.001, 0.004, 0.016];
const TIME: &str = "2026-06-21T13:30:00+02:00";

fn demo(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../demo")
        .join(name)
}

/// Runs the CLI and the pipeline for `sun` and compares every output.
fn same_bytes(sun: &str, mode: SunMode) {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = |n: &str| dir.path().join(n);
    let frames: Vec<_> = (0..3).map(|i| demo(&format!("frame_{i}.jpg"))).collect();
    let st = Command::new(BIN)
        .arg("merge")
        .args(&frames)
        .args(["--times", "0.001,0.004,0.016", "--fisheye", "--lens-model"])
        .args(["stereographic", "--fov", "235", "--crop", "--north", "37"])
        .args([
            "--sun", sun, "--time", TIME, "--lat", "47.5", "--lon", "8.5",
        ])
        .args(["--quiet", "-o"])
        .arg(out("dome.hdr"))
        .arg("--equirect")
        .arg(out("latlong.hdr"))
        .arg("--preview")
        .arg(out("preview.jpg"))
        .arg("--overlay")
        .arg(out("overlay.png"))
        .status()
        .expect("run skydome");
    assert!(st.success());

    let input = Input {
        times: Some(TIMES.to_vec()),
        ..Input::new(Frames::Encoded(
            frames
                .iter()
                .map(|p| EncodedFrame {
                    name: p.display().to_string(),
                    bytes: std::fs::read(p).expect("read"),
                })
                .collect(),
        ))
    };
    let options = Options {
        lens: LensSource::Detect {
            model: LensKind::Stereographic,
            fov_deg: 235.0,
            circle: None,
        },
        sky: SkyOptions {
            crop: true,
            north_deg: Some(37.0),
            sun: mode,
            time: Some(TIME.into()),
            latitude_deg: Some(47.5),
            longitude_deg: Some(8.5),
            ..SkyOptions::default()
        },
        products: Products {
            preview: true,
            overlay: true,
            equirect: Some(EquirectOptions::default()),
            ..Products::default()
        },
        ..Options::default()
    };
    let mut events = Vec::new();
    let dome = pipeline::run(input, &options, &mut |p| {
        events.push(*p);
        std::ops::ControlFlow::Continue(())
    })
    .expect("pipeline");
    assert!(events.len() >= 12, "{} progress events", events.len());
    let sun_mark = dome.meta.sun.expect("a sun");
    assert!(sun_mark.elevation_deg.is_some() && sun_mark.azimuth_deg.is_some());
    assert!(dome.meta.north.is_some() && dome.meta.view.is_some());

    let hdr = |img, meta| {
        encode_radiance(img, meta, RadianceFormat::Hdr)
            .expect("encode")
            .bytes
    };
    let (eq, eq_meta) = dome.equirect.as_ref().expect("equirect");
    let jpeg = PictureFormat::from_extension("jpg").expect("jpg");
    let expected: [(&str, Vec<u8>); 4] = [
        ("dome.hdr", hdr(&dome.radiance, &dome.meta)),
        ("latlong.hdr", hdr(eq, eq_meta)),
        (
            "preview.jpg",
            picture::encode_rgb8(dome.preview.as_ref().expect("preview"), jpeg).expect("jpeg"),
        ),
        (
            "overlay.png",
            picture::encode_rgb8(dome.overlay.as_ref().expect("overlay"), PictureFormat::Png)
                .expect("png"),
        ),
    ];
    for (name, bytes) in expected {
        let written = std::fs::read(out(name)).expect("output");
        assert!(
            written == bytes,
            "{name} (--sun {sun}): the CLI wrote {} bytes, the pipeline gives {} different bytes",
            written.len(),
            bytes.len()
        );
    }
}

#[test]
fn cli_equals_pipeline_with_the_detected_sun() {
    same_bytes("auto", SunMode::Auto);
}

#[test]
fn cli_equals_pipeline_with_the_ephemeris_sun() {
    same_bytes("ephemeris", SunMode::Ephemeris);
}
