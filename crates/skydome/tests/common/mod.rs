//! Helpers shared by the integration tests (each test crate uses a subset of them).
#![allow(dead_code)]

pub mod encode;

use std::path::{Path, PathBuf};

use skydome::bracket::{Exposure, Frame, Pixels};
use skydome::response::Response;

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

/// For every frame, the median over its well-exposed pixels (all channels in 20..=235) of
/// `|log2(E_j / E_merged)|`, where `E_j = exp(g(Z) − ln Δt_j)` is what that frame alone says
/// (8-bit frames): how well a merge agrees with each of its frames.
pub fn frame_consistency(frames: &[Frame], r: &Response, merged: &skydome::HdrImage) -> Vec<f64> {
    frames
        .iter()
        .map(|f| {
            let Pixels::U8(v) = &f.pixels else {
                panic!("8-bit")
            };
            let lt = f.exposure.relative().ln();
            let mut d: Vec<f64> = Vec::new();
            for p in 0..f.width * f.height {
                let px = &v[3 * p..3 * p + 3];
                if px.iter().all(|&z| (20..=235).contains(&z)) {
                    for (c, &z) in px.iter().enumerate() {
                        let ej = r.curve(c)[z as usize] - lt;
                        let em = (merged.data[3 * p + c] as f64).ln();
                        d.push(((ej - em) / std::f64::consts::LN_2).abs());
                    }
                }
            }
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        })
        .collect()
}
