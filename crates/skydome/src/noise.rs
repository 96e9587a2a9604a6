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
//! moving or misaligned pixels).
//!
//! The three channels are one sensor: they share **one gain and one read noise**. Channel `c`
//! collects `K_c = K · w_c` electrons at its code 128, where `w_c` (green = 1) is the
//! white-balance factor the camera applied before its tone curve (a red channel amplified 2× by
//! white balance reads code 128 at half the electrons); the read noise is `σ_r` electrons in
//! every channel. So `a_c = a / w_c`, `b_c = b / w_c²` with `a = 1/K`, `b = σ_r²/K²`, and each
//! channel keeps its own code-domain noise `c_c` (JPEG treats chroma differently). For given
//! `(w_R, w_B)` the model is linear in `(a, b, c_R, c_G, c_B)`, fitted by non-negative least
//! squares on the relative residuals of all bins of all channels; `(w_R, w_B)` are searched on
//! a log grid within [`WB_RANGE`] (coarse, then two finer passes about the best).
//!
//! A parameter that ends **at a bound** is not measured: no shot noise (`a = 0`: downscaled,
//! denoised or heavily compressed photos), no read noise (`b = 0`), a white-balance factor at
//! the edge of [`WB_RANGE`]. It takes the prior's value ([`NoiseModel::default`]: 600 e⁻ at
//! code 128, 3 e⁻ read noise, no white balance), [`NoiseEstimate::fitted`] is false and
//! [`NoiseEstimate::from_prior`] says which. A code-domain noise of zero is not a bound but a
//! measurement (lossless frames have quantisation only). With too few usable pixels the whole
//! prior is used, and said so.
//!
//! **16-bit frames** are fitted on their own values (`v / 257` on the 8-bit scale, `g`
//! interpolated as the merge reads it, [`Response::g16`]), not binned to 256 levels, and their
//! code-domain term is held at zero: a 16-bit frame went through no JPEG and no 8-bit
//! quantisation. Binned, with the term free, the fit gave that term the shot noise's place (on
//! gamma-like curves `g'(z)²` and `1/X_e` fall alike with the code): 0.9 codes of code noise and
//! 40–75× the true electrons on 16-bit lossless brackets, whose merge lost up to 1.45× to the
//! oracle; fitted on their values the green gain came to 1.06–4.5× the truth on four such
//! brackets and their merges to 1.01–1.14× the oracle (docs/accuracy.md, "Thirteenth round").
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
/// Range of the white-balance factors `w_R`, `w_B` (relative to green) [`estimate`] searches;
/// a factor at either end is a bound (not measured).
pub const WB_RANGE: [f64; 2] = [0.2, 5.0];
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

/// Which parameters of a [`NoiseEstimate`] are the prior's ([`NoiseModel::default`]) because
/// the fit could not measure them (it ended at a bound, or there was too little data).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct FromPrior {
    /// The gain (electrons at code 128): no shot noise was measurable.
    pub gain: bool,
    /// The read noise: none was measurable.
    pub read_noise: bool,
    /// The white-balance factors: at the edge of [`WB_RANGE`], or undetermined without shot
    /// and read noise.
    pub white_balance: bool,
    /// The code-domain noise (only when nothing was fitted at all).
    pub code_noise: bool,
}

impl FromPrior {
    /// Everything from the prior.
    pub const ALL: Self = Self {
        gain: true,
        read_noise: true,
        white_balance: true,
        code_noise: true,
    };

    /// True when some parameter came from the prior.
    pub fn any(&self) -> bool {
        self.gain || self.read_noise || self.white_balance || self.code_noise
    }

    /// The parameters from the prior, named for a message ("gain, read noise").
    pub fn names(&self) -> String {
        [
            (self.gain, "gain"),
            (self.read_noise, "read noise"),
            (self.white_balance, "white balance"),
            (self.code_noise, "code noise"),
        ]
        .iter()
        .filter(|(b, _)| *b)
        .map(|(_, n)| *n)
        .collect::<Vec<_>>()
        .join(", ")
    }
}

/// What [`estimate`] found.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseEstimate {
    /// The model: the fitted parameters, the prior's where [`from_prior`](Self::from_prior) says.
    pub model: NoiseModel,
    /// Pixel differences that entered the fit, all channels and frame pairs.
    pub differences: usize,
    /// Bins that entered the fit, all channels.
    pub bins: usize,
    /// True when every parameter was measured: none ended at a bound and none is the prior's.
    pub fitted: bool,
    /// White-balance factors `w_R, w_G, w_B` (green = 1): channel `c` collects
    /// `K · w_c` electrons at its code 128 (see the module docs).
    #[serde(default = "unit_wb")]
    pub white_balance: [f64; 3],
    /// Which parameters are the prior's.
    #[serde(default)]
    pub from_prior: FromPrior,
    /// The ISO speed the model was measured at, when it was a camera profile's measured at
    /// another ISO than the bracket's and its gains were scaled to the bracket's
    /// ([`crate::camera::CameraProfile::noise_estimate_at_iso`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scaled_from_iso: Option<f64>,
}

fn unit_wb() -> [f64; 3] {
    [1.0; 3]
}

impl NoiseEstimate {
    /// An estimate that is a given model (a camera profile's): every parameter counts as fitted.
    pub fn given(model: NoiseModel) -> Self {
        let g = model.channels[1].electrons_at_gauge;
        Self {
            model,
            differences: 0,
            bins: 0,
            fitted: true,
            white_balance: model.channels.map(|c| c.electrons_at_gauge / g),
            from_prior: FromPrior::default(),
            scaled_from_iso: None,
        }
    }

    /// The channels' gains (electrons at code 128), red, green, blue.
    pub fn gains(&self) -> [f64; 3] {
        self.model.channels.map(|c| c.electrons_at_gauge)
    }
}

/// The pixels [`estimate`] reads are every `sample_stride(np)`-th of a frame of `np` pixels
/// (row-major, from the first): at most about 250 000.
pub fn sample_stride(np: usize) -> usize {
    (np / 250_000).max(1)
}

/// The 8-bit RGB pixels of a frame (`3 · np` samples) that [`estimate`] reads, in order: a
/// frame read one photo at a time keeps only these (a twentieth of a 6 MP photo), and
/// [`estimate`] on such frames (`width` the count, `height` 1) reads exactly them, so it gives
/// the model of the whole frames.
pub fn sampled_pixels(px: &[u8]) -> Vec<u8> {
    let np = px.len() / 3;
    let stride = sample_stride(np);
    px.chunks_exact(3)
        .step_by(stride)
        .flatten()
        .copied()
        .collect()
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
    estimate_from_code(frames, response, black, mask, 0)
}

/// The lowest code (8-bit scale) from which the merge fits its noise model on a calibration
/// whose step-periodic correction applied ([`crate::response::Calibration::wide_step`]): on
/// brackets 3 EV apart the toe's codes, where the curve is least certain, decided a fit of
/// 3–7× the true electrons (docs/accuracy.md, "Eighth round, second part" and "Eleventh
/// round").
pub const WIDE_STEP_NOISE_LO: u8 = 24;

/// The merge's noise model for a calibrated curve: with `wide_step` (the calibration's
/// step-periodic correction applied, [`crate::response::Calibration::wide_step`]) fitted from
/// codes [`WIDE_STEP_NOISE_LO`] up ([`estimate_from_code`]), falling back to [`estimate`]
/// when that fit does not measure the gain; else [`estimate`].
pub fn estimate_for_calibration(
    frames: &[Frame],
    response: &Response,
    black: u8,
    mask: Option<&[bool]>,
    wide_step: bool,
) -> NoiseEstimate {
    if wide_step {
        let est = estimate_from_code(frames, response, black, mask, WIDE_STEP_NOISE_LO);
        if !est.from_prior.gain && est.differences > 0 {
            return est;
        }
    }
    estimate(frames, response, black, mask)
}

/// [`estimate`] using only codes from `lo` up (8-bit scale; the codes below `black + 6` and
/// above 245 are left out as there). `lo` 0 is [`estimate`].
pub fn estimate_from_code(
    frames: &[Frame],
    response: &Response,
    black: u8,
    mask: Option<&[bool]>,
    lo: u8,
) -> NoiseEstimate {
    let fallback = |differences, bins| NoiseEstimate {
        model: NoiseModel::default(),
        differences,
        bins,
        fitted: false,
        white_balance: [1.0; 3],
        from_prior: FromPrior::ALL,
        scaled_from_iso: None,
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
    let stride = sample_stride(np);
    let lo = (black as usize + 6).max(6).max(lo as usize);
    let hi = 245usize;
    if lo >= hi {
        return fallback(0, 0);
    }
    let lt: Vec<f64> = frames.iter().map(|f| f.exposure.relative().ln()).collect();
    let (mut total, mut total_bins) = (0usize, 0usize);
    if matches!(first.pixels, Pixels::U16(_)) {
        let (rows, t) = rows_16(frames, response, mask, stride, lo, hi, &lt);
        total = t;
        total_bins = rows.iter().map(Vec::len).sum();
        return finish_fit(rows, total, total_bins, Some(0.0), fallback);
    }
    // How often each code pair `(z₁, z₂)` of adjacent frames occurs, per channel and frame
    // pair: [c][j][z₁ · 256 + z₂]. One sweep over the strided pixels reads each pixel's cache
    // line once for every channel and frame pair; a bin of the shorter frame's code then holds
    // thousands of pairs but only a few hundred distinct ones.
    let pairs = frames.len() - 1;
    let mut counts: [Vec<Vec<u32>>; 3] = std::array::from_fn(|_| vec![vec![0u32; 1 << 16]; pairs]);
    // One pixel's codes in every frame, each read once; `NONE` where out of `lo ..= hi`.
    const NONE: u16 = u16::MAX;
    let mut z = vec![[NONE; 3]; frames.len()];
    let mut p = 0;
    while p < np {
        if mask.is_none_or(|m| m[p]) {
            for (zj, f) in z.iter_mut().zip(frames) {
                for (c, v) in zj.iter_mut().enumerate() {
                    let u = code(&f.pixels, 3 * p + c) as usize;
                    *v = if (lo..=hi).contains(&u) {
                        u as u16
                    } else {
                        NONE
                    };
                }
            }
            for (j, pair) in z.windows(2).enumerate() {
                for (c, per_pair) in counts.iter_mut().enumerate() {
                    let (u1, u2) = (pair[0][c], pair[1][c]);
                    if u1 != NONE && u2 != NONE {
                        per_pair[j][(u1 as usize) << 8 | u2 as usize] += 1;
                    }
                }
            }
        }
        p += stride;
    }
    let mut all_rows: [Vec<Row>; 3] = Default::default();
    let mut bin: Vec<(usize, usize, u32)> = Vec::new();
    for ((c, rows), per_pair) in all_rows.iter_mut().enumerate().zip(&counts) {
        let g = response.curve(c);
        let u: Vec<f64> = g.iter().map(|v| (-v).exp()).collect();
        let s: Vec<f64> = (0..LEVELS).map(|z| slope(g, z).powi(2)).collect();
        // Rows of the fit: regressors (Σu, Σu², Σs) and the measured variance, with a weight.
        for (j, pc) in per_pair.iter().enumerate() {
            let dl = lt[j + 1] - lt[j];
            for k in 0..BINS {
                // The distinct pairs whose shorter frame's code falls in bin k, with counts.
                bin.clear();
                for u1 in (lo..=hi).filter(|u1| (u1 - lo) * BINS / (hi - lo + 1) == k) {
                    for u2 in lo..=hi {
                        let n = pc[u1 << 8 | u2];
                        if n > 0 {
                            bin.push((u1, u2, n));
                        }
                    }
                }
                let len: usize = bin.iter().map(|b| b.2 as usize).sum();
                if len < MIN_PER_BIN {
                    continue;
                }
                // The medians of the differences and of their deviations (the middle values,
                // as selecting among all the pairs would give).
                let mut d: Vec<(f64, u32)> = bin
                    .iter()
                    .map(|&(z1, z2, n)| (g[z2] - g[z1] - dl, n))
                    .collect();
                let med = kth_counted(&mut d, len / 2);
                let mut dev: Vec<(f64, u32)> =
                    d.iter().map(|&(v, n)| ((v - med).abs(), n)).collect();
                let mad = kth_counted(&mut dev, len / 2) * 1.4826;
                let var = mad * mad;
                if !(var.is_finite() && var > 0.0) {
                    continue;
                }
                let n = len as f64;
                let mut r = [0f64; 3];
                for &(z1, z2, m) in &bin {
                    let m = m as f64;
                    r[0] += m * (u[z1] + u[z2]);
                    r[1] += m * (u[z1] * u[z1] + u[z2] * u[z2]);
                    r[2] += m * (s[z1] + s[z2]);
                }
                rows.push((r.map(|v| v / n), var, n.sqrt()));
                total += len;
            }
        }
        total_bins += rows.len();
    }
    finish_fit(all_rows, total, total_bins, None, fallback)
}

/// The fit's rows for 16-bit frames, on their own values (`v / 257` on the 8-bit scale, `g`
/// interpolated, [`Response::g16`]): no binning to 256 levels, so no quantisation term to
/// confuse with the shot noise. Differences are kept per channel, frame pair and bin of the
/// shorter frame's value; returns the rows and the differences used.
fn rows_16(
    frames: &[Frame],
    response: &Response,
    mask: Option<&[bool]>,
    stride: usize,
    lo: usize,
    hi: usize,
    lt: &[f64],
) -> ([Vec<Row>; 3], usize) {
    let np = frames[0].width * frames[0].height;
    let pairs = frames.len() - 1;
    let px: Vec<&[u16]> = frames
        .iter()
        .filter_map(|f| match &f.pixels {
            Pixels::U16(v) => Some(v.as_slice()),
            Pixels::U8(_) => None,
        })
        .collect();
    let mut rows: [Vec<Row>; 3] = Default::default();
    if px.len() != frames.len() {
        return (rows, 0);
    }
    let (lo_f, hi_f) = (lo as f64, hi as f64);
    let mut total = 0;
    for (c, rows_c) in rows.iter_mut().enumerate() {
        let g = response.curve(c);
        // At a 16-bit value: `g` as the merge reads it, and the regressors `u = e^{−g}` and
        // `s = g'²` (the slope interpolated on the 8-bit scale).
        let at = |v: u16| -> (f64, f64, f64) {
            let z = v as f64 / 257.0;
            let i = (z.floor() as usize).min(LEVELS - 2);
            let f = z - i as f64;
            let gi = response.g16(c, v);
            let si = slope(g, i) * (1.0 - f) + slope(g, i + 1) * f;
            (gi, (-gi).exp(), si * si)
        };
        for j in 0..pairs {
            let dl = lt[j + 1] - lt[j];
            let mut d: Vec<Vec<f64>> = vec![Vec::new(); BINS];
            let mut r: Vec<[f64; 3]> = vec![[0.0; 3]; BINS];
            let mut p = 0;
            while p < np {
                if mask.is_none_or(|m| m[p]) {
                    let (v1, v2) = (px[j][3 * p + c], px[j + 1][3 * p + c]);
                    let (z1, z2) = (v1 as f64 / 257.0, v2 as f64 / 257.0);
                    if (lo_f..=hi_f).contains(&z1) && (lo_f..=hi_f).contains(&z2) {
                        let k = (((z1 - lo_f) * BINS as f64 / (hi_f - lo_f + 1.0)) as usize)
                            .min(BINS - 1);
                        let ((g1, u1, s1), (g2, u2, s2)) = (at(v1), at(v2));
                        d[k].push(g2 - g1 - dl);
                        r[k][0] += u1 + u2;
                        r[k][1] += u1 * u1 + u2 * u2;
                        r[k][2] += s1 + s2;
                    }
                }
                p += stride;
            }
            for (dk, rk) in d.iter_mut().zip(&r) {
                let len = dk.len();
                if len < MIN_PER_BIN {
                    continue;
                }
                // The median and the median absolute deviation, as for 8-bit frames.
                let med = *dk.select_nth_unstable_by(len / 2, f64::total_cmp).1;
                dk.iter_mut().for_each(|v| *v = (*v - med).abs());
                let mad = *dk.select_nth_unstable_by(len / 2, f64::total_cmp).1 * 1.4826;
                let var = mad * mad;
                if !(var.is_finite() && var > 0.0) {
                    continue;
                }
                let n = len as f64;
                rows_c.push((rk.map(|v| v / n), var, n.sqrt()));
                total += len;
            }
        }
    }
    (rows, total)
}

/// The shared-sensor fit on the rows (with `fixed_c`, the code-domain term held at that value)
/// and the model it gives; `fallback` where there are too few rows or the fit fails.
fn finish_fit(
    all_rows: [Vec<Row>; 3],
    total: usize,
    total_bins: usize,
    fixed_c: Option<f64>,
    fallback: impl Fn(usize, usize) -> NoiseEstimate,
) -> NoiseEstimate {
    if all_rows.iter().any(|r| r.len() < 4) {
        return fallback(total, total_bins);
    }
    let Some(fit) = fit_shared(&all_rows, fixed_c) else {
        return fallback(total, total_bins);
    };
    let prior = NoiseModel::default().channels[1];
    let from_prior = FromPrior {
        gain: fit.a <= 0.0,
        read_noise: fit.b <= 0.0,
        white_balance: fit.at_bound || (fit.a <= 0.0 && fit.b <= 0.0),
        code_noise: false,
    };
    let wb = if from_prior.white_balance {
        [1.0; 3]
    } else {
        fit.wb
    };
    // Green's gain and read noise; the prior's where not measured.
    let k = if from_prior.gain {
        prior.electrons_at_gauge
    } else {
        1.0 / fit.a
    };
    let rn = if from_prior.read_noise {
        prior.read_noise
    } else {
        fit.b.sqrt() * (if from_prior.gain { k } else { 1.0 / fit.a })
    };
    let model = NoiseModel {
        channels: std::array::from_fn(|c| ChannelNoise {
            electrons_at_gauge: k * wb[c],
            read_noise: rn,
            code_noise: if fixed_c.is_some() {
                0.0
            } else {
                (fit.c[c] - 1.0 / 12.0).max(0.0).sqrt()
            },
        }),
    };
    if !model.is_valid() {
        return fallback(total, total_bins);
    }
    NoiseEstimate {
        model,
        differences: total,
        bins: total_bins,
        fitted: !from_prior.any(),
        white_balance: wb,
        from_prior,
        scaled_from_iso: None,
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

/// The `k`-th smallest value (0-based, in [`f64::total_cmp`]'s order) of the multiset given as
/// `(value, count)` pairs, which are reordered; 0 when there are not `k + 1` values.
fn kth_counted(v: &mut [(f64, u32)], k: usize) -> f64 {
    v.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut seen = 0usize;
    for &(x, n) in v.iter() {
        seen += n as usize;
        if seen > k {
            return x;
        }
    }
    0.0
}

/// A row of the noise fit: regressors `(Σu, Σu², Σs)` averaged over a bin, the bin's measured
/// variance, and the row's weight.
type Row = ([f64; 3], f64, f64);

/// The shared-sensor fit (see the module docs).
struct SharedFit {
    /// `1/K` of green.
    a: f64,
    /// `σ_r²/K²` of green.
    b: f64,
    /// `1/12 + σ_c²` per channel.
    c: [f64; 3],
    /// White-balance factors (green = 1).
    wb: [f64; 3],
    /// A white-balance factor is at the edge of [`WB_RANGE`].
    at_bound: bool,
}

/// Per channel, the moments of its rows that the fit's normal equations need: with the row's
/// regressors divided by its variance, `x = r / var`, and its weight `wt`, `m[i][k] = Σ wt² x_i x_k`,
/// `v[i] = Σ wt² x_i` and `s = Σ wt²`. For any white-balance factors the normal equations are
/// sums of these, scaled (see [`fit_shared`]), so the grid search never revisits the rows.
#[derive(Default)]
struct Moments {
    m: [[f64; 3]; 3],
    v: [f64; 3],
    s: f64,
}

impl Moments {
    fn of(rows: &[Row]) -> Self {
        let mut out = Self::default();
        for (r, var, wt) in rows {
            let w2 = wt * wt;
            let x = r.map(|v| v / var);
            for i in 0..3 {
                out.v[i] += w2 * x[i];
                for k in 0..3 {
                    out.m[i][k] += w2 * x[i] * x[k];
                }
            }
            out.s += w2;
        }
        out
    }
}

/// Fits `(a, b, c_R, c_G, c_B)` for the white-balance factors on a log grid, keeping the best;
/// with `fixed_c`, every `c` is held at that value and only `a` and `b` are fitted.
fn fit_shared(rows: &[Vec<Row>; 3], fixed_c: Option<f64>) -> Option<SharedFit> {
    let (lo, hi) = (WB_RANGE[0].ln(), WB_RANGE[1].ln());
    let moments = [0, 1, 2].map(|c| Moments::of(&rows[c]));
    // Channel c's row enters with `x = (r0 / w_c, r1 / w_c², r2)` at unknowns `(0, 1, 2 + c)`.
    let solve = |wr: f64, wbl: f64| -> Option<([f64; 5], f64)> {
        let w = [wr.exp(), 1.0, wbl.exp()];
        let mut ata = [[0f64; 5]; 5];
        let mut atb = [0f64; 5];
        let mut s = 0.0;
        for (c, mo) in moments.iter().enumerate() {
            let scale = [1.0 / w[c], 1.0 / (w[c] * w[c]), 1.0];
            let at = [0, 1, 2 + c];
            match fixed_c {
                None => {
                    for i in 0..3 {
                        atb[at[i]] += mo.v[i] * scale[i];
                        for k in 0..3 {
                            ata[at[i]][at[k]] += mo.m[i][k] * scale[i] * scale[k];
                        }
                    }
                    s += mo.s;
                }
                Some(c0) => {
                    // The known term moves to the target: `Σ wt² (x·(a, b) − (1 − c0 x₂))²`;
                    // `c` itself is pinned by an identity row (`c = c0`, no residual).
                    for i in 0..2 {
                        atb[at[i]] += (mo.v[i] - c0 * mo.m[i][2]) * scale[i];
                        for k in 0..2 {
                            ata[at[i]][at[k]] += mo.m[i][k] * scale[i] * scale[k];
                        }
                    }
                    ata[2 + c][2 + c] = 1.0;
                    atb[2 + c] = c0;
                    s += mo.s - 2.0 * c0 * mo.v[2] + c0 * c0 * mo.m[2][2] + c0 * c0;
                }
            }
        }
        fit_nonneg_normal(&ata, &atb, s)
    };
    let mut best: Option<(f64, f64, [f64; 5], f64)> = None;
    let consider = |wr: f64, wbl: f64, best: &mut Option<(f64, f64, [f64; 5], f64)>| {
        if let Some((x, res)) = solve(wr.clamp(lo, hi), wbl.clamp(lo, hi)) {
            if best.is_none_or(|b| res < b.3) {
                *best = Some((wr.clamp(lo, hi), wbl.clamp(lo, hi), x, res));
            }
        }
    };
    const STEPS: usize = 16;
    let step = (hi - lo) / STEPS as f64;
    for i in 0..=STEPS {
        for k in 0..=STEPS {
            consider(lo + i as f64 * step, lo + k as f64 * step, &mut best);
        }
    }
    let mut h = step;
    for _ in 0..3 {
        let (cr, cb, _, _) = best?;
        h /= 4.0;
        for i in -4..=4 {
            for k in -4..=4 {
                consider(cr + i as f64 * h, cb + k as f64 * h, &mut best);
            }
        }
    }
    let (wr, wbl, x, _) = best?;
    let near = |v: f64| v - lo < 1e-9 || hi - v < 1e-9;
    if near(wr) || near(wbl) {
        // Not measured: the prior's white balance (none), and the rest refitted under it so
        // that the model stays the best one with the factors it states.
        let (x, _) = solve(0.0, 0.0)?;
        return Some(SharedFit {
            a: x[0],
            b: x[1],
            c: [x[2], x[3], x[4]],
            wb: [1.0; 3],
            at_bound: true,
        });
    }
    Some(SharedFit {
        a: x[0],
        b: x[1],
        c: [x[2], x[3], x[4]],
        wb: [wr.exp(), 1.0, wbl.exp()],
        at_bound: false,
    })
}

/// Non-negative least squares for five unknowns (exhaustive over the 31 active sets) from the
/// rows `(regressors, variance, weight)`, minimising `Σ (wt · (r·x / var − 1))²`: the solution
/// and its residual.
#[cfg(test)]
fn fit_nonneg_n(rows: &[([f64; 5], f64, f64)]) -> Option<([f64; 5], f64)> {
    const N: usize = 5;
    let mut ata = [[0f64; N]; N];
    let mut atb = [0f64; N];
    let mut s = 0.0;
    for (r, var, wt) in rows {
        let w2 = wt * wt;
        for i in 0..N {
            let ai = r[i] / var;
            atb[i] += w2 * ai;
            for k in 0..N {
                ata[i][k] += w2 * ai * r[k] / var;
            }
        }
        s += w2;
    }
    fit_nonneg_normal(&ata, &atb, s)
}

/// Non-negative least squares for five unknowns from the normal equations `AᵀA`, `Aᵀb` and
/// `bᵀb` of the weighted problem, exhaustive over the 31 active sets: the solution and its
/// residual `xᵀAᵀAx − 2xᵀAᵀb + bᵀb`.
fn fit_nonneg_normal(ata: &[[f64; 5]; 5], atb: &[f64; 5], btb: f64) -> Option<([f64; 5], f64)> {
    const N: usize = 5;
    let mut best: Option<([f64; N], f64)> = None;
    let (mut a, mut b) = ([0f64; N * N], [0f64; N]);
    for set in 1u8..(1 << N) {
        let mut idx = [0usize; N];
        let mut m = 0;
        for k in 0..N {
            if set & (1 << k) != 0 {
                idx[m] = k;
                m += 1;
            }
        }
        let idx = &idx[..m];
        for (i, &ki) in idx.iter().enumerate() {
            b[i] = atb[ki];
            for (k, &kk) in idx.iter().enumerate() {
                a[i * m + k] = ata[ki][kk];
            }
        }
        let Some(sol) = solve_small(&mut a[..m * m], &mut b[..m], m) else {
            continue;
        };
        if sol[..m].iter().any(|&v| !(v.is_finite() && v >= 0.0)) {
            continue;
        }
        let mut x = [0f64; N];
        for (i, &ki) in idx.iter().enumerate() {
            x[ki] = sol[i];
        }
        let mut res = btb;
        for i in 0..N {
            res -= 2.0 * x[i] * atb[i];
            for k in 0..N {
                res += x[i] * ata[i][k] * x[k];
            }
        }
        if best.is_none_or(|(_, b)| res < b) {
            best = Some((x, res));
        }
    }
    best
}

/// Gaussian elimination with partial pivoting on an `m × m` system (m ≤ 5): the solution in
/// the first `m` values.
fn solve_small(a: &mut [f64], b: &mut [f64], m: usize) -> Option<[f64; 5]> {
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
    let mut x = [0f64; 5];
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
        let truth = [2e-3, 1e-5, 0.3, 0.0, 0.1];
        let rows: Vec<([f64; 5], f64, f64)> = (1..30)
            .map(|k| {
                let kf = k as f64;
                let r = [
                    1.0 / kf,
                    1.0 / (kf * kf),
                    0.01 * kf,
                    0.02 * kf,
                    0.5 + 0.01 * kf * kf,
                ];
                let var: f64 = r.iter().zip(&truth).map(|(a, b)| a * b).sum();
                (r, var, 1.0)
            })
            .collect();
        let (x, _) = fit_nonneg_n(&rows).unwrap();
        for k in 0..5 {
            assert!((x[k] - truth[k]).abs() < 1e-9 * (1.0 + truth[k]), "{x:?}");
        }
    }

    /// [`estimate`] on the pixels [`sampled_pixels`] keeps of each frame gives the whole
    /// frames' estimate exactly (the streamed intake keeps only these), for frames read every
    /// pixel (below 500 000 pixels) and every second and third.
    #[test]
    fn the_sampled_pixels_give_the_whole_frames_estimate() {
        use crate::bracket::{assemble, DecodedFrame, OrientationPolicy, Pixels};
        for (w, h) in [(300, 200), (820, 700), (1000, 760)] {
            let b = crate::synth::generate(&crate::synth::SynthOptions {
                width: w,
                height: h,
                ..Default::default()
            })
            .expect("synth");
            let frames = b.frames.into_iter().map(DecodedFrame::from).collect();
            let br = assemble(frames, None, OrientationPolicy::Apply).expect("bracket");
            let response = Response::linear();
            let whole = estimate(&br.frames, &response, 0, None);
            let kept: Vec<Frame> = br
                .frames
                .iter()
                .map(|f| {
                    let Pixels::U8(v) = &f.pixels else {
                        panic!("8-bit frames")
                    };
                    let px = sampled_pixels(v);
                    Frame {
                        width: px.len() / 3,
                        height: 1,
                        pixels: Pixels::U8(px),
                        ..f.clone()
                    }
                })
                .collect();
            assert_eq!(kept[0].width, (w * h).div_ceil(sample_stride(w * h)));
            assert!(whole.differences > 1000, "{whole:?}");
            assert_eq!(estimate(&kept, &response, 0, None), whole, "{w} × {h}");
        }
    }

    /// The fit from a code up reads fewer differences than the whole fit, is the whole fit
    /// from code 0, and the calibration's choice ([`estimate_for_calibration`]) is the whole
    /// fit unless the step-periodic correction applied.
    #[test]
    fn the_fit_from_a_code_up_leaves_the_toe_out() {
        let b = crate::synth::generate(&crate::synth::SynthOptions {
            width: 300,
            height: 200,
            ..Default::default()
        })
        .expect("synth");
        let response = Response::linear();
        let whole = estimate(&b.frames, &response, 0, None);
        assert_eq!(estimate_from_code(&b.frames, &response, 0, None, 0), whole);
        let upper = estimate_from_code(&b.frames, &response, 0, None, WIDE_STEP_NOISE_LO);
        assert!(upper.differences > 0, "{upper:?}");
        assert!(upper.differences < whole.differences, "{upper:?} {whole:?}");
        let plain = estimate_for_calibration(&b.frames, &response, 0, None, false);
        assert_eq!(plain, whole);
        let wide = estimate_for_calibration(&b.frames, &response, 0, None, true);
        assert!(wide == upper || wide == whole);
    }

    /// The shared fit from the channels' moments finds what a fit over the rows themselves
    /// finds at the white balance it chose (the same parameters to rounding), and that white
    /// balance is the sensor's to the grid's resolution.
    #[test]
    fn the_shared_fit_from_moments_matches_the_fit_over_the_rows() {
        // Bins of a sensor with white balance (1.8, 1, 0.6), K = 900 e⁻, σ_r = 4 e⁻ and JPEG
        // noise per channel, each bin's variance off by a few per cent.
        let (a, b, wb) = (1.0 / 900.0, 16.0 / (900.0 * 900.0), [1.8, 1.0, 0.6]);
        let cn = [0.5f64, 0.3, 0.7];
        let rows: [Vec<Row>; 3] = std::array::from_fn(|c| {
            (1..40)
                .map(|k| {
                    let u = 3.0 / k as f64;
                    let r = [2.0 * u, 2.0 * u * u, 1e-3 * (1.0 + 0.1 * k as f64)];
                    let var = r[0] * a / wb[c]
                        + r[1] * b / (wb[c] * wb[c])
                        + r[2] * (1.0 / 12.0 + cn[c] * cn[c]);
                    let wobble = 1.0 + 0.03 * ((k * (c + 3)) as f64).sin();
                    (r, var * wobble, (50.0 + k as f64).sqrt())
                })
                .collect()
        });
        let fit = fit_shared(&rows, None).unwrap();
        // The reference: the same grid search, each point fitted over the rows directly.
        let solve = |w: [f64; 3]| {
            let flat: Vec<([f64; 5], f64, f64)> = (0..3)
                .flat_map(|c| {
                    rows[c].iter().map(move |(r, var, wt)| {
                        let mut x = [0f64; 5];
                        x[0] = r[0] / w[c];
                        x[1] = r[1] / (w[c] * w[c]);
                        x[2 + c] = r[2];
                        (x, *var, *wt)
                    })
                })
                .collect();
            fit_nonneg_n(&flat).unwrap()
        };
        let (x, _) = solve(fit.wb);
        let got = [fit.a, fit.b, fit.c[0], fit.c[1], fit.c[2]];
        for k in 0..5 {
            assert!(
                (got[k] - x[k]).abs() <= 1e-9 * x[k].abs() + 1e-15,
                "{got:?} vs {x:?}"
            );
        }
        for c in [0, 2] {
            assert!(
                (fit.wb[c] / wb[c] - 1.0).abs() < 0.1,
                "{:?} vs {wb:?}",
                fit.wb
            );
        }
        assert!(!fit.at_bound);
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
