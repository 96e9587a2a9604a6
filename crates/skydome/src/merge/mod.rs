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
//! - [`Weighting::Hat`] — Debevec's hat `w(z) = min(z, 255 − z)`, **zero** at 0 and
//!   255 so clipped codes never vote (OpenCV's `MergeDebevec` adds 1 to its triangle, which
//!   lets clipped pixels in: opencv#24966). Two changes make clipping safe: the *shortest*
//!   frame keeps the full weight (127) for every code above mid-grey and the *longest* for every
//!   code below it — so a pixel clipped in every frame takes the shortest frame's value (a lower
//!   bound, never dark or NaN) and a pixel black in every frame takes the longest's. Such a
//!   pixel is *flagged* ([`Merged::clipped`]). The shortest frame also carries a 1e-6 floor
//!   weight, so the denominator is never zero even for impossible (non-monotonic) inputs.
//!
//! - [`Weighting::Noise`] (default) — inverse variance under the camera noise model, refining
//!   the hat's estimate; see the variant's documentation and [`crate::noise`].
//!
//! ## 16-bit input
//! Merged through a 65 536-entry table per frame and channel (1.5 MB per frame): `g` is
//! interpolated at `v / 257` (exact for [`Response::linear`]) and the hat is evaluated at the
//! continuous `v / 257` (full weight stays 127), so the extra precision of 16-bit input is kept
//! and a 16-bit value `257 · z` merges exactly like the 8-bit code `z`.
//!
//! ## Speed
//! Per frame and channel a table of `(w, w · log2 E_j)` pairs (`log2 E_j = (g − ln Δt_j) ·
//! log2 e`) replaces all per-pixel `ln` and weight arithmetic. Frames are taken three at a
//! time: each sample's three look-ups are summed in registers and divided in blocks of four
//! pixels, so the division vectorises; more than three frames add group sums into a row
//! buffer. Then one `2^x` per sample, a branch-free polynomial that vectorises
//! ([`fast_exp2`]). The clipped-pixel scan and the confidence are byte and integer passes over
//! the same rows while they are in cache. Rows are processed in bands of 16 (in parallel with
//! the `parallel` feature); the output is written once. [`merge_into`] reuses the output
//! buffers of an earlier merge, which saves the page faults of a fresh allocation (≈ 18 ms of
//! the ≈ 57 ms a 6 MP merge takes on a 2-core machine; see `benches/calibrate_merge.rs`).
//! [`Weighting::Noise`] refines each row right after the hat has merged it, while the row's
//! codes are in cache: one pass over the frames, its table indices and final `2^x` vector
//! passes over the row, the three look-ups per vote (hat, vote, expected-code weight) scalar.

mod consistency;
mod flags;
#[allow(unsafe_code)] // std::arch gathers, loads and stores; see the module's SAFETY notes.
mod fused;
mod hat;
mod linear;
mod refine;
mod uncertainty;

use crate::bracket::{Frame, Pixels};
use crate::image::{Circle, HdrImage};
use crate::noise::{self, NoiseEstimate, NoiseModel};
use crate::response::{Response, LEVELS};
use consistency::{consistency, Votes};
use hat::{run_bands, run_releasing, weight, Tables};
use refine::Refine;

pub use flags::{clipped_flags, ClippedFlags};
pub use linear::{estimate_linear_noise, merge_linear, LinearMerged, LinearNoise, SAFE_FRACTION};
pub use uncertainty::{standard_error, summarise as summarise_standard_error};

/// [`Merged::clipped`] bit: the pixel is saturated (code 255 or the hat's zero) in every frame in
/// some channel; its value is the shortest frame's lower bound.
pub const CLIPPED_HIGH: u8 = 1;
/// [`Merged::clipped`] bit: the pixel is black in every frame in some channel; its value is the
/// longest frame's upper bound.
pub const CLIPPED_LOW: u8 = 2;
/// [`Merged::clipped`] bit (always with [`CLIPPED_LOW`]): every channel is at or below the black
/// level in every frame. Such a pixel carries no colour, so all three channels get the same
/// value — the smallest of the three channels' upper bounds from the longest frame, the
/// tightest bound that is neutral — instead of the coloured fog the curves' extrapolated toes
/// would give.
pub const BLACK: u8 = 4;
/// [`Merged::warnings`] speaks up when more than this fraction of the tested pixels disagree
/// between frames beyond their noise.
pub const INCONSISTENT_WARN_FRACTION: f64 = 0.02;
/// [`Merged::warnings`] speaks up when more than this fraction of the area is black in every
/// frame.
pub const BLACK_WARN_FRACTION: f64 = 0.001;
/// The consistency test flags a vote more than this many standard deviations from the
/// best-exposed frame's.
pub const CONSISTENCY_SIGMAS: f32 = 4.0;
/// Standard deviation (stops) added to every vote in the consistency test for what the noise
/// model does not describe: the calibrated curve's own error, sub-pixel misregistration.
pub const CONSISTENCY_MODEL_STOPS: f32 = 0.1;

const ROWS_PER_BAND: usize = 16;

/// How frames are weighted when merging (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// Every frame counts equally: the seed's eq. 4, an unweighted mean of `g(Z) − ln Δt`.
    /// Clipped values pull the mean down ("dark suns"); kept for reproducing the seed.
    None,
    /// Debevec's hat, zero at 0 and 255, with full weight for the shortest frame above
    /// mid-grey and for the longest below it (the default before issue 27; also the noise
    /// merge's first estimate).
    Hat,
    /// Inverse variance of each vote under a camera noise model (shot, read, quantisation and
    /// JPEG noise; see [`crate::noise`]), evaluated at the code the frame is *expected* to read
    /// given the hat's first estimate (two passes, as Granados et al. 2010): a longer exposure,
    /// which collected more light, counts for more. Zero at the black level and 255, fading to
    /// zero over the top codes; a frame expected within 5 codes of clipping gets no weight. The
    /// default (issue 27). On the synthetic brackets of `tests/lib/oracle.rs` its error is
    /// 1.04–1.26× the oracle's (true curve and true noise) where the hat's is 1.37–2.45×, and
    /// never worse than the hat's on any bracket's sky, dim ground or clipped sun; on every real
    /// set its median frame agrees better with the merge than the hat's. A whole `skydome merge`
    /// costs 1.10–1.25× the hat's (3–9 frames, 6 and 12 MP, `scripts/bench.sh --noise`), the
    /// model fitted from the frames (each row is refined right after the hat has merged it, from
    /// one weight row per 1/32-stop bin of the hat's estimate).
    #[default]
    Noise,
}

crate::named_enum!(Weighting, "weighting", [None => "none", Hat => "hat", Noise => "noise"]);

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
    /// Frame weighting (default [`Weighting::Noise`]).
    pub weighting: Weighting,
    /// Also return a per-pixel confidence.
    pub confidence: bool,
    /// Also return the per-pixel clipped mask.
    pub clipped_mask: bool,
    /// Noise model for [`Weighting::Noise`] and the consistency test (e.g. from a camera
    /// profile); `None` estimates it from the bracket ([`noise::estimate`]).
    #[serde(default)]
    pub noise: Option<NoiseModel>,
    /// Black level, 8-bit code: a code at or below it counts as black (no weight under
    /// [`Weighting::Noise`]; a pixel black in every frame is flagged and kept neutral). 0 by
    /// default; a film scan or a camera that lifts its blacks has ≈ 16.
    #[serde(default)]
    pub black_level: u8,
    /// Run the per-pixel consistency test: flag pixels where some frame's vote differs from the
    /// best-exposed frame's by more than [`CONSISTENCY_SIGMAS`] standard deviations of the
    /// noise model (moving clouds, a shifted hand-held frame). Fills
    /// [`Merged::inconsistent`] and its counts.
    #[serde(default)]
    pub consistency: bool,
    /// Ghost-aware merge (implies `consistency`): where frames disagree, instead of a blend of
    /// two scenes, the precision-weighted mean of the frames that agree with the frame most
    /// others agree with (what moved is usually in the minority).
    #[serde(default)]
    pub ghosts: bool,
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
    /// Number of pixels flagged [`CLIPPED_HIGH`] (always counted).
    pub clipped_high: usize,
    /// Number of pixels flagged [`CLIPPED_LOW`] (always counted).
    pub clipped_low: usize,
    /// Number of pixels flagged [`BLACK`]: every channel black in every frame, kept neutral
    /// (always counted).
    pub black_pixels: usize,
    /// The noise model used, when the weighting or the consistency test needed one.
    pub noise: Option<NoiseEstimate>,
    /// Per pixel (row-major): 1 where the frames disagree beyond their noise, else 0. Present
    /// when the consistency test ran.
    pub inconsistent: Option<Vec<u8>>,
    /// Pixels the consistency test flagged.
    pub inconsistent_pixels: usize,
    /// Pixels the consistency test could judge (at least two usable frames in some channel).
    pub tested_pixels: usize,
}

impl Merged {
    /// Fraction of the tested pixels flagged inconsistent (0 when the test did not run).
    pub fn inconsistent_fraction(&self) -> f64 {
        if self.tested_pixels == 0 {
            0.0
        } else {
            self.inconsistent_pixels as f64 / self.tested_pixels as f64
        }
    }

    /// Things the user should know about this merge, one plain sentence each. `area`, when
    /// given, is the part of the image that matters — a fish-eye's image circle (pixel centres
    /// inside it), whose black housing is otherwise counted as black pixels; it needs the
    /// clipped mask ([`MergeOptions::clipped_mask`]) to take effect.
    pub fn warnings(&self, area: Option<&Circle>) -> Vec<String> {
        let mut w = Vec::new();
        let np = self.radiance.width * self.radiance.height;
        let (black, total) = match (area, &self.clipped) {
            (Some(c), Some(m)) if m.len() == np => {
                // Row by row over the circle's span of each row: no per-pixel mask.
                let width = self.radiance.width;
                let (mut black, mut total) = (0usize, 0usize);
                for (y, row) in m.chunks_exact(width.max(1)).enumerate() {
                    let (x0, x1) = c.row_span(y, width);
                    total += x1 - x0;
                    black += row[x0..x1].iter().filter(|&&f| f & BLACK != 0).count();
                }
                (black, total)
            }
            _ => (self.black_pixels, np),
        };
        if total > 0 && black as f64 > BLACK_WARN_FRACTION * total as f64 {
            w.push(format!(
                "{:.2} % of the image ({black} pixels) is black in every frame: its radiance is only an upper bound, shown neutral; add a longer exposure to see into the shadows",
                100.0 * black as f64 / total as f64
            ));
        }
        if let Some(n) = &self.noise {
            if n.from_prior == noise::FromPrior::ALL {
                w.push(
                    "the camera noise model could not be estimated from this bracket (too few pixels well exposed in two frames): a typical phone sensor was assumed for the weights".into(),
                );
            } else if !n.fitted {
                w.push(format!(
                    "the bracket does not show the camera's {} (the fit ended at a bound): a typical phone sensor's value was assumed for the weights",
                    n.from_prior.names()
                ));
            }
        }
        if self.inconsistent.is_some() && self.inconsistent_fraction() > INCONSISTENT_WARN_FRACTION
        {
            w.push(format!(
                "{:.1} % of the pixels differ between frames beyond their noise (moving clouds or people, or a hand-held camera): align the frames or use the ghost-aware merge",
                100.0 * self.inconsistent_fraction()
            ));
        }
        w
    }
}

/// Merges `frames` (sorted shortest exposure first, same size and bit depth) through `response`.
pub fn merge(
    frames: &[Frame],
    response: &Response,
    opts: &MergeOptions,
) -> Result<Merged, MergeError> {
    let mut m = merge_empty();
    merge_into(frames, response, opts, &mut m)?;
    Ok(m)
}

/// Bands of rows [`merge_releasing`] merges before giving their frame rows back.
const RELEASE_BANDS: usize = 8;

/// As [`merge`] for a caller that no longer needs the frames' pixels (the pipeline, after
/// calibration): the rows are merged from the bottom up in [`RELEASE_BANDS`] bands, and after
/// each band the frames' rows below it are given back, so the frames and the radiance are never
/// both whole in memory — 9 × 12 MP peaks at about the frames' size (324 MB) instead of frames
/// plus radiance (468 MB). Afterwards every frame's pixel buffer is empty (its size, name and
/// exposure are kept). The consistency test reads every frame again after the merge, so with it
/// the frames are merged whole and emptied at the end.
pub fn merge_releasing(
    frames: &mut [Frame],
    response: &Response,
    opts: &MergeOptions,
) -> Result<Merged, MergeError> {
    let mut m = merge_empty();
    merge_impl(Source::Releasing(frames), response, opts, &mut m)?;
    for f in frames.iter_mut() {
        f.pixels.release_from(0);
    }
    Ok(m)
}

/// The frames a merge reads: shared, or owned by a caller that lets the merge give their rows
/// back as it goes ([`merge_releasing`]).
enum Source<'a> {
    Shared(&'a [Frame]),
    Releasing(&'a mut [Frame]),
}

impl Source<'_> {
    fn frames(&self) -> &[Frame] {
        match self {
            Source::Shared(f) => f,
            Source::Releasing(f) => f,
        }
    }
}

/// An empty [`Merged`] for [`merge_into`] to fill.
fn merge_empty() -> Merged {
    Merged {
        radiance: HdrImage {
            width: 0,
            height: 0,
            data: Vec::new(),
        },
        confidence: None,
        clipped: None,
        clipped_high: 0,
        clipped_low: 0,
        black_pixels: 0,
        noise: None,
        inconsistent: None,
        inconsistent_pixels: 0,
        tested_pixels: 0,
    }
}

/// As [`merge`], into `out`, reusing its buffers: when the size is unchanged nothing is
/// allocated, which spares a 6 MP merge the page faults of a fresh 72 MB output (for a
/// preview or video loop, or a phone app merging bracket after bracket). On error `out` is
/// left unchanged.
pub fn merge_into(
    frames: &[Frame],
    response: &Response,
    opts: &MergeOptions,
    out: &mut Merged,
) -> Result<(), MergeError> {
    merge_impl(Source::Shared(frames), response, opts, out)
}

/// Checks the frames, estimates the noise when the weighting or the consistency test needs it,
/// and merges at the frames' bit depth ([`merge_codes`]).
fn merge_impl(
    source: Source<'_>,
    response: &Response,
    opts: &MergeOptions,
    out: &mut Merged,
) -> Result<(), MergeError> {
    let frames = source.frames();
    let lt = log_exposures(frames)?;
    let noise_est = noise_estimate(frames, response, opts);
    match frames[0].pixels.bit_depth() {
        16 => merge_codes::<u16, 65536>(source, response, opts, &lt, noise_est, out),
        _ => merge_codes::<u8, LEVELS>(source, response, opts, &lt, noise_est, out),
    }
    Ok(())
}

/// `ln Δt_j` of every frame, after checking that the frames share one size and bit depth and
/// that their relative exposures are finite, positive and increasing.
fn log_exposures(frames: &[Frame]) -> Result<Vec<f64>, MergeError> {
    let first = frames.first().ok_or(MergeError::NoFrames)?;
    let (w, h, bits) = (first.width, first.height, first.pixels.bit_depth());
    let n = samples(w, h);
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
    Ok(lt)
}

/// Samples of a `w` × `h` RGB image (`usize::MAX` when that overflows, which no frame matches).
fn samples(w: usize, h: usize) -> usize {
    w.checked_mul(h)
        .and_then(|v| v.checked_mul(3))
        .unwrap_or(usize::MAX)
}

/// The noise model, when the noise-aware merge or the consistency test needs one: the caller's
/// when valid, else estimated from the frames.
fn noise_estimate(
    frames: &[Frame],
    response: &Response,
    opts: &MergeOptions,
) -> Option<NoiseEstimate> {
    let check = opts.consistency || opts.ghosts;
    (opts.weighting == Weighting::Noise || check).then(|| match opts.noise {
        Some(model) if model.is_valid() => NoiseEstimate::given(model),
        _ => noise::estimate(frames, response, opts.black_level, None),
    })
}

/// The noise-aware merge's refinement of each row after the hat pass: the vector kernel
/// ([`fused::Fused`], where the CPU has one and the input is 8-bit) takes whole steps of eight
/// pixels, the scalar [`Refine`] the rest, with the same bits.
struct Refinement<const N: usize> {
    /// The scalar refinement, whose tables the kernel copies.
    scalar: Refine<N>,
    /// The vector kernel, built from `scalar` and the hat's tables.
    fused: Option<fused::Fused>,
}

/// The merge of frames whose samples are of type `T` (`N` codes): the hat merge, then the
/// noise-model refinement and the consistency test when asked for.
fn merge_codes<T: Code, const N: usize>(
    mut source: Source<'_>,
    response: &Response,
    opts: &MergeOptions,
    lt: &[f64],
    noise_est: Option<NoiseEstimate>,
    out: &mut Merged,
) {
    let frames = source.frames();
    let (w, h, p) = (frames[0].width, frames[0].height, frames.len());
    let check = opts.consistency || opts.ghosts;
    // The noise-aware merge starts from the hat's estimate and refines it (see [`Refine`]).
    let first_pass = match opts.weighting {
        Weighting::Noise => Weighting::Hat,
        other => other,
    };
    let g = |c: usize, v: usize| T::g(response, c, v);
    let luts = Tables::<N>::new(lt, |j, _c, z| weight(z, j, p, first_pass), g);
    let black = T::black(opts.black_level);
    // The noise-aware merge refines each row right after the hat has merged it (one pass).
    let refine = match (opts.weighting, &noise_est) {
        (Weighting::Noise, Some(e)) => {
            let scalar = Refine::<N>::new(lt, response, &e.model, opts.black_level, g);
            let fused = fused::Fused::new(&scalar, |j, c, z| luts.entry(j, c, z));
            Some(Refinement { scalar, fused })
        }
        _ => None,
    };
    let (data, conf, clip) = outputs(out, opts, w, h);
    // Without the consistency test, which reads every frame again, the rows can be given back
    // as they are merged.
    if let (Source::Releasing(frames), false) = (&mut source, check) {
        let counts = run_releasing(frames, &luts, refine.as_ref(), w, black, data, conf, clip);
        finish(out, counts, noise_est, 0, 0, None);
        return;
    }
    let srcs: Vec<&[T]> = source
        .frames()
        .iter()
        .filter_map(|f| T::samples(&f.pixels))
        .collect();
    let counts = run_bands(&srcs, &luts, refine.as_ref(), w, black, data, conf, clip);
    let mut flags = if check { vec![0u8; w * h] } else { Vec::new() };
    let (tested, flagged) = match &noise_est {
        Some(e) if check => {
            let upper = e.model.upper_bound();
            let votes = Votes::<N>::new(lt, response, &upper, opts.black_level, g);
            consistency(&srcs, &votes, w, data, &mut flags, opts.ghosts)
        }
        _ => (0, 0),
    };
    finish(
        out,
        counts,
        noise_est,
        tested,
        flagged,
        check.then_some(flags),
    );
}

/// `out`'s radiance, confidence and clipped-mask buffers sized for a `w` × `h` merge (the last
/// two empty, and dropped from `out`, when not asked for).
fn outputs<'a>(
    out: &'a mut Merged,
    opts: &MergeOptions,
    w: usize,
    h: usize,
) -> (&'a mut [f32], &'a mut [f32], &'a mut [u8]) {
    out.radiance.width = w;
    out.radiance.height = h;
    let data = sized(&mut out.radiance.data, samples(w, h));
    let conf = match (opts.confidence, &mut out.confidence) {
        (true, Some(c)) => sized(c, w * h),
        (true, c @ None) => sized(c.insert(Vec::new()), w * h),
        (false, c) => {
            *c = None;
            &mut []
        }
    };
    let clip = match (opts.clipped_mask, &mut out.clipped) {
        (true, Some(c)) => sized(c, w * h),
        (true, c @ None) => sized(c.insert(Vec::new()), w * h),
        (false, c) => {
            *c = None;
            &mut []
        }
    };
    (data, conf, clip)
}

/// Stores the merge's counts and the consistency test's results in `out`.
fn finish(
    out: &mut Merged,
    counts: (usize, usize, usize),
    noise: Option<NoiseEstimate>,
    tested: usize,
    flagged: usize,
    flags: Option<Vec<u8>>,
) {
    (out.clipped_high, out.clipped_low, out.black_pixels) = counts;
    out.noise = noise;
    out.tested_pixels = tested;
    out.inconsistent_pixels = flagged;
    out.inconsistent = flags;
}

/// One `[f32; 2]` per frame, channel and code of an `N`-level input, frame-major then channel:
/// `entry(j, c, code, vote)` with frame `j`'s vote `log2 E_j = (g(c, code) − ln Δt_j) · log2 e`.
/// The layout [`Tables`], [`Refine`] and [`Votes`] share.
fn code_tables<const N: usize>(
    lt: &[f64],
    g: impl Fn(usize, usize) -> f64,
    entry: impl Fn(usize, usize, usize, f32) -> [f32; 2],
) -> Vec<[f32; 2]> {
    let mut flat = Vec::with_capacity(lt.len() * 3 * N);
    for (j, &l) in lt.iter().enumerate() {
        for c in 0..3 {
            flat.extend(
                (0..N).map(|v| entry(j, c, v, ((g(c, v) - l) * std::f64::consts::LOG2_E) as f32)),
            );
        }
    }
    flat
}

/// `v` with exactly `n` elements, for the merge to overwrite. A buffer of another size is
/// replaced by a fresh zeroed allocation (which the OS provides lazily) rather than resized,
/// so no pass writes zeros the merge would overwrite anyway.
fn sized<T: Copy + Default>(v: &mut Vec<T>, n: usize) -> &mut [T] {
    if v.len() != n {
        *v = vec![T::default(); n];
    }
    v
}

/// An input sample type: its table index and the code of a clipped (saturated) sample.
trait Code: Copy + Sync + PartialOrd {
    /// Highest code (`2^bits − 1`).
    const MAX: Self;
    /// The hat weight in this type's units, [`HAT_PEAK`](Code::HAT_PEAK) at mid-grey.
    const HAT_PEAK: u32;
    /// Table index.
    fn index(self) -> usize;
    /// The hat `min(v, MAX − v)` in this type's units (`257 ×` the 8-bit hat for 16-bit input).
    fn hat_units(self) -> u32;
    /// The samples of `p` when they are of this type.
    fn samples(p: &Pixels) -> Option<&[Self]>;
    /// `g` (natural log) of channel `c` at code `v` of this type.
    fn g(response: &Response, c: usize, v: usize) -> f64;
    /// The black level, given as an 8-bit code, in this type's units: the highest value that
    /// bins to an 8-bit code at or below it.
    fn black(level: u8) -> Self;
    /// Merges what the noise-aware merge's vector kernel can of one row (see
    /// [`fused::Fused::row`]); returns how many samples that was, from the row's start.
    fn fused_row<const N: usize>(rows: &[&[Self]], r: &Refinement<N>, out: &mut [f32]) -> usize;
}

impl Code for u8 {
    const MAX: u8 = u8::MAX;
    const HAT_PEAK: u32 = 127;
    #[inline(always)]
    fn index(self) -> usize {
        self as usize
    }
    #[inline(always)]
    fn hat_units(self) -> u32 {
        self.min(u8::MAX - self) as u32
    }
    fn samples(p: &Pixels) -> Option<&[Self]> {
        match p {
            Pixels::U8(v) => Some(v),
            Pixels::U16(_) => None,
        }
    }
    #[inline(always)]
    fn g(response: &Response, c: usize, v: usize) -> f64 {
        response.curve(c)[v]
    }
    fn black(level: u8) -> Self {
        level
    }
    fn fused_row<const N: usize>(rows: &[&[Self]], r: &Refinement<N>, out: &mut [f32]) -> usize {
        r.fused.as_ref().map_or(0, |f| f.row(rows, out))
    }
}

impl Code for u16 {
    const MAX: u16 = u16::MAX;
    const HAT_PEAK: u32 = 127 * 257;
    #[inline(always)]
    fn index(self) -> usize {
        self as usize
    }
    #[inline(always)]
    fn hat_units(self) -> u32 {
        self.min(u16::MAX - self) as u32
    }
    fn samples(p: &Pixels) -> Option<&[Self]> {
        match p {
            Pixels::U16(v) => Some(v),
            Pixels::U8(_) => None,
        }
    }
    #[inline(always)]
    fn g(response: &Response, c: usize, v: usize) -> f64 {
        response.g16(c, v as u16)
    }
    fn black(level: u8) -> Self {
        // A 16-bit value bins to an 8-bit code ≤ b below `257·b + 128`; code 0 means exactly 0.
        match level {
            0 => 0,
            b => (b as u32 * 257 + 128).min(65535) as u16,
        }
    }
    fn fused_row<const N: usize>(_: &[&[Self]], _: &Refinement<N>, _: &mut [f32]) -> usize {
        // The kernel is for 8-bit codes (its tables would not stay in cache at 16 bits).
        0
    }
}

/// `2^x` in f32, branch-free (see [`crate::fastmath::exp2`]: relative error below 3·10⁻⁷).
pub use crate::fastmath::exp2 as fast_exp2;

#[cfg(test)]
mod tests {
    use super::*;

    /// The merge's definition, evaluated per sample in f64 with no tables.
    fn reference(frames: &[Frame], r: &Response, weighting: Weighting) -> Vec<f64> {
        let p = frames.len();
        let n = frames[0].pixels.len();
        (0..n)
            .map(|i| {
                let c = i % 3;
                let (mut num, mut den) = (0f64, 0f64);
                for (j, f) in frames.iter().enumerate() {
                    let (z, g) = match &f.pixels {
                        Pixels::U8(v) => (v[i] as f64, r.curve(c)[v[i] as usize]),
                        Pixels::U16(v) => (v[i] as f64 / 257.0, r.g16(c, v[i])),
                    };
                    let w = match weighting {
                        Weighting::None => 1.0,
                        Weighting::Hat | Weighting::Noise => {
                            let mut w = z.min(255.0 - z).max(0.0);
                            if (j == 0 && z >= 127.5) || (j + 1 == p && z <= 127.5) {
                                w = 127.0;
                            }
                            if j == 0 {
                                w = w.max(1e-6);
                            }
                            w
                        }
                    };
                    num += w * (g - f.exposure.relative().ln());
                    den += w;
                }
                (num / den).exp()
            })
            .collect::<Vec<f64>>()
            .chunks(3)
            .enumerate()
            .flat_map(|(k, v)| {
                // Every channel 0 in every frame: neutral at the smallest channel.
                let black = frames.iter().all(|f| match &f.pixels {
                    Pixels::U8(p) => p[3 * k..3 * k + 3].iter().all(|&z| z == 0),
                    Pixels::U16(p) => p[3 * k..3 * k + 3].iter().all(|&z| z == 0),
                });
                let m = v.iter().copied().fold(f64::INFINITY, f64::min);
                if black {
                    vec![m; 3]
                } else {
                    v.to_vec()
                }
            })
            .collect()
    }

    fn frames(p: usize, sixteen: bool, w: usize, h: usize) -> Vec<Frame> {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        (0..p)
            .map(|j| {
                let n = w * h * 3;
                // Mostly random codes, with runs of the extreme codes to exercise clipping.
                let pixels = if sixteen {
                    Pixels::U16(
                        (0..n)
                            .map(|_| match next() % 8 {
                                0 => 0,
                                1 => u16::MAX,
                                _ => next() as u16,
                            })
                            .collect(),
                    )
                } else {
                    Pixels::U8(
                        (0..n)
                            .map(|_| match next() % 8 {
                                0 => 0,
                                1 => u8::MAX,
                                _ => next() as u8,
                            })
                            .collect(),
                    )
                };
                Frame {
                    name: format!("f{j}"),
                    width: w,
                    height: h,
                    pixels,
                    exposure: crate::bracket::Exposure {
                        time_s: 2f64.powi(2 * j as i32) / 100.0,
                        iso: None,
                        f_number: None,
                    },
                }
            })
            .collect()
    }

    #[test]
    fn tables_and_groups_match_the_definition_for_1_to_7_frames() {
        let r = Response::from_curves([0.9, 1.0, 1.1].map(|a| {
            (0..LEVELS)
                .map(|z| a * ((z as f64 + 0.5) / 128.5).ln())
                .collect::<Vec<_>>()
        }))
        .unwrap();
        for sixteen in [false, true] {
            for p in 1..=7 {
                for weighting in [Weighting::Hat, Weighting::None] {
                    // 37 rows: more than two bands, the last one short.
                    let fs = frames(p, sixteen, 29, 37);
                    let m = merge(
                        &fs,
                        &r,
                        &MergeOptions {
                            weighting,
                            confidence: true,
                            clipped_mask: true,
                            ..Default::default()
                        },
                    )
                    .unwrap();
                    let want = reference(&fs, &r, weighting);
                    let worst = m
                        .radiance
                        .data
                        .iter()
                        .zip(&want)
                        .map(|(&a, &b)| ((a as f64 - b) / b).abs())
                        .fold(0f64, f64::max);
                    assert!(
                        worst < 2e-5,
                        "{p} frames, 16-bit {sixteen}, {weighting:?}: worst {worst}"
                    );
                    let clip = m.clipped.as_ref().unwrap();
                    let high = clip.iter().filter(|&&c| c & CLIPPED_HIGH != 0).count();
                    let low = clip.iter().filter(|&&c| c & CLIPPED_LOW != 0).count();
                    assert_eq!((m.clipped_high, m.clipped_low), (high, low));
                    let conf = m.confidence.as_ref().unwrap();
                    for (k, (&f, &c)) in clip.iter().zip(conf).enumerate() {
                        assert_eq!(f != 0, c == 0.0, "pixel {k}: flag {f}, confidence {c}");
                        let want = (0..3)
                            .map(|ch| {
                                let sum: f64 = fs
                                    .iter()
                                    .map(|f| match &f.pixels {
                                        Pixels::U8(v) => crate::response::hat(v[3 * k + ch]),
                                        Pixels::U16(v) => {
                                            crate::response::hat_f(v[3 * k + ch] as f64 / 257.0)
                                        }
                                    })
                                    .sum();
                                (sum / 127.0).min(1.0)
                            })
                            .fold(1.0, f64::min);
                        assert!((c as f64 - want).abs() < 1e-6, "pixel {k}: {c} vs {want}");
                    }
                    if p == 1 {
                        assert!(high > 0 && low > 0, "{high} {low}");
                    }
                }
            }
        }
    }
}
