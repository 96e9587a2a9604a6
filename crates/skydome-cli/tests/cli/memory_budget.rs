//! `--memory-budget MiB`: a bracket whose photos decoded at once exceed it is read one photo
//! at a time (the same bytes as without it, in `merge` and in `batch`, whose table does not
//! change either), and a photo that does not decode is still one line naming it, with nothing
//! written.

use std::path::Path;
use std::process::{Command, Output};

use crate::SYNTH_DOME as DOME;

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

fn skydome(args: &[String]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A synthetic 9-frame bracket (`size`² pixels, -4..4 EV) in `dir`: the frames' paths.
fn nine(dir: &Path, size: usize) -> Vec<String> {
    let o = skydome(&[
        "synth".into(),
        "-o".into(),
        dir.display().to_string(),
        "--size".into(),
        size.to_string(),
        "--evs=-4,-3,-2,-1,0,1,2,3,4".into(),
        "--quiet".into(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let mut frames: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path().display().to_string())
        .filter(|p| p.ends_with(".jpg") && p.contains("frame_"))
        .collect();
    frames.sort();
    assert_eq!(frames.len(), 9);
    frames
}

fn merge(frames: &[String], times: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<String> = vec!["merge".into()];
    args.extend(frames.iter().cloned());
    args.extend([
        "--times-file".into(),
        times.display().to_string(),
        "-o".into(),
        out.display().to_string(),
        "--north".into(),
        "0".into(),
        "--quiet".into(),
    ]);
    args.extend(DOME.iter().chain(extra).map(|s| s.to_string()));
    skydome(&args)
}

#[test]
fn a_bracket_over_the_memory_budget_merges_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let frames = nine(dir.path(), 400);
    let times = dir.path().join("times.txt");
    let whole = dir.path().join("whole.hdr");
    let o = merge(&frames, &times, &whole, &[]);
    assert!(o.status.success(), "{}", text(&o));
    // 9 × 400² × 3 bytes = 4.3 MB: over a budget of 1 MiB, within one of 5 MiB.
    for budget in ["1", "5"] {
        let out = dir.path().join(format!("budget{budget}.hdr"));
        let o = merge(&frames, &times, &out, &["--memory-budget", budget]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(
            std::fs::read(&out).unwrap() == std::fs::read(&whole).unwrap(),
            "--memory-budget {budget}: the .hdr differs"
        );
    }
}

#[test]
fn a_corrupt_fifth_photo_over_the_memory_budget_is_one_line_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let frames = nine(dir.path(), 300);
    let bytes = std::fs::read(&frames[4]).unwrap();
    std::fs::write(&frames[4], &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.path().join("out.hdr");
    let o = merge(
        &frames,
        &dir.path().join("times.txt"),
        &out,
        &["--memory-budget", "1"],
    );
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.starts_with("error: "), "{err}");
    assert!(err.contains(&frames[4]), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with("out") || n.starts_with(".skydome-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn batch_with_a_memory_budget_writes_the_same_table_and_domes() {
    let photos = tempfile::tempdir().unwrap();
    let o = skydome(&[
        "synth".into(),
        "-o".into(),
        photos.path().display().to_string(),
        "--captures".into(),
        "2".into(),
        "--size".into(),
        "240".into(),
        "--gps".into(),
        "47.37,8.54".into(),
        "--quiet".into(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let run = |out: &Path, extra: &[&str]| {
        let mut args: Vec<String> = vec![
            "batch".into(),
            photos.path().display().to_string(),
            "-o".into(),
            out.display().to_string(),
        ];
        args.extend(DOME.iter().chain(extra).map(|s| s.to_string()));
        let o = Command::new(BIN)
            .args(&args)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
    };
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    run(a.path(), &[]);
    run(b.path(), &["--memory-budget", "0"]);
    let files = |d: &Path| {
        let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(d)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("hdr" | "csv")))
            .map(|p| {
                let name = p.file_name().unwrap().to_string_lossy().to_string();
                (name, std::fs::read(&p).unwrap())
            })
            .collect();
        v.sort();
        v
    };
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert!(
        fa.len() >= 3,
        "{:?}",
        fa.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    assert_eq!(
        fa.iter().map(|f| &f.0).collect::<Vec<_>>(),
        fb.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    for ((n, x), (_, y)) in fa.iter().zip(&fb) {
        assert!(x == y, "{n} differs with --memory-budget 0");
    }
}
