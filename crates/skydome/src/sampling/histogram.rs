//! Histogram sampling (Grossberg & Nayar 2003, "Determining the camera response from images:
//! what is knowable?"; the sampling colour-hdri's `samples_Grossberg2003` implements).
//!
//! If the scene does not change between the frames, the exposure moves every pixel's code
//! along the same monotone response, so the *fraction of pixels darker than a pixel* is the
//! same in every frame. Sample `i` of channel `c` is therefore the code at which each frame's
//! cumulative histogram of that channel comes closest to `uᵢ = i / (N − 1)`: `N` "pixels"
//! matched across the frames by rank instead of by position. Nothing needs to line up — a
//! hand-held bracket, a moving cloud or a swaying branch change a few ranks, not the curve —
//! and every code the frames reach is represented in proportion to its pixels.
//!
//! The histograms count the pixels whose centres lie inside the fish-eye circle (the black
//! housing around it would otherwise pile up at code 0 in every frame), or the whole frame
//! without a circle. 16-bit input is binned to 256 codes (`⌊v · 256 / 65536⌋`), as
//! colour-hdri bins its `[0, 1]` floats. The rank match cannot reject anything, so the
//! clipped, edge and monotonicity tests of the grid draw do not apply: clipped observations
//! get no weight from the hat in the solve.

use super::{
    check_frames, code_range, usable_area, SampleOptions, SampleReport, Samples, SamplingError,
};
use crate::bracket::{Frame, Pixels};
use crate::image::Circle;

/// Codes of the histograms (the 8-bit scale).
const BINS: usize = 256;

/// Draws `opts.samples` rank-matched samples (see the module documentation). The samples have
/// no pixel position: [`Samples::positions`] is empty and [`Samples::count`] gives `N`.
pub(super) fn sample_histogram(
    frames: &[Frame],
    circle: Option<Circle>,
    opts: &SampleOptions,
) -> Result<Samples, SamplingError> {
    let (w, h) = check_frames(frames)?;
    // Refuses a circle that is not finite or lies beside the frame, as the grid draw does.
    usable_area(circle, w, h)?;
    let p = frames.len();
    let n = opts.samples;
    let mut values = vec![[0f32; 3]; n * p];
    for (j, frame) in frames.iter().enumerate() {
        let hist = histograms(frame, circle, w, h)?;
        for (c, counts) in hist.iter().enumerate() {
            let cdf = cumulative(counts);
            for i in 0..n {
                let u = if n > 1 {
                    i as f64 / (n - 1) as f64
                } else {
                    0.0
                };
                values[i * p + j][c] = nearest_rank(&cdf, u) as f32;
            }
        }
    }
    let report = SampleReport {
        requested: n,
        target: n,
        used: n,
        frames: p,
        code_range: code_range(&values),
        histogram: true,
        ..SampleReport::default()
    };
    Ok(Samples {
        positions: Vec::new(),
        values,
        frames: p,
        report,
    })
}

/// Per channel, the number of pixels (inside `circle` when given) at each code.
fn histograms(
    frame: &Frame,
    circle: Option<Circle>,
    w: usize,
    h: usize,
) -> Result<[[u64; BINS]; 3], SamplingError> {
    let mut hist = [[0u64; BINS]; 3];
    let mut pixels = 0u64;
    for y in 0..h {
        let (x0, x1) = match circle {
            Some(c) => c.row_span(y, w),
            None => (0, w),
        };
        let (a, b) = ((y * w + x0) * 3, (y * w + x1) * 3);
        match &frame.pixels {
            Pixels::U8(v) => {
                for px in v[a..b].chunks_exact(3) {
                    for c in 0..3 {
                        hist[c][px[c] as usize] += 1;
                    }
                }
            }
            Pixels::U16(v) => {
                for px in v[a..b].chunks_exact(3) {
                    for c in 0..3 {
                        hist[c][(px[c] >> 8) as usize] += 1;
                    }
                }
            }
        }
        pixels += (x1 - x0) as u64;
    }
    if let (0, Some(c)) = (pixels, circle) {
        // A circle so small that no pixel centre lies inside it.
        return Err(SamplingError::EmptyArea {
            cx: c.cx,
            cy: c.cy,
            r: c.r,
            width: w,
            height: h,
        });
    }
    Ok(hist)
}

/// The cumulative histogram normalised to end at 1.
fn cumulative(counts: &[u64; BINS]) -> [f64; BINS] {
    let mut cdf = [0f64; BINS];
    let mut sum = 0u64;
    for (k, &n) in counts.iter().enumerate() {
        sum += n;
        cdf[k] = sum as f64;
    }
    let total = sum.max(1) as f64;
    for v in &mut cdf {
        *v /= total;
    }
    cdf
}

/// The first code whose cumulative fraction is closest to `u` (ties to the lowest code, as
/// `numpy.argmin`).
fn nearest_rank(cdf: &[f64; BINS], u: f64) -> usize {
    let mut best = 0;
    let mut best_d = f64::INFINITY;
    for (k, &v) in cdf.iter().enumerate() {
        let d = (v - u).abs();
        if d < best_d {
            best = k;
            best_d = d;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bracket::Exposure;

    /// A `w × w` frame whose pixel `(x, y)` has code `code(x, y)` in every channel.
    fn frame(w: usize, t: f64, code: impl Fn(usize, usize) -> u8) -> Frame {
        let mut v = Vec::with_capacity(w * w * 3);
        for y in 0..w {
            for x in 0..w {
                let z = code(x, y);
                v.extend_from_slice(&[z, z, z]);
            }
        }
        Frame {
            name: format!("t{t}"),
            width: w,
            height: w,
            pixels: Pixels::U8(v),
            exposure: Exposure {
                time_s: t,
                iso: None,
                f_number: None,
            },
        }
    }

    /// Two frames of one scene through one monotone response, the second twice as long and
    /// its rows in another order (as if the scene had moved): rank matching pairs each code of
    /// the first with the response's code of twice the exposure, within one code.
    #[test]
    fn ranks_pair_the_codes_of_one_scene_point_without_positions() {
        let radiance = |x: usize, y: usize| 0.02 + 0.96 * ((y * 64 + x) as f64 / 4096.0);
        let response = |e: f64| (255.0 * e.min(1.0).powf(1.0 / 2.2)).round() as u8;
        let a = frame(64, 1.0, |x, y| response(0.5 * radiance(x, y)));
        let b = frame(64, 2.0, |x, y| response(radiance(x, 63 - y)));
        let opts = SampleOptions::histogram_method(200);
        let s = sample_histogram(&[a, b], None, &opts).unwrap();
        assert_eq!(s.count(), 200);
        assert!(s.positions.is_empty() && s.report.histogram);
        for i in 0..200 {
            let (za, zb) = (s.z(i, 0, 1) as f64, s.z(i, 1, 1) as f64);
            let e = (za / 255.0).powf(2.2) * 2.0;
            let expect = 255.0 * e.min(1.0).powf(1.0 / 2.2);
            assert!(
                (zb - expect).abs() <= 2.0,
                "sample {i}: {za} → {zb}, expected {expect}"
            );
        }
    }

    /// Only pixels inside the circle count: the black border outside it (60 % of the frame)
    /// never becomes a sample. (Sample 0, `u = 0`, is the first code whose cumulative
    /// fraction is 0 — code 0 — as in colour-hdri; the hat gives it no weight.)
    #[test]
    fn the_housing_outside_the_circle_is_not_counted() {
        let c = Circle {
            cx: 32.0,
            cy: 32.0,
            r: 20.0,
        };
        let f = |t: f64, base: usize| {
            frame(64, t, move |x, y| {
                if c.contains_pixel(x, y) {
                    (base + (x + y) % 100) as u8
                } else {
                    0
                }
            })
        };
        let opts = SampleOptions::histogram_method(50);
        let s = sample_histogram(&[f(1.0, 50), f(2.0, 120)], Some(c), &opts).unwrap();
        for i in 1..50 {
            let (za, zb) = (s.z(i, 0, 0), s.z(i, 1, 0));
            assert!((50.0..150.0).contains(&za), "sample {i}: {za}");
            assert_eq!(zb - za, 70.0, "sample {i}");
        }
        let outside = Circle {
            cx: 500.0,
            cy: 500.0,
            r: 3.0,
        };
        assert!(sample_histogram(&[f(1.0, 1), f(2.0, 2)], Some(outside), &opts).is_err());
    }

    #[test]
    fn nearest_rank_takes_the_first_of_a_plateau() {
        let mut cdf = [1.0; BINS];
        cdf[0] = 0.0;
        cdf[1] = 0.5;
        cdf[2] = 0.5;
        assert_eq!(nearest_rank(&cdf, 0.0), 0);
        assert_eq!(nearest_rank(&cdf, 0.5), 1);
        assert_eq!(nearest_rank(&cdf, 0.8), 3);
        assert_eq!(nearest_rank(&cdf, 1.0), 3);
    }
}
