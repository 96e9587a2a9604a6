//! Helpers shared by the integration tests (each test crate uses a subset of them).
#![allow(dead_code)]

pub mod required;
#[allow(unused_imports)] // each test crate uses some of them
pub use required::{independent_readers, radiance_tools, shared_data};

use std::path::{Path, PathBuf};

use skydome::bracket::{Exposure, Frame, Pixels};
use skydome::response::Response;

/// `../shared/data`, or `None` after saying the test skips (a failure when
/// `SKYDOME_REQUIRE_SHARED_DATA=1`, as in CI); see [`required`].
#[track_caller]
pub fn data_dir() -> Option<PathBuf> {
    required::shared_data("")
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

/// For every frame, the median over its well-exposed pixels (all channels in 20..=235) of
/// `|log2(E_j / E_merged)|`, where `E_j = exp(g(Z) − ln Δt_j)` is what that frame alone says
/// (8-bit frames): how well a merge agrees with each of its frames.
pub fn frame_consistency(frames: &[Frame], r: &Response, merged: &skydome::HdrImage) -> Vec<f64> {
    frames
        .iter()
        .map(|f| frame_deviation(f, r, merged))
        .collect()
}

/// One frame's median over its well-exposed pixels (all channels in 20..=235, `map` positive
/// in every channel) and channels of `|log2(E_frame / E_map)|` (8-bit frame; NaN when no pixel
/// qualifies): [`frame_consistency`] when `map` is the merge of all frames, a prediction error
/// when it is the merge of the others.
pub fn frame_deviation(f: &Frame, r: &Response, map: &skydome::HdrImage) -> f64 {
    let Pixels::U8(v) = &f.pixels else {
        panic!("8-bit")
    };
    let lt = f.exposure.relative().ln();
    let mut d: Vec<f64> = Vec::new();
    for p in 0..f.width * f.height {
        let px = &v[3 * p..3 * p + 3];
        if px.iter().all(|&z| (20..=235).contains(&z)) && (0..3).all(|c| map.data[3 * p + c] > 0.0)
        {
            for (c, &z) in px.iter().enumerate() {
                let ej = r.curve(c)[z as usize] - lt;
                let em = (map.data[3 * p + c] as f64).ln();
                d.push(((ej - em) / std::f64::consts::LN_2).abs());
            }
        }
    }
    if d.is_empty() {
        return f64::NAN;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}
