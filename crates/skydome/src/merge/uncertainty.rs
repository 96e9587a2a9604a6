//! The per-pixel standard error of a merge, in stops, from the camera noise model.
//!
//! For a pixel of merged radiance `E`, frame `j` is expected to read the code
//! `zⱼ = g⁻¹(ln E + ln Δtⱼ)`; its vote `g(zⱼ) − ln Δtⱼ` has the variance `σ²(zⱼ)` of the noise
//! model ([`NoiseModel::log_variance`]). The merge is a weighted mean of the votes with
//! weights `wⱼ` (the weighting's, evaluated at the expected codes: `1/σ²` for
//! [`Weighting::Noise`], the hat otherwise), so its variance is
//!
//! ```text
//! Var(ln E) = Σ wⱼ² σ²(zⱼ) / (Σ wⱼ)²          (= 1 / Σ 1/σ² for inverse-variance weights)
//! ```
//!
//! and the standard error in stops is `√Var / ln 2`. Frames expected at or above code 255 − 1
//! or at or below the black level do not count. A pixel flagged clipped (in the shortest
//! frame) or black (in the longest) was not measured: its standard error is `+∞`.
//! Everything is computed from the merged radiance alone, so the frames' pixels may already
//! have been given back.

use crate::image::HdrImage;
use crate::noise::NoiseModel;
use crate::response::{Response, LEVELS};

use super::hat::weight;
use super::Weighting;

/// Points of the inverse-response table per channel.
const INVERSE: usize = 4096;

/// The inverse of `g` (continuous code for a value of `g`) as a table over `g(0)..g(255)`.
struct Inverse {
    lo: f64,
    step: f64,
    z: Vec<f32>,
}

impl Inverse {
    fn new(g: &[f64]) -> Self {
        let lo = g[0];
        let hi = g[LEVELS - 1];
        let step = (hi - lo).max(1e-9) / (INVERSE - 1) as f64;
        let mut z = Vec::with_capacity(INVERSE);
        let mut k = 0usize;
        for i in 0..INVERSE {
            let v = lo + step * i as f64;
            while k + 1 < LEVELS - 1 && g[k + 1] < v {
                k += 1;
            }
            let (a, b) = (g[k], g[k + 1]);
            let f = if b > a {
                ((v - a) / (b - a)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            z.push((k as f64 + f) as f32);
        }
        Self { lo, step, z }
    }

    /// The continuous code whose `g` is `v`; below `g(0)` gives −1, above `g(255)` 256.
    #[inline]
    fn code(&self, v: f64) -> f32 {
        let i = (v - self.lo) / self.step;
        if i < 0.0 {
            -1.0
        } else if i > (INVERSE - 1) as f64 {
            LEVELS as f32
        } else {
            self.z[i.round() as usize]
        }
    }
}

/// The per-pixel, per-channel standard error in stops of a merge (see the module docs):
/// `radiance` as merged (relative units, before any crop), `clipped` its flags when kept,
/// `log_exposures` the frames' `ln Δt` shortest first, the response and noise model and the
/// weighting the merge used, and the black level (8-bit code).
pub fn standard_error(
    radiance: &HdrImage,
    clipped: Option<&[u8]>,
    log_exposures: &[f64],
    response: &Response,
    noise: &NoiseModel,
    weighting: Weighting,
    black_level: u8,
) -> HdrImage {
    let n = radiance.width * radiance.height;
    let p = log_exposures.len();
    let inv: Vec<Inverse> = (0..3).map(|c| Inverse::new(response.curve(c))).collect();
    let var: Vec<Vec<f64>> = (0..3)
        .map(|c| {
            (0..LEVELS)
                .map(|z| noise.log_variance(response, c, z))
                .collect()
        })
        .collect();
    let ln2 = std::f64::consts::LN_2;
    let mut out = vec![0f32; 3 * n];
    for k in 0..n {
        let flagged = clipped.is_some_and(|m| m.get(k).is_some_and(|&f| f != 0));
        for c in 0..3 {
            let e = radiance.data[3 * k + c];
            if flagged || e.is_nan() || e <= 0.0 || e.is_infinite() {
                out[3 * k + c] = f32::INFINITY;
                continue;
            }
            let le = f64::from(e).ln();
            let (mut sw, mut sw2v) = (0f64, 0f64);
            for (j, &lt) in log_exposures.iter().enumerate() {
                let z = inv[c].code(le + lt);
                if z <= f32::from(black_level) || z >= (LEVELS - 2) as f32 {
                    continue;
                }
                let v = var[c][(z.round() as usize).min(LEVELS - 1)];
                let w = match weighting {
                    Weighting::Noise => 1.0 / v,
                    other => f64::from(weight(z, j, p, other)),
                };
                sw += w;
                sw2v += w * w * v;
            }
            out[3 * k + c] = if sw > 0.0 {
                ((sw2v.sqrt() / sw) / ln2) as f32
            } else {
                f32::INFINITY
            };
        }
    }
    HdrImage {
        width: radiance.width,
        height: radiance.height,
        data: out,
    }
}

/// Summary of a standard-error map over the pixels selected by `keep` (all when `None`):
/// the median and 90th percentile (stops) of each pixel's largest channel error among the
/// measured pixels, and the fraction of pixels not measured (`+∞`).
pub fn summarise(sigma: &HdrImage, keep: Option<&dyn Fn(usize) -> bool>) -> (f64, f64, f64) {
    let n = sigma.width * sigma.height;
    let mut finite = Vec::with_capacity(n);
    let mut total = 0usize;
    for k in 0..n {
        if keep.is_some_and(|f| !f(k)) {
            continue;
        }
        total += 1;
        let m = sigma.data[3 * k..3 * k + 3]
            .iter()
            .copied()
            .fold(0f32, f32::max);
        if m.is_finite() {
            finite.push(m);
        }
    }
    if finite.is_empty() {
        return (f64::INFINITY, f64::INFINITY, 1.0);
    }
    finite.sort_unstable_by(f32::total_cmp);
    let q = |f: f64| f64::from(finite[((finite.len() - 1) as f64 * f).round() as usize]);
    let unmeasured = 1.0 - finite.len() as f64 / total.max(1) as f64;
    (q(0.5), q(0.9), unmeasured)
}
