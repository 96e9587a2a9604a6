//! Vignetting from flat-field photos: pictures of a uniform target (an integrating sphere, a
//! diffuser over the lens under an even sky, a uniformly lit white dome) through the lens. Each
//! photo is linearised with the camera's response, the luminance of every well-exposed pixel is
//! collected in rings of equal angle θ from the optical axis (the lens profile's circle centre
//! and projection), and each ring's median over the centre ring's median is the fall-off
//! `V(θ)` there. Several photos (e.g. the target turned between shots, to average out its own
//! unevenness) are averaged ring by ring. [`Vignetting::fit`] then fits the even polynomial.
//!
//! Pixels are taken in stored order (as `lens detect` takes a single photo), so the photos must
//! be stored the way the sky photos the lens profile came from were.

use crate::bracket::{bin16, DecodedFrame, Pixels};
use crate::fisheye::{FisheyeError, LensProfile};
use crate::image::radiance_luminance;
use crate::response::Response;

/// Width of the rings, degrees.
pub const RING_DEG: f64 = 2.0;

/// Fewest pixels a ring needs to count.
const MIN_RING_PIXELS: usize = 25;

/// 8-bit codes outside this range are clipped or in the noise: not used.
const USABLE: std::ops::RangeInclusive<u8> = 6..=249;

/// The fall-off measured in `frames` through `lens`: `(angle_deg, relative value)` per ring of
/// [`RING_DEG`] (its centre angle; the centre ring, 1 by definition, is left out), ready for
/// [`Vignetting::fit`](crate::fisheye::Vignetting::fit). `response` linearises the codes.
pub fn flat_field_falloff(
    frames: &[DecodedFrame],
    lens: &LensProfile,
    response: &Response,
) -> Result<Vec<(f64, f64)>, FisheyeError> {
    lens.validate()?;
    let theta_max = (0.5 * lens.fov_deg).to_radians();
    let rings = (0.5 * lens.fov_deg / RING_DEG).ceil() as usize;
    let mut sums = vec![0.0f64; rings];
    let mut counts = vec![0usize; rings];
    for f in frames {
        let values = ring_medians(f, lens, response, rings, theta_max)?;
        let Some(centre) = values[0].filter(|v| *v > 0.0) else {
            return Err(FisheyeError::BadParameter {
                what: "well-exposed pixels within 2° of the optical axis",
                value: 0.0,
                hint:
                    "the flat field must be exposed so that its centre is neither clipped nor black",
            });
        };
        for (i, v) in values.iter().enumerate().skip(1) {
            if let Some(v) = v {
                sums[i] += v / centre;
                counts[i] += 1;
            }
        }
    }
    let points: Vec<(f64, f64)> = (1..rings)
        .filter(|&i| counts[i] > 0)
        .map(|i| {
            let angle = ((i as f64 + 0.5) * RING_DEG).min(0.5 * lens.fov_deg);
            (angle, sums[i] / counts[i] as f64)
        })
        .collect();
    Ok(points)
}

/// Median linear luminance per ring of one frame (`None` for rings with too few usable pixels).
fn ring_medians(
    f: &DecodedFrame,
    lens: &LensProfile,
    response: &Response,
    rings: usize,
    theta_max: f64,
) -> Result<Vec<Option<f64>>, FisheyeError> {
    let (w, h) = (f.width, f.height);
    crate::image::check_samples(
        match &f.pixels {
            Pixels::U8(p) => p.len(),
            Pixels::U16(p) => p.len(),
        },
        w,
        h,
        3,
    )?;
    let code = |i: usize| -> u8 {
        match &f.pixels {
            Pixels::U8(p) => p[i],
            Pixels::U16(p) => bin16(p[i]),
        }
    };
    let g = |c: usize, i: usize| -> f64 {
        match &f.pixels {
            Pixels::U8(p) => response.curve(c)[p[i] as usize],
            Pixels::U16(p) => response.g16(c, p[i]),
        }
    };
    let limit = lens.projection.theta_limit();
    let (cx, cy) = (lens.circle.cx, lens.circle.cy);
    let mut buckets: Vec<Vec<f64>> = vec![Vec::new(); rings];
    for y in 0..h {
        let dy = y as f64 + 0.5 - cy;
        for x in 0..w {
            let rho = (x as f64 + 0.5 - cx).hypot(dy);
            let Some(t) = lens.projection.theta_within(rho, limit) else {
                continue;
            };
            if t > theta_max {
                continue;
            }
            let i = 3 * (y * w + x);
            if !(0..3).all(|c| USABLE.contains(&code(i + c))) {
                continue;
            }
            let e = [0, 1, 2].map(|c| g(c, i + c).exp());
            let ring = ((t.to_degrees() / RING_DEG) as usize).min(rings - 1);
            buckets[ring].push(radiance_luminance(e));
        }
    }
    Ok(buckets
        .into_iter()
        .map(|mut b| {
            if b.len() < MIN_RING_PIXELS {
                return None;
            }
            let mid = b.len() / 2;
            Some(*b.select_nth_unstable_by(mid, f64::total_cmp).1)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fisheye::{LensKind, Vignetting};
    use crate::image::{Circle, HdrImage};
    use crate::synth::{photograph, SynthOptions};

    /// A uniform target through a lens with fall-off `v`, photographed at one exposure.
    fn flat(v: &Vignetting, lens: &LensProfile, size: usize, seed: u64) -> DecodedFrame {
        let mut truth = HdrImage::new(size, size);
        for y in 0..size {
            for x in 0..size {
                let rho = (x as f64 + 0.5 - lens.circle.cx).hypot(y as f64 + 0.5 - lens.circle.cy);
                let val = match lens
                    .projection
                    .theta_within(rho, lens.projection.theta_limit())
                {
                    Some(t) if t <= (0.5 * lens.fov_deg).to_radians() => 2.5 * v.at(t),
                    _ => 0.0,
                };
                truth.set_pixel(x, y, [val as f32; 3]);
            }
        }
        let opts = SynthOptions {
            evs: vec![0.0],
            seed,
            ..SynthOptions::default()
        };
        photograph(&truth, &opts)
            .expect("photograph")
            .remove(0)
            .into()
    }

    #[test]
    fn a_known_falloff_comes_back_from_flat_fields() {
        let size = 400;
        let lens = LensProfile::from_fov(
            Circle {
                cx: 200.3,
                cy: 199.6,
                r: 190.0,
            },
            185.0,
            LensKind::Equisolid,
        )
        .expect("lens");
        let truth = Vignetting {
            coefficients: [-0.25, 0.03, 0.0],
            rms: 0.0,
            samples: 0,
        };
        // The simulated camera's true response, as a calibration would give it.
        let crf = SynthOptions::default().crf;
        let response = Response::from_curves(crf.map(|c| c.g())).expect("response");
        let frames: Vec<DecodedFrame> = (1..=2).map(|s| flat(&truth, &lens, size, s)).collect();
        let points = flat_field_falloff(&frames, &lens, &response).expect("falloff");
        assert!(points.len() > 40, "{}", points.len());
        let fit = Vignetting::fit(&points).expect("fit");
        let [a, b, c] = fit.at_30_60_90();
        let [ta, tb, tc] = truth.at_30_60_90();
        for (got, want, at) in [(a, ta, 30), (b, tb, 60), (c, tc, 90)] {
            assert!((got / want - 1.0).abs() < 0.02, "V({at}°) {got} vs {want}");
        }
        // A black frame says what is wrong.
        let mut black = frames[0].clone();
        black.pixels = Pixels::U8(vec![0; 3 * size * size]);
        let e = flat_field_falloff(&[black], &lens, &response).unwrap_err();
        assert!(e.to_string().contains("optical axis"), "{e}");
    }
}
