//! Radiance's own tools read skydome's domes: `evalglare -V` (vertical illuminance in the view
//! direction, i.e. horizontal illuminance for an upward view) on every fish-eye output with a
//! `VIEW=` agrees with skydome's own horizontal illuminance within 2 %. Radiance's binaries come
//! from the `pyradiance` package (PyPI), found through `SKYDOME_PYTHON`; CI requires them
//! (`SKYDOME_REQUIRE_INDEPENDENT_READERS=1`).

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_skydome");

/// pyradiance's `bin` and `lib` folders, or `None` (skipped) when it is not installed.
fn radiance() -> Option<(PathBuf, PathBuf)> {
    let py = std::env::var("SKYDOME_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = Command::new(&py)
        .args([
            "-c",
            "import os, pyradiance; print(os.path.dirname(pyradiance.__file__))",
        ])
        .output()
        .ok()
        .filter(|o| o.status.success());
    match out {
        Some(o) => {
            let dir = PathBuf::from(String::from_utf8_lossy(&o.stdout).trim());
            Some((dir.join("bin"), dir.join("lib")))
        }
        None => {
            assert!(
                std::env::var("SKYDOME_REQUIRE_INDEPENDENT_READERS").as_deref() != Ok("1"),
                "{py} lacks pyradiance but SKYDOME_REQUIRE_INDEPENDENT_READERS=1"
            );
            eprintln!("skipping: {py} lacks pyradiance (pip install -r scripts/requirements.txt)");
            None
        }
    }
}

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
    let Some((bin, lib)) = radiance() else {
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
