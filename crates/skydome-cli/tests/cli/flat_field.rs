//! `skydome lens fit --flat-field`: the fall-off of a lens measured from photos of a uniform
//! target, linearised with a camera profile that `skydome calibrate` made from the demo bracket
//! (the same simulated camera), comes back within 3 % at 30°, 60° and 90°.

use std::path::Path;
use std::process::Command;

use skydome::bracket::Pixels;
use skydome::fisheye::{LensKind, LensProfile, Vignetting};
use skydome::image::{Circle, HdrImage};
use skydome::synth::{photograph, SynthOptions};

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

fn skydome(args: &[&str]) -> std::process::Output {
    let o = Command::new(BIN).args(args).output().expect("run skydome");
    assert!(
        o.status.success(),
        "skydome {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

#[test]
fn falloff_from_flat_field_photos() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).display().to_string();
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../demo");
    let frames: Vec<String> = (0..3)
        .map(|i| demo.join(format!("frame_{i}.jpg")).display().to_string())
        .collect();
    let times = demo.join("times.txt").display().to_string();
    let mut args = vec!["calibrate"];
    args.extend(frames.iter().map(String::as_str));
    let camera = p("camera.json");
    args.extend(["--times-file", &times, "-o", &camera, "--quiet"]);
    skydome(&args);

    let circle = Circle {
        cx: 200.0,
        cy: 200.0,
        r: 190.0,
    };
    let lens = LensProfile::from_fov(circle, 185.0, LensKind::Equisolid).unwrap();
    let truth = Vignetting {
        coefficients: [-0.22, 0.02, 0.0],
        rms: 0.0,
        samples: 0,
    };
    let mut photos = Vec::new();
    for seed in [3, 4] {
        let mut scene = HdrImage::new(400, 400);
        for y in 0..400 {
            for x in 0..400 {
                let rho = (x as f64 + 0.5 - circle.cx).hypot(y as f64 + 0.5 - circle.cy);
                let v = match lens
                    .projection
                    .theta_within(rho, lens.projection.theta_limit())
                {
                    Some(t) if t <= 92.5f64.to_radians() => 2.0 * truth.at(t),
                    _ => 0.0,
                };
                scene.set_pixel(x, y, [v as f32; 3]);
            }
        }
        let opts = SynthOptions {
            evs: vec![0.0],
            seed,
            jpeg_quality: None,
            ..SynthOptions::default()
        };
        let f = photograph(&scene, &opts).unwrap().remove(0);
        let Pixels::U8(codes) = f.pixels else {
            panic!("8-bit")
        };
        let path = p(&format!("flat_{seed}.png"));
        image::RgbImage::from_raw(400, 400, codes)
            .unwrap()
            .save(&path)
            .unwrap();
        photos.push(path);
    }
    let out = p("lens.json");
    let o = skydome(&[
        "lens",
        "fit",
        "--circle",
        "200,200,190",
        "--fov",
        "185",
        "--model",
        "equisolid",
        "--flat-field",
        &photos[0],
        "--flat-field",
        &photos[1],
        "--camera",
        &camera,
        "-o",
        &out,
        "--json",
    ]);
    let profile: LensProfile = serde_json::from_slice(&o.stdout).unwrap();
    let v = profile.vignetting.expect("a fall-off in the profile");
    let got = v.at_30_60_90();
    let want = truth.at_30_60_90();
    eprintln!("V(30°, 60°, 90°) = {got:?}, true {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!((g / w - 1.0).abs() < 0.03, "{got:?} vs {want:?}");
    }
    // The profile on disk is the one printed.
    let disk = LensProfile::from_json(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(disk.vignetting, Some(v));

    // Flat fields need the response to be linearised.
    let o = Command::new(BIN)
        .args([
            "lens",
            "fit",
            "--circle",
            "200,200,190",
            "--flat-field",
            &photos[0],
        ])
        .args(["-o", &p("x.json")])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--camera"));
}
