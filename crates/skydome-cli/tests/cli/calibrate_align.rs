//! `skydome calibrate --align`: a hand-held calibration bracket is aligned by the same library
//! step as `merge --align`, and the curve it gives is the curve of the steady bracket.

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

fn demo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../demo")
}

/// The bundled frame `i` with its content moved by `(dx, dy)` pixels (edges repeated), as PNG.
fn shifted_frame(i: usize, dx: i32, dy: i32, out: &Path) -> PathBuf {
    let img = image::open(demo().join(format!("frame_{i}.jpg")))
        .unwrap()
        .to_rgb8();
    let (w, h) = (img.width() as i32, img.height() as i32);
    let moved = image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let xs = (x as i32 - dx).clamp(0, w - 1) as u32;
        let ys = (y as i32 - dy).clamp(0, h - 1) as u32;
        *img.get_pixel(xs, ys)
    });
    let p = out.join(format!("frame_{i}.png"));
    moved.save(&p).unwrap();
    p
}

/// Frame 1 (the middle exposure) is the reference; the others moved as a hand would.
const SHIFTS: [(i32, i32); 3] = [(6, -4), (0, 0), (-9, 5)];

/// The demo bracket as it is (in `dir`) and moved by [`SHIFTS`] (in `dir/moved`).
fn steady_and_moved(dir: &Path) -> (Vec<PathBuf>, Vec<PathBuf>, PathBuf) {
    let steady: Vec<PathBuf> = (0..3).map(|i| shifted_frame(i, 0, 0, dir)).collect();
    let moved_dir = dir.join("moved");
    std::fs::create_dir(&moved_dir).unwrap();
    let moved: Vec<PathBuf> = (0..3)
        .map(|i| shifted_frame(i, SHIFTS[i].0, SHIFTS[i].1, &moved_dir))
        .collect();
    (steady, moved, moved_dir)
}

fn run(args: &[std::ffi::OsString]) -> serde_json::Value {
    let o = Command::new(BIN).args(args).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// `command FRAMES --times … EXTRA…` as arguments.
fn args(command: &str, frames: &[PathBuf], extra: &[&std::ffi::OsStr]) -> Vec<std::ffi::OsString> {
    let mut a: Vec<std::ffi::OsString> = vec![command.into()];
    a.extend(frames.iter().map(|p| p.clone().into_os_string()));
    a.extend(["--times".into(), "0.001,0.004,0.016".into()]);
    a.extend(extra.iter().map(|&e| e.to_owned()));
    a
}

fn calibrate(frames: &[PathBuf], align: bool, out: &Path) -> (serde_json::Value, Vec<Vec<f64>>) {
    let flags: &[&str] = if align { &["--align"] } else { &[] };
    calibrate_with(frames, flags, out)
}

/// `skydome calibrate` inside the demo's circle with `flags`; the report and the curves.
fn calibrate_with(
    frames: &[PathBuf],
    flags: &[&str],
    out: &Path,
) -> (serde_json::Value, Vec<Vec<f64>>) {
    let profile = out.join(format!("camera_{}.json", flags.join("_")));
    let mut extra: Vec<&std::ffi::OsStr> = vec![
        "--circle".as_ref(),
        "200,200,192".as_ref(),
        "--json".as_ref(),
    ];
    extra.extend(flags.iter().map(std::ffi::OsStr::new));
    extra.extend(["-o".as_ref(), profile.as_os_str()]);
    let report = run(&args("calibrate", frames, &extra));
    let p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&profile).unwrap()).unwrap();
    let g = (0..3)
        .map(|c| {
            p["g"][c]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect()
        })
        .collect();
    (report, g)
}

/// RMS difference of two sets of curves over the codes 30..=225 (where the demo's data are).
fn rms(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let d: Vec<f64> = (0..3)
        .flat_map(|c| (30..=225).map(move |z| a[c][z] - b[c][z]))
        .collect();
    (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt()
}

#[test]
fn calibrate_align_finds_the_shifts_merge_finds_and_recovers_the_steady_curve() {
    let tmp = tempfile::tempdir().unwrap();
    let (steady, moved, moved_dir) = steady_and_moved(tmp.path());

    let (_, g_steady) = calibrate(&steady, false, tmp.path());
    let (plain, g_plain) = calibrate(&moved, false, &moved_dir);
    let (aligned, g_aligned) = calibrate(&moved, true, &moved_dir);
    assert!(plain["alignment"].is_null());
    let shifts: Vec<(i64, i64)> = aligned["alignment"]["shifts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| (s[0].as_i64().unwrap(), s[1].as_i64().unwrap()))
        .collect();
    assert_eq!(shifts, vec![(6, -4), (0, 0), (-9, 5)]);

    // merge --align reports the very same shifts on the same files.
    let hdr = moved_dir.join("m.hdr");
    let extra: [&std::ffi::OsStr; 4] = [
        "--align".as_ref(),
        "--json".as_ref(),
        "-o".as_ref(),
        hdr.as_os_str(),
    ];
    let merged = run(&args("merge", &moved, &extra));
    assert_eq!(merged["alignment"], aligned["alignment"]);

    // Aligned, the curve is the steady bracket's; unaligned, samples mix scene points.
    let (e_plain, e_aligned) = (rms(&g_plain, &g_steady), rms(&g_aligned, &g_steady));
    println!("RMS of g against the steady bracket: unaligned {e_plain:.4}, aligned {e_aligned:.4}");
    assert!(e_aligned < 0.02, "aligned {e_aligned}");
    assert!(
        e_aligned < 0.5 * e_plain,
        "aligned {e_aligned}, unaligned {e_plain}"
    );
}

/// `--method colour-hdri` matches pixels by rank in each frame's histogram, not by position: on
/// the hand-held bracket (not aligned) its curve stays near its own curve of the steady
/// bracket (measured 0.061 ln units RMS: the fixed circle lets a few pixels of the moved
/// housing into the histograms), where the default's unaligned samples mix scene points
/// (0.159).
#[test]
fn colour_hdri_histogram_samples_need_no_alignment() {
    let tmp = tempfile::tempdir().unwrap();
    let (steady, moved, moved_dir) = steady_and_moved(tmp.path());
    let method = ["--method", "colour-hdri"];
    let (report, g_steady) = calibrate_with(&steady, &method, tmp.path());
    assert_eq!(report["sampling"]["histogram"], true, "{report}");
    assert_eq!(report["sampling"]["used"], 1000, "{report}");
    let (_, g_moved) = calibrate_with(&moved, &method, &moved_dir);
    let (_, d_steady) = calibrate(&steady, false, tmp.path());
    let (_, d_moved) = calibrate(&moved, false, &moved_dir);
    let (e_hist, e_default) = (rms(&g_moved, &g_steady), rms(&d_moved, &d_steady));
    println!("RMS of g, moved against steady: colour-hdri {e_hist:.4}, default {e_default:.4}");
    assert!(
        e_hist < 0.5 * e_default,
        "colour-hdri {e_hist}, default {e_default}"
    );
}

/// Issue 27 part 3: `skydome calibrate` stores the noise model (with what came from the prior)
/// and `merge --profile --weighting noise` uses it instead of fitting one: the same `.hdr`
/// bytes as a merge with the profile stripped of its model (which fits it on the same frames),
/// and the report says the same about the model.
#[test]
fn calibrate_stores_the_noise_model_and_a_merge_with_it_gives_the_fits_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let (steady, _, _) = steady_and_moved(tmp.path());
    calibrate(&steady, false, tmp.path());
    let stored = tmp.path().join("camera_.json");
    let mut p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stored).unwrap()).unwrap();
    assert!(
        p["noise"]["channels"][1]["electrons_at_gauge"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    p.as_object_mut().unwrap().remove("noise");
    p.as_object_mut().unwrap().remove("noise_from_prior");
    let stripped = tmp.path().join("stripped.json");
    std::fs::write(&stripped, p.to_string()).unwrap();
    let merged = |profile: &Path, name: &str| {
        let out = tmp.path().join(name);
        let extra: Vec<&std::ffi::OsStr> = vec![
            "--profile".as_ref(),
            profile.as_os_str(),
            "--weighting".as_ref(),
            "noise".as_ref(),
            "--json".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
        ];
        let report = run(&args("merge", &steady, &extra));
        (std::fs::read(&out).unwrap(), report["noise"].clone())
    };
    let (a, na) = merged(&stored, "stored.hdr");
    let (b, nb) = merged(&stripped, "fitted.hdr");
    assert!(a == b, "the .hdr differs");
    for k in ["model", "fitted", "from_prior"] {
        assert_eq!(na[k], nb[k], "{k}");
    }
    // A stored model's white balance is recomputed from its electrons (`k·wb / k`), the fit's is
    // the fitted factor itself: equal up to the last bit.
    for c in 0..3 {
        let (x, y) = (
            na["white_balance"][c].as_f64().unwrap(),
            nb["white_balance"][c].as_f64().unwrap(),
        );
        assert!((x - y).abs() <= 1e-12 * y.abs(), "white_balance {x} {y}");
    }
    // The merge with the stored model fitted nothing.
    assert_eq!(na["differences"], 0);
    assert!(nb["differences"].as_u64().unwrap() > 0);
}

/// A profile made by `calibrate` on a wide-step bracket (5 × 3 EV, so with the step-periodic
/// correction) merges as the calibration would have merged right away: `merge --profile`
/// writes the same bytes as `merge`, with the same noise model (the stored one is fitted as
/// the merge's own, `noise::estimate_for_calibration`; the library test
/// `a_step_periodic_profile_stores_the_merges_noise_model` shows the rule on a bracket whose
/// gain is measured, which `skydome synth`'s is not). `--no-step-periodic` gives another map.
#[test]
fn a_step_periodic_profile_merges_as_its_calibration_did() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("wide");
    std::fs::create_dir_all(&dir).unwrap();
    let o = Command::new(BIN)
        .args(["synth", "-o"])
        .arg(&dir)
        .args([
            "--size",
            "256",
            "--evs=-6,-3,0,3,6",
            "--seed",
            "5",
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut frames: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "jpg"))
        .collect();
    frames.sort();
    assert_eq!(frames.len(), 5);
    let times = dir.join("times.txt");
    let with = |command: &str, extra: &[&std::ffi::OsStr]| {
        let mut a: Vec<std::ffi::OsString> = vec![command.into()];
        a.extend(frames.iter().map(|p| p.clone().into_os_string()));
        a.extend(["--times-file".into(), times.clone().into_os_string()]);
        a.extend(extra.iter().map(|&e| e.to_owned()));
        run(&a)
    };
    let profile = tmp.path().join("wide_cam.json");
    let cal = with(
        "calibrate",
        &["--json".as_ref(), "-o".as_ref(), profile.as_os_str()],
    );
    let merged = |name: &str, extra: &[&std::ffi::OsStr]| {
        let out = tmp.path().join(name);
        let mut e: Vec<&std::ffi::OsStr> = vec![
            "--weighting".as_ref(),
            "noise".as_ref(),
            "--json".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
        ];
        e.extend(extra);
        let report = with("merge", &e);
        (std::fs::read(&out).unwrap(), report["noise"].clone())
    };
    let (a, na) = merged("calibrated.hdr", &[]);
    let (b, nb) = merged("profile.hdr", &["--profile".as_ref(), profile.as_os_str()]);
    assert_eq!(na["model"], nb["model"]);
    assert_eq!(na["model"], cal["noise"]["model"], "{cal}");
    assert!(a == b, "the .hdr differs");
    // Without the correction: another curve, so another map.
    let (c, _) = merged("plain.hdr", &["--no-step-periodic".as_ref()]);
    assert!(a != c, "--no-step-periodic changed nothing");
    // The report names the method: asking for what the default does at 5 frames changes
    // nothing and says so; turning it off is a change.
    assert_eq!(cal["calibration"], "covering", "{cal}");
    let named = |flag: &str| {
        with(
            "calibrate",
            &[
                flag.as_ref(),
                "--json".as_ref(),
                "-o".as_ref(),
                tmp.path().join(format!("named{flag}.json")).as_os_str(),
            ],
        )["calibration"]
            .clone()
    };
    assert_eq!(named("--step-periodic"), "covering");
    assert_eq!(named("--no-step-periodic"), "covering (options changed)");
}
