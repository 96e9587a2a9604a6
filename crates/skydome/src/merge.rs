//! Merging a bracket into one floating-point radiance map.
//!
//! For each pixel and channel, every frame `j` with code `Z_j` votes for
//! `ln E = g(Z_j) − ln Δt_j` (`Δt_j` = [`Exposure::relative`](crate::bracket::Exposure::relative),
//! `g` from [`crate::response`]); the result is the weighted mean in the log domain,
//!
//! ```text
//! E = exp( Σ_j w_j(Z_j) · (g(Z_j) − ln Δt_j)  /  Σ_j w_j(Z_j) )
//! ```
//!
//! in relative units (a frame with `Δt_rel = 1` and code 128 gives `E = 1` for a calibrated
//! response).
//!
//! ## Weightings ([`Weighting`])
//! - [`Weighting::None`] — the seed's eq. 4, every frame weight 1. It is not the default: a
//!   code of 255 says only "at least this bright", yet it votes like any other, so a sun or
//!   specular highlight clipped in the longer frames is averaged with their too-low votes and
//!   comes out several stops too dark ("dark suns"); noisy, quantised near-black codes pull
//!   the shadows the same way. On the synthetic fish-eye bracket it triples the log error.
//! - [`Weighting::Hat`] (default) — Debevec's hat `w(z) = min(z, 255 − z)`, **zero** at 0 and
//!   255 so clipped codes never vote (OpenCV's `MergeDebevec` adds 1 to its triangle, which
//!   lets clipped pixels in: opencv#24966). Two changes make clipping safe: the *shortest*
//!   frame keeps the full weight (127) for every code above mid-grey and the *longest* for every
//!   code below it — so a pixel clipped in every frame takes the shortest frame's value (a lower
//!   bound, never dark or NaN) and a pixel black in every frame takes the longest's. Such a
//!   pixel is *flagged* ([`Merged::clipped`]). The shortest frame also carries a 1e-6 floor
//!   weight, so the denominator is never zero even for impossible (non-monotonic) inputs.
//!
//! ## 16-bit input
//! Merged through a 65 536-entry table per frame and channel (1.5 MB per frame): `g` is
//! interpolated at `v / 257` (exact for [`Response::linear`]) and the hat is evaluated at the
//! continuous `v / 257` (full weight stays 127), so the extra precision of 16-bit input is kept
//! and a 16-bit value `257 · z` merges exactly like the 8-bit code `z`.
//!
//! ## Speed
//! Per frame a table of `(w, w · (g − ln Δt))` pairs replaces all per-pixel `ln` and weight
//! arithmetic; the inner loops are table look-ups and adds, followed by one `exp` per channel
//! per pixel, computed by a branch-free polynomial (`2^x` with round-to-nearest range
//! reduction and a degree-6 Taylor series, relative error < 5e-7) that the compiler
//! vectorises. Rows are processed in bands (in parallel with the `parallel` feature); the
//! output is written once.

use crate::bracket::{Frame, Pixels};
use crate::image::HdrImage;
pub use crate::response::Weighting;
use crate::response::{hat, Response, LEVELS};

/// [`Merged::clipped`] bit: the pixel is saturated (code 255 or the hat's zero) in every frame in
/// some channel; its value is the shortest frame's lower bound.
pub const CLIPPED_HIGH: u8 = 1;
/// [`Merged::clipped`] bit: the pixel is black in every frame in some channel; its value is the
/// longest frame's upper bound.
pub const CLIPPED_LOW: u8 = 2;

const ROWS_PER_BAND: usize = 16;
/// Peak of the 8-bit hat.
const W_MAX: f32 = 127.0;
/// Floor weight of the shortest frame: keeps `Σ w > 0` without moving any real result.
const W_FLOOR: f32 = 1e-6;

/// Errors from merging; each message says what to change.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MergeError {
    /// No frames.
    #[error("no frames to merge: give at least one exposure")]
    NoFrames,
    /// Frames differ in size, buffer length or bit depth.
    #[error("frame {name:?} ({width}x{height}, {bits}-bit, {len} samples) does not match the first frame ({ew}x{eh}, {ebits}-bit): give frames of one bracket")]
    Mismatch {
        /// Frame name.
        name: String,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
        /// Its bit depth.
        bits: u32,
        /// Its sample count.
        len: usize,
        /// First frame's width.
        ew: usize,
        /// First frame's height.
        eh: usize,
        /// First frame's bit depth.
        ebits: u32,
    },
    /// Bad exposure, or frames not sorted shortest first.
    #[error("frame {name:?} has relative exposure {value}: exposures must be positive, finite, distinct and sorted shortest first")]
    BadExposure {
        /// Frame name.
        name: String,
        /// Its relative exposure.
        value: f64,
    },
}

/// Merge options.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct MergeOptions {
    /// Frame weighting (default [`Weighting::Hat`]).
    pub weighting: Weighting,
    /// Also return a per-pixel confidence.
    pub confidence: bool,
    /// Also return the per-pixel clipped mask.
    pub clipped_mask: bool,
}

/// A merged radiance map.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged {
    /// Linear radiance, relative units.
    pub radiance: HdrImage,
    /// Per pixel (row-major): for the channel with the least support, the sum over frames of
    /// the hat weights divided by the peak weight, capped at 1. 0 = extrapolated from a clipped
    /// or black value; 1 = at least one frame well exposed. Present when asked for.
    pub confidence: Option<Vec<f32>>,
    /// Per pixel (row-major) flags [`CLIPPED_HIGH`] | [`CLIPPED_LOW`]; 0 = fine. Present when
    /// asked for.
    pub clipped: Option<Vec<u8>>,
    /// Number of pixels flagged clipped high (counted when the mask or confidence is asked for).
    pub clipped_high: usize,
    /// Number of pixels flagged clipped low (counted when the mask or confidence is asked for).
    pub clipped_low: usize,
}

/// Merges `frames` (sorted shortest exposure first, same size and bit depth) through `response`.
pub fn merge(
    frames: &[Frame],
    response: &Response,
    opts: &MergeOptions,
) -> Result<Merged, MergeError> {
    let first = frames.first().ok_or(MergeError::NoFrames)?;
    let (w, h, bits) = (first.width, first.height, first.pixels.bit_depth());
    let n = w
        .checked_mul(h)
        .and_then(|v| v.checked_mul(3))
        .unwrap_or(usize::MAX);
    let mut prev = 0.0f64;
    let mut lt = Vec::with_capacity(frames.len());
    for f in frames {
        if f.width != w || f.height != h || f.pixels.bit_depth() != bits || f.pixels.len() != n {
            return Err(MergeError::Mismatch {
                name: f.name.clone(),
                width: f.width,
                height: f.height,
                bits: f.pixels.bit_depth(),
                len: f.pixels.len(),
                ew: w,
                eh: h,
                ebits: bits,
            });
        }
        let t = f.exposure.relative();
        if !(t.is_finite() && t > 0.0 && t > prev) {
            return Err(MergeError::BadExposure {
                name: f.name.clone(),
                value: t,
            });
        }
        prev = t;
        lt.push(t.ln());
    }
    let extras = opts.confidence || opts.clipped_mask;
    let mut out = vec![0f32; n];
    let mut conf = if extras {
        vec![0f32; w * h]
    } else {
        Vec::new()
    };
    let mut clip = if extras { vec![0u8; w * h] } else { Vec::new() };

    match bits {
        16 => {
            let srcs: Vec<&[u16]> = frames
                .iter()
                .filter_map(|f| match &f.pixels {
                    Pixels::U16(v) => Some(v.as_slice()),
                    Pixels::U8(_) => None,
                })
                .collect();
            let lut = build_lut16(response, &lt, opts.weighting);
            let hat_lut: Vec<f32> = (0..65536)
                .map(|v| hat_f(v as f32 / 257.0) / W_MAX)
                .collect();
            run_bands(
                &srcs, &lut, 65536, &hat_lut, w, &mut out, &mut conf, &mut clip, extras,
            );
        }
        _ => {
            let srcs: Vec<&[u8]> = frames
                .iter()
                .filter_map(|f| match &f.pixels {
                    Pixels::U8(v) => Some(v.as_slice()),
                    Pixels::U16(_) => None,
                })
                .collect();
            let lut = build_lut8(response, &lt, opts.weighting);
            let hat_lut: Vec<f32> = (0..LEVELS).map(|z| hat(z as u8) as f32 / W_MAX).collect();
            run_bands(
                &srcs, &lut, LEVELS, &hat_lut, w, &mut out, &mut conf, &mut clip, extras,
            );
        }
    }
    let clipped_high = clip.iter().filter(|&&c| c & CLIPPED_HIGH != 0).count();
    let clipped_low = clip.iter().filter(|&&c| c & CLIPPED_LOW != 0).count();
    Ok(Merged {
        radiance: HdrImage {
            width: w,
            height: h,
            data: out,
        },
        confidence: opts.confidence.then_some(conf),
        clipped: opts.clipped_mask.then_some(clip),
        clipped_high,
        clipped_low,
    })
}

#[inline]
fn hat_f(z: f32) -> f32 {
    z.min(255.0 - z).max(0.0)
}

/// Weight of code `z` (continuous 0..=255) in frame `j` of `p` for the given weighting.
fn weight(z: f32, j: usize, p: usize, weighting: Weighting, w_max: f32, hat_z: f32) -> f32 {
    match weighting {
        Weighting::None => 1.0,
        Weighting::Hat => {
            let mut w = hat_z;
            if j == 0 && z >= 127.5 {
                w = w_max;
            }
            if j + 1 == p && z <= 127.5 {
                w = w_max;
            }
            if j == 0 {
                w = w.max(W_FLOOR);
            }
            w
        }
    }
}

/// `(w, w · (g − ln Δt))` per frame, channel and code: index `(j·3 + c)·256 + z`.
fn build_lut8(response: &Response, lt: &[f64], weighting: Weighting) -> Vec<[f32; 2]> {
    let p = lt.len();
    let mut lut = Vec::with_capacity(p * 3 * LEVELS);
    for (j, &l) in lt.iter().enumerate() {
        for c in 0..3 {
            let g = response.curve(c);
            for (z, &gz) in g.iter().enumerate() {
                let w = weight(z as f32, j, p, weighting, W_MAX, hat(z as u8) as f32);
                lut.push([w, w * (gz - l) as f32]);
            }
        }
    }
    lut
}

/// As [`build_lut8`] for 16-bit values: index `(j·3 + c)·65536 + v`.
fn build_lut16(response: &Response, lt: &[f64], weighting: Weighting) -> Vec<[f32; 2]> {
    let p = lt.len();
    let mut lut = Vec::with_capacity(p * 3 * 65536);
    for (j, &l) in lt.iter().enumerate() {
        for c in 0..3 {
            for v in 0..=u16::MAX {
                let z = v as f32 / 257.0;
                let w = weight(z, j, p, weighting, W_MAX, hat_f(z));
                lut.push([w, w * (response.g16(c, v) - l) as f32]);
            }
        }
    }
    lut
}

/// One band of work: offset of its first sample, its output, confidence and mask slices.
type Band<'a> = (
    usize,
    &'a mut [f32],
    Option<&'a mut [f32]>,
    Option<&'a mut [u8]>,
);

#[allow(clippy::too_many_arguments)]
fn run_bands<T: Copy + Into<usize> + Sync>(
    srcs: &[&[T]],
    lut: &[[f32; 2]],
    levels: usize,
    hat_lut: &[f32],
    w: usize,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
    extras: bool,
) {
    let band = ROWS_PER_BAND * 3 * w;
    let pband = ROWS_PER_BAND * w;
    let mut jobs: Vec<Band<'_>> = out
        .chunks_mut(band)
        .enumerate()
        .map(|(k, o)| (k * band, o, None, None))
        .collect();
    if extras {
        for ((job, c), m) in jobs
            .iter_mut()
            .zip(conf.chunks_mut(pband))
            .zip(clip.chunks_mut(pband))
        {
            job.2 = Some(c);
            job.3 = Some(m);
        }
    }
    let work = |(off, o, c, m): Band<'_>| {
        merge_band(srcs, lut, levels, hat_lut, w, off, o, c, m);
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        jobs.into_par_iter().for_each(work);
    }
    #[cfg(not(feature = "parallel"))]
    jobs.into_iter().for_each(work);
}

#[allow(clippy::too_many_arguments)]
fn merge_band<T: Copy + Into<usize>>(
    srcs: &[&[T]],
    lut: &[[f32; 2]],
    levels: usize,
    hat_lut: &[f32],
    w: usize,
    off: usize,
    out: &mut [f32],
    mut conf: Option<&mut [f32]>,
    mut clip: Option<&mut [u8]>,
) {
    let row = 3 * w;
    let mut num = vec![0f32; row];
    let mut den = vec![0f32; row];
    let mut hs = vec![0f32; if conf.is_some() { row } else { 0 }];
    for (r, orow) in out.chunks_mut(row).enumerate() {
        let start = off + r * row;
        num.fill(0.0);
        den.fill(0.0);
        for (j, src) in srcs.iter().enumerate() {
            let s = &src[start..start + row];
            let l0 = &lut[j * 3 * levels..(j * 3 + 1) * levels];
            let l1 = &lut[(j * 3 + 1) * levels..(j * 3 + 2) * levels];
            let l2 = &lut[(j * 3 + 2) * levels..(j * 3 + 3) * levels];
            for ((px, nn), dd) in s
                .chunks_exact(3)
                .zip(num.chunks_exact_mut(3))
                .zip(den.chunks_exact_mut(3))
            {
                let a = l0[px[0].into()];
                let b = l1[px[1].into()];
                let c = l2[px[2].into()];
                dd[0] += a[0];
                nn[0] += a[1];
                dd[1] += b[0];
                nn[1] += b[1];
                dd[2] += c[0];
                nn[2] += c[1];
            }
        }
        for ((o, &nv), &dv) in orow.iter_mut().zip(&num).zip(&den) {
            *o = fast_exp(nv / dv);
        }
        if let (Some(conf), Some(clip)) = (conf.as_deref_mut(), clip.as_deref_mut()) {
            hs.fill(0.0);
            for src in srcs {
                for (h, &v) in hs.iter_mut().zip(&src[start..start + row]) {
                    *h += hat_lut[v.into()];
                }
            }
            let prow = r * w;
            let first = &srcs[0][start..start + row];
            for x in 0..w {
                let hh = &hs[3 * x..3 * x + 3];
                conf[prow + x] = hh[0].min(hh[1]).min(hh[2]).min(1.0);
                let mut flag = 0u8;
                for c in 0..3 {
                    if hh[c] == 0.0 {
                        let z: usize = first[3 * x + c].into();
                        flag |= if z >= levels / 2 {
                            CLIPPED_HIGH
                        } else {
                            CLIPPED_LOW
                        };
                    }
                }
                clip[prow + x] = flag;
            }
        }
    }
}

/// `e^x` in f32, branch-free so loops over it vectorise. `x` is clamped to ±87 (the f32
/// range); relative error below 5e-7.
#[inline(always)]
pub fn fast_exp(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 · 2²³: adding it rounds to an integer in the low bits
                                     // Cody–Waite: ln 2 split into a short high part (exact products) and a low correction.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let x = x.clamp(-87.0, 87.0);
    let t = x * std::f32::consts::LOG2_E + MAGIC;
    let k = t.to_bits() as i32 - 0x4B40_0000;
    let kf = t - MAGIC;
    let u = x - kf * LN2_HI - kf * LN2_LO; // |u| ≤ ln2 / 2
                                           // e^u, |u| ≤ 0.347, Horner form of the degree-6 Taylor series.
    let p = 1.0
        + u * (1.0
            + u * (0.5
                + u * (1.0 / 6.0 + u * (1.0 / 24.0 + u * (1.0 / 120.0 + u * (1.0 / 720.0))))));
    p * f32::from_bits(((k + 127) as u32) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_exp_matches_std_exp() {
        let mut worst = 0f64;
        let mut x = -80.0f32;
        while x < 80.0 {
            let a = fast_exp(x) as f64;
            let b = (x as f64).exp();
            worst = worst.max(((a - b) / b).abs());
            x += 0.0137;
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
    }

    #[test]
    fn fast_exp_saturates_instead_of_wrapping() {
        assert!(fast_exp(1000.0).is_finite() && fast_exp(1000.0) > 1e37);
        assert!(fast_exp(-1000.0) >= 0.0 && fast_exp(-1000.0) < 1e-37);
    }
}
