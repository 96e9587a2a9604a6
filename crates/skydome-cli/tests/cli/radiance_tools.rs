//! Radiance's own tools read skydome's domes: `evalglare -V` (vertical illuminance in the view
//! direction, i.e. horizontal illuminance for an upward view) on every fish-eye output with a
//! `VIEW=` agrees with skydome's own horizontal illuminance within 2 %. Radiance's binaries come
//! from the `pyradiance` package (PyPI), found through `SKYDOME_PYTHON`; CI requires them
//! (`SKYDOME_REQUIRE_INDEPENDENT_READERS=1`).

use crate::common;
use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

fn evalglare_v(bin: &Path, lib: &Path, file: &Path) -> f64 {
    let o = Command::new(bin.join("evalglare"))
        .arg("-V")
        .arg(file)
        .env("RAYPATH", lib)
        .output()
        .expect("run evalglare");
    // evalglare exits 1 even when it succeeds; its answer is the number it prints.
    let text = String::from_utf8_lossy(&o.stdout);
    text.trim().parse().unwrap_or_else(|_| {
        panic!(
            "evalglare on {} said '{text}' {}",
            file.display(),
            String::from_utf8_lossy(&o.stderr)
        )
    })
}

#[test]
fn evalglare_reads_every_dome_and_agrees_on_illuminance() {
    let Some((bin, lib)) = common::radiance_tools() else {
        return;
    };
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../demo");
    let dir = tempfile::tempdir().unwrap();
    let mut checked = 0;
    for (model, north) in [
        ("equidistant", "0"),
        ("stereographic", "30"),
        ("equisolid", "-75"),
    ] {
        let dome = dir.path().join(format!("dome_{model}.hdr"));
        let angular = dir.path().join(format!("angular_{model}.hdr"));
        let o = Command::new(BIN)
            .arg("merge")
            .args((0..3).map(|i| demo.join(format!("frame_{i}.jpg"))))
            .arg("--times-file")
            .arg(demo.join("times.txt"))
            .args(["--fisheye", "--lens-model", model, "--fov", "235", "--crop"])
            .args(["--north", north, "--json", "--quiet", "-o"])
            .arg(&dome)
            .arg("--angular")
            .arg(&angular)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let ours = report["geometry"]["horizontal_illuminance"]
            .as_f64()
            .unwrap();
        let has_view = report["meta"]["view"].is_string();
        // Radiance has no view type for equisolid: only the angular map carries a VIEW there.
        assert_eq!(has_view, model != "equisolid", "{model}");
        let mut files = vec![angular];
        if has_view {
            files.push(dome);
        }
        for f in files {
            let theirs = evalglare_v(&bin, &lib, &f);
            let rel = theirs / ours - 1.0;
            assert!(
                rel.abs() < 0.02,
                "{}: evalglare {theirs}, skydome {ours}",
                f.display()
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 5);
}

/// Runs `skydome merge` on the demo bracket (uncropped, angular dome for evalglare) with `extra`
/// and returns the JSON report.
fn merge_demo(dir: &Path, name: &str, extra: &[&str]) -> serde_json::Value {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../demo");
    let o = Command::new(BIN)
        .arg("merge")
        .args((0..3).map(|i| demo.join(format!("frame_{i}.jpg"))))
        .arg("--times-file")
        .arg(demo.join("times.txt"))
        .args(["--fisheye", "--lens-model", "equidistant", "--fov", "235"])
        .args(["--json", "--quiet", "-o"])
        .arg(dir.join(format!("{name}.hdr")))
        .arg("--angular")
        .arg(dir.join(format!("{name}_vta.hdr")))
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn absolute_calibration_from_illuminance_and_spot_luminance() {
    use skydome::formats::read_radiance;
    use skydome::photometry::{patch_luminance, SpotLuminance};
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../demo");
    let dir = tempfile::tempdir().unwrap();
    // The truth's luminance at a sky patch and its horizontal illuminance, in a made-up absolute
    // scale (×1000): what a spot meter and a lux meter beside the camera would read.
    let truth = read_radiance(&std::fs::read(demo.join("truth.hdr")).unwrap()).unwrap();
    let spot = SpotLuminance {
        pixel: skydome::image::PixelPoint { x: 230.5, y: 110.5 },
        radius_px: 4.0,
        cd_per_m2: 1.0,
    };
    let k = 1000.0;
    let cd = k * patch_luminance(&truth.image, &spot).unwrap();
    let rel = merge_demo(dir.path(), "rel", &[]);
    let e_rel = rel["geometry"]["horizontal_illuminance"].as_f64().unwrap();

    // Illuminance alone: the dome's illuminance becomes the reading, and evalglare agrees.
    let lux = 84_000.0;
    let r = merge_demo(dir.path(), "lux", &["--illuminance", "84000"]);
    let ours = r["geometry"]["horizontal_illuminance"].as_f64().unwrap();
    assert!((ours / lux - 1.0).abs() < 1e-3, "{ours}");
    assert_eq!(r["photometry"]["from"], "illuminance");
    let scale = r["photometry"]["scale"].as_f64().unwrap();
    assert!((scale * e_rel / lux - 1.0).abs() < 1e-3);
    let head = std::fs::read(dir.path().join("lux.hdr")).unwrap();
    let head = String::from_utf8_lossy(&head[..600]);
    assert!(head.contains("#UNITS= absolute"), "{head}");
    if let Some((bin, lib)) = common::radiance_tools() {
        let theirs = evalglare_v(&bin, &lib, &dir.path().join("lux_vta.hdr"));
        assert!((theirs / lux - 1.0).abs() < 0.02, "evalglare {theirs}");
    }

    // Spot luminance: the patch reads what the meter read. A lux meter on the same (true)
    // scale sees the sun, which is clipped in every frame of this bracket (it holds about half
    // the truth's light): kept clipped, the dome falls far short of the reading, and that is
    // reported; rebuilt (the default), the disc makes up the difference.
    let spot_arg = format!("230.5,110.5={cd}");
    let geom = demo_geometry(&truth.image);
    let lux_of = |img: &skydome::HdrImage| {
        k * skydome::sky::radiance_luminance(skydome::reproject::horizontal_irradiance_fisheye(
            img, &geom,
        ))
    };
    let lux_true = lux_of(&truth.image);
    // The same sky with the sun clipped where the shortest frame clips it (about 20 in the
    // truth's units; the sky's 99.9th percentile is 8.6, the sun 2048).
    let mut sunless = truth.image.clone();
    sunless.data.iter_mut().for_each(|v| *v = v.min(20.0));
    let lux_sunless = lux_of(&sunless);
    let run = |name: &str, lux: f64, disc: &str| {
        let lux = lux.to_string();
        let args = [
            "--luminance",
            &spot_arg,
            "--luminance-radius",
            "4",
            "--illuminance",
            &lux,
            "--sun-disc",
            disc,
        ];
        merge_demo(dir.path(), name, &args)
    };
    let both = run("both", lux_sunless, "reconstruct");
    let p = &both["photometry"];
    assert_eq!(p["from"], "luminance");
    assert!((p["patch_luminance_cd_m2"].as_f64().unwrap() / cd - 1.0).abs() < 1e-6);
    let d = p["disagreement_percent"].as_f64().unwrap();
    assert!(d.abs() < 5.0, "consistent readings disagree by {d} %");
    let warned = |r: &serde_json::Value| {
        r["warnings"].as_array().unwrap().iter().any(|w| {
            w.as_str()
                .is_some_and(|w| w.contains("illuminance reading"))
        })
    };
    let kept = run("kept", lux_true, "keep");
    let d_sun = kept["photometry"]["disagreement_percent"].as_f64().unwrap();
    assert!(d_sun < -30.0, "{d_sun}");
    assert!(warned(&kept), "{}", kept["warnings"]);
    assert!(kept["geometry"]["sun_disc"].is_null());
    assert!(!warned(&both), "{}", both["warnings"]);

    let rebuilt = run("sun", lux_true, "reconstruct");
    let disc = &rebuilt["geometry"]["sun_disc"];
    assert_eq!(disc["from"], "measured_illuminance", "{rebuilt}");
    assert!(!warned(&rebuilt), "{}", rebuilt["warnings"]);
    let ours = rebuilt["geometry"]["horizontal_illuminance"]
        .as_f64()
        .unwrap();
    assert!((ours / lux_true - 1.0).abs() < 1e-3, "{ours} vs {lux_true}");
    let head = std::fs::read(dir.path().join("sun.hdr")).unwrap();
    let head = String::from_utf8_lossy(&head[..1500]);
    assert!(head.contains("#SUN_DISC= reconstructed"), "{head}");
    // `info` reads the units back and gives the luminance in cd/m², the sun's included.
    let o = Command::new(BIN)
        .args(["info", "--json"])
        .arg(dir.path().join("sun.hdr"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(info["absolute"], true);
    let max = info["luminance"]["max"].as_f64().unwrap();
    let disc_l = disc["luminance"].as_f64().unwrap();
    // The brightest pixel is the disc's, diluted by its coverage of that pixel.
    assert!(
        max > 0.1 * disc_l && max <= disc_l * 1.001,
        "{max} vs {disc_l}"
    );
    // And the illuminance, from the upward VIEW= of the angular map, as evalglare -V does.
    let o = Command::new(BIN)
        .args(["info", "--json"])
        .arg(dir.path().join("sun_vta.hdr"))
        .output()
        .unwrap();
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let e = info["horizontal_illuminance"].as_f64().unwrap();
    assert!((e / lux_true - 1.0).abs() < 0.02, "info {e} vs {lux_true}");
    // Radiance sees the rebuilt sun in the angular map too.
    if let Some((bin, lib)) = common::radiance_tools() {
        let theirs = evalglare_v(&bin, &lib, &dir.path().join("sun_vta.hdr"));
        assert!(
            (theirs / lux_true - 1.0).abs() < 0.02,
            "evalglare {theirs} vs {lux_true}"
        );
    }
}

/// The demo's lens: equidistant 235° around circle.txt's circle, north at the top.
fn demo_geometry(img: &skydome::HdrImage) -> skydome::sky::SkyGeometry {
    use skydome::fisheye::{LensKind, LensProfile};
    use skydome::image::Circle;
    use skydome::sky::{DevicePose, ImageOrientation, SkyGeometry};
    let c = Circle {
        cx: 200.0,
        cy: 200.0,
        r: 192.0,
    };
    assert_eq!((img.width, img.height), (400, 400));
    let lens = LensProfile::from_fov(c, 235.0, LensKind::Equidistant).unwrap();
    SkyGeometry::new(&lens, 0.0, DevicePose::ScreenDown, ImageOrientation::Normal).unwrap()
}
