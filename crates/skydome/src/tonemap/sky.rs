//! Where automatic exposure looks: the dome circle of a fish-eye picture and the sky weighting
//! inside it (module docs of [`super`], "Sky-keyed exposure").

use crate::fisheye::detect_circle_luma;
use crate::image::{luminance, Circle, HdrImage};

use super::stats::fast_log2;

/// Longest side of the thumbnail the circle is detected on, in pixels.
const THUMB: usize = 256;
/// Frames smaller than this (either side, pixels) are never treated as fish-eye.
const MIN_SIDE: usize = 48;

/// Radius fractions of the sky weighting: full weight within `INNER · r` of the centre, none
/// beyond `OUTER · r`. For a 180° dome the horizon is at `r`; for a 235° lens at 0.61–0.83 `r`
/// (stereographic … equisolid), so 0.8 keeps most of a ground ring out.
pub(crate) const INNER: f64 = 0.5;
pub(crate) const OUTER: f64 = 0.8;

/// Detects the image circle of a clearly fish-eye radiance map, or `None`.
///
/// A thumbnail (point samples, longest side ≤ 256 px) is rendered to 8 bits — maximum of R, G, B
/// scaled so the log-average sits at 0.18, gamma 1/2.2 — and passed to
/// [`crate::fisheye::detect_circle_luma`]. The fit is accepted only when it is plausible:
/// radius ≥ 1/10 of the short side and ≤ the frame's half-diagonal, centre inside the frame, RMS
/// residual ≤ 1.5 % of the radius, ≥ 60 % of boundary points are inliers, and the frame around
/// the circle is housing — at least 3 % of the frame lies outside it and its 95th-percentile
/// luminance is below 1/32 of the median inside.
pub(crate) fn detect_dome(img: &HdrImage) -> Option<Circle> {
    let (w, h) = (img.width, img.height);
    if w < MIN_SIDE || h < MIN_SIDE {
        return None;
    }
    let step = w.max(h).div_ceil(THUMB).max(1);
    let (tw, th) = (w / step, h / step);
    // Point samples at block centres: cheap, and the detector blurs anyway.
    let mut lum = Vec::with_capacity(tw * th);
    let mut peak = Vec::with_capacity(tw * th);
    for ty in 0..th {
        let y = ty * step + step / 2;
        let row = &img.data[3 * y * w..3 * (y + 1) * w];
        for tx in 0..tw {
            let x = tx * step + step / 2;
            let p = [
                row[3 * x].max(0.0),
                row[3 * x + 1].max(0.0),
                row[3 * x + 2].max(0.0),
            ];
            let p = p.map(|v| if v.is_finite() { v } else { f32::MAX });
            lum.push(luminance(p));
            peak.push(p[0].max(p[1]).max(p[2]));
        }
    }
    let (mut sum, mut n) = (0.0f64, 0u32);
    for &l in &lum {
        if l > 0.0 && l < f32::MAX {
            sum += f64::from(fast_log2(l));
            n += 1;
        }
    }
    if n < 64 {
        return None;
    }
    let k = 0.18 / (sum / f64::from(n)).exp2();
    let luma: Vec<u8> = peak
        .iter()
        .map(|&v| ((f64::from(v) * k).min(1.0).powf(1.0 / 2.2) * 255.0).round() as u8)
        .collect();
    let fit = detect_circle_luma(&luma, tw, th).ok()?;
    let c = fit.circle;
    let short = tw.min(th) as f64;
    let half_diag = 0.5 * ((tw * tw + th * th) as f64).sqrt();
    let plausible_shape = c.r >= 0.1 * short
        && c.r <= half_diag
        && (0.0..tw as f64).contains(&c.cx)
        && (0.0..th as f64).contains(&c.cy)
        && fit.residual_px <= (0.015 * c.r).max(1.0)
        && fit.points >= 24
        && 10 * fit.points >= 6 * fit.candidates;
    if !plausible_shape {
        return None;
    }
    // Housing test on the thumbnail: outside (beyond 1.04 r) dark, inside (within 0.9 r) lit.
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for ty in 0..th {
        for tx in 0..tw {
            let dx = tx as f64 + 0.5 - c.cx;
            let dy = ty as f64 + 0.5 - c.cy;
            let rho = (dx * dx + dy * dy).sqrt() / c.r;
            let l = lum[ty * tw + tx];
            if rho > 1.04 {
                outside.push(l);
            } else if rho < 0.9 {
                inside.push(l);
            }
        }
    }
    if outside.len() * 100 < 3 * tw * th || inside.is_empty() {
        return None;
    }
    let q = |v: &mut Vec<f32>, f: f64| {
        let i = ((v.len() - 1) as f64 * f) as usize;
        *v.select_nth_unstable_by(i, f32::total_cmp).1
    };
    let out95 = q(&mut outside, 0.95);
    let in50 = q(&mut inside, 0.5);
    if !(in50 > 0.0 && out95 < in50 / 32.0) {
        return None;
    }
    // Thumbnail coordinate u is full-frame coordinate u·step + (step/2 + ½ − step/2 exactly).
    let s = step as f64;
    let off = (step / 2) as f64 + 0.5 - 0.5 * s;
    Some(Circle {
        cx: c.cx * s + off,
        cy: c.cy * s + off,
        r: c.r * s,
    })
}
