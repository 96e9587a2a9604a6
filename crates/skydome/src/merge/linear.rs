//! Merging linear (RAW) frames: no response curve, a Poisson–Gaussian noise model estimated
//! from the frames, inverse-variance weights, clipped photosites excluded per channel, and the
//! per-pixel standard error.
//!
//! A RAW frame's value `v` (black subtracted, 1 = white level; see [`crate::bracket::dng`]) of a
//! point of radiance `E` (in "value per unit of relative exposure") is `v ≈ E · t` with
//!
//! ```text
//! Var(v) = a · v + b        a = 1 / (electrons at the white level)   shot noise (Poisson)
//!                           b = (read noise / white level)²          read noise (Gaussian)
//! ```
//!
//! per camera channel. **Estimation** ([`estimate_linear_noise`]): where a photosite is
//! measured (not interpolated) and unclipped in two adjacent frames `j`, `j + 1`, the
//! difference `d = v₂ − r · v₁` (`r` = their exposure ratio, measured as the median of `v₂ / v₁`
//! over mid-level photosites so an inexact shutter does not pass for noise) has
//! `Var(d) = a · v₂ · (1 + r) + b · (1 + r²)`. Differences are binned by `v₂`; each bin's
//! variance is measured robustly (median absolute deviation); `a` and `b` are fitted by
//! non-negative weighted least squares on the bins' relative residuals.
//!
//! **Merge** ([`merge_linear`]): per pixel and camera channel, a first estimate from the
//! shortest unclipped frame decides which frames are safely below clipping (expected value
//! under [`SAFE_FRACTION`] of the clip level: a frame whose noise may cross the clip level
//! would be truncated, and biased low, by dropping its clipped photosites); then two passes of
//! the inverse-variance mean `E = Σ wⱼ vⱼ/tⱼ / Σ wⱼ` with `wⱼ = tⱼ² / (a · E · tⱼ + b)`
//! evaluated at the current estimate (the expected value, not the observed one: Granados et
//! al. 2010). Its variance is `1 / Σ wⱼ`. A channel clipped in every frame keeps the shortest
//! frame's lower bound (flag [`CLIPPED_HIGH`](super::CLIPPED_HIGH)); one whose light in the
//! longest frame is below three read-noise deviations is flagged
//! [`CLIPPED_LOW`](super::CLIPPED_LOW). The camera-RGB result goes through the file's colour
//! matrix ([`RawColour::camera_to_rec709`]) to linear Rec.709, the variance with it
//! (channels independent), and the standard error is given in stops,
//! `σ_stops = √Var / E / ln 2`.

use crate::bracket::dng::{raw_value, CLIP_FRACTION};
use crate::bracket::{Frame, Pixels, RawColour};
use crate::image::HdrImage;

use super::{MergeError, CLIPPED_HIGH, CLIPPED_LOW};

/// A frame counts in the merge of a channel when its expected value is below this fraction of
/// the clip level (see the module docs).
pub const SAFE_FRACTION: f32 = 0.85;
/// Fewest differences in a bin for it to enter the noise fit.
const MIN_PER_BIN: usize = 64;

/// The Poisson–Gaussian noise of linear frames, per camera channel, in units of the white
/// level: `Var(v) = a · v + b`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinearNoise {
    /// Shot-noise coefficient per channel (1 / electrons at the white level).
    pub a: [f64; 3],
    /// Read-noise variance per channel ((read noise / white level)²).
    pub b: [f64; 3],
    /// True when fitted on this bracket; false when the typical sensor of
    /// [`LinearNoise::default`] was assumed (too few photosites well exposed in two frames).
    pub fitted: bool,
    /// Photosite differences the fit used.
    pub differences: usize,
}

impl Default for LinearNoise {
    /// A phone sensor: 6000 electrons at the white level, read noise 3 electrons.
    fn default() -> Self {
        Self {
            a: [1.0 / 6000.0; 3],
            b: [(3.0f64 / 6000.0).powi(2); 3],
            fitted: false,
            differences: 0,
        }
    }
}

impl LinearNoise {
    /// Electrons at the white level per channel (`1 / a`), for the report.
    pub fn full_well_electrons(&self) -> [f64; 3] {
        self.a.map(|a| 1.0 / a.max(1e-12))
    }
    /// Read noise in electrons per channel (`√b / a`).
    pub fn read_noise_electrons(&self) -> [f64; 3] {
        std::array::from_fn(|c| self.b[c].sqrt() / self.a[c].max(1e-12))
    }
}

/// The merge of a linear bracket.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearMerged {
    /// Linear Rec.709 radiance, relative units (value at the white level per unit of relative
    /// exposure, after white balance).
    pub radiance: HdrImage,
    /// Per pixel and channel (R, G, B, like `radiance`) the standard error in stops (log2
    /// units); `f32::INFINITY` where the bracket did not measure (clipped in the shortest
    /// frame, black in the longest, or no positive value after the colour matrix).
    pub sigma_stops: HdrImage,
    /// Per pixel flags [`CLIPPED_HIGH`](super::CLIPPED_HIGH) | [`CLIPPED_LOW`](super::CLIPPED_LOW).
    pub clipped: Vec<u8>,
    /// Pixels flagged clipped high / low.
    pub clipped_high: usize,
    /// Pixels flagged low.
    pub clipped_low: usize,
    /// The noise model used.
    pub noise: LinearNoise,
}

/// The frames' values as raw values (`None` = clipped), checked for size and exposure order.
fn check(frames: &[Frame]) -> Result<(Vec<&[u16]>, Vec<f64>), MergeError> {
    let lt = super::log_exposures(frames)?;
    let mut src = Vec::with_capacity(frames.len());
    for f in frames {
        match &f.pixels {
            Pixels::U16(v) => src.push(v.as_slice()),
            Pixels::U8(_) => {
                return Err(MergeError::Mismatch {
                    name: f.name.clone(),
                    width: f.width,
                    height: f.height,
                    bits: 8,
                    len: f.pixels.len(),
                    ew: f.width,
                    eh: f.height,
                    ebits: 16,
                })
            }
        }
    }
    Ok((src, lt.iter().map(|l| l.exp()).collect()))
}

/// Estimates the Poisson–Gaussian noise from the frames (see the module docs).
pub fn estimate_linear_noise(frames: &[Frame], colour: &RawColour) -> LinearNoise {
    let Ok((src, t)) = check(frames) else {
        return LinearNoise::default();
    };
    let w = frames[0].width;
    let mut out = LinearNoise::default();
    let mut fitted = [false; 3];
    for c in 0..3 {
        // (level v₂ · (1 + r), 1 + r², variance) per bin, over all frame pairs.
        let mut rows: Vec<BinRow> = Vec::new();
        for j in 0..src.len().saturating_sub(1) {
            let (s1, s2) = (src[j], src[j + 1]);
            let pairs = |k: usize| -> Option<(f32, f32)> {
                let (x, y) = (k % w, k / w);
                if !colour.native(x, y, c) {
                    return None;
                }
                Some((raw_value(s1[3 * k + c])?, raw_value(s2[3 * k + c])?))
            };
            let n = src[0].len() / 3;
            // The exposure ratio as the frames show it.
            let mut ratios: Vec<f32> = (0..n)
                .filter_map(pairs)
                .filter(|&(v1, v2)| (0.2..0.8).contains(&v2) && v1 > 0.0)
                .map(|(v1, v2)| v2 / v1)
                .collect();
            let r = match median(&mut ratios) {
                Some(r) if ratios.len() >= 100 && r.is_finite() && r > 1.0 => f64::from(r),
                _ => t[j + 1] / t[j],
            };
            // Geometric bins of v₂ from 2⁻¹⁴ to SAFE_FRACTION, and one below.
            const BINS: usize = 28;
            let lo = (-14f64).exp2();
            let mut bins: Vec<Vec<f32>> = vec![Vec::new(); BINS + 1];
            let mut level = vec![0f64; BINS + 1];
            for (v1, v2) in (0..n).filter_map(pairs) {
                let v2d = f64::from(v2);
                if v2d >= f64::from(SAFE_FRACTION) {
                    continue;
                }
                let b = if v2d < lo {
                    0
                } else {
                    (((v2d / lo).ln() / (f64::from(SAFE_FRACTION) / lo).ln() * BINS as f64)
                        as usize
                        + 1)
                    .min(BINS)
                };
                bins[b].push((v2d - r * f64::from(v1)) as f32);
                level[b] += v2d.max(0.0);
            }
            for (b, d) in bins.iter_mut().enumerate() {
                if d.len() < MIN_PER_BIN {
                    continue;
                }
                let m = level[b] / d.len() as f64;
                let n = d.len();
                let Some(med) = median(d) else { continue };
                let mut dev: Vec<f32> = d.iter().map(|x| (x - med).abs()).collect();
                let Some(mad) = median(&mut dev) else {
                    continue;
                };
                let sd = 1.4826 * f64::from(mad);
                rows.push((m * (1.0 + r), 1.0 + r * r, sd * sd, n));
            }
        }
        out.differences += rows.iter().map(|r| r.3).sum::<usize>();
        if rows.len() >= 3 {
            if let Some((a, b)) = fit_ab(&rows) {
                out.a[c] = a;
                out.b[c] = b;
                fitted[c] = true;
            }
        }
    }
    out.fitted = fitted.iter().all(|&f| f);
    if !out.fitted {
        let d = out.differences;
        out = LinearNoise {
            differences: d,
            ..LinearNoise::default()
        };
    }
    out
}

/// One bin of the noise fit: the regressors `x = v₂ (1 + r)` and `y = 1 + r²`, the measured
/// variance and the number of differences.
type BinRow = (f64, f64, f64, usize);

/// Non-negative weighted least squares of `var = a · x + b · y` on relative residuals.
fn fit_ab(rows: &[BinRow]) -> Option<(f64, f64)> {
    let solve = |wts: &dyn Fn(&BinRow) -> f64| -> Option<(f64, f64)> {
        let (mut sxx, mut sxy, mut syy, mut sxv, mut syv) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for r in rows {
            let w = wts(r);
            sxx += w * r.0 * r.0;
            sxy += w * r.0 * r.1;
            syy += w * r.1 * r.1;
            sxv += w * r.0 * r.2;
            syv += w * r.1 * r.2;
        }
        let det = sxx * syy - sxy * sxy;
        let (mut a, mut b) = if det.abs() > 1e-300 {
            ((sxv * syy - syv * sxy) / det, (syv * sxx - sxv * sxy) / det)
        } else {
            (-1.0, -1.0)
        };
        if b < 0.0 {
            b = 0.0;
            a = sxv / sxx;
        }
        if a <= 0.0 {
            a = 0.0;
            b = syv / syy;
        }
        (a.is_finite() && b.is_finite() && (a > 0.0 || b > 0.0)).then_some((a, b))
    };
    // First on relative residuals of the measured variances, then of the fitted ones.
    let (a, b) = solve(&|r| 1.0 / (r.2 * r.2).max(1e-40))?;
    let (a, b) = solve(&|r| {
        let p = a * r.0 + b * r.1;
        1.0 / (p * p).max(1e-40)
    })?;
    // A sensor without shot noise or without read noise is not physical: keep a floor.
    Some((a.max(1e-7), b.max(1e-14)))
}

fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let k = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    Some(*m)
}

/// Merges linear frames (sorted shortest first, as [`crate::bracket::assemble`] leaves them)
/// with the given noise model, or one estimated from the frames (see the module docs).
pub fn merge_linear(
    frames: &[Frame],
    colour: &RawColour,
    noise: Option<LinearNoise>,
) -> Result<LinearMerged, MergeError> {
    let (src, t) = check(frames)?;
    let noise = noise.unwrap_or_else(|| estimate_linear_noise(frames, colour));
    let (w, h) = (frames[0].width, frames[0].height);
    let n = w * h;
    let p = src.len();
    let mut cam = vec![0f32; 3 * n];
    let mut var = vec![0f32; 3 * n];
    let mut clipped = vec![0u8; n];
    let t32: Vec<f32> = t.iter().map(|&t| t as f32).collect();
    let (a, b) = (noise.a.map(|v| v as f32), noise.b.map(|v| v as f32));
    let mut vals = vec![None; p];
    for k in 0..n {
        let (x, y) = (k % w, k / w);
        for c in 0..3 {
            for (v, s) in vals.iter_mut().zip(&src) {
                *v = raw_value(s[3 * k + c]);
            }
            let Some(first) = (0..p).find(|&j| vals[j].is_some()) else {
                // Clipped in every frame: the shortest frame's lower bound.
                cam[3 * k + c] = CLIP_FRACTION / t32[0];
                var[3 * k + c] = f32::INFINITY;
                clipped[k] |= CLIPPED_HIGH;
                continue;
            };
            let mut e = vals[first].unwrap_or(0.0) / t32[first];
            let safe = SAFE_FRACTION * CLIP_FRACTION;
            let usable = |j: usize, e: f32| j == first || e * t32[j] < safe;
            let mut sw = 0f32;
            for _ in 0..2 {
                let (mut num, mut den) = (0f32, 0f32);
                for (j, v) in vals.iter().enumerate() {
                    let Some(v) = *v else { continue };
                    if !usable(j, e) {
                        continue;
                    }
                    let wj = t32[j] * t32[j] / (a[c] * (e.max(0.0) * t32[j]) + b[c]);
                    num += wj * v / t32[j];
                    den += wj;
                }
                if den > 0.0 {
                    e = num / den;
                    sw = den;
                }
            }
            // Interpolated channels average several photosites: less variance.
            let share = interpolated_share(colour, x, y, c, w, h);
            cam[3 * k + c] = e;
            var[3 * k + c] = if sw > 0.0 { share / sw } else { f32::INFINITY };
            let last = p - 1;
            if e.max(0.0) * t32[last] < 3.0 * b[c].sqrt() {
                clipped[k] |= CLIPPED_LOW;
            }
        }
    }
    let m = colour.camera_to_rec709;
    let mut radiance = vec![0f32; 3 * n];
    let mut sigma = vec![0f32; 3 * n];
    let ln2 = std::f32::consts::LN_2;
    for k in 0..n {
        let e = &cam[3 * k..3 * k + 3];
        let v = &var[3 * k..3 * k + 3];
        for o in 0..3 {
            let out: f32 = (0..3).map(|c| m[o][c] * e[c]).sum();
            let vo: f32 = (0..3).map(|c| m[o][c] * m[o][c] * v[c]).sum();
            radiance[3 * k + o] = out.max(0.0);
            sigma[3 * k + o] = if clipped[k] != 0 || out <= 0.0 || !vo.is_finite() {
                f32::INFINITY
            } else {
                vo.sqrt() / out / ln2
            };
        }
    }
    let clipped_high = clipped.iter().filter(|&&f| f & CLIPPED_HIGH != 0).count();
    let clipped_low = clipped.iter().filter(|&&f| f & CLIPPED_LOW != 0).count();
    Ok(LinearMerged {
        radiance: HdrImage {
            width: w,
            height: h,
            data: radiance,
        },
        sigma_stops: HdrImage {
            width: w,
            height: h,
            data: sigma,
        },
        clipped,
        clipped_high,
        clipped_low,
        noise,
    })
}

/// The variance factor of channel `c` at `(x, y)` after bilinear demosaicing: 1 where it was
/// measured, `1 / n` where it is the mean of `n` photosites.
fn interpolated_share(colour: &RawColour, x: usize, y: usize, c: usize, w: usize, h: usize) -> f32 {
    if colour.cfa.is_none() || colour.native(x, y, c) {
        return 1.0;
    }
    let mut n = 0u32;
    for yy in y.saturating_sub(1)..(y + 2).min(h) {
        for xx in x.saturating_sub(1)..(x + 2).min(w) {
            n += u32::from(colour.native(xx, yy, c));
        }
    }
    1.0 / n.max(1) as f32
}
