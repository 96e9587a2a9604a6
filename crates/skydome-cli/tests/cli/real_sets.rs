//! `skydome merge` on the real photo sets in `../shared/data`, with the outputs checked by
//! independent readers (OpenCV and OpenImageIO through `scripts/independent_readers.py`).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{data_dir, independent_readers};

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

fn merge_set(dir: &Path, files: &[&str], extra: &[&str], out: &Path) -> serde_json::Value {
    let hdr = out.with_extension("hdr");
    let exr = out.with_extension("exr");
    let o = Command::new(BIN)
        .arg("merge")
        .args(files.iter().map(|f| dir.join(f)))
        .args([
            "-o".as_ref(),
            hdr.as_os_str(),
            "--exr".as_ref(),
            exr.as_os_str(),
        ])
        .args(extra)
        .args(["--json", "--quiet"])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "merge failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(hdr.is_file() && exr.is_file());
    if let Some(py) = independent_readers() {
        let script =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/independent_readers.py");
        let c = Command::new(py)
            .arg(script)
            .arg("--check")
            .args([&hdr, &exr])
            .output()
            .unwrap();
        assert!(
            c.status.success(),
            "independent readers disagree on {}: {}{}",
            hdr.display(),
            String::from_utf8_lossy(&c.stdout),
            String::from_utf8_lossy(&c.stderr)
        );
    }
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn frobisher_merges_from_exif_alone() {
    let Some(d) = data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let s = merge_set(
        &d.join("frobisher_001"),
        &["IMG_2600.jpg", "IMG_2601.jpg", "IMG_2602.jpg"],
        &[],
        &tmp.path().join("frobisher"),
    );
    let times: Vec<f64> = s["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["time_s"].as_f64().unwrap())
        .collect();
    assert_eq!(times, [0.125, 1.0, 8.0]);
    let hdr = std::fs::read(tmp.path().join("frobisher.hdr")).unwrap();
    let head = String::from_utf8_lossy(&hdr[..200]);
    assert!(head.contains("CAPDATE="), "{head}");
}

#[test]
fn banterle_room_merges_seven_frames() {
    let Some(d) = data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let names: Vec<String> = (0..7).map(|i| format!("stack_room_exp_{i}.jpg")).collect();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    // PIZ here (the independent readers check it); the other sets use the default ZIP.
    let s = merge_set(
        &d.join("banterle_room"),
        &refs,
        &["--exr-compression", "piz"],
        &tmp.path().join("room"),
    );
    assert_eq!(s["frames"].as_array().unwrap().len(), 7);
    let meta = exr::meta::MetaData::read_from_file(tmp.path().join("room.exr"), false).unwrap();
    assert_eq!(
        meta.headers[0].compression,
        exr::compression::Compression::PIZ
    );
}

#[test]
fn banterle_alignment_files_out_of_order_merge() {
    let Some(d) = data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let s = merge_set(
        &d.join("banterle_alignment"),
        &["IMG_4209.jpg", "IMG_4210.jpg", "IMG_4211.jpg"],
        &[],
        &tmp.path().join("align"),
    );
    let files: Vec<&str> = s["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["file"].as_str().unwrap())
        .collect();
    assert!(
        files[0].ends_with("IMG_4210.jpg") && files[2].ends_with("IMG_4211.jpg"),
        "{files:?}"
    );
}

#[test]
fn alpnach_fisheye_dome_finds_circle_and_sun() {
    let Some(d) = data_dir() else { return };
    let dir = d.join("skycam_alpnach_fisheye");
    let tmp = tempfile::tempdir().unwrap();
    // Frames 06..12; their times are not published, so rough ratios estimated from the pixels.
    let files: Vec<PathBuf> = (6..=12)
        .map(|i| {
            dir.join(format!(
                "Alpnach_20180129_11-09-20_ExposureStack_Image_{i:02}_image.png"
            ))
        })
        .collect();
    let o = Command::new(BIN)
        .arg("merge")
        .args(&files)
        .args([
            "--times",
            "1,2,5,12,50,110,220",
            "--fisheye",
            "--lens-model",
            "equidistant",
        ])
        .args([
            "--fov", "185", "--crop", "--north", "0", "--json", "--quiet", "-o",
        ])
        .arg(tmp.path().join("alp.hdr"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let g = &s["geometry"];
    let c = &g["lens"]["circle"];
    // The circle of this camera: centre ≈ (150, 141), radius ≈ 130 (SOURCE.txt).
    assert!((c["cx"].as_f64().unwrap() - 150.0).abs() < 2.0, "{c}");
    assert!((c["cy"].as_f64().unwrap() - 141.0).abs() < 2.0, "{c}");
    assert!((c["r"].as_f64().unwrap() - 131.0).abs() < 3.0, "{c}");
    // The sun disc of the short frames sits at (83.5, 81.3) in the full frame; the crop moves
    // the origin by the circle centre minus the horizon radius.
    let off_x = c["cx"].as_f64().unwrap() - g["horizon"]["r"].as_f64().unwrap();
    let off_y = c["cy"].as_f64().unwrap() - g["horizon"]["r"].as_f64().unwrap();
    let sun = &g["sun"]["pixel"];
    let (sx, sy) = (
        sun["x"].as_f64().unwrap() + off_x,
        sun["y"].as_f64().unwrap() + off_y,
    );
    assert_eq!(g["sun_source"], "detected");
    assert!(
        ((sx - 83.5).powi(2) + (sy - 81.3).powi(2)).sqrt() < 8.0,
        "sun at ({sx}, {sy})"
    );
}

#[test]
fn frobisher_frame_cut_short_is_refused_by_name() {
    let Some(data) = data_dir() else {
        return;
    };
    let dir = data.join("frobisher_001");
    let tmp = tempfile::tempdir().unwrap();
    let whole = std::fs::read(dir.join("IMG_2601.jpg")).unwrap();
    for n in [30_000, 60_000, 100_000, 150_000, whole.len() - 3] {
        let cut = tmp.path().join(format!("cut_{n}.jpg"));
        std::fs::write(&cut, &whole[..n]).unwrap();
        let out = tmp.path().join(format!("out_{n}.hdr"));
        let o = Command::new(BIN)
            .arg("merge")
            .arg(dir.join("IMG_2600.jpg"))
            .arg(&cut)
            .arg(dir.join("IMG_2602.jpg"))
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "cut at {n}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.contains(&cut.display().to_string()) && err.contains("truncated"),
            "{err}"
        );
        assert!(!out.exists());
    }
}

/// The street set's list (`name time 1/time`, a `#` header) is read and matched to the files by
/// name; the bracket is then refused for what it is: the camera ignored the bracket.
#[test]
fn ssarcandy_three_column_list_is_read_and_the_ignored_bracket_refused() {
    let Some(data) = data_dir() else {
        return;
    };
    let dir = data.join("ssarcandy_street");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("street.hdr");
    let o = Command::new(BIN)
        .arg("merge")
        .args((92..=102).map(|i| dir.join(format!("DSC_{i:04}.png"))))
        .arg("--times-file")
        .arg(dir.join("image_list.txt"))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("the camera probably ignored the bracket")
            && err.contains("--exposures measured"),
        "{err}"
    );
    // Every frame that duplicates another is named (four of them carry one exposure), and no
    // other frame is.
    for i in 92..=102 {
        let named = err.contains(&format!("DSC_{i:04}.png"));
        assert_eq!(named, (97..=100).contains(&i), "DSC_{i:04}.png: {err}");
    }
    assert!(!out.exists());
}

/// The street set with `--exposures measured`: the four frames of one picture (DSC_0097–0100)
/// are one exposure and one of them is merged, every frame's listed and measured time is in
/// the report, the anchor keeps its listed time, and the frames whose listed times are wrong
/// are named in a warning.
#[test]
fn ssarcandy_merges_with_measured_exposures() {
    let Some(data) = data_dir() else {
        return;
    };
    let dir = data.join("ssarcandy_street");
    let tmp = tempfile::tempdir().unwrap();
    let list = dir.join("image_list.txt");
    let files: Vec<String> = (92..=102).map(|i| format!("DSC_{i:04}.png")).collect();
    let files: Vec<&str> = files.iter().map(String::as_str).collect();
    let s = merge_set(
        &dir,
        &files,
        &[
            "--times-file",
            list.to_str().unwrap(),
            "--exposures",
            "measured",
        ],
        &tmp.path().join("street"),
    );
    let e = &s["exposures"];
    assert_eq!(e["source"], "measured", "{e}");
    let frames = e["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 11);
    for f in frames {
        let name = f["file"].as_str().unwrap();
        let i: u32 = name[name.len() - 8..name.len() - 4].parse().unwrap();
        let same = f["same_as"].as_str();
        assert_eq!(same.is_some(), (98..=100).contains(&i), "{name}: {f}");
        if let Some(first) = same {
            assert!(first.ends_with("DSC_0097.png"), "{f}");
        }
    }
    let anchor = e["anchor"].as_str().unwrap();
    let a = frames.iter().find(|f| f["file"] == anchor).unwrap();
    assert_eq!(a["measured_s"], a["listed_s"], "{a}");
    assert_eq!(s["frames"].as_array().unwrap().len(), 8);
    let warnings = s["warnings"].to_string();
    assert!(
        warnings.contains("disagree with their listed exposure times")
            && warnings.contains("DSC_0100.png")
            && warnings.contains("anchored on the listed time of"),
        "{warnings}"
    );
}
