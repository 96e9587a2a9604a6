//! The noise-model refinement: the second estimate of [`Weighting::Noise`](super::Weighting::Noise),
//! which re-weights every vote by the noise of the code its frame was expected to read.

use super::consistency::LOWER_BOUND_CODE;
use super::fused::Fused;
use super::{code_tables, fast_exp2, Code};
use crate::noise::{self, NoiseModel};
use crate::response::{Response, LEVELS};

/// Bins per stop of the hat's estimate `log2 E₀` in the weight rows of [`Refine`].
pub(super) const BINS_PER_STOP: f32 = 32.0;

/// A frame whose code is below this (8-bit scale) is well exposed enough for its vote to pick
/// the weights of every frame: [`Refine`]'s first estimate is the vote of the longest such
/// frame. It is below the top codes' fade ([`noise::TOP_FADE`]) and JPEG's ringing there, and
/// far enough below [`LOWER_BOUND_CODE`] that no frame's weight is cut off near it.
pub(super) const SELECT_BELOW: u8 = 224;

/// The noise-aware merge ([`Weighting::Noise`](super::Weighting::Noise)).
///
/// A vote's variance is that of the code the frame *should* read for the pixel's light, not of
/// the code it happened to read: weighting by the observed code lets each frame's own noise
/// choose its weight (a vote that came out high also came out more trusted), which biases the
/// mean and, measured against the truth, lost to the hat on the well-exposed sky. So a first
/// estimate `log2 E₀` picks the weights; frame `j` is then expected at
/// `g(z*) = ln E₀ + ln Δt_j`, and its vote gets the weight `1 / σ²(z*)` of the noise model
/// (Granados et al. 2010 use the same two-pass scheme), zero where `z*` is within
/// [`LOWER_BOUND_CODE`] of clipping, times a factor of the observed code: zero at the black
/// level and at full scale, fading over the top [`noise::TOP_FADE`] codes. The first estimate
/// only has to pick a 1/32-stop bin, so it is one frame's vote, not a merge: that of the
/// longest frame whose code is below [`SELECT_BELOW`] (the best-exposed frame that is surely
/// not clipped), or the shortest frame's when every frame is above it. A pixel no frame can
/// vote for keeps that vote: the shortest frame's lower bound for a clipped sun, the longest
/// frame's upper bound for a pixel black in every frame, as the hat gives them.
///
/// The chosen frame's own noise now picks the bin, but only its own weight depends on it, and
/// smoothly (the weight of a code below [`SELECT_BELOW`] changes by a few per cent over a bin);
/// measured against the oracle of `tests/lib/oracle.rs` it merges as well as the hat's
/// estimate did, at about half the cost.
///
/// The weights are looked up, not computed: `log2 E₀` is binned at [`BINS_PER_STOP`] bins a
/// stop, and each channel's table holds, per bin, one row of every frame's weight at that
/// bin's expected code (`p` values side by side, one cache line for a few frames). A sample
/// then costs one table entry per frame (vote and factor), one bin index and one row.
pub(super) struct Refine<const N: usize> {
    /// Frame-major, then channel, then code: `[log2 E_j, observed-code factor]`.
    pub(super) votes: Vec<[f32; 2]>,
    /// The three channels' weight rows, one channel after the other: channel `c`'s row `b`,
    /// the `start[c] + b`-th row of `frames` values, holds each frame's weight for `log2 E₀` in bin `b`, that is
    /// `⌊log2 E₀ · BINS_PER_STOP − off[c]⌋ = b` (clamped to `0 ..= last[c]`).
    pub(super) rows: Vec<f32>,
    /// Frames per row.
    pub(super) frames: usize,
    /// Per channel: the bin offset (see `rows`).
    pub(super) off: [f32; 3],
    /// Per channel: the last bin, as `f32` for clamping.
    pub(super) last: [f32; 3],
    /// Per channel: its first row's index in `rows` (in rows).
    pub(super) start: [i32; 3],
    /// [`SELECT_BELOW`] in this input's code units.
    pub(super) select: u32,
    /// The vector kernel that merges 8-bit rows with the same bits, where the CPU has one (see
    /// [`Fused`]).
    pub(super) fused: Option<Fused>,
}

impl<const N: usize> Refine<N> {
    pub(super) fn new(
        lt: &[f64],
        response: &Response,
        model: &NoiseModel,
        black: u8,
        g: impl Fn(usize, usize) -> f64,
    ) -> Self {
        let l2 = std::f64::consts::LOG2_E;
        let bps = BINS_PER_STOP as f64;
        let scale = 255.0 / (N - 1) as f64;
        let votes = code_tables::<N>(lt, &g, |_, _, v, vote| {
            let z = v as f64 * scale;
            let usable = z > black as f64 + 0.5 * scale && v + 1 < N;
            let fade = ((255.0 - z) / noise::TOP_FADE).clamp(0.0, 1.0);
            [vote, if usable { fade as f32 } else { 0.0 }]
        });
        let p = lt.len().max(1);
        // Frame j's exposure offset in bins: expected `log2` code value = log2 E₀ + shift/bps.
        let shift: Vec<f64> = lt.iter().map(|l| l * l2 * bps).collect();
        let smax = shift.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let smin = shift.iter().copied().fold(f64::INFINITY, f64::min);
        let (mut off, mut last, mut start) = ([0f32; 3], [0f32; 3], [0i32; 3]);
        let mut rows = Vec::new();
        for c in 0..3 {
            let curve = response.curve(c);
            let y: Vec<f64> = curve.iter().map(|v| v * l2).collect();
            let var: Vec<f64> = (0..LEVELS)
                .map(|z| model.log_variance(response, c, z))
                .collect();
            let first = (black as usize + 1).min(LOWER_BOUND_CODE - 1);
            let top = LOWER_BOUND_CODE;
            // The inverse variance at the code where the curve reaches `target` (log2 units):
            // the first usable code's below it, zero beyond the usable codes.
            let weight = |target: f64| -> f32 {
                if target.is_nan() || target > y[top] {
                    return 0.0;
                }
                let target = target.max(y[first]);
                let i = first + y[first..=top].partition_point(|&v| v < target);
                let i = i.clamp(first + 1, top);
                let (a, b) = (y[i - 1], y[i]);
                let f = if b > a {
                    ((target - a) / (b - a)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                let v = var[i - 1] * (1.0 - f) + var[i] * f;
                if v.is_finite() && v > 0.0 {
                    (1.0 / v) as f32
                } else {
                    0.0
                }
            };
            // Bin 0 has every frame expected at or below the first usable code, the last bin
            // every frame beyond the usable codes: bins outside change nothing.
            let lo = y[first] as f32;
            let span = (y[top] - y[first]) * bps;
            let kmin = (-smax).floor() - 1.0;
            let bins = ((span - smin - kmin).ceil() + 2.0).clamp(2.0, 65_536.0) as usize;
            off[c] = lo * BINS_PER_STOP + kmin as f32;
            last[c] = (bins - 1) as f32;
            start[c] = (rows.len() / p) as i32;
            for b in 0..bins {
                for s in &shift {
                    rows.push(weight(lo as f64 + (b as f64 + kmin + s) / bps));
                }
            }
        }
        Self {
            votes,
            rows,
            frames: p,
            off,
            last,
            start,
            select: (SELECT_BELOW as f64 / scale).ceil() as u32,
            fused: None,
        }
    }
}

/// Merges one row: `rows` holds that row of every frame, `out` (`3 · width` samples, starting
/// at a pixel's red sample) receives the radiance.
///
/// One pass over the pixels, the frame loop unrolled for up to nine frames: each sample's votes
/// and observed-code factors (one table entry per frame), its first estimate `log2 E₀` (the vote
/// of the frame [`Refine`] picks, see [`SELECT_BELOW`]), its weight row, and the weighted mean
/// in registers; then the final `2^x` (vector arithmetic).
pub(super) fn refine_row<T: Code, const N: usize>(rows: &[&[T]], r: &Refine<N>, out: &mut [f32]) {
    debug_assert_eq!(rows.len(), r.frames);
    match rows.len() {
        1 => sums::<T, N, 1>(rows, r, out),
        2 => sums::<T, N, 2>(rows, r, out),
        3 => sums::<T, N, 3>(rows, r, out),
        4 => sums::<T, N, 4>(rows, r, out),
        5 => sums::<T, N, 5>(rows, r, out),
        6 => sums::<T, N, 6>(rows, r, out),
        7 => sums::<T, N, 7>(rows, r, out),
        8 => sums::<T, N, 8>(rows, r, out),
        9 => sums::<T, N, 9>(rows, r, out),
        _ => sums_any(rows, r, out),
    }
    for o in out.iter_mut() {
        *o = fast_exp2(*o);
    }
}

/// The weighted means of [`refine_row`] for `P` frames, in `log2` units: per pixel, every
/// frame's three votes, each weighted by its observed-code factor and its entry in the
/// sample's weight row.
#[inline(always)]
fn sums<T: Code, const N: usize, const P: usize>(rows: &[&[T]], r: &Refine<N>, out: &mut [f32]) {
    let (tables, _) = r.votes.as_chunks::<N>();
    let (frames, _) = tables.as_chunks::<3>();
    let frames: &[[[[f32; 2]; N]; 3]; P] = match frames[..P].try_into() {
        Ok(f) => f,
        Err(_) => unreachable!("P frames"),
    };
    // Whole pixels, every slice cut to the same length so the loop needs no bounds checks.
    let m = out.len() / 3;
    let srcs: [&[[T; 3]]; P] = std::array::from_fn(|j| &rows[j].as_chunks::<3>().0[..m]);
    let out = &mut out.as_chunks_mut::<3>().0[..m];
    let (wrows, _) = r.rows.as_chunks::<P>();
    let none = [0f32; P];
    for (k, o) in out.iter_mut().enumerate() {
        for c in 0..3 {
            let z: [usize; P] = std::array::from_fn(|j| srcs[j][k][c].index());
            let e: [[f32; 2]; P] = std::array::from_fn(|j| frames[j][c][z[j]]);
            let l0 = first_estimate(&z, &e, r.select);
            // A row index is in range by construction; a missing row would weigh nothing.
            let at = r.start[c] + floor_bin(l0 * BINS_PER_STOP - r.off[c], r.last[c]);
            let w = wrows.get(at as usize).unwrap_or(&none);
            let (mut nv, mut dv) = (0f32, 0f32);
            for j in 0..P {
                let [vote, f] = e[j];
                let wt = f * w[j];
                nv += wt * vote;
                dv += wt;
            }
            o[c] = refined(l0, nv, dv);
        }
    }
}

/// [`sums`] for any number of frames.
fn sums_any<T: Code, const N: usize>(rows: &[&[T]], r: &Refine<N>, out: &mut [f32]) {
    let p = rows.len();
    let (tables, _) = r.votes.as_chunks::<N>();
    let (frames, _) = tables.as_chunks::<3>();
    let mut z = vec![0usize; p];
    let mut e = vec![[0f32; 2]; p];
    for (i, o) in out.iter_mut().enumerate() {
        let c = i % 3;
        for (j, (src, tab)) in rows.iter().zip(frames).enumerate() {
            z[j] = src[i].index();
            e[j] = tab[c][z[j]];
        }
        let l0 = first_estimate(&z, &e, r.select);
        let a = (r.start[c] + floor_bin(l0 * BINS_PER_STOP - r.off[c], r.last[c])) as usize * p;
        let Some(w) = r.rows.get(a..a + p) else {
            *o = l0;
            continue;
        };
        let (mut sn, mut sd) = (0f32, 0f32);
        for (&[vote, f], &wj) in e.iter().zip(w) {
            let wt = f * wj;
            sn += wt * vote;
            sd += wt;
        }
        *o = refined(l0, sn, sd);
    }
}

/// The first estimate `log2 E₀` of one sample from its frames' codes `z` and table entries `e`
/// (shortest frame first): the vote of the longest frame whose code is below `select`, or the
/// shortest frame's when none is (see [`Refine`]).
#[inline(always)]
fn first_estimate(z: &[usize], e: &[[f32; 2]], select: u32) -> f32 {
    let mut l0 = e[0][0];
    for (&zj, ej) in z.iter().zip(e) {
        if (zj as u32) < select {
            l0 = ej[0];
        }
    }
    l0
}

/// `⌊x⌋` of `x` clamped to `0 ..= top` (`top` a whole number below 2²²; NaN gives 0), by
/// arithmetic that vectorises: adding 2²³ rounds to the nearest whole number in the low bits
/// of the sum, and one compare corrects a round-up. (`x as i32` saturates, which takes the
/// compiler a scalar conversion and two branches per sample.)
#[inline(always)]
fn floor_bin(x: f32, top: f32) -> i32 {
    const BIAS: f32 = 8_388_608.0; // 2²³
    let x = if x > 0.0 { x } else { 0.0 };
    let x = if x < top { x } else { top };
    let t = x + BIAS;
    let rounded = t.to_bits() as i32 - BIAS.to_bits() as i32;
    rounded - ((t - BIAS) > x) as i32
}

/// The merged value in `log2` units: `num / den` where some frame could vote (`den > 0`) and
/// the first estimate `log2 E₀` is a number, else `log2 E₀`. (The caller's [`fast_exp2`]
/// clamps its argument, so its value is positive and finite exactly when that is not NaN.)
#[inline(always)]
fn refined(l0: f32, num: f32, den: f32) -> f32 {
    let x = num / den;
    if (den > 0.0) & !l0.is_nan() {
        x
    } else {
        l0
    }
}
