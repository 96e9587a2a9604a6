//! The whole response curve: code-band sampling on a many-frame bracket with a black level
//! (a film-scan-like case), against the true curve and OpenCV's measured figures.
use skydome::response::{calibrate, CalibrateOptions};
use skydome::sampling::SampleOptions;
use skydome::synth::{generate, SynthBracket, SynthOptions};

/// Black level of the synthetic film-scan bracket, 8-bit code.
const BLACK: f64 = 16.0;
/// Lowest code of the curve comparison: g below the black level is undefined.
const ZMIN: usize = 20;

/// 16 frames, 32 s … 1/1024 s, a black level at code 16, JPEG quality 95, a moderately noisy
/// sensor.
fn film(seed: u64) -> SynthBracket {
    generate(&SynthOptions {
        width: 320,
        height: 320,
        evs: (-10..=5).map(f64::from).collect(),
        base_time_s: 1.0,
        seed,
        jpeg_quality: Some(95),
        full_well: 20_000.0,
        read_noise: 2.0,
        black_level: BLACK,
        ..SynthOptions::default()
    })
    .unwrap()
}

/// RMS of `rec − truth` over `ZMIN..=245` after removing the mean offset, in stops.
fn rmse(rec: &[f64], truth: &[f64]) -> f64 {
    let d: Vec<f64> = (ZMIN..=245).map(|z| rec[z] - truth[z]).collect();
    let m = d.iter().sum::<f64>() / d.len() as f64;
    (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
        / std::f64::consts::LN_2
}

fn banded() -> CalibrateOptions {
    CalibrateOptions {
        sampling: SampleOptions {
            code_bands: 16,
            ..SampleOptions::default()
        },
        ..CalibrateOptions::default()
    }
}
