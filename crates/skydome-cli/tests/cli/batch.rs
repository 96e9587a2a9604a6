//! `skydome batch`: a synthetic station day (one folder, frames of every capture mixed, EXIF
//! capture times) becomes `captures.csv`, the day plot and one dome per capture; bad captures are
//! rows, not stops; a killed run resumes to the same bytes; shards join into the same table.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

use crate::SYNTH_DOME as DOME;

fn skydome(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Writes a synthetic day of `captures` 3-frame captures, `size`² pixels, one hour apart from
/// 06:00 +02:00 (04:00 UTC), into `dir`.
fn day(dir: &Path, captures: usize, size: usize) {
    let o = skydome(&[
        "synth",
        "-o",
        dir.to_str().unwrap(),
        "--captures",
        &captures.to_string(),
        "--size",
        &size.to_string(),
        "--gps",
        "47.37,8.54",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

fn batch(inputs: &[&Path], out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<String> = vec!["batch".into()];
    args.extend(inputs.iter().map(|p| p.display().to_string()));
    args.extend(["-o".into(), out.display().to_string()]);
    args.extend(DOME.iter().map(|s| s.to_string()));
    args.extend(extra.iter().map(|s| s.to_string()));
    Command::new(BIN)
        .args(&args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap()
}

fn csv(out: &Path) -> Vec<Vec<String>> {
    let t = std::fs::read_to_string(out.join("captures.csv")).unwrap();
    t.lines().map(split_csv).collect()
}

/// Splits one CSV line (RFC 4180 quotes).
fn split_csv(l: &str) -> Vec<String> {
    let mut out = vec![String::new()];
    let mut quoted = false;
    let mut chars = l.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                out.last_mut().unwrap().push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(String::new()),
            (c, _) => out.last_mut().unwrap().push(c),
        }
    }
    out
}

fn column(rows: &[Vec<String>], name: &str) -> Vec<String> {
    let i = rows[0].iter().position(|h| h == name).unwrap();
    rows[1..].iter().map(|r| r[i].clone()).collect()
}

/// Every regular file under `dir` (relative name → bytes), hidden state excluded.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().to_string(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn a_station_day_becomes_a_table_a_plot_and_domes_and_bad_captures_are_rows() {
    let photos = tempfile::tempdir().unwrap();
    day(photos.path(), 5, 128);
    // The third capture (frames 6..8) gets a truncated frame; a stray photo has no EXIF at all.
    let p7 = photos.path().join("IMG_0007.jpg");
    let b = std::fs::read(&p7).unwrap();
    std::fs::write(&p7, &b[..b.len() / 2]).unwrap();
    image::RgbImage::from_pixel(32, 32, image::Rgb([90, 90, 90]))
        .save(photos.path().join("stray.png"))
        .unwrap();
    let out = tempfile::tempdir().unwrap();
    let o = batch(
        &[photos.path()],
        out.path(),
        &["--preview", "--plot", "day.png", "-j", "2"],
    );
    let said = text(&o);
    assert_eq!(o.status.code(), Some(3), "{said}");
    assert!(
        said.contains(
            "grouped: 15 frames in 5 captures (3 frames each), a new capture after a gap over"
        ) && said.contains("1 frames without a capture time"),
        "{said}"
    );
    let rows = csv(out.path());
    assert_eq!(rows[0].join(","), skydome::batch::CaptureRow::CSV_HEADER);
    assert_eq!(rows.len(), 1 + 6, "{rows:?}");
    assert!(rows.iter().all(|r| r.len() == rows[0].len()));
    let names = column(&rows, "capture");
    assert_eq!(
        &names[..5],
        [
            "20260621T040000Z",
            "20260621T050000Z",
            "20260621T060000Z",
            "20260621T070000Z",
            "20260621T080000Z"
        ]
    );
    assert_eq!(names[5], "stray");
    let status = column(&rows, "status");
    for i in [0, 1, 3, 4] {
        assert_eq!(status[i], "ok", "{rows:?}");
    }
    assert!(
        status[2].starts_with("failed: ") && status[2].contains("IMG_0007.jpg"),
        "{}",
        status[2]
    );
    assert!(status[5].contains("no capture time"), "{}", status[5]);
    assert_eq!(column(&rows, "capture_time_utc")[0], "2026-06-21T04:00:00Z");
    let units = column(&rows, "illuminance_unit");
    let lux = column(&rows, "horizontal_illuminance");
    let ephem = column(&rows, "sun_elevation_deg");
    for i in [0, 1, 3, 4] {
        assert_eq!(units[i], "relative");
        assert!(lux[i].parse::<f64>().unwrap() > 0.0);
        // The sun's elevation at Zurich on the solstice, from EXIF time and GPS: 04:00 UTC is
        // about 10° (sunrise 03:30 UTC), 08:00 UTC about 55°.
        let el: f64 = ephem[i].parse().unwrap();
        assert!((-5.0..70.0).contains(&el), "{el}");
    }
    let el0: f64 = ephem[0].parse().unwrap();
    let el4: f64 = ephem[4].parse().unwrap();
    assert!(el4 > el0 + 30.0, "{el0} {el4}");
    assert_eq!(column(&rows, "frames")[0], "3");
    assert_eq!(column(&rows, "exposure_times_s")[0].split(';').count(), 3);
    let out_col = column(&rows, "output");
    assert_eq!(out_col[0], "20260621T040000Z.hdr");
    assert!(out_col[2].is_empty());
    for n in [0, 1, 3, 4] {
        assert!(out.path().join(format!("{}.hdr", names[n])).is_file());
        assert!(out.path().join(format!("{}.jpg", names[n])).is_file());
    }
    assert!(!out.path().join(format!("{}.hdr", names[2])).exists());
    let plot = image::open(out.path().join("day.png")).unwrap();
    assert_eq!((plot.width(), plot.height()), (1400, 900));
    let jsonl = std::fs::read_to_string(out.path().join("captures.jsonl")).unwrap();
    assert_eq!(jsonl.lines().count(), 6);
    let first: serde_json::Value = serde_json::from_str(jsonl.lines().next().unwrap()).unwrap();
    assert_eq!(first["capture"], "20260621T040000Z");
    assert_eq!(first["report"]["frames"].as_array().unwrap().len(), 3);

    // The shell adds nothing: the same three frames through `skydome merge` give the same bytes.
    let single = out.path().join("single.hdr");
    let mut args = vec!["merge".to_string()];
    for k in 0..3 {
        args.push(
            photos
                .path()
                .join(format!("IMG_{k:04}.jpg"))
                .display()
                .to_string(),
        );
    }
    args.extend(["-o".into(), single.display().to_string(), "--quiet".into()]);
    args.extend(DOME.iter().map(|s| s.to_string()));
    let o = Command::new(BIN).args(&args).output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        std::fs::read(&single).unwrap(),
        std::fs::read(out.path().join("20260621T040000Z.hdr")).unwrap()
    );
}

#[test]
fn a_killed_batch_resumes_to_the_same_table_and_bytes_and_other_options_redo_it() {
    let photos = tempfile::tempdir().unwrap();
    day(photos.path(), 10, 256);
    let whole = tempfile::tempdir().unwrap();
    let o = batch(&[photos.path()], whole.path(), &["-j", "1", "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));

    let killed = tempfile::tempdir().unwrap();
    let state = killed.path().join(".skydome-batch");
    let mut args: Vec<String> = vec![
        "batch".into(),
        photos.path().display().to_string(),
        "-o".into(),
        killed.path().display().to_string(),
        "-j".into(),
        "1".into(),
        "--quiet".into(),
    ];
    args.extend(DOME.iter().map(|s| s.to_string()));
    let mut child = Command::new(BIN).args(&args).spawn().unwrap();
    let records = |d: &Path| {
        std::fs::read_dir(d)
            .map(|r| {
                r.filter(|e| {
                    e.as_ref()
                        .unwrap()
                        .path()
                        .extension()
                        .is_some_and(|x| x == "json")
                })
                .count()
            })
            .unwrap_or(0)
    };
    let started = std::time::Instant::now();
    while records(&state) < 3 && started.elapsed().as_secs() < 300 {
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let at_kill = records(&state);
    assert!(
        (3..10).contains(&at_kill),
        "the run was to be killed part-way; {at_kill} of 10 captures had finished"
    );
    assert!(!killed.path().join("captures.csv").exists());

    let o = Command::new(BIN)
        .args(args.iter().filter(|a| *a != "--quiet"))
        .output()
        .unwrap();
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("resuming: "), "{said}");
    assert_eq!(files(whole.path()), files(killed.path()));

    // Other options: nothing is reused, every dome is made again.
    let o = Command::new(BIN)
        .args(args.iter().filter(|a| *a != "--quiet"))
        .args(["--weighting", "none"])
        .output()
        .unwrap();
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(!said.contains("resuming"), "{said}");
    let h_before = column(&csv(whole.path()), "options_hash");
    let h_after = column(&csv(killed.path()), "options_hash");
    assert_ne!(h_before[0], h_after[0]);
    assert_ne!(
        std::fs::read(whole.path().join("20260621T040000Z.hdr")).unwrap(),
        std::fs::read(killed.path().join("20260621T040000Z.hdr")).unwrap()
    );
}

#[test]
fn shards_from_kubernetes_and_slurm_environments_collect_to_the_one_machine_table() {
    let photos = tempfile::tempdir().unwrap();
    day(photos.path(), 5, 128);
    let one = tempfile::tempdir().unwrap();
    let o = batch(&[photos.path()], one.path(), &["--quiet"]);
    assert!(o.status.success(), "{}", text(&o));

    for (env, extra) in [("k8s", vec!["--shards", "3"]), ("slurm", vec![])] {
        let out = tempfile::tempdir().unwrap();
        for i in 0..3 {
            let mut c = Command::new(BIN);
            c.arg("batch")
                .arg(photos.path())
                .arg("-o")
                .arg(out.path())
                .args(DOME)
                .args(&extra)
                .env_remove("SLURM_ARRAY_TASK_ID")
                .env_remove("JOB_COMPLETION_INDEX");
            if env == "k8s" {
                c.env("JOB_COMPLETION_INDEX", i.to_string());
            } else {
                c.env("SLURM_ARRAY_TASK_ID", (i + 1).to_string())
                    .env("SLURM_ARRAY_TASK_MIN", "1")
                    .env("SLURM_ARRAY_TASK_COUNT", "3");
            }
            let o = c.output().unwrap();
            let said = text(&o);
            assert!(o.status.success(), "{env} {i}: {said}");
            assert!(said.contains(&format!("shard {i}/3")), "{said}");
            if i == 1 {
                // Two of three shards: collecting must refuse, naming the missing one.
                let o = skydome(&["batch", "--collect", out.path().to_str().unwrap()]);
                assert_eq!(o.status.code(), Some(1));
                assert!(
                    text(&o).contains("shard(s) 2 of 3 have not finished"),
                    "{}",
                    text(&o)
                );
            }
        }
        let o = skydome(&[
            "batch",
            "--collect",
            out.path().to_str().unwrap(),
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", text(&o));
        for f in ["captures.csv", "captures.jsonl"] {
            assert_eq!(
                std::fs::read(one.path().join(f)).unwrap(),
                std::fs::read(out.path().join(f)).unwrap(),
                "{env}: {f}"
            );
        }
    }
    // --shards without Kubernetes' index is a usage mistake, said in one line.
    let o = batch(&[photos.path()], one.path(), &["--shards", "3"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("--shards N needs JOB_COMPLETION_INDEX"));
}

#[test]
fn manifest_and_frames_per_capture_group_cameras_without_exif() {
    // `skydome synth` without --captures writes one bracket without EXIF, and its times.
    let a = tempfile::tempdir().unwrap();
    let o = skydome(&[
        "synth",
        "-o",
        a.path().to_str().unwrap(),
        "--size",
        "128",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let list = std::fs::read_to_string(a.path().join("times.txt")).unwrap();
    let mut manifest = String::from("capture,file,exposure_s\n");
    for l in list.lines().filter(|l| !l.starts_with('#')) {
        let (f, t) = l.split_once(' ').unwrap();
        manifest += &format!("morning,{f},{t}\n");
    }
    // A second capture with only one frame: too few frames is a failed row.
    manifest += "noon,frame_0.jpg,0.001\n";
    std::fs::write(a.path().join("manifest.csv"), manifest).unwrap();
    let out = tempfile::tempdir().unwrap();
    let o = batch(&[&a.path().join("manifest.csv")], out.path(), &[]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(
        text(&o).contains("4 rows in 2 captures (manifest)"),
        "{}",
        text(&o)
    );
    let rows = csv(out.path());
    assert_eq!(column(&rows, "capture"), ["morning", "noon"]);
    assert_eq!(column(&rows, "status")[0], "ok");
    assert!(column(&rows, "status")[1].starts_with("failed: "));
    assert!(out.path().join("morning.hdr").is_file());

    // Without times the frames cannot be grouped by EXIF: --frames-per-capture does it.
    let out2 = tempfile::tempdir().unwrap();
    let frames: Vec<PathBuf> = (0..3)
        .map(|i| a.path().join(format!("frame_{i}.jpg")))
        .collect();
    let refs: Vec<&Path> = frames.iter().map(PathBuf::as_path).collect();
    let o = batch(&refs, out2.path(), &["--frames-per-capture", "3"]);
    // No EXIF exposure times either: the capture fails, naming what to give.
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    let rows = csv(out2.path());
    assert_eq!(rows.len(), 2);
    assert!(column(&rows, "status")[0].contains("exposure"), "{rows:?}");
}

/// `--time-zone` reaches every capture: the camera's clock (EXIF says +02:00) read as UTC−05:00,
/// so 06:00 local is 11:00 UTC, in the table, each capture's report (time from EXIF and the
/// flag) and each dome's `GMT=` line.
#[test]
fn the_time_zone_reaches_every_capture() {
    let photos = tempfile::tempdir().unwrap();
    day(photos.path(), 2, 64);
    let out = tempfile::tempdir().unwrap();
    let o = batch(&[photos.path()], out.path(), &["--time-zone", "-05:00"]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = csv(out.path());
    assert_eq!(
        column(&rows, "capture_time_utc"),
        ["2026-06-21T11:00:00Z", "2026-06-21T12:00:00Z"]
    );
    let lines = std::fs::read_to_string(out.path().join("captures.jsonl")).unwrap();
    for (l, hour) in lines.lines().zip([11, 12]) {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        let c = &v["report"]["capture"];
        assert_eq!(c["time_from"], "exif+flag", "{l}");
        // The bracket's own clock (its frames are 1 s apart), read in the given zone.
        let utc = c["time_utc"].as_str().unwrap();
        assert!(utc.starts_with(&format!("2026-06-21T{hour}:00:0")), "{l}");
        let dome = out.path().join(v["output"].as_str().unwrap());
        let head = std::fs::read(&dome).unwrap();
        let head = String::from_utf8_lossy(&head[..head.len().min(2000)]).to_string();
        assert!(
            head.contains(&format!("GMT=2026:06:21 {hour}:00:0")),
            "{head}"
        );
    }
}
