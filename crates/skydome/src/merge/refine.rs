//! The noise-model refinement: the second pass of [`Weighting::Noise`](super::Weighting::Noise),
//! which re-weights every vote by the noise of the code its frame was expected to read.

use super::consistency::LOWER_BOUND_CODE;
use super::{code_tables, fast_exp2, fast_log2, Code};
use crate::noise::{self, NoiseModel};
use crate::response::{Response, LEVELS};

/// Bins per stop of the expected-code weight tables of [`Refine`].
const EXPECTED_BINS_PER_STOP: f32 = 32.0;

/// The second pass of the noise-aware merge ([`Weighting::Noise`](super::Weighting::Noise)).
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
pub(super) struct Refine<const N: usize> {
    /// Frame-major, then channel, then code: `[log2 E_j, observed-code factor]`.
    votes: Vec<[f32; 2]>,
    /// `ln Δt_j · log2 e · EXPECTED_BINS_PER_STOP`: frame j's offset in bins.
    shift: Vec<f32>,
    /// Per channel: `g · log2 e` of the first bin of its weight table.
    lo: [f32; 3],
    /// The three channels' weight tables, one after the other: channel `c`'s, from
    /// `start[c]`, holds the weight at expected `g · log2 e = lo[c] + k / EXPECTED_BINS_PER_STOP`
    /// for `k = 0 ..= top[c]`, its last bin zero (expected beyond the usable codes).
    flat: Vec<f32>,
    /// Where each channel's weight table starts in `flat`.
    start: [i32; 3],
    /// Each channel's last bin (its table's length − 1), as `f32` for clamping bins.
    top: [f32; 3],
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
        let scale = 255.0 / (N - 1) as f64;
        let votes = code_tables::<N>(lt, &g, |_, _, v, vote| {
            let z = v as f64 * scale;
            let usable = z > black as f64 + 0.5 * scale && v + 1 < N;
            let fade = ((255.0 - z) / noise::TOP_FADE).clamp(0.0, 1.0);
            [vote, if usable { fade as f32 } else { 0.0 }]
        });
        let mut lo = [0f32; 3];
        let weights = [0, 1, 2].map(|c| {
            let curve = response.curve(c);
            let y: Vec<f64> = curve.iter().map(|v| v * l2).collect();
            let var: Vec<f64> = (0..LEVELS)
                .map(|z| model.log_variance(response, c, z))
                .collect();
            let first = black as usize + 1;
            let top = LOWER_BOUND_CODE;
            lo[c] = y[first] as f32;
            let bins = (((y[top] - y[first]) * EXPECTED_BINS_PER_STOP as f64).ceil() as usize)
                .clamp(1, 1 << 16);
            let mut w: Vec<f32> = (0..bins)
                .map(|k| {
                    let target = y[first] + k as f64 / EXPECTED_BINS_PER_STOP as f64;
                    // The continuous code where the curve reaches `target` (nondecreasing).
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
                })
                .collect();
            w.push(0.0);
            w
        });
        let mut flat = Vec::with_capacity(weights.iter().map(Vec::len).sum());
        let (mut start, mut top) = ([0i32; 3], [0f32; 3]);
        for (c, w) in weights.iter().enumerate() {
            // At most 2^16 + 1 bins per channel: offsets and last bins are exact in i32 and f32.
            start[c] = flat.len() as i32;
            top[c] = (w.len() - 1) as f32;
            flat.extend_from_slice(w);
        }
        Self {
            votes,
            flat,
            start,
            top,
            shift: lt
                .iter()
                .map(|l| (l * l2) as f32 * EXPECTED_BINS_PER_STOP)
                .collect(),
            lo,
        }
    }
}

/// Row buffers of [`refine_row`], allocated once per band of rows.
#[derive(Default)]
pub(super) struct Scratch {
    /// Per frame, then sample: the index of the vote's weight in [`Refine::flat`].
    at: Vec<i32>,
    /// Per sample: `Σ w · log2 E_j`.
    num: Vec<f32>,
    /// Per sample: `Σ w`.
    den: Vec<f32>,
}

/// Refines one row of the hat's estimate in `out` (`3 · width` samples, starting at a pixel's
/// red sample), given that row of every frame in `rows`. The merge calls it on each row right
/// after the hat pass, while the row's codes are still in cache.
///
/// Three passes over the row: the weight-table index of every vote (vector arithmetic), the
/// look-ups and sums (scalar, one pixel's three channels at a time with the sums in
/// registers), and the final `2^x` (vector arithmetic). Keeping the scalar look-ups apart
/// from the vector passes, a row apart in time, avoids the store-to-load stalls of mixing
/// scalar stores and vector loads on the same few values.
pub(super) fn refine_row<T: Code, const N: usize>(
    rows: &[&[T]],
    r: &Refine<N>,
    scratch: &mut Scratch,
    out: &mut [f32],
) {
    let n = out.len();
    let p = rows.len();
    let (tables, _) = r.votes.as_chunks::<N>();
    let (frames, _) = tables.as_chunks::<3>();
    let frames = &frames[..p];
    scratch.at.resize(p * n, 0);
    scratch.num.resize(n, 0.0);
    scratch.den.resize(n, 0.0);
    // 1. Per frame, the index of each vote's weight: the expected bin, clamped to its channel's
    //    table, plus where that table starts. Eight pixels at a time (a multiple of three
    //    samples, so each lane's channel is fixed), so it vectorises.
    const LANES: usize = 24;
    let lo: [f32; LANES] = std::array::from_fn(|s| r.lo[s % 3]);
    let top: [f32; LANES] = std::array::from_fn(|s| r.top[s % 3]);
    let start: [i32; LANES] = std::array::from_fn(|s| r.start[s % 3]);
    let (blocks, tail) = out.as_chunks::<LANES>();
    let nb = blocks.len() * LANES;
    for (b, o) in blocks.iter().enumerate() {
        let mut base = [0f32; LANES];
        for s in 0..LANES {
            base[s] = (fast_log2(o[s]) - lo[s]) * EXPECTED_BINS_PER_STOP;
        }
        for (at, &shift) in scratch.at.chunks_exact_mut(n).zip(&r.shift) {
            let at: &mut [i32; LANES] = match (&mut at[b * LANES..(b + 1) * LANES]).try_into() {
                Ok(v) => v,
                Err(_) => unreachable!("a block of LANES samples"),
            };
            for s in 0..LANES {
                at[s] = start[s] + floor_bin(base[s] + shift, top[s]);
            }
        }
    }
    for (k, o) in tail.iter().enumerate() {
        let c = (nb + k) % 3;
        let base = (fast_log2(*o) - r.lo[c]) * EXPECTED_BINS_PER_STOP;
        for (at, &shift) in scratch.at.chunks_exact_mut(n).zip(&r.shift) {
            at[nb + k] = r.start[c] + floor_bin(base + shift, r.top[c]);
        }
    }
    // 2. The weighted sums.
    let at = &scratch.at[..p * n];
    let (num, den) = (&mut scratch.num[..n], &mut scratch.den[..n]);
    for i in (0..n).step_by(3) {
        let (mut nv, mut dv) = ([0f32; 3], [0f32; 3]);
        for (j, (src, tab)) in rows.iter().zip(frames).enumerate() {
            for c in 0..3 {
                let [vote, f] = tab[c][src[i + c].index()];
                let w = f * r.flat[at[j * n + i + c] as usize];
                nv[c] += w * vote;
                dv[c] += w;
            }
        }
        num[i..i + 3].copy_from_slice(&nv);
        den[i..i + 3].copy_from_slice(&dv);
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
/// estimate `e0` is positive and finite, else `e0`.
#[inline(always)]
fn refined(e0: f32, num: f32, den: f32) -> f32 {
    let v = fast_exp2(num / den);
    let finite = (e0.to_bits() & 0x7fff_ffff) < 0x7f80_0000;
    if (den > 0.0) & (e0 > 0.0) & finite {
        v
    } else {
        e0
    }
}
