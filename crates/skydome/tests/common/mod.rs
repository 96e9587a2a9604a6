//! Helpers shared by the integration tests (each test crate uses a subset of them).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use skydome::bracket::{Exposure, Frame, Pixels};

/// `../shared/data` beside the repository, or `None` (with a message) in a fresh clone; a
/// failure instead when `SKYDOME_REQUIRE_SHARED_DATA=1` (CI).
pub fn data_dir() -> Option<PathBuf> {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if d.is_dir() {
        Some(d)
    } else {
        // CI sets SKYDOME_REQUIRE_SHARED_DATA=1 so a broken data path fails instead of skipping.
        assert!(
            std::env::var("SKYDOME_REQUIRE_SHARED_DATA").as_deref() != Ok("1"),
            "{} not found but SKYDOME_REQUIRE_SHARED_DATA=1",
            d.display()
        );
        eprintln!("skipping: ../shared/data not found");
        None
    }
}

/// Decodes `(file, exposure time in s)` pairs from `dir` as 8-bit frames, shortest first.
pub fn load_jpegs(dir: &Path, files: &[(&str, f64)]) -> Vec<Frame> {
    let mut frames: Vec<Frame> = files
        .iter()
        .map(|&(name, t)| {
            let img = image::open(dir.join(name)).unwrap().to_rgb8();
            Frame {
                name: name.into(),
                width: img.width() as usize,
                height: img.height() as usize,
                pixels: Pixels::U8(img.into_raw()),
                exposure: Exposure {
                    time_s: t,
                    iso: None,
                    f_number: None,
                },
            }
        })
        .collect();
    frames.sort_by(|a, b| a.exposure.time_s.total_cmp(&b.exposure.time_s));
    frames
}

/// pyradiance's `bin` and `lib` folders (Radiance's own binaries: `gendaylit`, `rpict`,
/// `evalglare` …), found through the Python in `SKYDOME_PYTHON` (default `python3`); `None`
/// (skipped, with a message) when it lacks pyradiance, a failure instead when
/// `SKYDOME_REQUIRE_INDEPENDENT_READERS=1` (CI).
pub fn radiance_tools() -> Option<(PathBuf, PathBuf)> {
    let py = std::env::var("SKYDOME_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = std::process::Command::new(&py)
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
