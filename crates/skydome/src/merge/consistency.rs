//! The consistency test: does every frame's vote for a pixel agree with the best-exposed
//! frame's within the noise? Flags the pixels where one does not (moving clouds or people, a
//! hand-held camera) and, for the ghost-aware merge, replaces them with the majority's value.

use super::{code_tables, fast_exp2, Code};
use super::{CONSISTENCY_MODEL_STOPS, CONSISTENCY_SIGMAS, ROWS_PER_BAND};
use crate::noise::{self, NoiseModel};
use crate::response::{Response, LEVELS};

/// Per frame, channel and code: the vote `log2 E_j` and its standard deviation in stops
/// (infinite where the code is unusable: black, 255, or faded out), for the consistency test.
pub(super) struct Votes<const N: usize> {
    /// Frame-major, then channel, then code: `[vote, sd]`.
    flat: Vec<[f32; 2]>,
}

impl<const N: usize> Votes<N> {
    pub(super) fn new(
        lt: &[f64],
        response: &Response,
        model: &NoiseModel,
        black: u8,
        g: impl Fn(usize, usize) -> f64,
    ) -> Self {
        let scale = 255.0 / (N - 1) as f32;
        let l2 = std::f64::consts::LOG2_E;
        let mut sd8 = [[f64::INFINITY; LEVELS]; 3];
        for (c, sd) in sd8.iter_mut().enumerate() {
            for (z, v) in sd.iter_mut().enumerate() {
                if z <= black as usize || z == LEVELS - 1 {
                    continue;
                }
                let fade = ((255.0 - z as f64) / noise::TOP_FADE).min(1.0);
                let var = model.log_variance(response, c, z) / fade;
                let m = CONSISTENCY_MODEL_STOPS as f64;
                *v = (var * l2 * l2 + m * m).sqrt();
                // Near the top a code may be a clipped value that JPEG ringing pulled below
                // 255: only a lower bound on the light (marked by a negative deviation).
                if z >= LOWER_BOUND_CODE {
                    *v = -*v;
                }
            }
        }
        let flat = code_tables::<N>(lt, g, |_, c, v, vote| {
            // The nearer 8-bit code's deviation (a 16-bit value between two codes has the
            // noise of either).
            let z = v as f32 * scale;
            [vote, sd8[c][(z.round() as usize).min(LEVELS - 1)] as f32]
        });
        Self { flat }
    }

    #[inline(always)]
    fn get(&self, j: usize, c: usize, v: usize) -> [f32; 2] {
        self.flat[(j * 3 + c) * N + v]
    }
}

/// The consistency test (and the ghost-aware replacement) over all pixels; returns the tested
/// and flagged pixel counts. `flags` gets 1 per flagged pixel.
pub(super) fn consistency<T: Code, const N: usize>(
    srcs: &[&[T]],
    votes: &Votes<N>,
    w: usize,
    out: &mut [f32],
    flags: &mut [u8],
    ghosts: bool,
) -> (usize, usize) {
    let rows = ROWS_PER_BAND;
    let work = |(k, (o, f)): (usize, (&mut [f32], &mut [u8]))| {
        let start = k * rows * w;
        consistency_band(srcs, votes, start, o, f, ghosts)
    };
    let add = |a: (usize, usize), b: (usize, usize)| (a.0 + b.0, a.1 + b.1);
    let chunks = out
        .chunks_mut((3 * rows * w).max(1))
        .zip(flags.chunks_mut((rows * w).max(1)));
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        let jobs: Vec<_> = chunks.enumerate().collect();
        jobs.into_par_iter().map(work).reduce(|| (0, 0), add)
    }
    #[cfg(not(feature = "parallel"))]
    chunks.enumerate().map(work).fold((0, 0), add)
}

fn consistency_band<T: Code, const N: usize>(
    srcs: &[&[T]],
    votes: &Votes<N>,
    start: usize,
    out: &mut [f32],
    flags: &mut [u8],
    ghosts: bool,
) -> (usize, usize) {
    let p = srcs.len();
    let (mut tested, mut flagged) = (0usize, 0usize);
    let mut v: Vec<Vote> = vec![[[0f32; 2]; 3]; p];
    for (k, (o, fl)) in out.chunks_exact_mut(3).zip(flags.iter_mut()).enumerate() {
        let i = 3 * (start + k);
        // Best-exposed frame: largest total precision over the three channels.
        let (mut best, mut best_prec) = (usize::MAX, 0f32);
        let mut usable = [0u8; 3];
        for (j, vj) in v.iter_mut().enumerate() {
            let mut prec = 0f32;
            for c in 0..3 {
                vj[c] = votes.get(j, c, srcs[j][i + c].index());
                if vj[c][1].is_finite() {
                    prec += 1.0 / (vj[c][1] * vj[c][1]);
                    usable[c] += 1;
                }
            }
            if prec > best_prec {
                best_prec = prec;
                best = j;
            }
        }
        if best == usize::MAX || usable.iter().all(|&u| u < 2) {
            *fl = 0;
            continue;
        }
        tested += 1;
        let bad = v
            .iter()
            .enumerate()
            .any(|(j, vj)| j != best && !agree(vj, &v[best]));
        *fl = bad as u8;
        if bad {
            flagged += 1;
            if ghosts {
                ghost_free(&v, best, o);
            }
        }
    }
    (tested, flagged)
}

/// One frame's votes for a pixel: per channel `[log2 E, σ]` (σ infinite: no vote; σ negative:
/// the code may be clipped, so the vote is only a lower bound, with deviation `|σ|`).
type Vote = [[f32; 2]; 3];

/// Codes from here up vote only a lower bound in the consistency test: the false alarms on
/// static scenes were almost all pixels whose longest frame read 250..254 where the light had
/// clipped (JPEG ringing pulls a clipped 255 down by a few codes).
pub(super) const LOWER_BOUND_CODE: usize = 250;

/// Two frames agree when every channel both can judge lies within the noise (a lower bound
/// disagrees only with a vote clearly below it).
fn agree(a: &Vote, b: &Vote) -> bool {
    (0..3).all(|c| {
        let (a, b) = (a[c], b[c]);
        if !(a[1].is_finite() && b[1].is_finite()) {
            return true;
        }
        let lim = CONSISTENCY_SIGMAS * (a[1] * a[1] + b[1] * b[1]).sqrt();
        match (a[1] < 0.0, b[1] < 0.0) {
            (false, false) => (a[0] - b[0]).abs() <= lim,
            (true, false) => b[0] >= a[0] - lim,
            (false, true) => a[0] >= b[0] - lim,
            (true, true) => true,
        }
    })
}

/// The ghost-aware value of a pixel whose frames disagree: the reference is the frame that
/// agrees with the most others (what moved is usually in the minority), ties going to the
/// best-exposed frame `best`; the value is the precision-weighted mean of the log votes of the
/// frames that agree with the reference. (Trusting the best-exposed frame alone kept the moved
/// content whenever the frame that saw it was the best exposed: twice the plain merge's error.)
fn ghost_free(v: &[Vote], best: usize, o: &mut [f32]) {
    let usable = |x: &Vote| x.iter().any(|c| c[1].is_finite());
    let support = |j: usize| {
        v.iter()
            .enumerate()
            .filter(|&(k, vk)| k != j && usable(vk) && agree(&v[j], vk))
            .count()
    };
    let mut reference = best;
    let mut most = support(best);
    for (j, vj) in v.iter().enumerate() {
        if j != best && usable(vj) {
            let s = support(j);
            if s > most {
                (reference, most) = (j, s);
            }
        }
    }
    for c in 0..3 {
        // Proper votes first; lower bounds only when nothing else saw the channel.
        for bounds in [false, true] {
            let (mut num, mut den) = (0f32, 0f32);
            for vj in v.iter().filter(|vj| agree(vj, &v[reference])) {
                let [x, sigma] = vj[c];
                if sigma.is_finite() && sigma != 0.0 && (sigma < 0.0) == bounds {
                    let w = 1.0 / (sigma * sigma);
                    num += w * x;
                    den += w;
                }
            }
            if den > 0.0 {
                o[c] = fast_exp2(num / den);
                break;
            }
        }
    }
}
