//! The noise-model refinement: the second pass of [`Weighting::Noise`](super::Weighting::Noise),
//! which re-weights every vote by the noise of the code its frame was expected to read.

use super::consistency::LOWER_BOUND_CODE;
use super::{code_tables, fast_exp2, fast_log2, Code, ROWS_PER_BAND};
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
    /// Per channel: `g · log2 e` of the first bin of `weights`.
    lo: [f32; 3],
    /// Per channel: the weight at expected `g · log2 e = lo + k / EXPECTED_BINS_PER_STOP`,
    /// ending in a zero bin (expected beyond the usable codes).
    weights: [Vec<f32>; 3],
}

impl<const N: usize> Refine<N> {
    /// The weight of a vote expected `bin` bins above `lo[c]` in channel `c`.
    #[inline(always)]
    fn weight(&self, c: usize, bin: f32) -> f32 {
        let t = self.weights[c].as_slice();
        t[(bin.max(0.0) as usize).min(t.len() - 1)]
    }

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
        Self {
            votes,
            shift: lt
                .iter()
                .map(|l| (l * l2) as f32 * EXPECTED_BINS_PER_STOP)
                .collect(),
            lo,
            weights,
        }
    }
}

/// Runs [`Refine`] over the hat's estimate in `out` (in parallel with the `parallel` feature).
pub(super) fn refine<T: Code, const N: usize>(
    srcs: &[&[T]],
    r: &Refine<N>,
    w: usize,
    out: &mut [f32],
) {
    let band = (3 * ROWS_PER_BAND * w).max(1);
    let work = |(k, o): (usize, &mut [f32])| refine_band(srcs, r, k * band, o);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(band).enumerate().for_each(work);
    }
    #[cfg(not(feature = "parallel"))]
    out.chunks_mut(band).enumerate().for_each(work);
}

fn refine_band<T: Code, const N: usize>(
    srcs: &[&[T]],
    r: &Refine<N>,
    start: usize,
    out: &mut [f32],
) {
    // Eight pixels at a time (a multiple of three samples, so the channel of each lane is
    // fixed): the look-ups are scalar, the arithmetic around them vectorises.
    const LANES: usize = 24;
    let (tables, _) = r.votes.as_chunks::<N>();
    let lo: [f32; LANES] = std::array::from_fn(|s| r.lo[s % 3]);
    let mut blocks = out.chunks_exact_mut(LANES);
    let mut i = start;
    for o in blocks.by_ref() {
        let o: &mut [f32; LANES] = o.try_into().unwrap_or_else(|_| unreachable!());
        let mut base = [0f32; LANES];
        for s in 0..LANES {
            base[s] = (fast_log2(o[s]) - lo[s]) * EXPECTED_BINS_PER_STOP;
        }
        let (mut num, mut den) = ([0f32; LANES], [0f32; LANES]);
        for (j, (src, shift)) in srcs.iter().zip(&r.shift).enumerate() {
            let src = &src[i..i + LANES];
            for s in 0..LANES {
                let c = s % 3;
                let [vote, f] = tables[j * 3 + c][src[s].index()];
                let w = f * r.weight(c, base[s] + shift);
                num[s] += w * vote;
                den[s] += w;
            }
        }
        for s in 0..LANES {
            let e0 = o[s];
            let v = fast_exp2(num[s] / den[s]);
            o[s] = if den[s] > 0.0 && e0 > 0.0 && e0.is_finite() {
                v
            } else {
                e0
            };
        }
        i += LANES;
    }
    for (k, o) in blocks.into_remainder().iter_mut().enumerate() {
        let i = i + k;
        let c = i % 3;
        let e0 = *o;
        let base = (fast_log2(e0) - r.lo[c]) * EXPECTED_BINS_PER_STOP;
        let (mut num, mut den) = (0f32, 0f32);
        for (j, (src, shift)) in srcs.iter().zip(&r.shift).enumerate() {
            let [vote, f] = tables[j * 3 + c][src[i].index()];
            let w = f * r.weight(c, base + shift);
            num += w * vote;
            den += w;
        }
        if den > 0.0 && e0 > 0.0 && e0.is_finite() {
            *o = fast_exp2(num / den);
        }
    }
}
