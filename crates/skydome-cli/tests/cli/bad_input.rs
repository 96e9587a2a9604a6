//! Table-driven bad-input test: every case must give exit code 1, a single line
//! `error: <file>: <what>` on stderr, no panic, and no output file (or temporary) left behind.

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

/// A small synthetic scene: a smooth gradient with some texture, `scale` times brighter.
fn scene(w: u32, h: u32, scale: f32) -> image::RgbImage {
    image::RgbImage::from_fn(w, h, |x, y| {
        let base = 0.02 + 0.5 * (x as f32 / w as f32) * (0.5 + 0.5 * (y as f32 / h as f32));
        let tex = 1.0 + 0.3 * ((x as f32 * 0.7).sin() * (y as f32 * 0.45).cos());
        let v = |k: f32| {
            let e = (base * tex * k * scale).min(1.0);
            (255.0 * e.powf(1.0 / 2.2)).round() as u8
        };
        image::Rgb([v(1.0), v(0.8), v(0.6)])
    })
}

struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        for (i, s) in [0.25f32, 1.0, 4.0].iter().enumerate() {
            scene(64, 48, *s)
                .save(dir.path().join(format!("f{i}.png")))
                .unwrap();
        }
        scene(32, 48, 1.0)
            .save(dir.path().join("small.png"))
            .unwrap();
        scene(1, 1, 1.0).save(dir.path().join("one.png")).unwrap();
        let wide: image::ImageBuffer<image::Rgb<u16>, Vec<u16>> =
            image::ImageBuffer::from_fn(64, 48, |x, y| {
                let p = scene(64, 48, 4.0).get_pixel(x, y).0;
                image::Rgb(p.map(|v| u16::from(v) * 257))
            });
        wide.save(dir.path().join("deep.png")).unwrap();
        let mut jpeg = Vec::new();
        scene(64, 48, 1.0)
            .write_to(
                &mut std::io::Cursor::new(&mut jpeg),
                image::ImageFormat::Jpeg,
            )
            .unwrap();
        std::fs::write(dir.path().join("good.jpg"), &jpeg).unwrap();
        std::fs::write(dir.path().join("truncated.jpg"), &jpeg[..jpeg.len() / 3]).unwrap();
        std::fs::write(dir.path().join("empty.jpg"), b"").unwrap();
        std::fs::write(dir.path().join("text.jpg"), b"this is not a picture\n").unwrap();
        std::fs::write(
            dir.path().join("image.gif"),
            b"GIF89a\x01\x00\x01\x00\x00\x00\x00;",
        )
        .unwrap();
        std::fs::copy(dir.path().join("f1.png"), dir.path().join("f1_copy.png")).unwrap();
        std::fs::write(dir.path().join("bad.json"), b"{\"version\": 99}").unwrap();
        std::fs::write(
            dir.path().join("bad.hdr"),
            b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X",
        )
        .unwrap();
        Fixture { dir }
    }
    fn p(&self, name: &str) -> String {
        self.dir.path().join(name).display().to_string()
    }
}

fn leftovers(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            n.starts_with("out") || n.starts_with(".skydome-")
        })
        .collect()
}

#[test]
fn bad_input_gives_one_line_error_exit_1_and_no_output() {
    let fx = Fixture::new();
    let out = fx.p("out.hdr");
    let f = |n: &str| fx.p(n);
    let merge = |files: &[&str], extra: &[&str]| -> Vec<String> {
        let mut v = vec!["merge".to_string()];
        v.extend(files.iter().map(|n| fx.p(n)));
        v.extend(["-o".to_string(), out.clone()]);
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let times3 = ["--times", "1/400,1/100,1/25"];
    // (name, arguments, text the message must contain)
    let cases: Vec<(&str, Vec<String>, String)> = vec![
        (
            "one frame",
            merge(&["f0.png"], &["--times", "1/100"]),
            "at least 2 frames".into(),
        ),
        (
            "different sizes",
            merge(&["f0.png", "small.png"], &["--times", "1/100,1/25"]),
            f("small.png"),
        ),
        (
            "same exposure",
            merge(
                &["f0.png", "f1.png", "f2.png"],
                &["--times", "1/100,1/100,1/25"],
            ),
            "1/6 stop".into(),
        ),
        (
            "identical pixels",
            merge(&["f1.png", "f1_copy.png"], &["--times", "1/100,1/25"]),
            "nearly identical".into(),
        ),
        (
            "missing exposure",
            merge(&["f0.png", "f1.png", "f2.png"], &[]),
            format!("{}: no exposure time", f("f0.png")),
        ),
        (
            "file does not exist",
            merge(&["f0.png", "nothere.png"], &["--times", "1/100,1/25"]),
            f("nothere.png"),
        ),
        (
            "truncated jpeg",
            merge(&["good.jpg", "truncated.jpg"], &["--times", "1/100,1/25"]),
            f("truncated.jpg"),
        ),
        (
            "zero-byte file",
            merge(&["f0.png", "empty.jpg"], &["--times", "1/100,1/25"]),
            format!("{}: empty file", f("empty.jpg")),
        ),
        (
            "text file named .jpg",
            merge(&["f0.png", "text.jpg"], &["--times", "1/100,1/25"]),
            f("text.jpg"),
        ),
        (
            "unsupported format",
            merge(&["f0.png", "image.gif"], &["--times", "1/100,1/25"]),
            f("image.gif"),
        ),
        (
            "1x1 image",
            merge(&["one.png", "f0.png"], &["--times", "1/100,1/25"]),
            f("one.png"),
        ),
        (
            "16-bit/8-bit mix",
            merge(&["f0.png", "deep.png"], &["--times", "1/100,1/25"]),
            "bit depth".into(),
        ),
        (
            "negative time",
            merge(
                &["f0.png", "f1.png", "f2.png"],
                &["--times", "1/400,-1/100,1/25"],
            ),
            "-1/100".into(),
        ),
        (
            "zero time",
            merge(
                &["f0.png", "f1.png", "f2.png"],
                &["--times", "0,1/100,1/25"],
            ),
            "invalid exposure time '0'".into(),
        ),
        (
            "times that belong to other photos",
            merge(
                &["f0.png", "f1.png", "f2.png"],
                &["--times", "1/25,1/100,1/400"],
            ),
            "at most pixels although it was exposed longer".into(),
        ),
        (
            "wrong count of times",
            merge(&["f0.png", "f1.png", "f2.png"], &["--times", "1/100,1/25"]),
            "--times has 2 values but 3 files".into(),
        ),
        (
            "pixel limit",
            merge(
                &["f0.png", "f1.png", "f2.png"],
                &[times3[0], times3[1], "--max-pixels", "1000"],
            ),
            "above the limit".into(),
        ),
        (
            "unwritable output folder",
            {
                let mut v = merge(&["f0.png", "f1.png", "f2.png"], &times3);
                let i = v.iter().position(|a| a == "-o").unwrap();
                v[i + 1] = fx.p("no/such/dir/out.hdr");
                v
            },
            "does not exist".into(),
        ),
        (
            "output is an input",
            {
                let mut v = merge(&["f0.png", "f1.png", "f2.png"], &times3);
                let i = v.iter().position(|a| a == "-o").unwrap();
                v[i + 1] = fx.p("f2.png");
                v
            },
            "input".into(),
        ),
        (
            "bad camera profile",
            merge(
                &["f0.png", "f1.png", "f2.png"],
                &[times3[0], times3[1], "--profile", &f("bad.json")],
            ),
            f("bad.json"),
        ),
        (
            "corrupt hdr for info",
            vec!["info".into(), f("bad.hdr")],
            f("bad.hdr"),
        ),
        (
            "tonemap of a text file",
            vec![
                "tonemap".into(),
                f("text.jpg"),
                "-o".into(),
                fx.p("out.jpg"),
            ],
            f("text.jpg"),
        ),
    ];
    assert!(cases.len() >= 15);
    let mut failures = Vec::new();
    for (name, args, want) in &cases {
        let o = Command::new(BIN).args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        let lines: Vec<&str> = stderr
            .lines()
            .filter(|l| !l.starts_with("warning:"))
            .collect();
        let ok = o.status.code() == Some(1)
            && lines.len() == 1
            && lines[0].starts_with("error: ")
            && lines[0].contains(want.as_str())
            && !stderr.contains("panicked")
            && leftovers(fx.dir.path()).is_empty();
        if !ok {
            failures.push(format!(
                "{name}: exit {:?}, stderr {stderr:?}, want {want:?}, leftovers {:?}",
                o.status.code(),
                leftovers(fx.dir.path())
            ));
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

#[test]
fn usage_error_exits_2() {
    let o = Command::new(BIN)
        .args(["merge", "--no-such-flag"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn existing_output_is_kept_without_force() {
    let fx = Fixture::new();
    let out = fx.p("existing.hdr");
    std::fs::write(&out, b"keep me").unwrap();
    let o = Command::new(BIN)
        .args(["merge", &fx.p("f0.png"), &fx.p("f1.png"), &fx.p("f2.png")])
        .args(["--times", "1/400,1/100,1/25", "-o", &out])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--force"));
    assert_eq!(std::fs::read(&out).unwrap(), b"keep me");
}
