//! Choosing the pixels that calibrate the camera response.
//!
//! Debevec & Malik's solve (see [`crate::response`]) needs a few hundred pixel positions whose
//! values are read in every frame of the bracket. Both methods here draw them from a `G × G`
//! grid laid over the bounding square of the usable area — the fish-eye image circle
//! ([`Circle`]) clipped to the frame, or the whole frame when there is no circle — so the
//! samples spread over the whole sky instead of clustering where the histogram is dense.
//!
//! ## The seed's method ([`SampleOptions::seed_method`])
//! Each of the `G²` cells receives `⌊N / G²⌋` samples; the remaining `N mod G²` samples go to
//! distinct cells chosen at random. In a cell, positions are drawn uniformly at random and kept
//! when the pixel centre lies inside the circle (at most [`ATTEMPTS_PER_SAMPLE`] draws per
//! wanted sample, so a cell outside the circle gives up instead of looping). Nothing else is
//! checked, so the used count can fall short of `N` at the edge of the circle.
//!
//! ## The default: robust ([`SampleOptions::default`])
//! Same grid and draws, values are 3 × 3 patch means (see below), and a candidate is rejected
//! when it cannot inform the curve:
//! - **clipped**: fewer than two frames in which some channel lies inside
//!   `[clip_low, clip_high]` (a sample seen well exposed in only one frame constrains only its
//!   own `ln E`, never the slope of `g`) — this includes the pixel clipped in all frames;
//! - **edge**: the standard deviation of the 3 × 3 neighbourhood, in any channel of any frame,
//!   exceeds `edge_threshold` codes; at an edge a one-pixel misalignment or JPEG ringing
//!   changes the value more than the exposure does;
//! - **non-monotonic**: some channel *decreases* by more than `monotonic_tolerance` codes from a
//!   shorter to a longer exposure (motion, a flickering light, or frames out of order).
//!
//! Rejected candidates are replaced by new draws from the same cell, then — when a cell runs
//! dry — from the other cells in turn, so the used count reaches the target whenever the image
//! has enough usable pixels. The target is raised so that `N · (P − 1) ≥ 255` (`P` frames):
//! the solve has 256 unknowns of `g` plus `N` of `ln E`, and with fewer observations than that
//! the curve is held up by the smoothness term alone (the seed's 100 samples for 3 frames give
//! only 200). Everything that happened is in [`SampleReport`].
//!
//! ## Histogram sampling ([`SampleOptions::histogram_method`])
//! Grossberg & Nayar's (2003) rank match, colour-hdri's default: sample `i` is, in every
//! frame, the code at which that frame's cumulative histogram (inside the circle) is nearest
//! `i / (N − 1)`. No positions, so no alignment is needed; see the `histogram` submodule.
//!
//! ## Randomness
//! [`SplitMix64`] (Steele, Lea & Flood 2014) is written here rather than taken from `rand`
//! so that a seed gives the same samples on every platform, compiler and crate version,
//! including `wasm32` — a profile can quote its seed and be reproduced years later.
//!
//! ## Sample values
//! The seed reads the single pixel. The robust default reads the mean of the 3 × 3 patch
//! around it (as AliceVision does): in the flat regions that survive the edge test this
//! divides sensor noise and JPEG block noise by about three, and noisy single pixels are what
//! bend a recovered curve in the dark codes. Values are kept on a continuous 8-bit scale
//! (`f32`, `0.0..=255.0`); the solve spreads a fractional code over its two neighbouring
//! entries of `g` by linear interpolation. 16-bit values enter as `v / 257` (65535 → 255.0).

use crate::bracket::{Frame, Pixels};
use crate::image::Circle;

mod cover;
mod histogram;

/// Draws per wanted sample before a cell gives up (the cell may lie outside the circle).
pub const ATTEMPTS_PER_SAMPLE: usize = 32;

/// Errors from sampling; each message says what to change.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SamplingError {
    /// No frames were given.
    #[error("no frames to sample: give at least two exposures of the same scene")]
    NoFrames,
    /// Frames differ in size or their pixel buffers do not match their size.
    #[error("frame {name:?} is {width}x{height} with {len} samples, expected {ew}x{eh} RGB: give frames of one bracket, all the same size")]
    SizeMismatch {
        /// Frame name.
        name: String,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
        /// Its sample count.
        len: usize,
        /// Expected width.
        ew: usize,
        /// Expected height.
        eh: usize,
    },
    /// A parameter is out of range.
    #[error("invalid sampling option: {0}")]
    BadOption(String),
    /// The circle does not overlap the frame.
    #[error("the image circle (centre {cx:.1},{cy:.1}, radius {r:.1}) does not cover any pixel of the {width}x{height} frame: check the lens circle")]
    EmptyArea {
        /// Circle centre x.
        cx: f64,
        /// Circle centre y.
        cy: f64,
        /// Circle radius.
        r: f64,
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
    },
}

/// A small, fast, seedable generator (SplitMix64) with identical output on every platform.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in `[0, n)` (`n > 0`; returns 0 for `n == 0`). Uses Lemire's
    /// multiply-shift, whose bias (< n / 2⁶⁴) is irrelevant here.
    #[inline]
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }

    /// A standard normal deviate (Box–Muller, one of the pair).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.next_f64(); // (0, 1]: ln never sees 0
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// How to choose calibration samples.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleOptions {
    /// Requested number of sample positions `N` (≥ 1).
    pub samples: usize,
    /// Grid size `G` (cells per side, 1..=256).
    pub grid: usize,
    /// PRNG seed; the same seed and frames give the same samples everywhere.
    pub seed: u64,
    /// Apply the clipped / edge / non-monotonic rejections (the robust method).
    pub reject: bool,
    /// Raise `N` so that `N · (P − 1) ≥ 255`.
    pub auto_raise: bool,
    /// Lowest 8-bit code counted as well exposed by the clipped test.
    pub clip_low: u8,
    /// Highest 8-bit code counted as well exposed by the clipped test.
    pub clip_high: u8,
    /// Largest 3 × 3 standard deviation (8-bit codes) of a non-edge sample.
    pub edge_threshold: f32,
    /// Largest decrease (8-bit codes) of a channel from a shorter to a longer exposure.
    pub monotonic_tolerance: u8,
    /// Patch radius: a sample's value is the mean of the `(2·patch + 1)²` pixels around it
    /// (clamped at the border); 0 = the single pixel, as the seed.
    pub patch: usize,
    /// Code bands (0 = off; default 16): the codes `clip_low..=clip_high` are split into this many bands,
    /// and after the grid pass every band that fewer than [`MIN_PER_BAND`] observations (a
    /// sample in a frame, per channel) fall into gets extra samples drawn from pixels whose
    /// code lies in it in some frame — so both ends of the curve are held by data, not by
    /// smoothness alone. Bands no pixel of the bracket reaches stay empty and show in
    /// [`SampleReport::code_range`].
    #[serde(default)]
    pub code_bands: usize,
    /// Stratified draw (0 = off, the grid draw, default; 32 in [`SampleOptions::stratified`]): instead of the grid, candidates
    /// are the pixels of an even lattice inside the usable area (about [`LATTICE_POINTS`]),
    /// put into this many equal bands of the *middle* frame's code (the mean of its three
    /// channels, `0..=255`), and taken in turn from every band — one from the darkest, one
    /// from the next, … — each passing the rejections, until the target is reached. A sky is
    /// mostly mid-grey in its middle frame; the grid then hands the curve's ends a few samples
    /// and its middle hundreds, and the stratified draw gives every part of the scene's
    /// brightness range its share. [`SampleOptions::grid`] is not used.
    #[serde(default)]
    pub stratify: usize,
    /// Covering draw (0 = off, default; see [`SampleOptions::covering`]): candidates from the
    /// even lattice are put into this many equal bands of `0..=255` *per frame and channel*,
    /// and the bands are filled in turn, sparse ones first, so every frame's every code band —
    /// the darkest codes of the longest frame, the brightest unclipped ones of the shortest —
    /// holds samples when the scene has pixels there. Takes precedence over
    /// [`SampleOptions::stratify`] and the grid.
    #[serde(default, skip_serializing_if = "is_zero_usize")]
    pub cover: usize,
    /// Histogram sampling (Grossberg & Nayar 2003; off by default, on in
    /// [`SampleOptions::histogram_method`]): `samples` rank-matched samples from each frame's
    /// cumulative histogram instead of pixel positions (see the module's *Histogram sampling*).
    /// Needs no alignment, so hand-held brackets and moving clouds do not bend the curve; the
    /// grid, seed, rejections, patch, code bands and stratification are not used.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub histogram: bool,
}

fn is_zero_usize(v: &usize) -> bool {
    *v == 0
}

/// About how many lattice pixels the stratified draw and the code-band fill consider.
pub const LATTICE_POINTS: usize = 65_536;

/// Fewest observations a code band should have (see [`SampleOptions::code_bands`]).
pub const MIN_PER_BAND: usize = 6;

impl Default for SampleOptions {
    /// The robust method: 100 requested samples on a 10 × 10 grid, seed 0, all rejections on,
    /// codes 5..=250 well exposed, edge threshold 8 codes, monotonic tolerance 4 codes, 16
    /// code bands (on the bundled demo bracket they cut the seed-to-seed spread of the curve
    /// from 0.25 to 0.018 ln units: the grid alone leaves the toe to smoothness). See
    /// [`SampleOptions::stratified`] for the draw of the noise-weighted calibration.
    fn default() -> Self {
        Self {
            samples: GRID_METHOD_SAMPLES,
            grid: 10,
            seed: 0,
            reject: true,
            auto_raise: true,
            clip_low: 5,
            clip_high: 250,
            edge_threshold: 8.0,
            monotonic_tolerance: 4,
            patch: 1,
            code_bands: 16,
            stratify: 0,
            cover: 0,
            histogram: false,
        }
    }
}

/// Samples of the grid draw ([`SampleOptions::grid_method`], the default).
pub const GRID_METHOD_SAMPLES: usize = 100;
/// Samples of the stratified draw ([`SampleOptions::stratified`]).
pub const STRATIFIED_SAMPLES: usize = 2000;
/// Lattice points of the code-band fill after a grid draw.
const GRID_LATTICE_POINTS: usize = 40_000;

impl SampleOptions {
    /// The seed's method exactly: `samples` positions on a `grid × grid` grid, no rejection,
    /// no raise.
    pub fn seed_method(samples: usize, grid: usize, seed: u64) -> Self {
        Self {
            samples,
            grid,
            seed,
            reject: false,
            auto_raise: false,
            patch: 0,
            code_bands: 0,
            stratify: 0,
            ..Self::default()
        }
    }

    /// The robust grid draw (the default): 100 samples on a 10 × 10 grid with every
    /// rejection, patch means and code bands, no stratification.
    pub fn grid_method() -> Self {
        Self::default()
    }

    /// The stratified draw of the noise-weighted calibration: 2000 samples over 32 bands of
    /// the middle frame's code, every rejection, patch means and code bands. On the oracle's
    /// tuning brackets (noise-weighted fit, λ = 100) the mean ratio to the oracle was 1.08
    /// with 500 samples, 1.07 with 1000 and 1.055 with 2000; they cost milliseconds to draw
    /// and to solve (the solve's cost hardly grows with `N`, see [`crate::response`]).
    pub fn stratified() -> Self {
        Self {
            samples: STRATIFIED_SAMPLES,
            stratify: 32,
            ..Self::default()
        }
    }

    /// The covering draw of [`crate::response::CalibrateOptions::covering`]: 2000 samples
    /// over 16 code bands of every frame and channel ([`SampleOptions::cover`]), every
    /// rejection, patch means and code bands, with codes from 1 (not 5) counted as measured by
    /// the clipped test — so a sample whose shorter frame reads 1–4 while the longest reads the
    /// dim ground can hold the curve's toe (the noise-weighted fit gives those codes little
    /// weight).
    pub fn covering() -> Self {
        Self {
            samples: STRATIFIED_SAMPLES,
            cover: 16,
            clip_low: 1,
            ..Self::default()
        }
    }

    /// Histogram sampling (Grossberg & Nayar 2003) with `samples` rank-matched samples per
    /// channel — colour-hdri's default sampling (it takes 1000).
    pub fn histogram_method(samples: usize) -> Self {
        Self {
            samples,
            histogram: true,
            ..Self::default()
        }
    }

    fn validate(&self) -> Result<(), SamplingError> {
        if self.samples == 0 || self.samples > 1_000_000 {
            return Err(SamplingError::BadOption(format!(
                "samples = {} (use 1..=1000000; 100-600 is typical)",
                self.samples
            )));
        }
        if self.grid == 0 || self.grid > 256 {
            return Err(SamplingError::BadOption(format!(
                "grid = {} (use 1..=256; 10 is typical)",
                self.grid
            )));
        }
        if self.clip_low >= self.clip_high {
            return Err(SamplingError::BadOption(format!(
                "clip_low {} must be below clip_high {}",
                self.clip_low, self.clip_high
            )));
        }
        if self.cover > 256 {
            return Err(SamplingError::BadOption(format!(
                "cover = {} (use 0..=256 bands; 16 is typical)",
                self.cover
            )));
        }
        if self.stratify > 256 {
            return Err(SamplingError::BadOption(format!(
                "stratify = {} (use 0..=256 bands; 32 is typical)",
                self.stratify
            )));
        }
        if !(self.edge_threshold.is_finite() && self.edge_threshold > 0.0) {
            return Err(SamplingError::BadOption(format!(
                "edge_threshold = {} (use a positive number of codes, e.g. 8)",
                self.edge_threshold
            )));
        }
        Ok(())
    }
}

/// What sampling did, for the CLI to print.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleReport {
    /// `N` as requested.
    pub requested: usize,
    /// The target after the `N · (P − 1) ≥ 255` raise (equals `requested` without raise).
    pub target: usize,
    /// Positions actually used.
    pub used: usize,
    /// Candidates rejected because they were clipped or black in all frames but at most one.
    pub rejected_clipped: usize,
    /// Candidates rejected as edges (high local variance).
    pub rejected_edge: usize,
    /// Candidates rejected because a channel decreased with exposure.
    pub rejected_non_monotonic: usize,
    /// Draws that fell outside the image circle (not a rejection of content).
    pub outside_circle: usize,
    /// Grid size used.
    pub grid: usize,
    /// The seed used.
    pub seed: u64,
    /// Number of frames.
    pub frames: usize,
    /// Samples added to fill code bands ([`SampleOptions::code_bands`]); included in `used`.
    #[serde(default)]
    pub band_samples: usize,
    /// Per channel (R, G, B), the lowest and highest code observed in a sample with a non-zero
    /// weight: the part of the curve that data constrain. Outside it the curve is extrapolated
    /// by the smoothness term.
    #[serde(default)]
    pub code_range: [[u8; 2]; 3],
    /// How many times the edge and monotonicity thresholds were doubled because too few
    /// samples passed them (noisy frames); 0 = as asked.
    #[serde(default)]
    pub relaxed: u32,
    /// The edge threshold in force (8-bit codes).
    #[serde(default)]
    pub edge_threshold: f32,
    /// The monotonicity tolerance in force (8-bit codes).
    #[serde(default)]
    pub monotonic_tolerance: u8,
    /// Samples taken by the stratified draw ([`SampleOptions::stratify`]); included in `used`.
    #[serde(default)]
    pub stratified: usize,
    /// The samples are rank-matched histogram samples ([`SampleOptions::histogram`]): no
    /// positions, nothing rejected.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub histogram: bool,
}

impl SampleReport {
    /// A warning when some channel's data cover less than codes 20..=235: the curve outside
    /// the covered range is extrapolated, not measured. `None` when the range is covered.
    pub fn range_warning(&self) -> Option<String> {
        let short: Vec<String> = self
            .code_range
            .iter()
            .zip(["red", "green", "blue"])
            .filter(|(r, _)| r[0] > 20 || r[1] < 235)
            .map(|(r, n)| format!("{n} {}..{}", r[0], r[1]))
            .collect();
        if short.is_empty() {
            return None;
        }
        Some(format!(
            "the response is measured only over codes {} (the rest is extrapolated by smoothness, so radiance from those codes is less certain); a bracket with more frames or a scene with darker and brighter parts covers more",
            short.join(", ")
        ))
    }

    /// A warning when the rejection thresholds had to be relaxed ([`SampleReport::relaxed`]).
    pub fn relaxed_warning(&self) -> Option<String> {
        (self.relaxed > 0).then(|| {
            format!(
                "the frames are noisy: too few samples passed the edge and monotonicity tests, so they were relaxed to {} and {} codes (the curve rests on noisier samples)",
                self.edge_threshold, self.monotonic_tolerance
            )
        })
    }

    /// A warning when the samples used give fewer observations than the solve needs,
    /// `used · (frames − 1) < 255`: parts of the curve are then held by the smoothness term
    /// alone, and the curve may be wrong without looking it. `None` when there are enough.
    pub fn shortfall_warning(&self) -> Option<String> {
        let have = self.used * self.frames.saturating_sub(1);
        if have >= 255 {
            return None;
        }
        let need = 255usize.div_ceil(self.frames.saturating_sub(1).max(1));
        Some(format!(
            "CALIBRATION UNDER-CONSTRAINED: only {} of {} requested sample positions were usable ({} rejected as clipped, {} as edges, {} as non-monotonic), giving {} observations where at least 255 are needed; the response curve is partly guessed. Use more samples (at least {need}), a bracket with more frames or smaller steps, a less clipped or less textured scene, or a saved camera profile",
            self.used,
            self.target,
            self.rejected_clipped,
            self.rejected_edge,
            self.rejected_non_monotonic,
            have
        ))
    }
}

/// The chosen positions and their (binned 8-bit) values.
#[derive(Debug, Clone, PartialEq)]
pub struct Samples {
    /// Pixel positions `(x, y)` (origin top-left).
    pub positions: Vec<(usize, usize)>,
    /// Values, `values[(i * frames + j)]` = RGB codes of sample `i` in frame `j`, on the
    /// 8-bit scale `0.0..=255.0` (fractional for patch means and 16-bit input, `v / 257`).
    pub values: Vec<[f32; 3]>,
    /// Number of frames `P`.
    pub frames: usize,
    /// What happened.
    pub report: SampleReport,
}

impl Samples {
    /// The number of samples `N` (each seen in every frame). Histogram samples have no
    /// positions, so this is not always `positions.len()`.
    pub fn count(&self) -> usize {
        self.values.len() / self.frames.max(1)
    }

    /// The code (8-bit scale, possibly fractional) of sample `i`, frame `j`, channel `c`.
    #[inline]
    pub fn z(&self, i: usize, j: usize, c: usize) -> f32 {
        self.values[i * self.frames + j][c]
    }
}

/// Checks that all frames share one size and have matching buffers; returns `(width, height)`.
pub(crate) fn check_frames(frames: &[Frame]) -> Result<(usize, usize), SamplingError> {
    let first = frames.first().ok_or(SamplingError::NoFrames)?;
    let (w, h) = (first.width, first.height);
    for f in frames {
        let expected = w.checked_mul(h).and_then(|n| n.checked_mul(3));
        if f.width != w || f.height != h || Some(f.pixels.len()) != expected || w == 0 || h == 0 {
            return Err(SamplingError::SizeMismatch {
                name: f.name.clone(),
                width: f.width,
                height: f.height,
                len: f.pixels.len(),
                ew: w,
                eh: h,
            });
        }
    }
    Ok((w, h))
}

/// The 8-bit (binned for 16-bit input) RGB value at sample index `idx = 3·(y·w + x)`.
#[inline]
pub(crate) fn code8(p: &Pixels, idx: usize) -> [u8; 3] {
    match p {
        Pixels::U8(v) => [v[idx], v[idx + 1], v[idx + 2]],
        Pixels::U16(v) => [bin16(v[idx]), bin16(v[idx + 1]), bin16(v[idx + 2])],
    }
}

/// RGB at sample index `idx` on the continuous 8-bit scale (16-bit values divided by 257).
#[inline]
pub(crate) fn code_f(p: &Pixels, idx: usize) -> [f32; 3] {
    match p {
        Pixels::U8(v) => [v[idx] as f32, v[idx + 1] as f32, v[idx + 2] as f32],
        Pixels::U16(v) => [
            v[idx] as f32 / 257.0,
            v[idx + 1] as f32 / 257.0,
            v[idx + 2] as f32 / 257.0,
        ],
    }
}

pub use crate::bracket::bin16;

/// Chooses calibration samples from `frames` (sorted shortest exposure first), inside `circle`
/// when given. See the module docs for both methods.
pub fn sample(
    frames: &[Frame],
    circle: Option<Circle>,
    opts: &SampleOptions,
) -> Result<Samples, SamplingError> {
    opts.validate()?;
    if opts.histogram {
        return histogram::sample_histogram(frames, circle, opts);
    }
    let size = check_frames(frames)?;
    let whole = Whole { frames, size };
    match sample_from(&whole, size, circle, opts)? {
        Ok(s) => Ok(s),
        // Unreachable: the whole frames answer every read.
        Err(Missing(_)) => Err(SamplingError::NoFrames),
    }
}

/// A draw of pixels held out from earlier draws: as [`sample`] with `opts` (which must ask for
/// the covering or the stratified draw, [`SampleOptions::cover`] or
/// [`SampleOptions::stratify`]; its code bands are not filled), but no candidate whose patch
/// shares a pixel with a patch of radius `used_patch` around any position of `used` — so its
/// noise is independent of theirs. For scoring curves fitted on `used` (a cross-validation of
/// the calibration; [`crate::response::held_out_residuals`]).
pub fn sample_held_out(
    frames: &[Frame],
    circle: Option<Circle>,
    opts: &SampleOptions,
    used: &[&Samples],
    used_patch: usize,
) -> Result<Samples, SamplingError> {
    opts.validate()?;
    if opts.histogram || (opts.cover == 0 && opts.stratify == 0) {
        return Err(SamplingError::BadOption(
            "a held-out draw needs the covering or the stratified draw".into(),
        ));
    }
    let size = check_frames(frames)?;
    let r = (used_patch + opts.patch) as isize;
    let mut exclude = std::collections::HashSet::new();
    for s in used {
        for &(x, y) in &s.positions {
            for dy in -r..=r {
                for dx in -r..=r {
                    let (u, v) = (x as isize + dx, y as isize + dy);
                    if u >= 0 && v >= 0 && (u as usize) < size.0 && (v as usize) < size.1 {
                        exclude.insert((u as usize, v as usize));
                    }
                }
            }
        }
    }
    let o = SampleOptions {
        code_bands: 0,
        ..opts.clone()
    };
    let whole = Whole { frames, size };
    match sample_from_excluding(&whole, size, circle, &o, &exclude)? {
        Ok(s) => Ok(s),
        Err(Missing(_)) => Err(SamplingError::NoFrames),
    }
}

/// Where sampling reads the bracket (sorted shortest exposure first): every frame's patch
/// means and 3 × 3 spread at a position. The whole frames ([`Whole`]), or the values gathered
/// at planned positions while the frames were decoded one at a time ([`Gathered`]).
pub(crate) trait Source: Sync {
    /// Number of frames.
    fn frames(&self) -> usize;
    /// The means of the `(2r+1)²` patch at `(x, y)` of every frame into `out` (one per frame);
    /// false when they are not at hand.
    fn means(&self, x: usize, y: usize, r: usize, out: &mut [[f32; 3]]) -> bool;
    /// Whether some frame's 3 × 3 variance at `(x, y)` exceeds `thr2` in some channel; `None`
    /// when it is not at hand.
    fn edge(&self, x: usize, y: usize, thr2: f32) -> Option<bool>;
}

/// Positions a [`Source`] did not have: sampling stopped there, and goes the same way again
/// once they are gathered.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Missing(pub Vec<(usize, usize)>);

/// The whole frames as a [`Source`].
struct Whole<'a> {
    frames: &'a [Frame],
    size: (usize, usize),
}

impl Source for Whole<'_> {
    fn frames(&self) -> usize {
        self.frames.len()
    }

    fn means(&self, x: usize, y: usize, r: usize, out: &mut [[f32; 3]]) -> bool {
        let (w, h) = self.size;
        for (s, f) in out.iter_mut().zip(self.frames) {
            *s = patch_mean(&f.pixels, x, y, w, h, r);
        }
        true
    }

    fn edge(&self, x: usize, y: usize, thr2: f32) -> Option<bool> {
        let (w, h) = self.size;
        Some(
            self.frames
                .iter()
                .any(|f| spread3(&f.pixels, x, y, w, h).iter().any(|&v| v > thr2)),
        )
    }
}

/// Per channel, the variance of the 3 × 3 neighbourhood of `(x, y)` (clamped at the frame
/// border) as the edge test computes it.
fn spread3(p: &Pixels, x: usize, y: usize, w: usize, h: usize) -> [f32; 3] {
    let (mut s, mut s2, mut n) = ([0f32; 3], [0f32; 3], 0f32);
    for yy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
        for xx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
            let v = code_f(p, 3 * (yy * w + xx));
            for c in 0..3 {
                s[c] += v[c];
                s2[c] += v[c] * v[c];
            }
            n += 1.0;
        }
    }
    let mut out = [0f32; 3];
    for c in 0..3 {
        let mean = s[c] / n;
        out[c] = s2[c] / n - mean * mean;
    }
    out
}

/// Every frame's patch means and 3 × 3 spreads at a set of positions, gathered frame by frame
/// (see [`plan`]), as a [`Source`].
#[derive(Debug, Clone, Default)]
pub(crate) struct Gathered {
    /// Positions `(y, x)`, sorted.
    keys: Vec<(usize, usize)>,
    frames: usize,
    patch: usize,
    size: (usize, usize),
    /// Per key and frame, the patch means.
    means: Vec<[f32; 3]>,
    /// Per key, the largest 3 × 3 variance of any channel and frame (all the edge test asks).
    spread: Vec<f32>,
}

impl Gathered {
    /// Room for `positions` (`(x, y)`) of `frames` frames of `size`, patch radius `patch`.
    pub(crate) fn new(
        positions: &[(usize, usize)],
        frames: usize,
        patch: usize,
        size: (usize, usize),
    ) -> Self {
        let mut keys: Vec<(usize, usize)> = positions
            .iter()
            .filter(|&&(x, y)| x < size.0 && y < size.1)
            .map(|&(x, y)| (y, x))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        Gathered {
            means: vec![[0f32; 3]; keys.len() * frames],
            spread: vec![f32::NEG_INFINITY; keys.len()],
            keys,
            frames,
            patch,
            size,
        }
    }

    /// Reads frame `j` (of the bracket's order) at every position.
    pub(crate) fn add_frame(&mut self, j: usize, p: &Pixels) {
        let (w, h) = self.size;
        let (frames, r) = (self.frames, self.patch);
        for (k, &(y, x)) in self.keys.iter().enumerate() {
            self.means[k * frames + j] = patch_mean(p, x, y, w, h, r);
            let s = spread3(p, x, y, w, h);
            self.spread[k] = self.spread[k].max(s[0]).max(s[1]).max(s[2]);
        }
    }

    fn find(&self, x: usize, y: usize) -> Option<usize> {
        self.keys.binary_search(&(y, x)).ok()
    }
}

/// Several [`Gathered`] sets, read in turn.
impl Source for Vec<Gathered> {
    fn frames(&self) -> usize {
        self.first().map_or(0, |g| g.frames)
    }

    fn means(&self, x: usize, y: usize, r: usize, out: &mut [[f32; 3]]) -> bool {
        for g in self.iter().filter(|g| g.patch == r) {
            if let Some(k) = g.find(x, y) {
                out.copy_from_slice(&g.means[k * g.frames..(k + 1) * g.frames]);
                return true;
            }
        }
        false
    }

    fn edge(&self, x: usize, y: usize, thr2: f32) -> Option<bool> {
        // `v > thr2` for some variance `v` is `max > thr2` (none is NaN: codes are finite).
        self.iter()
            .find_map(|g| g.find(x, y).map(|k| g.spread[k] > thr2))
    }
}

/// The positions sampling of a `size` bracket of `frames` frames will read, as far as they
/// are known before reading any: the lattice of the stratified draw and of the code bands, and
/// every position the grid draw can reach while it meets the cells' quotas (whatever is
/// accepted, so for every relaxation). The top-up after the quotas depends on what was
/// accepted; sampling asks for its positions ([`Missing`]) when it gets there.
pub(crate) fn plan(
    size: (usize, usize),
    frames: usize,
    circle: Option<Circle>,
    opts: &SampleOptions,
) -> Result<Vec<(usize, usize)>, SamplingError> {
    opts.validate()?;
    let (w, h) = size;
    let area = usable_area(circle, w, h)?;
    let target = target_count(opts, frames);
    let mut rng = SplitMix64::new(opts.seed);
    let quota = cell_quotas(opts.grid, target, &mut rng);
    let inside = |x: usize, y: usize| circle.is_none_or(|c| c.contains_pixel(x, y));
    let mut out = Vec::new();
    if opts.stratify > 0 || opts.cover > 0 {
        out.extend(lattice_points(size, circle, LATTICE_POINTS));
        return Ok(out);
    }
    if opts.code_bands > 0 {
        out.extend(lattice_points(size, circle, GRID_LATTICE_POINTS));
    }
    // Cell k starts after between `lo` and `hi` draws (each takes two numbers), and makes
    // between its quota and 32 times it.
    let most: usize = quota.iter().map(|q| q * ATTEMPTS_PER_SAMPLE).sum();
    let stream: Vec<u64> = (0..2 * most).map(|_| rng.next_u64()).collect();
    let below = |u: u64, n: usize| ((u as u128 * n as u128) >> 64) as usize;
    let (mut lo, mut hi) = (0usize, 0usize);
    for (cell, &q) in quota.iter().enumerate() {
        let (cx0, cx1, cy0, cy1) = cell_bounds(area, opts.grid, cell);
        if q == 0 || cx1 <= cx0 || cy1 <= cy0 {
            continue;
        }
        for t in lo..(hi + q * ATTEMPTS_PER_SAMPLE).min(most) {
            let x = cx0 + below(stream[2 * t], cx1 - cx0);
            let y = cy0 + below(stream[2 * t + 1], cy1 - cy0);
            if inside(x, y) {
                out.push((x, y));
            }
        }
        lo += q;
        hi += q * ATTEMPTS_PER_SAMPLE;
    }
    Ok(out)
}

/// Chooses calibration samples from `src` (frames of `size`), as [`sample`] does.
pub(crate) fn sample_from(
    src: &dyn Source,
    size: (usize, usize),
    circle: Option<Circle>,
    opts: &SampleOptions,
) -> Result<Result<Samples, Missing>, SamplingError> {
    sample_from_excluding(src, size, circle, opts, &std::collections::HashSet::new())
}

/// [`sample_from`] with the lattice's candidates at `exclude` never taken (the covering and
/// stratified draws; see [`sample_held_out`]).
fn sample_from_excluding(
    src: &dyn Source,
    size: (usize, usize),
    circle: Option<Circle>,
    opts: &SampleOptions,
    exclude: &std::collections::HashSet<(usize, usize)>,
) -> Result<Result<Samples, Missing>, SamplingError> {
    opts.validate()?;
    let mut o = opts.clone();
    let mut out = match sample_once(src, size, circle, &o, exclude)? {
        Ok(s) => s,
        Err(m) => return Ok(Err(m)),
    };
    // Noisy frames (a small sensor, many frames, 1-EV steps) fail the edge and monotonicity
    // tests by noise alone: fewer than half the samples survive, or none. The thresholds are
    // then doubled, up to twice (edge 32 codes, monotonic 16 codes from the defaults), and the
    // report says so; a curve from relaxed samples beats no curve or one held by smoothness.
    let mut relaxed = 0;
    while o.reject && relaxed < MAX_RELAXATIONS && out.report.used * 2 < out.report.target {
        relaxed += 1;
        o.edge_threshold *= 2.0;
        o.monotonic_tolerance = o.monotonic_tolerance.saturating_mul(2);
        let again = match sample_once(src, size, circle, &o, exclude)? {
            Ok(s) => s,
            Err(m) => return Ok(Err(m)),
        };
        if again.report.used > out.report.used {
            out = again;
            out.report.relaxed = relaxed;
            out.report.edge_threshold = o.edge_threshold;
            out.report.monotonic_tolerance = o.monotonic_tolerance;
        }
    }
    if out.report.relaxed == 0 {
        out.report.edge_threshold = opts.edge_threshold;
        out.report.monotonic_tolerance = opts.monotonic_tolerance;
    }
    Ok(Ok(out))
}

/// How many times [`sample`] doubles the edge and monotonicity thresholds when too few samples
/// survive them.
pub const MAX_RELAXATIONS: u32 = 2;

/// One sampling pass with the thresholds in `opts`: the area, each grid cell's quota, draws
/// until the quotas are met, a top-up when candidates were rejected, and the code bands.
fn sample_once(
    src: &dyn Source,
    (w, h): (usize, usize),
    circle: Option<Circle>,
    opts: &SampleOptions,
    exclude: &std::collections::HashSet<(usize, usize)>,
) -> Result<Result<Samples, Missing>, SamplingError> {
    let p = src.frames();
    let area = usable_area(circle, w, h)?;
    let target = target_count(opts, p);
    let mut rng = SplitMix64::new(opts.seed);
    let quota = cell_quotas(opts.grid, target, &mut rng);
    let report = SampleReport {
        requested: opts.samples,
        target,
        grid: opts.grid,
        seed: opts.seed,
        frames: p,
        ..SampleReport::default()
    };
    let mut draw = Draws {
        src,
        missing: None,
        circle,
        opts,
        area,
        report,
        positions: Vec::with_capacity(target),
        values: Vec::with_capacity(target * p),
        taken: std::collections::HashSet::new(),
        exclude,
        scratch: vec![[0f32; 3]; p],
    };
    let mut lattice = None;
    if opts.cover > 0 || opts.stratify > 0 {
        let lat = match Lattice::new(src, circle, opts, (w, h), &mut rng, LATTICE_POINTS) {
            Ok(l) => l,
            Err(m) => return Ok(Err(m)),
        };
        if opts.cover > 0 {
            draw.cover(&lat, target);
        } else {
            draw.stratified(&lat, target);
        }
        draw.report.stratified = draw.positions.len();
        lattice = Some(lat);
    } else {
        draw.meet_quotas(&quota, &mut rng);
        if opts.reject && draw.missing.is_none() {
            draw.top_up(target, &mut rng);
        }
    }
    let Draws {
        mut report,
        mut positions,
        mut values,
        missing,
        ..
    } = draw;
    if let Some(m) = missing {
        return Ok(Err(Missing(m)));
    }
    if opts.code_bands > 0 {
        // After a grid draw the lattice is drawn here, with the generator where the grid left
        // it, as before the stratified draw existed (the grid method's samples are unchanged).
        let lat = match lattice {
            Some(l) => l,
            None => match Lattice::new(src, circle, opts, (w, h), &mut rng, GRID_LATTICE_POINTS) {
                Ok(l) => l,
                Err(m) => return Ok(Err(m)),
            },
        };
        report.band_samples =
            match fill_bands(src, &lat, opts, &mut report, &mut positions, &mut values) {
                Ok(n) => n,
                Err(m) => return Ok(Err(m)),
            };
    }
    report.used = positions.len();
    report.code_range = code_range(&values);
    Ok(Ok(Samples {
        positions,
        values,
        frames: p,
        report,
    }))
}

/// The usable area's bounding square `(x0, y0, x1, y1)`, clipped to the `w × h` frame: the
/// circle's when given, else the whole frame.
fn usable_area(
    circle: Option<Circle>,
    w: usize,
    h: usize,
) -> Result<(usize, usize, usize, usize), SamplingError> {
    let Some(c) = circle else {
        return Ok((0, 0, w, h));
    };
    if !c.is_valid() {
        return Err(SamplingError::BadOption(format!(
            "circle centre {},{} radius {} is not a finite positive circle",
            c.cx, c.cy, c.r
        )));
    }
    let (xs, ys) = c.pixel_bounds(w, h);
    if xs.is_empty() || ys.is_empty() {
        return Err(empty_area(c, w, h));
    }
    Ok((xs.start, ys.start, xs.end, ys.end))
}

/// The error for a circle with no pixel of the `w × h` frame inside it.
fn empty_area(c: Circle, w: usize, h: usize) -> SamplingError {
    SamplingError::EmptyArea {
        cx: c.cx,
        cy: c.cy,
        r: c.r,
        width: w,
        height: h,
    }
}

/// The number of samples aimed at: the request, raised so that `N · (P − 1) ≥ 255` when asked.
fn target_count(opts: &SampleOptions, frames: usize) -> usize {
    if opts.auto_raise && frames >= 2 {
        opts.samples.max(255usize.div_ceil(frames - 1))
    } else {
        opts.samples
    }
}

/// Each of the `grid²` cells' share of `target`; the remainder goes to distinct random cells
/// (a partial Fisher–Yates shuffle).
fn cell_quotas(grid: usize, target: usize, rng: &mut SplitMix64) -> Vec<usize> {
    let cells = grid * grid;
    let mut quota = vec![target / cells; cells];
    let rem = target % cells;
    let mut order: Vec<usize> = (0..cells).collect();
    for i in 0..rem {
        let j = i + rng.below(cells - i);
        order.swap(i, j);
        quota[order[i]] += 1;
    }
    quota
}

/// Why a candidate position was turned down.
enum Refusal {
    /// Outside the image circle (not a judgement of the content).
    Outside,
    /// The source does not have the position's values.
    Missing,
    /// Already taken.
    Taken,
    /// Failed a content test.
    Rejected(Reject),
}

/// The draws of one sampling pass: what has been taken so far, and the report.
struct Draws<'a> {
    src: &'a dyn Source,
    /// Positions the source did not have, when sampling stopped for them.
    missing: Option<Vec<(usize, usize)>>,
    circle: Option<Circle>,
    opts: &'a SampleOptions,
    /// `(x0, y0, x1, y1)` of [`usable_area`].
    area: (usize, usize, usize, usize),
    report: SampleReport,
    positions: Vec<(usize, usize)>,
    values: Vec<[f32; 3]>,
    taken: std::collections::HashSet<(usize, usize)>,
    /// Lattice candidates never taken (held out for an earlier draw; [`sample_held_out`]).
    exclude: &'a std::collections::HashSet<(usize, usize)>,
    /// The candidate's patch means, one per frame.
    scratch: Vec<[f32; 3]>,
}

impl Draws<'_> {
    /// Draws in every cell until its quota is met or its attempts run out.
    fn meet_quotas(&mut self, quota: &[usize], rng: &mut SplitMix64) {
        let mut got = vec![0usize; quota.len()];
        for cell in 0..quota.len() {
            let mut attempts = 0;
            while got[cell] < quota[cell] && attempts < quota[cell] * ATTEMPTS_PER_SAMPLE {
                attempts += 1;
                if self.try_cell(cell, rng) {
                    got[cell] += 1;
                }
                if self.missing.is_some() {
                    return;
                }
            }
        }
    }

    /// Tops up to `target` from all cells in turn; bounded so a featureless or clipped frame
    /// ends.
    fn top_up(&mut self, target: usize, rng: &mut SplitMix64) {
        let cells = self.opts.grid * self.opts.grid;
        let mut budget = target * ATTEMPTS_PER_SAMPLE;
        let mut cell = 0;
        while self.positions.len() < target && budget > 0 {
            budget -= 1;
            self.try_cell(cell, rng);
            if let Some(mut m) = self.missing.take() {
                // What the rest of the top-up can draw, whatever it accepts.
                let mut rng = rng.clone();
                for _ in 0..budget {
                    cell = (cell + 1) % cells;
                    let (cx0, cx1, cy0, cy1) = self.cell_bounds(cell);
                    if cx1 <= cx0 || cy1 <= cy0 {
                        continue;
                    }
                    let x = cx0 + rng.below(cx1 - cx0);
                    let y = cy0 + rng.below(cy1 - cy0);
                    if self.circle.is_none_or(|c| c.contains_pixel(x, y)) {
                        m.push((x, y));
                    }
                }
                self.missing = Some(m);
                return;
            }
            cell = (cell + 1) % cells;
        }
    }

    /// Cell `k`'s pixel span `(x0, x1, y0, y1)`: `[x0 + k·aw/G, x0 + (k+1)·aw/G)` across,
    /// likewise down; empty when the area is narrower than `G` pixels.
    fn cell_bounds(&self, cell: usize) -> (usize, usize, usize, usize) {
        cell_bounds(self.area, self.opts.grid, cell)
    }

    /// Draws one position in `cell` and keeps it when it passes; true when kept.
    fn try_cell(&mut self, cell: usize, rng: &mut SplitMix64) -> bool {
        let (cx0, cx1, cy0, cy1) = self.cell_bounds(cell);
        if cx1 <= cx0 || cy1 <= cy0 {
            return false;
        }
        let x = cx0 + rng.below(cx1 - cx0);
        let y = cy0 + rng.below(cy1 - cy0);
        match self.judge(x, y) {
            Ok(()) => {
                self.positions.push((x, y));
                self.values.extend_from_slice(&self.scratch);
                true
            }
            Err(refusal) => {
                let r = &mut self.report;
                match refusal {
                    Refusal::Outside => r.outside_circle += 1,
                    Refusal::Missing => {
                        self.missing = Some(vec![(x, y)]);
                        return false;
                    }
                    Refusal::Taken => {}
                    Refusal::Rejected(Reject::Clipped) => r.rejected_clipped += 1,
                    Refusal::Rejected(Reject::Edge) => r.rejected_edge += 1,
                    Refusal::Rejected(Reject::NonMonotonic) => r.rejected_non_monotonic += 1,
                }
                false
            }
        }
    }

    /// Reads the patch means at `(x, y)` into the scratch values and judges the position.
    fn judge(&mut self, x: usize, y: usize) -> Result<(), Refusal> {
        let opts = self.opts;
        if let Some(c) = self.circle {
            if !c.contains_pixel(x, y) {
                return Err(Refusal::Outside);
            }
        }
        if opts.reject && !self.taken.insert((x, y)) {
            return Err(Refusal::Taken);
        }
        if !self.src.means(x, y, opts.patch, &mut self.scratch) {
            if opts.reject {
                self.taken.remove(&(x, y));
            }
            return Err(Refusal::Missing);
        }
        if opts.reject {
            match reject_reason(self.src, &self.scratch, x, y, opts) {
                Err(Missing(_)) => {
                    self.taken.remove(&(x, y));
                    return Err(Refusal::Missing);
                }
                Ok(Some(reason)) => return Err(Refusal::Rejected(reason)),
                Ok(None) => {}
            }
        }
        Ok(())
    }
}

/// Per channel, the lowest and highest code (rounded) with a non-zero weight among `values`;
/// `[255, 0]` for a channel with none.
fn code_range(values: &[[f32; 3]]) -> [[u8; 2]; 3] {
    let mut r = [[255u8, 0u8]; 3];
    for v in values {
        for c in 0..3 {
            let z = v[c].round().clamp(0.0, 255.0) as u8;
            if z > 0 && z < 255 {
                r[c][0] = r[c][0].min(z);
                r[c][1] = r[c][1].max(z);
            }
        }
    }
    r
}

/// The candidates of the stratified draw and the code-band fill: the pixels of an even lattice
/// (about [`LATTICE_POINTS`]) inside the circle, each with its patch means in every frame, in a
/// random order.
struct Lattice {
    /// Positions `(x, y)`, lattice (memory) order.
    cand: Vec<(usize, usize)>,
    /// `P` patch means per candidate, frame by frame.
    means: Vec<[f32; 3]>,
    /// A random permutation of the candidates.
    order: Vec<usize>,
}

impl Lattice {
    fn new(
        src: &dyn Source,
        circle: Option<Circle>,
        opts: &SampleOptions,
        (w, h): (usize, usize),
        rng: &mut SplitMix64,
        points: usize,
    ) -> Result<Self, Missing> {
        let cand = lattice_points((w, h), circle, points);
        let p = src.frames();
        // Every candidate's patch means, computed in lattice (memory) order: visited in the
        // random order they cost a cache miss per patch row and frame, about 40 ms on a 6 MP
        // bracket; in memory order, a few.
        let means_at = |&(x, y): &(usize, usize)| {
            let mut m = vec![[0f32; 3]; p];
            src.means(x, y, opts.patch, &mut m).then_some(m)
        };
        #[cfg(feature = "parallel")]
        let per: Vec<Option<Vec<[f32; 3]>>> = {
            use rayon::prelude::*;
            cand.par_iter().map(means_at).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let per: Vec<Option<Vec<[f32; 3]>>> = cand.iter().map(means_at).collect();
        let mut means = Vec::with_capacity(cand.len() * p);
        let mut missing = Vec::new();
        for (m, &xy) in per.into_iter().zip(&cand) {
            match m {
                Some(m) => means.extend_from_slice(&m),
                None => missing.push(xy),
            }
        }
        if !missing.is_empty() {
            return Err(Missing(missing));
        }
        let mut order: Vec<usize> = (0..cand.len()).collect();
        for i in (1..order.len()).rev() {
            let j = rng.below(i + 1);
            order.swap(i, j);
        }
        Ok(Self { cand, means, order })
    }

    /// Candidate `k`'s patch means, one per frame.
    fn values(&self, k: usize, p: usize) -> &[[f32; 3]] {
        &self.means[k * p..(k + 1) * p]
    }
}

impl Draws<'_> {
    /// Whether the lattice candidate at `(x, y)` with patch means `vals` is refused (counted in
    /// the report by reason) when [`SampleOptions::reject`] is on; `None` when the source
    /// lacks pixels it needs (kept in `missing`: sampling stops and asks for them).
    fn refuses(&mut self, vals: &[[f32; 3]], x: usize, y: usize) -> Option<bool> {
        if !self.opts.reject {
            return Some(false);
        }
        let reason = match reject_reason(self.src, vals, x, y, self.opts) {
            Ok(reason) => reason,
            Err(Missing(m)) => {
                self.missing = Some(m);
                return None;
            }
        };
        let Some(reason) = reason else {
            return Some(false);
        };
        let r = &mut self.report;
        match reason {
            Reject::Clipped => r.rejected_clipped += 1,
            Reject::Edge => r.rejected_edge += 1,
            Reject::NonMonotonic => r.rejected_non_monotonic += 1,
        }
        Some(true)
    }

    /// The stratified draw ([`SampleOptions::stratify`]): the lattice's candidates in bands of
    /// the middle frame's mean code, taken one band after another until `target` are kept.
    fn stratified(&mut self, lat: &Lattice, target: usize) {
        let p = self.src.frames();
        let mid = p / 2;
        let nb = self.opts.stratify.clamp(1, 256);
        let mut bands: Vec<Vec<usize>> = vec![Vec::new(); nb];
        // In the lattice's random order, so each band's list is random too.
        for &k in &lat.order {
            let v = lat.values(k, p)[mid];
            let z = (v[0] + v[1] + v[2]) / 3.0;
            let b = ((z / 256.0 * nb as f32) as usize).min(nb - 1);
            bands[b].push(k);
        }
        let mut next = vec![0usize; nb];
        while self.positions.len() < target {
            let mut any = false;
            for b in 0..nb {
                if self.positions.len() >= target {
                    break;
                }
                // The band's next candidate that passes.
                while next[b] < bands[b].len() {
                    let k = bands[b][next[b]];
                    next[b] += 1;
                    any = true;
                    let vals = lat.values(k, p);
                    let (x, y) = lat.cand[k];
                    if self.exclude.contains(&(x, y)) {
                        continue;
                    }
                    match self.refuses(vals, x, y) {
                        None => return,
                        Some(true) => continue,
                        Some(false) => {}
                    }
                    self.taken.insert((x, y));
                    self.positions.push((x, y));
                    self.values.extend_from_slice(vals);
                    break;
                }
            }
            if !any {
                break; // every band ran dry
            }
        }
    }
}

/// Adds samples to code bands with too few observations (see [`SampleOptions::code_bands`]);
/// returns how many were added. Candidates are the [`Lattice`]'s pixels, in its random order,
/// whose patch value falls in a short band in some frame; each must pass the same rejections as
/// any robust sample.
fn fill_bands(
    src: &dyn Source,
    lat: &Lattice,
    opts: &SampleOptions,
    report: &mut SampleReport,
    positions: &mut Vec<(usize, usize)>,
    values: &mut Vec<[f32; 3]>,
) -> Result<usize, Missing> {
    let p = src.frames();
    let (lo, hi) = (opts.clip_low as f32, opts.clip_high as f32);
    let nb = opts.code_bands.min(256);
    let band = |z: f32| -> Option<usize> {
        (z >= lo && z <= hi).then(|| (((z - lo) / (hi - lo + 1.0)) * nb as f32) as usize)
    };
    let mut counts = vec![[0usize; 3]; nb];
    for v in values.iter() {
        for c in 0..3 {
            if let Some(b) = band(v[c]) {
                counts[b.min(nb - 1)][c] += 1;
            }
        }
    }
    let filled =
        |counts: &[[usize; 3]]| counts.iter().all(|b| b.iter().all(|&n| n >= MIN_PER_BAND));
    if filled(&counts) {
        return Ok(0);
    }
    let (cand, means, order) = (&lat.cand, &lat.means, lat.order.iter().copied());
    let taken: std::collections::HashSet<(usize, usize)> = positions.iter().copied().collect();
    let mut added = 0;
    for k in order {
        if filled(&counts) {
            break;
        }
        let (x, y) = cand[k];
        if taken.contains(&(x, y)) {
            continue;
        }
        let scratch = &means[k * p..(k + 1) * p];
        let fills = scratch.iter().any(|v| {
            (0..3).any(|c| band(v[c]).is_some_and(|b| counts[b.min(nb - 1)][c] < MIN_PER_BAND))
        });
        if !fills {
            continue;
        }
        if let Some(reason) = reject_reason(src, scratch, x, y, opts)? {
            match reason {
                Reject::Clipped => report.rejected_clipped += 1,
                Reject::Edge => report.rejected_edge += 1,
                Reject::NonMonotonic => report.rejected_non_monotonic += 1,
            }
            continue;
        }
        for v in scratch {
            for c in 0..3 {
                if let Some(b) = band(v[c]) {
                    counts[b.min(nb - 1)][c] += 1;
                }
            }
        }
        positions.push((x, y));
        values.extend_from_slice(scratch);
        added += 1;
    }
    Ok(added)
}

enum Reject {
    Clipped,
    Edge,
    NonMonotonic,
}

/// Mean RGB of the `(2r+1)²` patch around `(x, y)`, clamped at the frame border.
fn patch_mean(p: &Pixels, x: usize, y: usize, w: usize, h: usize, r: usize) -> [f32; 3] {
    if r == 0 {
        return code_f(p, 3 * (y * w + x));
    }
    let mut s = [0f32; 3];
    let mut n = 0f32;
    for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
        for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
            let v = code_f(p, 3 * (yy * w + xx));
            s[0] += v[0];
            s[1] += v[1];
            s[2] += v[2];
            n += 1.0;
        }
    }
    s.map(|v| v / n)
}

fn reject_reason(
    src: &dyn Source,
    vals: &[[f32; 3]],
    x: usize,
    y: usize,
    opts: &SampleOptions,
) -> Result<Option<Reject>, Missing> {
    let ok = |z: f32| z >= opts.clip_low as f32 && z <= opts.clip_high as f32;
    let informative = (0..3).any(|c| vals.iter().filter(|v| ok(v[c])).count() >= 2);
    if !informative {
        return Ok(Some(Reject::Clipped));
    }
    let tol = opts.monotonic_tolerance as f32;
    for pair in vals.windows(2) {
        if pair[1].iter().zip(&pair[0]).any(|(&b, &a)| b < a - tol) {
            return Ok(Some(Reject::NonMonotonic));
        }
    }
    // 3 × 3 neighbourhood, clamped at the frame border; per channel, because JPEG's chroma
    // subsampling smears colour edges (blue sky against a white cloud of equal luminance)
    // that a luminance test would not see.
    let thr2 = opts.edge_threshold * opts.edge_threshold;
    match src.edge(x, y, thr2) {
        Some(true) => Ok(Some(Reject::Edge)),
        Some(false) => Ok(None),
        None => Err(Missing(vec![(x, y)])),
    }
}

/// The lattice of about `points` pixels (every `step`-th row and column, `step² ≈ w·h /
/// points`) inside `circle`, in memory order: the candidates of the stratified draw and the
/// code bands.
fn lattice_points(
    (w, h): (usize, usize),
    circle: Option<Circle>,
    points: usize,
) -> Vec<(usize, usize)> {
    let step = ((w * h) as f64 / points as f64).sqrt().max(1.0) as usize;
    (0..h)
        .step_by(step)
        .flat_map(|y| (0..w).step_by(step).map(move |x| (x, y)))
        .filter(|&(x, y)| circle.is_none_or(|c| c.contains_pixel(x, y)))
        .collect()
}

/// Cell `k`'s pixel span `(x0, x1, y0, y1)` in a `g × g` grid over `area` (`(x0, y0, x1,
/// y1)`): `[x0 + k·aw/G, x0 + (k+1)·aw/G)` across, likewise down; empty when the area is
/// narrower than `G` pixels.
fn cell_bounds(
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    g: usize,
    cell: usize,
) -> (usize, usize, usize, usize) {
    let (cx, cy) = (cell % g, cell / g);
    let (aw, ah) = (x1 - x0, y1 - y0);
    (
        x0 + cx * aw / g,
        x0 + (cx + 1) * aw / g,
        y0 + cy * ah / g,
        y0 + (cy + 1) * ah / g,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_few_usable_samples_give_a_loud_warning() {
        let mut r = SampleReport {
            requested: 100,
            target: 128,
            used: 33,
            frames: 3,
            ..Default::default()
        };
        let w = r.shortfall_warning().unwrap();
        assert!(
            w.contains("33 of 128") && w.contains("66 observations"),
            "{w}"
        );
        r.used = 128;
        assert_eq!(r.shortfall_warning(), None);
    }
    use crate::bracket::Exposure;

    /// A `w × h` grey frame of exposure `t` s whose pixel `(x, y)` has code `code(x, y)`.
    pub(super) fn grey_frame(
        w: usize,
        h: usize,
        t: f64,
        code: impl Fn(usize, usize) -> u8,
    ) -> Frame {
        let mut v = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let z = code(x, y);
                v.extend_from_slice(&[z, z, z]);
            }
        }
        Frame {
            name: format!("t{t}"),
            width: w,
            height: h,
            pixels: Pixels::U8(v),
            exposure: Exposure {
                time_s: t,
                iso: None,
                f_number: None,
            },
        }
    }

    fn gradient_frames(w: usize, h: usize) -> Vec<Frame> {
        [0.25f64, 1.0, 4.0]
            .iter()
            .map(|&t| {
                grey_frame(w, h, t, |x, y| {
                    let e = (x + y) as f64 / (w + h) as f64;
                    (255.0 * (e * t).min(1.0)).round() as u8
                })
            })
            .collect()
    }

    /// Sampling on values gathered at the planned positions (and, when it asks, at the top-up's)
    /// draws what it draws on the whole frames: the grid with its quotas, top-up and code bands,
    /// the stratified draw, with and without a circle, on frames with a clipped half (rejections
    /// make the top-up run).
    #[test]
    fn gathered_values_sample_as_the_whole_frames() {
        let mut frames = gradient_frames(96, 80);
        for fr in &mut frames {
            if let Pixels::U8(v) = &mut fr.pixels {
                for y in 0..80 {
                    for x in 0..40 {
                        v[3 * (y * 96 + x)..3 * (y * 96 + x) + 3].fill(255);
                    }
                }
            }
        }
        let circle = Circle {
            cx: 48.0,
            cy: 40.0,
            r: 38.0,
        };
        let mut rounds_needed = 0;
        for (k, opts) in [
            SampleOptions::default(),
            SampleOptions::stratified(),
            SampleOptions {
                seed: 5,
                samples: 300,
                ..SampleOptions::default()
            },
            SampleOptions::seed_method(50, 5, 3),
        ]
        .into_iter()
        .enumerate()
        {
            for circle in [None, Some(circle)] {
                let whole = sample(&frames, circle, &opts).unwrap();
                let size = (96, 80);
                let plan = plan(size, frames.len(), circle, &opts).unwrap();
                let gather = |positions: &[(usize, usize)]| {
                    let mut g = Gathered::new(positions, frames.len(), opts.patch, size);
                    for (j, f) in frames.iter().enumerate() {
                        g.add_frame(j, &f.pixels);
                    }
                    g
                };
                // The plan, and every other position of it only: sampling then stops at
                // positions it needs and goes the same way once they are gathered.
                let sparse: Vec<(usize, usize)> = plan.iter().copied().step_by(2).collect();
                for (positions, most) in [(&plan, 8), (&sparse, 100_000)] {
                    let mut src = vec![gather(positions)];
                    let mut rounds = 0;
                    let got = loop {
                        match sample_from(&src, size, circle, &opts).unwrap() {
                            Ok(s) => break s,
                            Err(Missing(m)) => {
                                rounds += 1;
                                assert!(rounds < most, "case {k}: no end of rounds");
                                src.push(gather(&m));
                            }
                        }
                    };
                    rounds_needed += rounds;
                    assert_eq!(got, whole, "case {k}, circle {circle:?}");
                }
            }
        }
        assert!(
            rounds_needed > 0,
            "no case needed positions beyond the plan"
        );
    }

    #[test]
    fn splitmix_matches_reference_sequence() {
        // First outputs for seed 1234567 from the reference C implementation (Vigna).
        let mut r = SplitMix64::new(1234567);
        assert_eq!(r.next_u64(), 6457827717110365317);
        assert_eq!(r.next_u64(), 3203168211198807973);
    }

    #[test]
    fn seed_method_takes_exactly_n_samples_without_circle() {
        let f = gradient_frames(64, 48);
        let s = sample(&f, None, &SampleOptions::seed_method(137, 10, 7)).unwrap();
        assert_eq!(s.positions.len(), 137);
        assert_eq!(s.report.used, 137);
        assert_eq!(s.values.len(), 137 * 3);
    }

    #[test]
    fn same_seed_same_samples_other_seed_other_samples() {
        let f = gradient_frames(64, 48);
        let o = SampleOptions::default();
        let a = sample(&f, None, &o).unwrap();
        let b = sample(&f, None, &o).unwrap();
        let c = sample(&f, None, &SampleOptions { seed: 1, ..o }).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.positions, c.positions);
    }

    #[test]
    fn samples_stay_inside_the_circle() {
        let f = gradient_frames(80, 80);
        let circle = Circle {
            cx: 40.0,
            cy: 40.0,
            r: 30.0,
        };
        let s = sample(&f, Some(circle), &SampleOptions::seed_method(300, 10, 3)).unwrap();
        assert!(s
            .positions
            .iter()
            .all(|&(x, y)| circle.contains_pixel(x, y)));
        assert!(s.report.outside_circle > 0);
    }

    #[test]
    fn robust_raises_n_to_cover_256_unknowns() {
        let f = gradient_frames(64, 64);
        let s = sample(&f, None, &SampleOptions::default()).unwrap();
        assert_eq!(s.report.requested, 100);
        assert_eq!(s.report.target, 128);
        assert!(s.report.used * 2 >= 255, "used {}", s.report.used);
    }

    #[test]
    fn robust_rejects_pixels_clipped_in_all_frames() {
        let mut f = gradient_frames(64, 64);
        for fr in &mut f {
            if let Pixels::U8(v) = &mut fr.pixels {
                // Saturate the left half in every frame.
                for y in 0..64 {
                    for x in 0..32 {
                        v[3 * (y * 64 + x)..3 * (y * 64 + x) + 3].fill(255);
                    }
                }
            }
        }
        let s = sample(&f, None, &SampleOptions::default()).unwrap();
        assert!(s.report.rejected_clipped > 0);
        assert!(s.positions.iter().all(|&(x, _)| x >= 32));
    }

    #[test]
    fn absurd_options_are_errors() {
        let f = gradient_frames(8, 8);
        for o in [
            SampleOptions {
                samples: 0,
                ..Default::default()
            },
            SampleOptions {
                grid: 0,
                ..Default::default()
            },
            SampleOptions {
                edge_threshold: f32::NAN,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                sample(&f, None, &o),
                Err(SamplingError::BadOption(_))
            ));
        }
        assert_eq!(
            sample(&[], None, &SampleOptions::default()),
            Err(SamplingError::NoFrames)
        );
    }

    #[test]
    fn sixteen_bit_values_bin_to_256_levels() {
        assert_eq!(bin16(0), 0);
        assert_eq!(bin16(65535), 255);
        assert_eq!(bin16(257 * 100), 100);
        assert_eq!(bin16(257 * 100 + 128), 100);
        assert_eq!(bin16(257 * 100 + 129), 101);
    }
}
