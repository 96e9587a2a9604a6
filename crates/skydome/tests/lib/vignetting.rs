//! Vignetting: a fall-off fitted from (angle, relative value) measurements is divided out by the
//! merge, so a uniform sky comes out flat.

use skydome::bracket::{DecodedFrame, Pixels};
use skydome::camera::CameraProfile;
use skydome::fisheye::{LensKind, LensProfile, Vignetting};
use skydome::image::Circle;
use skydome::pipeline::{self, Frames, Input, LensSource, Options, ResponseSource};

const CIRCLE: Circle = Circle {
    cx: 160.0,
    cy: 150.0,
    r: 140.0,
};

/// The fall-off of the simulated lens.
fn true_v(theta: f64) -> f64 {
    let t2 = theta * theta;
    1.0 - 0.25 * t2 + 0.02 * t2 * t2
}

/// A uniform sky of radiance 1 through the vignetting lens, as linear 8-bit frames at
/// `times` (code = 255 · min(1, E · t / 2.5e-3), rounded).
fn frames(lens: &LensProfile, times: &[f64]) -> Vec<DecodedFrame> {
    let (w, h) = (320, 300);
    times
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            let mut px = vec![0u8; 3 * w * h];
            for y in 0..h {
                for x in 0..w {
                    let rho = (x as f64 + 0.5 - CIRCLE.cx).hypot(y as f64 + 0.5 - CIRCLE.cy);
                    let Some(theta) = lens
                        .projection
                        .theta_within(rho, lens.projection.theta_limit())
                    else {
                        continue;
                    };
                    if rho > CIRCLE.r {
                        continue;
                    }
                    let e = true_v(theta) * t / 2.5e-3;
                    let z = (255.0 * e.min(1.0)).round() as u8;
                    px[3 * (y * w + x)..3 * (y * w + x) + 3].fill(z);
                }
            }
            DecodedFrame {
                exif_time_s: Some(t),
                ..DecodedFrame::new(&format!("f{i}"), w, h, Pixels::U8(px))
            }
        })
        .collect()
}

/// Max/min of the merged radiance over θ ≤ 90°, minus 1.
fn spread(lens: &LensProfile) -> f64 {
    let times = [0.5e-3, 1e-3, 2e-3];
    let input = Input::new(Frames::Decoded(frames(lens, &times)));
    let o = Options {
        response: ResponseSource::Profile(CameraProfile::linear()),
        lens: LensSource::Profile(lens.clone()),
        ..Options::default()
    };
    let dome = pipeline::run(input, &o, &mut pipeline::no_progress).expect("run");
    let r90 = lens.radius_at_deg(90.0).unwrap();
    let img = &dome.radiance;
    let (mut lo, mut hi) = (f32::MAX, 0f32);
    for y in 0..img.height {
        for x in 0..img.width {
            let rho = (x as f64 + 0.5 - CIRCLE.cx).hypot(y as f64 + 0.5 - CIRCLE.cy);
            if rho <= r90 - 1.0 {
                let g = img.pixel(x, y)[1];
                lo = lo.min(g);
                hi = hi.max(g);
            }
        }
    }
    f64::from(hi / lo) - 1.0
}

#[test]
fn fitted_fall_off_is_divided_out() {
    let mut lens = LensProfile::from_fov(CIRCLE, 200.0, LensKind::Equisolid).unwrap();
    // Measurements every 10° from 0 to 100°, as the rotate-the-camera procedure gives them,
    // with ±0.3 % meter noise.
    let pts: Vec<(f64, f64)> = (0..=10)
        .map(|k| {
            let a = 10.0 * k as f64;
            let noise = 0.003 * if k % 2 == 0 { 1.0 } else { -1.0 };
            (a, true_v(a.to_radians()) * (1.0 + noise))
        })
        .collect();
    let v = Vignetting::fit(&pts).unwrap();
    for (got, deg) in v.at_30_60_90().iter().zip([30.0f64, 60.0, 90.0]) {
        let want = true_v(deg.to_radians());
        assert!((got / want - 1.0).abs() < 0.01, "{deg}°: {got} vs {want}");
    }
    // Uncorrected, the dome falls off by half towards the horizon.
    let raw = spread(&lens);
    assert!(raw > 0.5, "uncorrected spread {raw}");
    lens.vignetting = Some(v);
    let flat = spread(&lens);
    assert!(flat < 0.02, "corrected spread {flat}");
    // The profile keeps the model through JSON, and old profiles without it still load.
    let json = lens.to_json().unwrap();
    assert_eq!(LensProfile::from_json(&json).unwrap(), lens);
    lens.vignetting = None;
    assert!(!lens.to_json().unwrap().contains("vignetting"));
}

#[test]
fn too_few_or_bad_measurements_are_refused() {
    assert!(Vignetting::fit(&[(0.0, 1.0), (30.0, 0.9), (60.0, 0.7)]).is_err());
    assert!(Vignetting::fit(&[(10.0, 1.0), (30.0, -0.9), (60.0, 0.7), (80.0, 0.5)]).is_err());
    assert!(Vignetting::fit(&[(10.0, 1.0), (30.0, 0.9), (60.0, f64::NAN)]).is_err());
}
