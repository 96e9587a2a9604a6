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

use crate::bracket::{Frame, Pixels};
use crate::image::{Circle, HdrImage};
use crate::noise::{self, NoiseEstimate, NoiseModel};
pub use crate::response::Weighting;
use crate::response::{Response, LEVELS};

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
/// Peak of the 8-bit hat: the full weight.
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
            if !n.fitted {
                w.push(
                    "the camera noise model could not be estimated from this bracket (too few pixels well exposed in two frames): a typical phone sensor was assumed for the weights".into(),
                );
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
/// exposure are kept). The noise-aware merge and the consistency test need every frame after
/// the first pass, so with them the frames are merged whole and emptied at the end.
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

fn merge_impl(
    mut source: Source<'_>,
    response: &Response,
    opts: &MergeOptions,
    out: &mut Merged,
) -> Result<(), MergeError> {
    let frames = source.frames();
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
    let check = opts.consistency || opts.ghosts;
    let noise_est = (opts.weighting == Weighting::Noise || check).then(|| match opts.noise {
        Some(model) if model.is_valid() => NoiseEstimate {
            model,
            differences: 0,
            bins: 0,
            fitted: true,
        },
        _ => noise::estimate(frames, response, opts.black_level, None),
    });
    let p = frames.len();
    // The noise-aware merge starts from the hat's estimate and refines it (see [`Refine`]).
    let first_pass = match opts.weighting {
        Weighting::Noise => Weighting::Hat,
        other => other,
    };
    let wfn = |j: usize, _c: usize, z: f32| weight(z, j, p, first_pass);
    out.radiance.width = w;
    out.radiance.height = h;
    let data = sized(&mut out.radiance.data, n);
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
    let mut flags = if check { vec![0u8; w * h] } else { Vec::new() };
    // A 16-bit value bins to an 8-bit code ≤ b below `257·b + 128`; code 0 means exactly 0.
    let black16 = match opts.black_level {
        0 => 0,
        b => (b as u32 * 257 + 128).min(65535) as u16,
    };
    let (counts, tested, flagged) = match bits {
        16 => {
            let g = |c: usize, v: usize| response.g16(c, v as u16);
            let luts = Tables::<65536>::new(&lt, wfn, g);
            // Without a second pass the rows can be given back as they are merged.
            if let (Source::Releasing(frames), None) = (&mut source, &noise_est) {
                let counts = run_releasing(frames, &luts, w, black16, data, conf, clip);
                finish(out, counts, None, 0, 0, None);
                return Ok(());
            }
            let srcs: Vec<&[u16]> = source
                .frames()
                .iter()
                .filter_map(|f| match &f.pixels {
                    Pixels::U16(v) => Some(v.as_slice()),
                    Pixels::U8(_) => None,
                })
                .collect();
            let counts = run_bands(&srcs, &luts, w, black16, data, conf, clip);
            if let (Weighting::Noise, Some(e)) = (opts.weighting, &noise_est) {
                let r = Refine::<65536>::new(&lt, response, &e.model, opts.black_level, g);
                refine(&srcs, &r, w, data);
            }
            let (t, f) = match &noise_est {
                Some(e) if check => {
                    let votes = Votes::<65536>::new(
                        &lt,
                        response,
                        &e.model.upper_bound(),
                        opts.black_level,
                        g,
                    );
                    consistency(&srcs, &votes, w, data, &mut flags, opts.ghosts)
                }
                _ => (0, 0),
            };
            (counts, t, f)
        }
        _ => {
            let g = |c: usize, z: usize| response.curve(c)[z];
            let luts = Tables::<LEVELS>::new(&lt, wfn, g);
            // Without a second pass the rows can be given back as they are merged.
            if let (Source::Releasing(frames), None) = (&mut source, &noise_est) {
                let counts = run_releasing(frames, &luts, w, opts.black_level, data, conf, clip);
                finish(out, counts, None, 0, 0, None);
                return Ok(());
            }
            let srcs: Vec<&[u8]> = source
                .frames()
                .iter()
                .filter_map(|f| match &f.pixels {
                    Pixels::U8(v) => Some(v.as_slice()),
                    Pixels::U16(_) => None,
                })
                .collect();
            let counts = run_bands(&srcs, &luts, w, opts.black_level, data, conf, clip);
            if let (Weighting::Noise, Some(e)) = (opts.weighting, &noise_est) {
                let r = Refine::<LEVELS>::new(&lt, response, &e.model, opts.black_level, g);
                refine(&srcs, &r, w, data);
            }
            let (t, f) = match &noise_est {
                Some(e) if check => {
                    let votes = Votes::<LEVELS>::new(
                        &lt,
                        response,
                        &e.model.upper_bound(),
                        opts.black_level,
                        g,
                    );
                    consistency(&srcs, &votes, w, data, &mut flags, opts.ghosts)
                }
                _ => (0, 0),
            };
            (counts, t, f)
        }
    };
    finish(
        out,
        counts,
        noise_est,
        tested,
        flagged,
        check.then_some(flags),
    );
    Ok(())
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

/// Bins per stop of the expected-code weight tables of [`Refine`].
const EXPECTED_BINS_PER_STOP: f32 = 32.0;

/// The second pass of the noise-aware merge ([`Weighting::Noise`]).
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
struct Refine<const N: usize> {
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

    fn new(
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
fn refine<T: Code, const N: usize>(srcs: &[&[T]], r: &Refine<N>, w: usize, out: &mut [f32]) {
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

/// Per frame, channel and code: the vote `log2 E_j` and its standard deviation in stops
/// (infinite where the code is unusable: black, 255, or faded out), for the consistency test.
struct Votes<const N: usize> {
    /// Frame-major, then channel, then code: `[vote, sd]`.
    flat: Vec<[f32; 2]>,
}

impl<const N: usize> Votes<N> {
    fn new(
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
fn consistency<T: Code, const N: usize>(
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
const LOWER_BOUND_CODE: usize = 250;

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

/// `v` with exactly `n` elements, for the merge to overwrite. A buffer of another size is
/// replaced by a fresh zeroed allocation (which the OS provides lazily) rather than resized,
/// so no pass writes zeros the merge would overwrite anyway.
fn sized<T: Copy + Default>(v: &mut Vec<T>, n: usize) -> &mut [T] {
    if v.len() != n {
        *v = vec![T::default(); n];
    }
    v
}

#[inline]
fn hat_f(z: f32) -> f32 {
    z.min(255.0 - z).max(0.0)
}

/// Weight of code `z` (continuous 0..=255) in frame `j` of `p` for the given weighting.
fn weight(z: f32, j: usize, p: usize, weighting: Weighting) -> f32 {
    match weighting {
        Weighting::None => 1.0,
        // Without a noise model (never reached from `merge_into`, which builds one) the hat.
        Weighting::Hat | Weighting::Noise => {
            let mut w = hat_f(z);
            if j == 0 && z >= 127.5 {
                w = W_MAX;
            }
            if j + 1 == p && z <= 127.5 {
                w = W_MAX;
            }
            if j == 0 {
                w = w.max(W_FLOOR);
            }
            w
        }
    }
}

/// The look-up tables of every frame and channel: per code, `(w, w · log2 E_j)` with
/// `log2 E_j = (g − ln Δt_j) · log2 e`. Working in base 2 lets the merge end with `2^x`, the
/// cheapest exponential. One flat allocation, frame-major then channel, so a group of frames'
/// tables is one fixed-size array (one base register in the inner loop, no bounds checks).
struct Tables<const N: usize> {
    flat: Vec<[f32; 2]>,
}

impl<const N: usize> Tables<N> {
    /// `g(c, code)` gives `g` (natural log) for a code of an `N`-level input and
    /// `weight(j, c, z)` the weight of frame `j`, channel `c` at the continuous 8-bit code `z`;
    /// codes map to the 8-bit scale as `code · 255 / (N − 1)`.
    fn new(
        lt: &[f64],
        weight: impl Fn(usize, usize, f32) -> f32,
        g: impl Fn(usize, usize) -> f64,
    ) -> Self {
        let scale = 255.0 / (N - 1) as f32;
        let flat = code_tables::<N>(lt, g, |j, c, v, vote| {
            let w = weight(j, c, v as f32 * scale);
            [w, w * vote]
        });
        Self { flat }
    }

    /// The tables of frames `j0 .. j0 + G`, per channel.
    #[inline(always)]
    fn group<const G: usize>(&self, j0: usize) -> &[[[[f32; 2]; N]; 3]; G] {
        let (channels, _) = self.flat.as_chunks::<N>();
        let (frames, _) = channels.as_chunks::<3>();
        match frames[j0..j0 + G].try_into() {
            Ok(t) => t,
            Err(_) => unreachable!("a slice of G frames"),
        }
    }
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
}

/// One band of work: offset of its first sample, its output, confidence and mask slices.
type Band<'a> = (usize, &'a mut [f32], &'a mut [f32], &'a mut [u8]);

/// Merges all bands (in parallel with the `parallel` feature); returns the clipped-high,
/// clipped-low and black pixel counts. `conf` and `clip` are empty when not asked for; a code
/// at or below `black` counts as black.
fn run_bands<T: Code, const N: usize>(
    srcs: &[&[T]],
    luts: &Tables<N>,
    w: usize,
    black: T,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
) -> (usize, usize, usize) {
    let band = ROWS_PER_BAND * 3 * w;
    let pband = ROWS_PER_BAND * w;
    let bands = out.len().div_ceil(band.max(1));
    let mut conf_chunks = conf.chunks_mut(pband.max(1));
    let mut clip_chunks = clip.chunks_mut(pband.max(1));
    let jobs: Vec<Band<'_>> = out
        .chunks_mut(band.max(1))
        .enumerate()
        .map(|(k, o)| {
            (
                k * band,
                o,
                conf_chunks.next().unwrap_or_default(),
                clip_chunks.next().unwrap_or_default(),
            )
        })
        .collect();
    debug_assert_eq!(jobs.len(), bands);
    let work = |(off, o, c, m): Band<'_>| merge_band(srcs, luts, w, black, off, o, c, m);
    let add =
        |a: (usize, usize, usize), b: (usize, usize, usize)| (a.0 + b.0, a.1 + b.1, a.2 + b.2);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        jobs.into_par_iter().map(work).reduce(|| (0, 0, 0), add)
    }
    #[cfg(not(feature = "parallel"))]
    jobs.into_iter().map(work).fold((0, 0, 0), add)
}

/// [`run_bands`] over [`RELEASE_BANDS`] bands of rows from the bottom up, giving each band's
/// frame rows back once it is merged (see [`merge_releasing`]).
fn run_releasing<T: Code, const N: usize>(
    frames: &mut [Frame],
    luts: &Tables<N>,
    w: usize,
    black: T,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
) -> (usize, usize, usize) {
    let h = out.len() / (3 * w).max(1);
    let rows = h.div_ceil(RELEASE_BANDS).max(1);
    let mut total = (0, 0, 0);
    for b in (0..h.div_ceil(rows)).rev() {
        let (r0, r1) = (b * rows, ((b + 1) * rows).min(h));
        let (s0, s1) = (3 * r0 * w, 3 * r1 * w);
        let srcs: Vec<&[T]> = frames
            .iter()
            .filter_map(|f| T::samples(&f.pixels))
            .map(|v| &v[s0..s1])
            .collect();
        let (cr, mr) = (
            band_of(conf.len(), r0 * w, r1 * w),
            band_of(clip.len(), r0 * w, r1 * w),
        );
        let c = run_bands(
            &srcs,
            luts,
            w,
            black,
            &mut out[s0..s1],
            &mut conf[cr],
            &mut clip[mr],
        );
        total = (total.0 + c.0, total.1 + c.1, total.2 + c.2);
        for f in frames.iter_mut() {
            f.pixels.release_from(s0);
        }
    }
    total
}

/// The range `a..b` of an optional per-pixel output (`0..0` when it was not asked for).
fn band_of(len: usize, a: usize, b: usize) -> std::ops::Range<usize> {
    if len == 0 {
        0..0
    } else {
        a..b
    }
}

/// How a group of frames contributes to a row: the only group writes the mean
/// (`num ← Σ w · log2 E_j / Σ w`); with several groups the first writes the sums to `num` and
/// `den`, later ones add to them and [`finish_row`] divides.
const ONLY: u8 = 0;
const FIRST: u8 = 1;
const LATER: u8 = 2;

/// Adds the votes of `G` frames (`srcs`, one row each, and their tables per channel) to one
/// row per `MODE`: the mean itself for the only group, else the sums `num` (`Σ w · log2 E_j`)
/// and `den` (`Σ w`). The frames are taken a few at a time so each sample's sums stay in
/// registers; the tables are fixed-size so look-ups need no bounds checks; samples go in
/// blocks of four pixels so the division vectorises.
#[inline(always)]
fn accumulate<T: Code, const N: usize, const G: usize, const MODE: u8>(
    srcs: [&[T]; G],
    luts: &[[[[f32; 2]; N]; 3]; G],
    num: &mut [f32],
    den: &mut [f32],
) {
    // Blocks of four pixels, so the compiler can divide four samples at once.
    const B: usize = 12;
    let n = num.len();
    let (nb, ntail) = num.as_chunks_mut::<B>();
    let blocks = nb.len();
    // `den` is unused (and may be empty) for the only group.
    let den = &mut den[..if MODE == ONLY { 0 } else { n }];
    let (db, dtail) = den.as_chunks_mut::<B>();
    let db = &mut db[..if MODE == ONLY { 0 } else { blocks }];
    let sb: [&[[T; B]]; G] = srcs.map(|s| &s[..n].as_chunks::<B>().0[..blocks]);
    for i in 0..blocks {
        let (mut nv, mut dv) = ([0f32; B], [0f32; B]);
        for k in 0..B {
            let c = k % 3;
            [dv[k], nv[k]] = luts[0][c][sb[0][i][k].index()];
            for g in 1..G {
                let e = luts[g][c][sb[g][i][k].index()];
                dv[k] += e[0];
                nv[k] += e[1];
            }
        }
        match MODE {
            ONLY => {
                for k in 0..B {
                    nb[i][k] = nv[k] / dv[k];
                }
            }
            FIRST => {
                nb[i] = nv;
                db[i] = dv;
            }
            _ => {
                for k in 0..B {
                    nb[i][k] += nv[k];
                    db[i][k] += dv[k];
                }
            }
        }
    }
    // The last few pixels of the row.
    let t0 = blocks * B;
    for (k, o) in ntail.iter_mut().enumerate() {
        let c = k % 3;
        let [mut d, mut v] = luts[0][c][srcs[0][t0 + k].index()];
        for g in 1..G {
            let e = luts[g][c][srcs[g][t0 + k].index()];
            d += e[0];
            v += e[1];
        }
        match MODE {
            ONLY => *o = v / d,
            FIRST => {
                *o = v;
                dtail[k] = d;
            }
            _ => {
                *o += v;
                dtail[k] += d;
            }
        }
    }
}

/// `num ← 2^(num / den)`: the log2 radiance's weighted mean, exponentiated; with an empty
/// `den` `num` already holds the mean.
#[inline(always)]
fn finish_row(num: &mut [f32], den: &[f32]) {
    if den.is_empty() {
        for o in num.iter_mut() {
            *o = fast_exp2(*o);
        }
    } else {
        for (o, &d) in num.iter_mut().zip(den) {
            *o = fast_exp2(*o / d);
        }
    }
}

/// Dispatches the group of frames `j0 .. j0 + srcs.len()` (one to three) to [`accumulate`].
#[inline(always)]
fn accumulate_group<T: Code, const N: usize, const MODE: u8>(
    srcs: &[&[T]],
    luts: &Tables<N>,
    j0: usize,
    num: &mut [f32],
    den: &mut [f32],
) {
    match *srcs {
        [a] => accumulate::<T, N, 1, MODE>([a], luts.group(j0), num, den),
        [a, b] => accumulate::<T, N, 2, MODE>([a, b], luts.group(j0), num, den),
        [a, b, c] => accumulate::<T, N, 3, MODE>([a, b, c], luts.group(j0), num, den),
        _ => unreachable!("groups hold one to three frames"),
    }
}

#[allow(clippy::too_many_arguments)]
fn merge_band<T: Code, const N: usize>(
    srcs: &[&[T]],
    luts: &Tables<N>,
    w: usize,
    black: T,
    off: usize,
    out: &mut [f32],
    conf: &mut [f32],
    clip: &mut [u8],
) -> (usize, usize, usize) {
    const GROUP: usize = 3;
    let row = 3 * w;
    let mut den = vec![0f32; if srcs.len() > GROUP { row } else { 0 }];
    let mut hs = vec![0u32; if conf.is_empty() { 0 } else { row }];
    let mut ext = vec![0u8; row];
    let mut rows: Vec<&[T]> = Vec::with_capacity(srcs.len());
    let (mut high, mut low, mut blk) = (0usize, 0usize, 0usize);
    for (r, orow) in out.chunks_mut(row).enumerate() {
        let start = off + r * row;
        rows.clear();
        rows.extend(srcs.iter().map(|s| &s[start..start + row]));
        if rows.len() <= GROUP {
            accumulate_group::<T, N, ONLY>(&rows, luts, 0, orow, &mut []);
        } else {
            for (k, fs) in rows.chunks(GROUP).enumerate() {
                if k == 0 {
                    accumulate_group::<T, N, FIRST>(fs, luts, 0, orow, &mut den);
                } else {
                    accumulate_group::<T, N, LATER>(fs, luts, k * GROUP, orow, &mut den);
                }
            }
        }
        finish_row(orow, &den);

        // Clipped pixels: some channel is black or full scale in every frame. Branch-free byte
        // passes over the row that vectorise: `ext` gets each sample's flag (CLIPPED_HIGH when
        // the shortest frame is saturated, else CLIPPED_LOW), then the flags are ORed per
        // pixel where there are any (fish-eye frames have black corners in most rows).
        for (e, &z0) in ext.iter_mut().zip(rows[0].iter()) {
            let extreme = (z0 <= black || z0 == T::MAX) as u8;
            *e = extreme * (CLIPPED_LOW - (z0 == T::MAX) as u8);
        }
        for s in &rows[1..] {
            for (e, &z) in ext.iter_mut().zip(s.iter()) {
                *e *= (z <= black || z == T::MAX) as u8;
            }
        }
        let prow = r * w;
        let mask = if clip.is_empty() {
            None
        } else {
            Some(&mut clip[prow..prow + w])
        };
        let (h, l, b) = pixel_flags(&ext, mask, orow);
        high += h;
        low += l;
        blk += b;

        if !conf.is_empty() {
            // Integer hat sums (`min(v, max − v)`, exact and vectorisable), then per pixel the
            // least-supported channel as a fraction of the peak weight.
            hs.fill(0);
            for s in &rows {
                for (h, &v) in hs.iter_mut().zip(s.iter()) {
                    *h += v.hat_units();
                }
            }
            for (c, hh) in conf[prow..prow + w].iter_mut().zip(hs.chunks_exact(3)) {
                *c = hh[0].min(hh[1]).min(hh[2]).min(T::HAT_PEAK) as f32 / T::HAT_PEAK as f32;
            }
        }
    }
    (high, low, blk)
}

/// ORs a row's per-sample clip flags (`ext`, 3 per pixel) per pixel into `mask` (when given),
/// and makes pixels black in every channel neutral in `out` (see [`BLACK`]); returns the number
/// of pixels flagged high, low and black. Runs of 16 pixels without a flag are skipped with one
/// vectorised test.
fn pixel_flags(ext: &[u8], mut mask: Option<&mut [u8]>, out: &mut [f32]) -> (usize, usize, usize) {
    const RUN: usize = 16;
    let (mut high, mut low, mut blk) = (0u32, 0u32, 0u32);
    for (k, run) in ext.chunks(3 * RUN).enumerate() {
        if run.iter().fold(0u8, |a, &e| a | e) == 0 {
            if let Some(m) = mask.as_deref_mut() {
                let x0 = k * RUN;
                m[x0..x0 + run.len() / 3].fill(0);
            }
            continue;
        }
        for (x, e) in run.chunks_exact(3).enumerate() {
            let mut flag = e[0] | e[1] | e[2];
            high += (flag & CLIPPED_HIGH) as u32;
            low += (flag >> 1) as u32;
            if e[0] & e[1] & e[2] & CLIPPED_LOW != 0 {
                let o = &mut out[3 * (k * RUN + x)..3 * (k * RUN + x) + 3];
                let v = o[0].min(o[1]).min(o[2]);
                o.fill(v);
                flag |= BLACK;
                blk += 1;
            }
            if let Some(m) = mask.as_deref_mut() {
                m[k * RUN + x] = flag;
            }
        }
    }
    (high as usize, low as usize, blk as usize)
}

/// `2^x` in f32, branch-free (see [`crate::fastmath::exp2`]: relative error below 3·10⁻⁷).
pub use crate::fastmath::exp2 as fast_exp2;
use crate::fastmath::log2 as fast_log2;

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
