//! A camera noise model, estimated from the bracket itself, and the merge weights it implies.
//!
//! A pixel's code `z` comes from `X_e = K · e^{g(z)}` electrons (`g` the calibrated log
//! response with `g(128) = 0`, so `K` is the electron count at code 128). The estimate of
//! `ln E = g(z) − ln Δt` that one frame gives has the variance
//!
//! ```text
//! σ²(z) = 1 / X_e              photon shot noise (Poisson: variance = electrons)
//!       + σ_r² / X_e²          read noise σ_r electrons r.m.s.
//!       + g'(z)² · (1/12 + σ_c²)  quantisation (1/12 code²) and code-domain noise σ_c codes
//!                                (JPEG, demosaicing), carried through the slope of g
//! ```
//!
//! in natural-log units squared. It depends on the code only, not on the frame: at a given
//! code, every frame collected the same number of electrons. What differs between frames is
//! *which* code a scene point lands on — a longer exposure puts it higher, where `X_e` is larger
//! and `σ²` smaller — so weighting each vote by `1 / σ²` is the minimum-variance combination
//! (Mitsunaga & Nayar 1999; Granados et al. 2010, *Optimal HDR reconstruction with linear
//! digital cameras*; Hasinoff et al. 2010). Debevec's hat instead gives code 200 the weight of
//! code 55, although in a 2-stop bracket code 200 collected about ten times the light. The
//! merge evaluates `σ²` at the code each frame is *expected* to read for the pixel's light (from
//! a first, hat-weighted estimate), not at the code it read: a weight taken from the observed
//! code lets each frame's own noise choose its weight, and measured against the truth that
//! biased merge lost to the hat on the sky it was meant to improve.

//! ## Estimation from the bracket ([`estimate`])
//! Where a pixel is well exposed in two adjacent frames `j` and `j + 1`, the difference of their
//! votes `d = (g(z₂) − ln Δt₂) − (g(z₁) − ln Δt₁)` has variance `σ²(z₁) + σ²(z₂)` — linear in
//! `a = 1/K`, `b = σ_r²/K²` and `c = 1/12 + σ_c²`. The differences are binned by `z₁` per frame
//! pair and channel; each bin's variance is measured robustly (the median absolute deviation
//! about the bin's median, which also removes any bias of the curve and ignores a minority of
//! moving or misaligned pixels); `(a, b, c)` are fitted by non-negative least squares on the
//! relative residuals of all bins. A channel whose best fit has no shot-noise term (downscaled
//! or heavily compressed photos, such as banterle_room's) gets [`NO_SHOT_NOISE`] electrons;
//! before, such a fit was refused and the phone-like default's weights were 21 % worse than the
//! fitted ones on that set. With too few usable pixels the fit is refused and
//! [`NoiseModel::default`] (a phone-like sensor) is used, and said so.
//!
//! ## Clipping
//! A code of 0 or 255 is a bound, not a measurement; its weight is zero. Codes near full scale
//! carry JPEG ringing from clipped neighbours, so the weight also fades linearly to zero over
//! the top [`TOP_FADE`] codes, and codes at or below a black level are given zero weight.

use crate::bracket::{Frame, Pixels};
use crate::response::{Response, LEVELS};
use crate::sampling::bin16;

/// The weight fades linearly to zero over this many codes below 255.
pub const TOP_FADE: f64 = 12.0;
/// `electrons_at_gauge` of a channel whose fit found no shot noise (see
/// [`NoiseModel::upper_bound`]).
pub const NO_SHOT_NOISE: f64 = 1e9;
/// Bins per frame pair and channel in [`estimate`].
const BINS: usize = 20;
/// Fewest differences in a bin for it to enter the fit.
const MIN_PER_BIN: usize = 48;

/// Noise parameters of one colour channel.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChannelNoise {
    /// Electrons collected at code 128 (`K`; > 0). Larger = less shot noise.
    pub electrons_at_gauge: f64,
    /// Read noise, electrons r.m.s. (≥ 0).
    pub read_noise: f64,
    /// Code-domain noise beyond quantisation (JPEG, demosaicing), 8-bit codes r.m.s. (≥ 0).
    pub code_noise: f64,
}

/// A camera noise model: one [`ChannelNoise`] per channel (R, G, B).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseModel {
    /// Red, green, blue.
    pub channels: [ChannelNoise; 3],
}

impl Default for NoiseModel {
    /// A phone-like sensor: 600 e⁻ at code 128 (a full well of about 3000 e⁻), read noise 3 e⁻,
    /// JPEG noise 0.7 codes.
    fn default() -> Self {
        let c = ChannelNoise {
            electrons_at_gauge: 600.0,
            read_noise: 3.0,
            code_noise: 0.7,
        };
        Self { channels: [c; 3] }
    }
}

impl NoiseModel {
    /// Checks every parameter is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.channels.iter().all(|c| {
            c.electrons_at_gauge.is_finite()
                && c.electrons_at_gauge > 0.0
                && c.read_noise.is_finite()
                && c.read_noise >= 0.0
                && c.code_noise.is_finite()
                && c.code_noise >= 0.0
        })
    }

    /// The model for judging whether frames disagree: when the fit found no shot noise in some
    /// channel ([`NO_SHOT_NOISE`]), the default sensor. The merge weights need only the
    /// *ratios* of variances, which such a fit still gets right; the consistency test needs
    /// their size, and a fit that cannot see shot noise (the bins' robust spread ignores JPEG's
    /// heavy tails) would flag pixels that merely look noisy.
    pub fn upper_bound(&self) -> Self {
        if self
            .channels
            .iter()
            .any(|c| c.electrons_at_gauge >= NO_SHOT_NOISE)
        {
            Self::default()
        } else {
            *self
        }
    }

    /// `σ²(z)` of `ln E` (natural log units squared) for channel `c` at the 8-bit code `z`,
    /// for the given response. See the module docs for the formula.
    pub fn log_variance(&self, response: &Response, c: usize, z: usize) -> f64 {
        let g = response.curve(c);
        let p = &self.channels[c];
        let xe = p.electrons_at_gauge * g[z.min(LEVELS - 1)].exp();
        let slope = slope(g, z);
        1.0 / xe
            + p.read_noise * p.read_noise / (xe * xe)
            + slope * slope * (1.0 / 12.0 + p.code_noise * p.code_noise)
    }
}

/// Slope `g'(z)` in natural-log units per code: a central difference over ±2 codes (one-sided
/// at the ends), which smooths the small wiggles of a calibrated curve.
fn slope(g: &[f64], z: usize) -> f64 {
    let lo = z.saturating_sub(2);
    let hi = (z + 2).min(LEVELS - 1);
    (g[hi] - g[lo]) / (hi - lo) as f64
}

/// What [`estimate`] found.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseEstimate {
    /// The model (the default when `fitted` is false).
    pub model: NoiseModel,
    /// Pixel differences that entered the fit, all channels and frame pairs.
    pub differences: usize,
    /// Bins that entered the fit, all channels.
    pub bins: usize,
    /// False when there were too few well-exposed pixel pairs and the default was used.
    pub fitted: bool,
}

/// Estimates the noise model from adjacent-frame differences (see the module docs). `frames`
/// sorted shortest first; codes below `black + 6` or above 245 (8-bit scale) are not used;
/// `mask`, when given, selects the pixels (row-major) that may be used. At most about 250 000
/// pixels are read (an even stride), so this takes a few milliseconds on a 6 MP bracket.
pub fn estimate(
    frames: &[Frame],
    response: &Response,
    black: u8,
    mask: Option<&[bool]>,
) -> NoiseEstimate {
    let fallback = |differences, bins| NoiseEstimate {
        model: NoiseModel::default(),
        differences,
        bins,
        fitted: false,
    };
    let Some(first) = frames.first() else {
        return fallback(0, 0);
    };
    let np = first.width * first.height;
    if frames.len() < 2
        || frames.iter().any(|f| f.pixels.len() != 3 * np)
        || mask.is_some_and(|m| m.len() != np)
    {
        return fallback(0, 0);
    }
    let stride = (np / 250_000).max(1);
    let lo = (black as usize + 6).max(6);
    let hi = 245usize;
    if lo >= hi {
        return fallback(0, 0);
    }
    let lt: Vec<f64> = frames.iter().map(|f| f.exposure.relative().ln()).collect();
    let mut model = NoiseModel::default();
    let (mut total, mut total_bins) = (0usize, 0usize);
    let mut fitted_all = true;
    for c in 0..3 {
        let g = response.curve(c);
        let u: Vec<f64> = g.iter().map(|v| (-v).exp()).collect();
        let s: Vec<f64> = (0..LEVELS).map(|z| slope(g, z).powi(2)).collect();
        // Rows of the fit: regressors (Σu, Σu², Σs) and the measured variance, with a weight.
        let mut rows: Vec<([f64; 3], f64, f64)> = Vec::new();
        for j in 0..frames.len() - 1 {
            let mut bins: Vec<Vec<(u8, u8)>> = vec![Vec::new(); BINS];
            let (a, b) = (&frames[j].pixels, &frames[j + 1].pixels);
            let mut p = 0;
            while p < np {
                if mask.is_none_or(|m| m[p]) {
                    let (z1, z2) = (code(a, 3 * p + c), code(b, 3 * p + c));
                    let (u1, u2) = (z1 as usize, z2 as usize);
                    if (lo..=hi).contains(&u1) && (lo..=hi).contains(&u2) {
                        bins[(u1 - lo) * BINS / (hi - lo + 1)].push((z1, z2));
                    }
                }
                p += stride;
            }
            let dl = lt[j + 1] - lt[j];
            for bin in bins.iter().filter(|b| b.len() >= MIN_PER_BIN) {
                let mut d: Vec<f64> = bin
                    .iter()
                    .map(|&(z1, z2)| g[z2 as usize] - g[z1 as usize] - dl)
                    .collect();
                let med = median(&mut d);
                let mut dev: Vec<f64> = d.iter().map(|v| (v - med).abs()).collect();
                let mad = median(&mut dev) * 1.4826;
                let var = mad * mad;
                if !(var.is_finite() && var > 0.0) {
                    continue;
                }
                let n = bin.len() as f64;
                let mut r = [0f64; 3];
                for &(z1, z2) in bin {
                    let (z1, z2) = (z1 as usize, z2 as usize);
                    r[0] += u[z1] + u[z2];
                    r[1] += u[z1] * u[z1] + u[z2] * u[z2];
                    r[2] += s[z1] + s[z2];
                }
                rows.push((r.map(|v| v / n), var, n.sqrt()));
                total += bin.len();
            }
        }
        total_bins += rows.len();
        match fit_nonneg(&rows) {
            Some([a, b, cc]) if rows.len() >= 4 && (a > 0.0 || b > 0.0 || cc > 0.0) => {
                // No measurable shot noise (downscaled, denoised or heavily compressed
                // photos): an electron count so large that the shot term vanishes.
                let k = if a > 0.0 { 1.0 / a } else { NO_SHOT_NOISE };
                model.channels[c] = ChannelNoise {
                    electrons_at_gauge: k,
                    read_noise: b.sqrt() * k,
                    code_noise: (cc - 1.0 / 12.0).max(0.0).sqrt(),
                };
            }
            _ => fitted_all = false,
        }
    }
    if !fitted_all || !model.is_valid() {
        return fallback(total, total_bins);
    }
    NoiseEstimate {
        model,
        differences: total,
        bins: total_bins,
        fitted: true,
    }
}

/// The 8-bit code (16-bit values binned) of sample `i`.
#[inline]
fn code(p: &Pixels, i: usize) -> u8 {
    match p {
        Pixels::U8(v) => v[i],
        Pixels::U16(v) => bin16(v[i]),
    }
}

/// Median by selection; `v` is reordered. 0 for an empty slice.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 2;
    v.select_nth_unstable_by(k, f64::total_cmp);
    v[k]
}

/// Non-negative least squares for three unknowns on rows `(r, var, weight)`: minimises
/// `Σ weight² · (r·x / var − 1)²` subject to `x ≥ 0`, by trying every active set (seven, so
/// exhaustive search is simpler and exact). `None` when no subset gives a solution.
fn fit_nonneg(rows: &[([f64; 3], f64, f64)]) -> Option<[f64; 3]> {
    let mut best: Option<([f64; 3], f64)> = None;
    for set in 1u8..8 {
        let idx: Vec<usize> = (0..3).filter(|k| set & (1 << k) != 0).collect();
        let m = idx.len();
        let mut ata = vec![0f64; m * m];
        let mut atb = vec![0f64; m];
        for (r, var, wt) in rows {
            let w2 = wt * wt;
            for (i, &ki) in idx.iter().enumerate() {
                let ai = r[ki] / var;
                atb[i] += w2 * ai;
                for (k, &kk) in idx.iter().enumerate() {
                    ata[i * m + k] += w2 * ai * r[kk] / var;
                }
            }
        }
        let Some(sol) = solve_small(&mut ata, &mut atb, m) else {
            continue;
        };
        if sol.iter().any(|&v| !(v.is_finite() && v >= 0.0)) {
            continue;
        }
        let mut x = [0f64; 3];
        for (i, &ki) in idx.iter().enumerate() {
            x[ki] = sol[i];
        }
        let res: f64 = rows
            .iter()
            .map(|(r, var, wt)| {
                let pred = r[0] * x[0] + r[1] * x[1] + r[2] * x[2];
                (wt * (pred / var - 1.0)).powi(2)
            })
            .sum();
        if best.is_none_or(|(_, b)| res < b) {
            best = Some((x, res));
        }
    }
    best.map(|(x, _)| x)
}

/// Gaussian elimination with partial pivoting on an `m × m` system (m ≤ 3).
fn solve_small(a: &mut [f64], b: &mut [f64], m: usize) -> Option<Vec<f64>> {
    for col in 0..m {
        let piv =
            (col..m).max_by(|&i, &k| a[i * m + col].abs().total_cmp(&a[k * m + col].abs()))?;
        if a[piv * m + col].abs() < 1e-300 {
            return None;
        }
        for k in 0..m {
            a.swap(col * m + k, piv * m + k);
        }
        b.swap(col, piv);
        for i in col + 1..m {
            let f = a[i * m + col] / a[col * m + col];
            for k in col..m {
                a[i * m + k] -= f * a[col * m + k];
            }
            b[i] -= f * b[col];
        }
    }
    let mut x = vec![0f64; m];
    for i in (0..m).rev() {
        let s: f64 = (i + 1..m).map(|k| a[i * m + k] * x[k]).sum();
        x[i] = (b[i] - s) / a[i * m + i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonnegative_fit_recovers_exact_parameters() {
        let truth = [2e-3, 1e-5, 0.3];
        let rows: Vec<([f64; 3], f64, f64)> = (1..30)
            .map(|k| {
                let r = [1.0 / k as f64, 1.0 / (k * k) as f64, 0.01 * k as f64];
                let var = r[0] * truth[0] + r[1] * truth[1] + r[2] * truth[2];
                (r, var, 1.0)
            })
            .collect();
        let x = fit_nonneg(&rows).unwrap();
        for k in 0..3 {
            assert!((x[k] - truth[k]).abs() < 1e-9 * (1.0 + truth[k]), "{x:?}");
        }
    }

    #[test]
    fn variance_falls_as_the_signal_grows() {
        let r = Response::linear();
        let m = NoiseModel::default();
        let v = |z| m.log_variance(&r, 1, z);
        assert!(v(200) < v(128) && v(128) < v(50) && v(50) < v(10));
        assert!((0..256).all(|z| v(z).is_finite() && v(z) > 0.0));
    }
}
