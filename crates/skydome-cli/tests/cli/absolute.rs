//! A camera made absolute once (issue 22, part 3) from the command line: `merge --illuminance
//! --save-profile` stores the camera's constant; later `merge`/`batch --profile` runs are
//! absolute from EXIF time, ISO and f-number alone; frames without them give a warning and a
//! relative dome; `--absolute exif` is labelled an estimate; refusals leave nothing written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

/// The synthetic lens (a 235° circle), cropped to the dome; no sun (the synthetic sky has no
/// real one to rebuild).
fn dome() -> Vec<&'static str> {
    [crate::SYNTH_DOME, &["--sun", "none"]].concat()
}

fn skydome(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Two 3-frame captures, 96² pixels, with EXIF ISO and f-number when `exposure_data`.
fn captures(dir: &Path, exposure_data: bool) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    let d = dir.to_str().unwrap();
    let mut args = vec![
        "synth",
        "-o",
        d,
        "--captures",
        "2",
        "--size",
        "96",
        "--quiet",
    ];
    if exposure_data {
        args.extend(["--iso", "64", "--f-number", "1.8"]);
    }
    let o = skydome(&args);
    assert!(o.status.success(), "{}", text(&o));
    (0..6)
        .map(|i| dir.join(format!("IMG_{i:04}.jpg")))
        .collect()
}

fn merge(frames: &[PathBuf], out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<String> = vec!["merge".into()];
    args.extend(frames.iter().map(|p| p.display().to_string()));
    args.extend(["-o".into(), out.display().to_string(), "--json".into()]);
    args.extend(dome().iter().map(|s| s.to_string()));
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    skydome(&args)
}

fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", text(o));
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {}", text(o)))
}

fn header(p: &Path) -> String {
    let b = std::fs::read(p).unwrap();
    let end = b.windows(2).position(|w| w == b"\n\n").unwrap();
    String::from_utf8_lossy(&b[..end]).to_string()
}

#[test]
fn one_reading_makes_every_later_merge_and_batch_absolute() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    let f = captures(&photos, true);
    let cam = dir.path().join("camera.json");
    let cam_s = cam.to_str().unwrap();
    // The meter reading on the first capture; the profile gets the constant.
    let first = json(&merge(
        &f[..3],
        &dir.path().join("cal.hdr"),
        &["--illuminance", "20000", "--save-profile", cam_s],
    ));
    assert_eq!(first["photometry"]["from"], "illuminance");
    let profile: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cam).unwrap()).unwrap();
    let k = profile["absolute"]["radiance_per_unit"].as_f64().unwrap();
    assert_eq!(profile["absolute"]["from"], "illuminance");
    assert!((first["photometry"]["scale"].as_f64().unwrap() / k - 1.0).abs() < 1e-12);
    // The same capture through the profile alone: the reading back, to the last digits.
    let again = dir.path().join("again.hdr");
    let r = json(&merge(&f[..3], &again, &["--profile", cam_s]));
    assert_eq!(r["photometry"]["from"], "camera profile");
    let lux = r["photometry"]["horizontal_illuminance_lux"]
        .as_f64()
        .unwrap();
    assert!((lux / 20000.0 - 1.0).abs() < 1e-4, "{lux}");
    let h = header(&again);
    assert!(
        h.contains("#UNITS= absolute") && h.contains("the camera profile's constant"),
        "{h}"
    );
    // The other capture: absolute, no reading.
    let r = json(&merge(
        &f[3..],
        &dir.path().join("second.hdr"),
        &["--profile", cam_s],
    ));
    assert_eq!(r["photometry"]["from"], "camera profile");
    assert!(
        r["photometry"]["horizontal_illuminance_lux"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    // A batch of both captures with the profile: every dome absolute.
    let out = dir.path().join("out");
    let mut args = vec![
        "batch",
        photos.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--profile",
        cam_s,
    ];
    args.extend(dome());
    let o = skydome(&args);
    assert!(o.status.success(), "{}", text(&o));
    let lines = std::fs::read_to_string(out.join("captures.jsonl")).unwrap();
    assert_eq!(lines.lines().count(), 2);
    for l in lines.lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        assert_eq!(v["report"]["photometry"]["from"], "camera profile", "{l}");
    }
    // The meter equation instead: labelled an estimate (±30 %).
    let est = dir.path().join("exif.hdr");
    let r = json(&merge(&f[3..], &est, &["--absolute", "exif"]));
    assert_eq!(r["photometry"]["from"], "exif meter equation");
    assert_eq!(r["photometry"]["uncertainty_percent"], 30.0);
    assert!(header(&est).contains("meter equation (K = 12.5), an estimate (+/-30 %)"));
    // `--absolute none` keeps the dome relative.
    let rel = dir.path().join("rel.hdr");
    let r = json(&merge(
        &f[3..],
        &rel,
        &["--profile", cam_s, "--absolute", "none"],
    ));
    assert!(r["photometry"].is_null());
    assert!(!header(&rel).contains("#UNITS"));
    // The profile read is an input: never overwritten.
    let before = std::fs::read(&cam).unwrap();
    let o = merge(
        &f[..3],
        &dir.path().join("x.hdr"),
        &[
            "--profile",
            cam_s,
            "--illuminance",
            "1000",
            "--save-profile",
            cam_s,
            "--force",
        ],
    );
    assert!(!o.status.success());
    assert_eq!(std::fs::read(&cam).unwrap(), before);
    assert!(!dir.path().join("x.hdr").exists());
}

#[test]
fn frames_without_iso_or_aperture_stay_relative_and_give_no_constant() {
    let dir = tempfile::tempdir().unwrap();
    let with = captures(&dir.path().join("with"), true);
    let without = captures(&dir.path().join("without"), false);
    let cam = dir.path().join("camera.json");
    let cam_s = cam.to_str().unwrap();
    json(&merge(
        &with[..3],
        &dir.path().join("cal.hdr"),
        &["--illuminance", "20000", "--save-profile", cam_s],
    ));
    // The profile's constant on frames without ISO and f-number: a warning, a relative dome.
    let out = dir.path().join("rel.hdr");
    let o = merge(&without[..3], &out, &["--profile", cam_s]);
    let r = json(&o);
    assert!(r["photometry"].is_null());
    assert!(!header(&out).contains("#UNITS"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("have no ISO speed; ") && err.contains("have no f-number in EXIF"),
        "{err}"
    );
    assert!(err.contains("the dome is relative"), "{err}");
    // A reading on them cannot give the camera a constant: refused, nothing written.
    let cam2 = dir.path().join("camera2.json");
    let out2 = dir.path().join("abs.hdr");
    let o = merge(
        &without[..3],
        &out2,
        &[
            "--illuminance",
            "20000",
            "--save-profile",
            cam2.to_str().unwrap(),
        ],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("cannot store the camera's absolute constant") && err.contains("ISO"),
        "{err}"
    );
    assert!(!cam2.exists() && !out2.exists());
    // `--absolute exif` on them: refused, naming what is missing.
    let o = merge(
        &without[..3],
        &dir.path().join("e.hdr"),
        &["--absolute", "exif"],
    );
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("have no ISO speed"),
        "{}",
        text(&o)
    );
}
