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
