//! The noise-model refinement: the second estimate of [`Weighting::Noise`](super::Weighting::Noise),
//! which re-weights every vote by the noise of the code its frame was expected to read.

use super::consistency::LOWER_BOUND_CODE;
use super::{code_tables, fast_exp2, Code};
use crate::noise::{self, NoiseModel};
use crate::response::{Response, LEVELS};

/// Bins per stop of the hat's estimate `log2 E₀` in the weight rows of [`Refine`].
pub(super) const BINS_PER_STOP: f32 = 32.0;

/// The second estimate of the noise-aware merge ([`Weighting::Noise`](super::Weighting::Noise)).
///
/// A vote's variance is that of the code the frame *should* read for the pixel's light, not of
/// the code it happened to read: weighting by the observed code lets each frame's own noise
/// choose its weight (a vote that came out high also came out more trusted), which biases the
/// mean and, measured against the truth, lost to the hat on the well-exposed sky. So the hat
/// merge gives a first estimate `log2 E₀`; frame `j` is then expected at
/// `g(z*) = ln E₀ + ln Δt_j`, and its vote gets the weight `1 / σ²(z*)` of the noise model
/// (Granados et al. 2010 use the same two-pass scheme), zero where `z*` is within
/// [`LOWER_BOUND_CODE`] of clipping, times a factor of the observed code: zero at the black
/// level and at full scale, fading over the top [`noise::TOP_FADE`] codes. A pixel no frame
/// can vote for keeps the hat's value (clipped suns, pixels black in every frame).
///
/// The weights are looked up, not computed: `log2 E₀` is binned at [`BINS_PER_STOP`] bins a
/// stop, and each channel's table holds, per bin, one row of every frame's weight at that
/// bin's expected code (`p` values side by side, one cache line for a few frames). A sample
/// then costs one bin index (vector arithmetic) and one row, whatever the frame count.
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
        }
    }
}

/// Samples per block of the vector passes: eight pixels, so each lane's channel is fixed.
const LANES: usize = 24;

/// Row buffers of [`refine_row`], allocated once per band of rows.
#[derive(Default)]
pub(super) struct Scratch {
    /// Per sample: the index of its weight row in [`Refine::rows`], in rows.
    at: Vec<u32>,
    /// Per sample: `Σ w · log2 E_j`.
    num: Vec<f32>,
    /// Per sample: `Σ w`.
    den: Vec<f32>,
}

/// Refines one row of the hat's estimate: `out` (`3 · width` samples, starting at a pixel's red
/// sample) holds the hat's `log2 E₀` on entry and the radiance on return; `rows` holds that row
/// of every frame. The merge calls it on each row right after the hat pass, while the row's
/// codes are still in cache.
///
/// Three passes over the row: each sample's weight row (vector arithmetic), the look-ups and
/// sums (scalar, one pixel's three channels at a time with the sums in registers, the frame
/// loop unrolled for up to nine frames), and the final `2^x` (vector arithmetic).
pub(super) fn refine_row<T: Code, const N: usize>(
    rows: &[&[T]],
    r: &Refine<N>,
    scratch: &mut Scratch,
    out: &mut [f32],
) {
    let n = out.len();
    debug_assert_eq!(rows.len(), r.frames);
    scratch.at.resize(n, 0);
    scratch.num.resize(n, 0.0);
    scratch.den.resize(n, 0.0);
    // 1. Each sample's weight row: its bin of `log2 E₀`, clamped, plus where its channel's
    //    rows start.
    let off: [f32; LANES] = std::array::from_fn(|s| r.off[s % 3]);
    let last: [f32; LANES] = std::array::from_fn(|s| r.last[s % 3]);
    let start: [i32; LANES] = std::array::from_fn(|s| r.start[s % 3]);
    let at = &mut scratch.at[..n];
    let (ab, atail) = at.as_chunks_mut::<LANES>();
    let (ob, otail) = out.as_chunks::<LANES>();
    for (a, o) in ab.iter_mut().zip(ob) {
        for s in 0..LANES {
            a[s] = (start[s] + floor_bin(o[s] * BINS_PER_STOP - off[s], last[s])) as u32;
        }
    }
    let nb = ob.len() * LANES;
    for (k, (a, o)) in atail.iter_mut().zip(otail).enumerate() {
        let c = (nb + k) % 3;
        *a = (r.start[c] + floor_bin(*o * BINS_PER_STOP - r.off[c], r.last[c])) as u32;
    }
    // 2. The weighted sums.
    let (num, den) = (&mut scratch.num[..n], &mut scratch.den[..n]);
    match rows.len() {
        1 => sums::<T, N, 1>(rows, r, at, num, den),
        2 => sums::<T, N, 2>(rows, r, at, num, den),
        3 => sums::<T, N, 3>(rows, r, at, num, den),
        4 => sums::<T, N, 4>(rows, r, at, num, den),
        5 => sums::<T, N, 5>(rows, r, at, num, den),
        6 => sums::<T, N, 6>(rows, r, at, num, den),
        7 => sums::<T, N, 7>(rows, r, at, num, den),
        8 => sums::<T, N, 8>(rows, r, at, num, den),
        9 => sums::<T, N, 9>(rows, r, at, num, den),
        _ => sums_any(rows, r, at, num, den),
    }
    // 3. The refined value where some frame could vote, else the hat's.
    let (ob, ot) = out.as_chunks_mut::<LANES>();
    let (nb, nt) = num.as_chunks::<LANES>();
    let (db, dt) = den.as_chunks::<LANES>();
    for ((o, nv), dv) in ob.iter_mut().zip(nb).zip(db) {
        for s in 0..LANES {
            o[s] = refined(o[s], nv[s], dv[s]);
        }
    }
    for ((o, &nv), &dv) in ot.iter_mut().zip(nt).zip(dt) {
        *o = refined(*o, nv, dv);
    }
}

/// The sums of [`refine_row`] for `P` frames: per pixel, every frame's three votes, each
/// weighted by its observed-code factor and its entry in the sample's weight row.
#[inline(always)]
fn sums<T: Code, const N: usize, const P: usize>(
    rows: &[&[T]],
    r: &Refine<N>,
    at: &[u32],
    num: &mut [f32],
    den: &mut [f32],
) {
    let (tables, _) = r.votes.as_chunks::<N>();
    let (frames, _) = tables.as_chunks::<3>();
    let frames: &[[[[f32; 2]; N]; 3]; P] = match frames[..P].try_into() {
        Ok(f) => f,
        Err(_) => unreachable!("P frames"),
    };
    // Whole pixels, every slice cut to the same length so the loop needs no bounds checks.
    let m = num.len() / 3;
    let srcs: [&[[T; 3]]; P] = std::array::from_fn(|j| &rows[j].as_chunks::<3>().0[..m]);
    let at = &at.as_chunks::<3>().0[..m];
    let num = &mut num.as_chunks_mut::<3>().0[..m];
    let den = &mut den.as_chunks_mut::<3>().0[..m];
    let (wrows, _) = r.rows.as_chunks::<P>();
    let none = [0f32; P];
    for k in 0..m {
        // A row index is in range by construction; a missing row would weigh nothing.
        let w: [&[f32; P]; 3] =
            std::array::from_fn(|c| wrows.get(at[k][c] as usize).unwrap_or(&none));
        let (mut nv, mut dv) = ([0f32; 3], [0f32; 3]);
        for j in 0..P {
            let z = srcs[j][k];
            for c in 0..3 {
                let [vote, f] = frames[j][c][z[c].index()];
                let wt = f * w[c][j];
                nv[c] += wt * vote;
                dv[c] += wt;
            }
        }
        num[k] = nv;
        den[k] = dv;
    }
}

/// [`sums`] for any number of frames.
fn sums_any<T: Code, const N: usize>(
    rows: &[&[T]],
    r: &Refine<N>,
    at: &[u32],
    num: &mut [f32],
    den: &mut [f32],
) {
    let p = rows.len();
    let (tables, _) = r.votes.as_chunks::<N>();
    let (frames, _) = tables.as_chunks::<3>();
    for (i, (nv, dv)) in num.iter_mut().zip(den.iter_mut()).enumerate() {
        let c = i % 3;
        let a = at[i] as usize * p;
        let Some(w) = r.rows.get(a..a + p) else {
            (*nv, *dv) = (0.0, 0.0);
            continue;
        };
        let (mut sn, mut sd) = (0f32, 0f32);
        for ((src, tab), &wj) in rows.iter().zip(frames).zip(w) {
            let [vote, f] = tab[c][src[i].index()];
            let wt = f * wj;
            sn += wt * vote;
            sd += wt;
        }
        (*nv, *dv) = (sn, sd);
    }
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

/// The refined value `2^(num / den)` where some frame could vote (`den > 0`) and the hat's
/// `log2 E₀` is a number, else the hat's `2^log2 E₀`. One `2^x` either way: [`fast_exp2`]
/// clamps its argument, so its value is positive and finite exactly when that is not NaN.
#[inline(always)]
fn refined(l0: f32, num: f32, den: f32) -> f32 {
    let x = num / den;
    fast_exp2(if (den > 0.0) & !l0.is_nan() { x } else { l0 })
}
