//! Camera response calibration (Debevec & Malik 1997).
//!
//! A pixel value `Z` is a fixed, monotonic function of the sensor exposure `E · Δt`; Debevec &
//! Malik recover its log inverse `g(Z) = ln E + ln Δt` (natural log, one curve per colour
//! channel, `Z = 0..=255`) from `N` pixel positions seen in `P` frames.
//!
//! ## The system solved (per channel)
//! Unknowns `g(0..=255)` and `ln E_i` for each sample `i`. Rows, exactly as the seed states them:
//! - data, for each sample `i` and frame `j` with code `Z = Z_ij`:
//!   `w(Z) · (g(Z) − ln E_i − ln Δt_j) = 0`;
//! - smoothness, for `z = 1..=254`: `λ · w(z) · (g(z−1) − 2 g(z) + g(z+1)) = 0`;
//! - gauge: `g(128) = 0` (so radiances are relative), weighted `λ · 127` (any weight gives the
//!   same solution; this one keeps the system well conditioned).
//!
//! `w` is Debevec's hat, `w(z) = z` for `z ≤ 127`, `255 − z` above (zero at 0 and 255), and
//! `Δt_j` is [`Exposure::relative`](crate::bracket::Exposure::relative) (only ratios matter).
//! A fractional code (a patch mean, or a 16-bit value `v / 257`, see [`crate::sampling`]) uses
//! `w(z)` at that code and `g(z) = (1 − f)·g(⌊z⌋) + f·g(⌊z⌋ + 1)`; for integer codes the rows are
//! exactly the seed's.
//!
//! ## How it is solved
//! The seed solves the dense `(N·P + 255) × (256 + N)` system by SVD (≈120 ms for
//! `N = 100, P = 3`). The normal equations have an arrow structure: the `ln E_i` block is
//! diagonal, because each `ln E_i` only meets its own `P` data rows. Eliminating it (the Schur
//! complement, as AliceVision does) leaves one symmetric positive-definite 256 × 256 system per
//! channel, `S = A_gg − A_gE · D⁻¹ · A_Eg`, built in `O(N·P²)` and factored by Cholesky in
//! `O(256³/6)`, independent of `N`. Forming normal equations squares the condition number, so
//! one step of iterative refinement on the *full* least-squares residual (corrected
//! semi-normal equations, Björck 1987) follows; the result matches the dense SVD reference
//! ([`solve_dense_svd`]) to better than 1e-6 — a test proves it.
//!
//! After the solve, `g` is made non-decreasing (a running maximum from `z = 128` upwards and a
//! running minimum downwards): where no sample lands the smoothness term alone can bend the
//! curve backwards, and a decreasing `g` would map brighter codes to lower radiance. The number
//! of adjusted entries is reported.
//!
//! ## Linear and 16-bit responses
//! [`Response::linear`] is `g(z) = ln(max(z, ½) / 128)` for 8-bit codes and, for 16-bit values
//! `v`, `ln(max(v, ½) / (128 · 257))` exactly. A calibrated curve is evaluated at a 16-bit
//! value by linear interpolation of `g` at `v / 257` ([`Response::g16`]).
//!
//! ## Camera profiles
//! [`crate::camera::CameraProfile`] stores a response (with a noise model) as JSON; readers
//! check the `version`, lengths, finiteness and monotonicity ([`Response::from_curves`]).
//!
//! References: P. Debevec, J. Malik, *Recovering High Dynamic Range Radiance Maps from
//! Photographs*, SIGGRAPH 1997; Å. Björck, *Stability analysis of the method of seminormal
//! equations for linear least squares problems*, 1987.

use crate::bracket::Frame;
use crate::image::Circle;
use crate::sampling::{sample, SampleOptions, SampleReport, Samples, SamplingError};

/// Number of 8-bit codes.
pub const LEVELS: usize = 256;
/// The code whose `g` is fixed to zero.
pub const GAUGE: usize = 128;
/// The camera-profile format version ([`crate::camera::CameraProfile`]), defined here because
/// [`ResponseError::Version`] names it.
pub const PROFILE_VERSION: u32 = 1;
/// [`stability`] calls a calibration unstable when the RMS (over `z = 10..=245` and the three
/// channels) of the standard deviation of `g(z)` across runs exceeds this many natural-log
/// units (0.05 ≈ 5 % in radiance ≈ 0.07 stops): well above the spread of a good 8-bit bracket
/// (≈ 0.01–0.02 with the robust sampler), well below that of a bracket with too few usable
/// samples or moving content.
pub const STABILITY_THRESHOLD: f64 = 0.05;

/// Errors from calibration and profiles; each message says what to change.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ResponseError {
    /// Sampling failed.
    #[error(transparent)]
    Sampling(#[from] SamplingError),
    /// Fewer than two frames.
    #[error("calibration needs at least two frames with different exposures, got {0}")]
    TooFewFrames(usize),
    /// A frame's exposure is not a positive finite time, or frames are not sorted.
    #[error("frame {name:?} has relative exposure {value}: exposures must be positive, finite, distinct and sorted shortest first")]
    BadExposure {
        /// The frame.
        name: String,
        /// Its relative exposure.
        value: f64,
    },
    /// λ or another parameter is out of range.
    #[error("invalid calibration option: {0}")]
    BadOption(String),
    /// Every candidate sample was rejected, even with relaxed thresholds.
    #[error("no calibration sample is usable: of the pixels tried, {clipped} were clipped or black, {edge} at edges and {non_monotonic} not brighter in longer exposures (frames out of order, misaligned, or a moving scene); check the exposure times and alignment, or use a saved camera profile")]
    NoSamples {
        /// Rejected as clipped or black.
        clipped: usize,
        /// Rejected as edges.
        edge: usize,
        /// Rejected as non-monotonic.
        non_monotonic: usize,
    },
    /// The normal equations are singular (no usable variation in the samples).
    #[error("the response cannot be solved for channel {channel}: the samples do not vary enough (use more samples, a bracket with wider exposure steps, or a less clipped scene)")]
    Singular {
        /// Channel 0 = R, 1 = G, 2 = B.
        channel: usize,
    },
    /// A curve is malformed.
    #[error("invalid response curve for channel {channel}: {reason}")]
    BadCurve {
        /// Channel.
        channel: usize,
        /// What is wrong.
        reason: String,
    },
    /// A profile's JSON could not be parsed.
    #[error("camera profile is not valid JSON: {0} (re-create it with `skydome calibrate`)")]
    Json(String),
    /// A profile has an unsupported version.
    #[error("camera profile version {found} is not supported (this skydome reads version {PROFILE_VERSION}): re-calibrate or upgrade skydome")]
    Version {
        /// The version found.
        found: u32,
    },
}

/// Debevec's hat weight of an 8-bit code: `z` up to 127, `255 − z` above; zero at 0 and 255.
#[inline]
pub fn hat(z: u8) -> f64 {
    if z <= 127 {
        z as f64
    } else {
        (255 - z) as f64
    }
}

/// The hat at a continuous code `z ∈ [0, 255]`: `min(z, 255 − z)` (equals [`hat`] at integers).
#[inline]
pub fn hat_f(z: f64) -> f64 {
    z.min(255.0 - z).max(0.0)
}

/// Debevec & Malik's hat with its ends moved in by `margin` codes:
/// `max(0, min(z, 255 − z) − margin)`. `margin = 0` is [`hat_f`] (the seed's hat, `Z_min = 0`,
/// `Z_max = 255`); colour-hdri's `weighting_function_Debevec1997` (domain `[0.01, 0.99]` of
/// `z / 255`) is `margin = 2.55` up to a constant factor, which does not change the solve.
#[inline]
pub fn hat_margin(z: f64, margin: f64) -> f64 {
    (z.min(255.0 - z) - margin).max(0.0)
}

/// A data row's entries of `g` for a continuous code: `z` is split between `⌊z⌋` and `⌊z⌋ + 1`
/// by linear interpolation; returns `(z0, 1 − f, f)`.
#[inline]
fn split(z: f32) -> (usize, f64, f64) {
    let z = (z as f64).clamp(0.0, 255.0);
    let z0 = (z.floor() as usize).min(LEVELS - 2);
    let f = z - z0 as f64;
    (z0, 1.0 - f, f)
}

/// A camera response: per channel, `g(z) = ln(exposure)` for codes `z = 0..=255` (natural log,
/// `g(128) = 0` for calibrated curves), non-decreasing.
#[derive(Debug, Clone, PartialEq)]
pub struct Response {
    g: [Vec<f64>; 3],
    linear: bool,
}

impl Response {
    /// A response from three 256-entry curves (R, G, B), checked: right length, finite,
    /// non-decreasing.
    pub fn from_curves(g: [Vec<f64>; 3]) -> Result<Self, ResponseError> {
        for (c, curve) in g.iter().enumerate() {
            check_curve(c, curve)?;
        }
        Ok(Self { g, linear: false })
    }

    /// The linear response `g(z) = ln(max(z, ½) / 128)` (e.g. RAW-derived TIFFs); 16-bit values
    /// use the exact `ln(max(v, ½) / (128 · 257))`.
    pub fn linear() -> Self {
        let curve: Vec<f64> = (0..LEVELS)
            .map(|z| ((z as f64).max(0.5) / GAUGE as f64).ln())
            .collect();
        Self {
            g: [curve.clone(), curve.clone(), curve],
            linear: true,
        }
    }

    /// True for [`Response::linear`].
    pub fn is_linear(&self) -> bool {
        self.linear
    }

    /// The 256-entry curve of channel `c` (0 = R, 1 = G, 2 = B; panics for `c > 2`).
    pub fn curve(&self, c: usize) -> &[f64] {
        &self.g[c]
    }

    /// All three curves.
    pub fn curves(&self) -> &[Vec<f64>; 3] {
        &self.g
    }

    /// `g` of channel `c` at a 16-bit value `v`: exact for a linear response, otherwise linear
    /// interpolation of the 8-bit curve at `v / 257`.
    pub fn g16(&self, c: usize, v: u16) -> f64 {
        if self.linear {
            return ((v as f64).max(0.5) / (GAUGE as f64 * 257.0)).ln();
        }
        let z = v as f64 / 257.0;
        let i = (z.floor() as usize).min(LEVELS - 2);
        let f = z - i as f64;
        self.g[c][i] * (1.0 - f) + self.g[c][i + 1] * f
    }
}

fn check_curve(c: usize, curve: &[f64]) -> Result<(), ResponseError> {
    let bad = |reason: String| ResponseError::BadCurve { channel: c, reason };
    if curve.len() != LEVELS {
        return Err(bad(format!("{} values, expected 256", curve.len())));
    }
    if let Some(z) = curve.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!("g({z}) is not finite")));
    }
    if let Some(z) = curve.windows(2).position(|w| w[1] < w[0]) {
        return Err(bad(format!(
            "g decreases from {} at z={} to {} at z={} (a response must be non-decreasing)",
            curve[z],
            z,
            curve[z + 1],
            z + 1
        )));
    }
    Ok(())
}

/// Which solver [`calibrate`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Solver {
    /// Schur complement + Cholesky + one refinement step (default, fast).
    #[default]
    Schur,
    /// The seed's dense SVD of the full system (slow; a reference).
    DenseSvd,
}

crate::named_enum!(Solver, "solver", [Schur => "schur", DenseSvd => "svd"]);

/// How the curve is fitted to the samples (see the module docs, "The noise-weighted fit").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Fit {
    /// Debevec & Malik's least squares with the hat weight, as the seed (default).
    #[default]
    Hat,
    /// Iterated reweighted least squares: weights from the noise the residuals show at each
    /// code, observations beyond [`CalibrateOptions::outlier_sigmas`] standard deviations
    /// dropped, as are observations near 255 that the pixel's shorter frames show clipped.
    Noise,
}

crate::named_enum!(Fit, "fit", [Hat => "hat", Noise => "noise"]);

/// Calibration options.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrateOptions {
    /// Sample selection.
    pub sampling: SampleOptions,
    /// Smoothness weight λ (> 0). Default 30, as colour-hdri (OpenCV uses 10); 100 in
    /// [`CalibrateOptions::noise_fit`] for its 2000 stratified samples and the noise-weighted fit (chosen on the oracle's tuning brackets: mean ratio to the oracle 1.05
    /// at λ = 100, 1.35 at 30, 2.5 at 10 — with twenty times the seed's samples, the data rows
    /// outweigh a smoothness term sized for 100); colour-hdri uses 30 for its 1000
    /// samples, OpenCV 10 for 70. The data rows' weights are scaled to the hat's size, so λ
    /// means the same for both fits.
    pub lambda: f64,
    /// Solver.
    pub solver: Solver,
    /// How the data rows are weighted.
    #[serde(default)]
    pub fit: Fit,
    /// Codes by which the hat's ends move in ([`hat_margin`]; `0..127`, default 0, the seed's
    /// hat). colour-hdri's hat is 2.55: codes 0–2 and 253–255 then get no weight in the data
    /// or smoothness rows (the curve there is the linear continuation of its neighbours).
    /// Used by the hat fit.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hat_margin: f64,
    /// The noise-weighted fit's outlier cut, in standard deviations of an observation's code
    /// band: an observation whose residual lies farther out gets no weight in the next pass
    /// (a pixel that moved, a flicker). [`OUTLIER_SIGMAS`] (4) by default and in
    /// [`CalibrateOptions::noise_fit`]; [`COVERING_OUTLIER_SIGMAS`] (5) in
    /// [`CalibrateOptions::covering`]. Not used by the hat fit.
    #[serde(default = "default_outlier_sigmas")]
    pub outlier_sigmas: f64,
    /// Brackets of at least this many frames are calibrated with
    /// [`CalibrateOptions::covering`] instead of these options (their sample seed and solver
    /// kept; see [`CalibrateOptions::for_frames`]): `Some(`[`COVERING_FROM_FRAMES`]`)` in the
    /// default, `None` — these options at every frame count — in every named method
    /// ([`CalibrateOptions::robust`], [`CalibrateOptions::covering`], …). Options read
    /// without the field take the default's.
    #[serde(default = "default_covering_from")]
    pub covering_from: Option<usize>,
    /// The grid calibration's toe under this calibration's curve (issue 27, docs/accuracy.md
    /// "Eighth round"): with `Some([a, b])` (codes), [`calibrate`] also fits
    /// [`CalibrateOptions::robust`] (with this sample seed and solver), and the curve's slopes
    /// `g(z+1) − g(z)` are the grid fit's below code `a` and these options' from code `b` up,
    /// blended linearly between ([`join_toe`]). Where these options' own draw or fit fails the
    /// grid fit's curve is used alone ([`Calibration::grid_alone`]). `None` (no join) in every
    /// method but [`CalibrateOptions::joined`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub toe_from_grid: Option<[u8; 2]>,
    /// The step-periodic correction (issue 27, docs/accuracy.md "Eleventh" and "Twelfth
    /// round"): on a wide-step bracket ([`is_wide_step`], a mean step of at least
    /// [`WIDE_STEP_EV`] EV) the fitted curve's component periodic in `g` with the bracket's mean
    /// step as period — invisible to frames that far apart — is removed
    /// ([`remove_step_periodic`], fitted on codes [`STEP_PERIODIC_LO`] up to
    /// [`STEP_PERIODIC_HI`]), and the merge fits its noise model from codes
    /// [`crate::noise::WIDE_STEP_NOISE_LO`] up ([`Calibration::wide_step`]).
    ///
    /// `None` (every named method) is the rule of [`CalibrateOptions::step_periodic_applies`]:
    /// on with the covering calibration from [`COVERING_FROM_FRAMES`] frames (so the
    /// default's), off otherwise. `Some(v)` is asked for and wins over the rule, through
    /// [`CalibrateOptions::for_frames`] too. Not written when `None`, so options written before
    /// it read and write as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_periodic: Option<bool>,
}

fn default_outlier_sigmas() -> f64 {
    OUTLIER_SIGMAS
}

fn default_covering_from() -> Option<usize> {
    Some(COVERING_FROM_FRAMES)
}

/// The frame count from which the default calibration is the covering one
/// ([`CalibrateOptions::covering_from`]). Measured on the oracle's brackets (issue 27,
/// docs/accuracy.md "Sixth round"): from 5 frames the covering calibration's sky is 1.01–1.05×
/// the oracle's on held-out seeds where the grid calibration's is 1.04–1.26×, and its dim
/// ground is level; at 2–4 frames it still reads some dim grounds 0.5–1 stop worse than the
/// grid calibration, whose curve is kept there.
pub const COVERING_FROM_FRAMES: usize = 5;

/// The codes between which [`CalibrateOptions::joined`] passes from the grid calibration's
/// slopes to the covering calibration's ([`CalibrateOptions::toe_from_grid`]). On the oracle's
/// held-out brackets of 2, 3 and 4 frames the mean sky ratio to the oracle is 1.087 1.059 1.049
/// (the grid calibration alone 1.172 1.125 1.117); on real 2–4-frame sub-brackets of the
/// 7–11-frame real sets, against the whole bracket's merge, it reads level with the grid
/// calibration (docs/accuracy.md, "Eighth round").
pub const JOINED_TOE: [u8; 2] = [128, 192];

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Default for CalibrateOptions {
    /// The covering calibration for brackets of [`COVERING_FROM_FRAMES`] frames or more,
    /// [`CalibrateOptions::robust`] for fewer (`skydome calibrate --method auto`).
    fn default() -> Self {
        Self {
            covering_from: Some(COVERING_FROM_FRAMES),
            ..Self::robust()
        }
    }
}

impl CalibrateOptions {
    /// Robust grid sampling ([`SampleOptions::default`]), λ = 30, Schur solver, the hat fit, at
    /// every frame count (the default before issue 27; `skydome calibrate --method robust`).
    pub fn robust() -> Self {
        Self {
            sampling: SampleOptions::default(),
            lambda: SEED_LAMBDA,
            solver: Solver::Schur,
            fit: Fit::Hat,
            hat_margin: 0.0,
            outlier_sigmas: OUTLIER_SIGMAS,
            covering_from: None,
            toe_from_grid: None,
            step_periodic: None,
        }
    }

    /// The options a bracket of `frames` frames is calibrated with: while
    /// [`CalibrateOptions::covering_from`] is set (the default), [`CalibrateOptions::covering`]
    /// from that many frames and [`CalibrateOptions::joined`] below (either with these options'
    /// sample seed and solver); else these options. Either way with `covering_from` `None`, so
    /// the result resolves to itself. An asked-for [`CalibrateOptions::step_periodic`] that the
    /// resolved method's rule would give anyway at `frames` frames is dropped (`None`), so the
    /// result names its method as [`CalibrateOptions::method_name`] would without the ask.
    pub fn for_frames(&self, frames: usize) -> Self {
        let mut c = match self.covering_from {
            Some(from) => {
                let mut c = if frames >= from {
                    Self::covering()
                } else {
                    Self::joined()
                };
                c.sampling.seed = self.sampling.seed;
                c.solver = self.solver;
                c
            }
            None => Self {
                covering_from: None,
                step_periodic: None,
                ..self.clone()
            },
        };
        if let Some(v) = self.step_periodic {
            if v != c.step_periodic_applies(frames) {
                c.step_periodic = Some(v);
            }
        }
        c
    }

    /// The name `skydome calibrate --method` gives these options: `auto` while
    /// [`CalibrateOptions::covering_from`] is set (resolve it with
    /// [`CalibrateOptions::for_frames`] first); else the method whose draw these options use —
    /// `colour-hdri` (histogram samples), `seed` (no rejections), `joined` (the covering draw
    /// with the grid's toe), `covering` (the covering draw), `noise` (the stratified draw) or
    /// `robust` (the grid draw) — followed by
    /// ` (options changed)` unless every option is that method's (the sample seed and solver
    /// may differ; the seed method's sample count, grid and λ too).
    pub fn method_name(&self) -> String {
        if self.covering_from.is_some() {
            return "auto".into();
        }
        let s = &self.sampling;
        let (name, named) = if s.histogram {
            ("colour-hdri", Self::colour_hdri())
        } else if !s.reject {
            (
                "seed",
                Self::seed_method(s.samples, s.grid, s.seed, self.lambda, self.solver),
            )
        } else if s.cover > 0 && self.toe_from_grid.is_some() {
            ("joined", Self::joined())
        } else if s.cover > 0 {
            ("covering", Self::covering())
        } else if s.stratify > 0 {
            ("noise", Self::noise_fit())
        } else {
            ("robust", Self::robust())
        };
        let mut n = named;
        n.sampling.seed = s.seed;
        n.solver = self.solver;
        if n == *self {
            name.into()
        } else {
            format!("{name} (options changed)")
        }
    }

    /// Whether [`CalibrateOptions::step_periodic`] applies to a wide-step bracket of `frames`
    /// frames: as asked, else the covering calibration's rule — the covering draw without the
    /// grid's toe, from [`COVERING_FROM_FRAMES`] frames (measured there; on 2–4 frames it read
    /// some dim grounds worse, docs/accuracy.md "Twelfth round").
    pub fn step_periodic_applies(&self, frames: usize) -> bool {
        self.step_periodic.unwrap_or(
            self.sampling.cover > 0
                && self.toe_from_grid.is_none()
                && frames >= COVERING_FROM_FRAMES,
        )
    }

    /// The calibration that uses the data (issue 27): 2000 samples stratified over the middle
    /// frame's codes ([`SampleOptions::stratified`]), the noise-weighted fit ([`Fit::Noise`]),
    /// λ = [`NOISE_FIT_LAMBDA`]. `skydome calibrate --method noise`.
    pub fn noise_fit() -> Self {
        Self {
            sampling: SampleOptions::stratified(),
            lambda: NOISE_FIT_LAMBDA,
            solver: Solver::Schur,
            fit: Fit::Noise,
            hat_margin: 0.0,
            outlier_sigmas: OUTLIER_SIGMAS,
            covering_from: None,
            toe_from_grid: None,
            step_periodic: None,
        }
    }

    /// The covering calibration (issue 27): 2000 samples spread over 16 code bands of every
    /// frame and channel ([`SampleOptions::covering`]; codes from 1 count as measured, so the
    /// darkest codes of the longest frame are sampled too), the noise-weighted fit
    /// ([`Fit::Noise`]), λ = [`COVERING_LAMBDA`], and on wide-step brackets of 5 frames or
    /// more the step-periodic correction ([`CalibrateOptions::step_periodic_applies`];
    /// docs/accuracy.md "Twelfth round"). `skydome calibrate --method covering`.
    ///
    /// Chosen on the oracle's tuning brackets (seeds 1–3 and 11–22, see
    /// `tests/lib/oracle.rs`): mean sky ratio to the oracle with the noise merge, 2–9 frames,
    /// 1.046 1.024 1.015 1.034 1.056 1.060 1.027 1.053 on seeds 11–22 (stratified draw, λ 100:
    /// 1.063 1.024 1.017 1.049 1.104 1.066 1.037 1.073), and no bracket's sky worse than on the
    /// default calibration's curve. Its dim ground is no better than the stratified draw's: on
    /// 2–4-frame brackets the toe below the codes both ends of a sample measure is still
    /// extrapolated, and the grid calibration (hat fit, λ 30) reads it better on some
    /// brackets. So the default calibration uses it from [`COVERING_FROM_FRAMES`] frames,
    /// where that loss is gone, and the grid below; its outlier cut is
    /// [`COVERING_OUTLIER_SIGMAS`] (docs/accuracy.md, "Sixth round").
    pub fn covering() -> Self {
        Self {
            sampling: SampleOptions::covering(),
            lambda: COVERING_LAMBDA,
            solver: Solver::Schur,
            fit: Fit::Noise,
            hat_margin: 0.0,
            outlier_sigmas: COVERING_OUTLIER_SIGMAS,
            covering_from: None,
            toe_from_grid: None,
            step_periodic: None,
        }
    }

    /// The covering calibration with the grid calibration's toe: [`CalibrateOptions::covering`]
    /// with [`CalibrateOptions::toe_from_grid`] `Some(`[`JOINED_TOE`]`)`, the default below
    /// [`COVERING_FROM_FRAMES`] frames (`skydome calibrate --method joined`). The covering
    /// curve meets the oracle's sky targets at 2–4 frames but extrapolates the toe below the
    /// codes a sample reads in two frames; the grid calibration reads that toe better on the
    /// oracle's dim grounds (docs/accuracy.md, "Seventh round" and "Eighth round").
    pub fn joined() -> Self {
        Self {
            toe_from_grid: Some(JOINED_TOE),
            ..Self::covering()
        }
    }

    /// The grid calibration [`CalibrateOptions::toe_from_grid`] takes the toe from: the
    /// robust method with these options' sample seed and solver.
    fn toe_options(&self) -> Self {
        let mut g = Self::robust();
        g.sampling.seed = self.sampling.seed;
        g.solver = self.solver;
        g
    }

    /// The seed's calibration exactly: its sampling ([`SampleOptions::seed_method`]), the hat
    /// fit, λ and solver as given.
    pub fn seed_method(
        samples: usize,
        grid: usize,
        seed: u64,
        lambda: f64,
        solver: Solver,
    ) -> Self {
        Self {
            sampling: SampleOptions::seed_method(samples, grid, seed),
            lambda,
            solver,
            fit: Fit::Hat,
            hat_margin: 0.0,
            outlier_sigmas: OUTLIER_SIGMAS,
            covering_from: None,
            toe_from_grid: None,
            step_periodic: None,
        }
    }

    /// colour-hdri's `camera_response_functions_Debevec1997` with its defaults: 1000
    /// histogram samples ([`SampleOptions::histogram_method`]), λ = 30 and its hat
    /// ([`hat_margin`] 2.55).
    pub fn colour_hdri() -> Self {
        Self {
            sampling: SampleOptions::histogram_method(COLOUR_HDRI_SAMPLES),
            lambda: SEED_LAMBDA,
            solver: Solver::Schur,
            fit: Fit::Hat,
            hat_margin: COLOUR_HDRI_HAT_MARGIN,
            outlier_sigmas: OUTLIER_SIGMAS,
            covering_from: None,
            toe_from_grid: None,
            step_periodic: None,
        }
    }
}

/// Samples of colour-hdri's histogram sampling (`samples_Grossberg2003`).
pub const COLOUR_HDRI_SAMPLES: usize = 1000;
/// colour-hdri's hat in codes: its domain `[0.01, 0.99]` of `z / 255`.
pub const COLOUR_HDRI_HAT_MARGIN: f64 = 2.55;

/// A calibration result.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The recovered response (non-decreasing, `g(128) = 0`).
    pub response: Response,
    /// The curves as solved, before the monotonic fix.
    pub raw_curves: [Vec<f64>; 3],
    /// Entries changed by the monotonic fix, per channel.
    pub monotonic_fixes: [usize; 3],
    /// The samples used.
    pub samples: Samples,
    /// `ln E_i` per channel and sample (0 for a sample with no weighted observation).
    pub log_irradiance: [Vec<f64>; 3],
    /// `ln Δt_j` (relative exposure) per frame.
    pub log_times: Vec<f64>,
    /// λ used.
    pub lambda: f64,
    /// True when a joined calibration ([`CalibrateOptions::toe_from_grid`]) gives the grid
    /// fit's curve alone, its own draw or fit having failed (a bracket whose few frames or wide
    /// steps leave the covering draw too little to solve); the samples, `ln E` and raw curves
    /// are then the grid fit's. Otherwise a joined calibration's samples, `ln E`, raw curves
    /// and monotonic fixes are its own fit's, and only `response` carries the grid's toe.
    pub grid_alone: bool,
    /// True when the step-periodic correction was applied
    /// ([`CalibrateOptions::step_periodic`] on a bracket whose mean step is at least
    /// [`WIDE_STEP_EV`] EV): `response` is then the fitted curve less its step-periodic
    /// component ([`remove_step_periodic`]), and the merge should fit its noise model from
    /// codes [`crate::noise::WIDE_STEP_NOISE_LO`] up ([`crate::noise::estimate_from_code`]).
    pub wide_step: bool,
}

impl Calibration {
    /// What sampling did.
    pub fn report(&self) -> &SampleReport {
        &self.samples.report
    }

    /// Plot coordinates for channel `c`: for every sample `i` and frame `j` with a non-zero
    /// weight, `x = ln E_i + ln Δt_j` (log exposure) and `y = Z_ij` (code). Returns `(x, y)`.
    pub fn plot_points(&self, c: usize) -> (Vec<f64>, Vec<f64>) {
        let s = &self.samples;
        let mut xs = Vec::with_capacity(s.count() * s.frames);
        let mut ys = Vec::with_capacity(xs.capacity());
        for i in 0..s.count() {
            for j in 0..s.frames {
                let z = s.z(i, j, c);
                if hat_f(z as f64) > 0.0 {
                    xs.push(self.log_irradiance[c][i] + self.log_times[j]);
                    ys.push(z as f64);
                }
            }
        }
        (xs, ys)
    }
}

/// `ln Δt_j` for frames that must be sorted by strictly increasing relative exposure.
pub(crate) fn log_times(frames: &[Frame]) -> Result<Vec<f64>, ResponseError> {
    let mut out = Vec::with_capacity(frames.len());
    let mut prev = 0.0f64;
    for f in frames {
        let t = f.exposure.relative();
        if !(t.is_finite() && t > 0.0 && t > prev) {
            return Err(ResponseError::BadExposure {
                name: f.name.clone(),
                value: t,
            });
        }
        prev = t;
        out.push(t.ln());
    }
    Ok(out)
}

/// Calibrates the response from `frames` (sorted shortest exposure first, same size), sampling
/// inside `circle` when given.
pub fn calibrate(
    frames: &[Frame],
    circle: Option<Circle>,
    opts: &CalibrateOptions,
) -> Result<Calibration, ResponseError> {
    let opts = &opts.for_frames(frames.len());
    let lt = checked_log_times(frames, opts)?;
    if let Some(toe) = opts.toe_from_grid {
        let g = opts.toe_options();
        let (grid, own) = side_by_side(
            || fit_drawn(sample(frames, circle, &g.sampling)?, &lt, &g),
            || {
                sample(frames, circle, &opts.sampling)
                    .map_err(ResponseError::from)
                    .and_then(|s| fit_drawn(s, &lt, opts))
            },
        );
        return Ok(joined(own, grid?, toe));
    }
    let samples = sample(frames, circle, &opts.sampling)?;
    fit_drawn(samples, &lt, opts)
}

/// A joined calibration ([`CalibrateOptions::toe_from_grid`]) with its samples drawn already
/// (as [`calibrate_with_samples`]): `own`, the draw of `opts` itself (or why it failed), and
/// `grid`, the draw of its grid calibration ([`CalibrateOptions::robust`] with the seed of
/// `opts`).
pub(crate) fn calibrate_joined_with_samples(
    frames: &[Frame],
    own: Result<Samples, ResponseError>,
    grid: Samples,
    opts: &CalibrateOptions,
) -> Result<Calibration, ResponseError> {
    let lt = checked_log_times(frames, opts)?;
    let g = opts.toe_options();
    let (grid, own) = side_by_side(
        || fit_drawn(grid, &lt, &g),
        || own.and_then(|s| fit_drawn(s, &lt, opts)),
    );
    let grid = grid?;
    Ok(match opts.toe_from_grid {
        Some(toe) => joined(own, grid, toe),
        None => own?,
    })
}

/// `(a(), b())`, the two run side by side with the `parallel` feature, one after the other
/// without it; the results are the same either way. The joined calibration's two draws and fits
/// are independent and each is mostly serial (the covering draw's lattice is parallel, its
/// draw and both fits are not): side by side, the command line's calibrating stage on
/// 3 × 12 MP with two threads went from 0.042 to 0.034 s (medians of six alternated runs).
fn side_by_side<A: Send, B: Send>(
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (a(), b())
    }
}

/// The draw of [`CalibrateOptions::toe_from_grid`]'s grid calibration for `opts` (the robust
/// method's sampling with the seed of `opts`), `None` when `opts` joins no toe.
pub(crate) fn toe_sampling(opts: &CalibrateOptions) -> Option<SampleOptions> {
    opts.toe_from_grid.map(|_| opts.toe_options().sampling)
}

/// `own` with the toe of `grid` below codes `a..b` ([`join_toe`], per channel), or `grid`
/// alone ([`Calibration::grid_alone`]) when `own` failed.
fn joined(
    own: Result<Calibration, ResponseError>,
    grid: Calibration,
    [a, b]: [u8; 2],
) -> Calibration {
    let Ok(mut cal) = own else {
        return Calibration {
            grid_alone: true,
            ..grid
        };
    };
    let curves = cal.response.curves();
    let toe = grid.response.curves();
    let blended = [0, 1, 2].map(|c| join_toe(&curves[c], &toe[c], a as usize, b as usize));
    match Response::from_curves(blended) {
        Ok(r) => {
            cal.response = r;
            cal
        }
        // Blended slopes of two non-decreasing curves never decrease; kept as a guard.
        Err(_) => Calibration {
            grid_alone: true,
            ..grid
        },
    }
}

/// `curve` with the toe of `toe` (one channel each, 256 entries, `g(z)` in natural log units):
/// the slopes `g(z+1) − g(z)` are `toe`'s below code `a`, `curve`'s from code `b` up, blended
/// linearly between (`a == b`: `toe`'s below `a`), and the result is shifted so that `g(128)`
/// is `curve`'s (the gauge, 0 in a calibration's curve). Both non-decreasing gives a
/// non-decreasing result. `a` and `b` are clamped to `a ≤ b ≤` the curves' last code.
pub fn join_toe(curve: &[f64], toe: &[f64], a: usize, b: usize) -> Vec<f64> {
    let n = curve.len().min(toe.len());
    let b = b.min(n.saturating_sub(1));
    let a = a.min(b);
    let mut out = curve.to_vec();
    for z in (0..b).rev() {
        let w = if z < a || b == a {
            0.0
        } else {
            (z - a) as f64 / (b - a) as f64
        };
        let slope = w * (curve[z + 1] - curve[z]) + (1.0 - w) * (toe[z + 1] - toe[z]);
        out[z] = out[z + 1] - slope;
    }
    if let (Some(&want), Some(&got)) = (curve.get(GAUGE), out.get(GAUGE)) {
        let shift = want - got;
        out.iter_mut().for_each(|v| *v += shift);
    }
    out
}

/// [`calibrate`] with the samples drawn already (by [`crate::sampling::sample_from`] on what
/// was gathered while the frames were decoded one at a time): the same checks and fit.
pub(crate) fn calibrate_with_samples(
    frames: &[Frame],
    samples: Samples,
    opts: &CalibrateOptions,
) -> Result<Calibration, ResponseError> {
    let lt = checked_log_times(frames, opts)?;
    fit_drawn(samples, &lt, opts)
}

/// The checks [`calibrate`] and [`calibrate_with_samples`] make before sampling: two frames
/// at least, usable exposure times, a usable smoothness weight; the frames' `ln Δt`.
fn checked_log_times(frames: &[Frame], opts: &CalibrateOptions) -> Result<Vec<f64>, ResponseError> {
    if frames.len() < 2 {
        return Err(ResponseError::TooFewFrames(frames.len()));
    }
    let lt = log_times(frames)?;
    check_lambda(opts.lambda)?;
    Ok(lt)
}

/// The fit shared by [`calibrate`] and [`calibrate_with_samples`] once the samples are drawn:
/// none drawn is an error saying why, else [`calibrate_samples_with`] (every option, the hat's
/// margin included, so a streamed run fits the same curve as a whole one).
fn fit_drawn(
    samples: Samples,
    lt: &[f64],
    opts: &CalibrateOptions,
) -> Result<Calibration, ResponseError> {
    if samples.count() == 0 {
        let r = &samples.report;
        return Err(ResponseError::NoSamples {
            clipped: r.rejected_clipped,
            edge: r.rejected_edge,
            non_monotonic: r.rejected_non_monotonic,
        });
    }
    let mut cal = calibrate_samples_with(samples, lt, opts)?;
    if opts.step_periodic_applies(lt.len()) && is_wide_step(lt) {
        let step = mean_step_ev(lt) * std::f64::consts::LN_2;
        let curves = cal.response.curves();
        let fixed = [0, 1, 2].map(|c| remove_step_periodic(&curves[c], step, STEP_PERIODIC_LO));
        cal.response = Response::from_curves(fixed)?;
        cal.wide_step = true;
    }
    Ok(cal)
}

/// The mean step from which a bracket counts as wide-step ([`is_wide_step`]), EV: brackets
/// 3 EV apart are (docs/accuracy.md, "Eighth round, second part" and "Eleventh round").
pub const WIDE_STEP_EV: f64 = 2.5;

/// The code from which [`remove_step_periodic`] fits and removes the step-periodic component
/// in calibration ([`CalibrateOptions::step_periodic`]); the toe below it is left to the fit.
pub const STEP_PERIODIC_LO: usize = 24;

/// The mean step of a bracket from its frames' `ln Δt` (sorted, shortest first), in EV:
/// `(ln Δt_last − ln Δt_first) / (P − 1) / ln 2`, the mean of `log2(Δt_{j+1} / Δt_j)`; 0 for
/// fewer than two frames.
pub fn mean_step_ev(log_times: &[f64]) -> f64 {
    match log_times {
        [first, .., last] => (last - first) / (log_times.len() - 1) as f64 / std::f64::consts::LN_2,
        _ => 0.0,
    }
}

/// True when a bracket's mean step ([`mean_step_ev`], from its frames' `ln Δt`) is at least
/// [`WIDE_STEP_EV`] EV (within 1e-9).
pub fn is_wide_step(log_times: &[f64]) -> bool {
    mean_step_ev(log_times) >= WIDE_STEP_EV - 1e-9
}

/// The code below which [`remove_step_periodic`] fits the step-periodic component: the top
/// band, codes 240–254 (and the clipped 255), is left out of the fit, though the harmonic is
/// removed there too. The curve is least certain next to clipping (on 9 × 3 EV brackets its
/// error there reaches 0.8 stop, docs/accuracy.md "Twelfth round"), and a harmonic fitted
/// through that error took it into the middle codes the sky reads.
pub const STEP_PERIODIC_HI: usize = 240;

/// Reweighting passes of [`remove_step_periodic`]: each takes the harmonic's phase from the
/// curve corrected by the previous pass.
const STEP_PERIODIC_PASSES: usize = 3;

/// `curve` (one channel, `g(z)` in natural log units, `z` = 0, 1, …) less its component
/// periodic in `g` with period `step` (natural log units; the bracket's mean step
/// `ln(Δt_{j+1} / Δt_j)`). Frames `step` apart constrain only `g(φ(z)) − g(z) = step`, where
/// `φ` maps a code to the code the same radiance reads one frame later, so such a component
/// costs the data nothing and the smoothness little (docs/accuracy.md, "Eighth round, second
/// part").
///
/// On codes `lo..min(STEP_PERIODIC_HI, len − 1)` (the top band [`STEP_PERIODIC_HI`]–254 and
/// the last code, often clipped, left out of the fit) the curve is fitted by least squares as
/// a smooth model — a cubic in `z` plus a multiple of `ln z` — plus one harmonic
/// `a·sin(2π g/step) + b·cos(2π g/step)`; only the harmonic is subtracted, from `lo` up, and
/// linearly faded to zero from code `lo` down to code 0 (so the curve stays continuous). The
/// harmonic's phase is taken from the curve itself, then from the corrected curve
/// ([`STEP_PERIODIC_PASSES`] passes). The result keeps `curve`'s value at [`GAUGE`] and
/// is made non-decreasing (as the fit's curves are). A curve too short to fit (fewer than 16
/// codes to fit from `lo`) or a `step` that is not finite and positive gives `curve`
/// unchanged, as does a singular fit.
pub fn remove_step_periodic(curve: &[f64], step: f64, lo: usize) -> Vec<f64> {
    let Some(harmonic) = periodic_harmonic(curve, step, lo) else {
        return curve.to_vec();
    };
    let mut fixed: Vec<f64> = curve.iter().zip(&harmonic).map(|(g, h)| g - h).collect();
    let shift = curve[GAUGE] - fixed[GAUGE];
    fixed.iter_mut().for_each(|v| *v += shift);
    // Exactly the gauge's value (the shift can leave a rounding error there).
    fixed[GAUGE] = curve[GAUGE];
    make_monotonic(&fixed).0
}

/// The harmonic of period `period` (natural log units of `g`) that [`remove_step_periodic`]
/// fits to `curve` from code `lo` up, per code (ln; faded linearly to zero below `lo`):
/// `None` where the curve is too short, not finite, or the fit is singular.
pub fn periodic_harmonic(curve: &[f64], period: f64, lo: usize) -> Option<Vec<f64>> {
    let n = curve.len();
    if !(period.is_finite() && period > 0.0)
        || n <= 1
        || STEP_PERIODIC_HI.min(n - 1) < lo.max(1) + 16
        || n <= GAUGE
        || curve.iter().any(|v| !v.is_finite())
    {
        return None;
    }
    let lo_fit = lo.max(1);
    let hi_fit = STEP_PERIODIC_HI.min(n - 1);
    let w = std::f64::consts::TAU / period;
    let mut phase_from = curve.to_vec();
    let mut harmonic = vec![0.0; n];
    for _ in 0..STEP_PERIODIC_PASSES {
        let basis = |z: usize, g: f64| -> [f64; 7] {
            let t = (z as f64 - 128.0) / 128.0;
            [
                1.0,
                t,
                t * t,
                t * t * t,
                (z as f64 / 128.0).ln(),
                (w * g).sin(),
                (w * g).cos(),
            ]
        };
        let mut ata = [[0.0f64; 7]; 7];
        let mut aty = [0.0f64; 7];
        for z in lo_fit..hi_fit {
            let b = basis(z, phase_from[z]);
            for r in 0..7 {
                aty[r] += b[r] * curve[z];
                for k in 0..7 {
                    ata[r][k] += b[r] * b[k];
                }
            }
        }
        let x = solve_small(ata, aty)?;
        let h = |g: f64| x[5] * (w * g).sin() + x[6] * (w * g).cos();
        let at_lo = h(phase_from[lo_fit]);
        for (z, v) in harmonic.iter_mut().enumerate() {
            *v = if z >= lo_fit {
                h(phase_from[z])
            } else {
                at_lo * z as f64 / lo_fit as f64
            };
        }
        phase_from = curve.iter().zip(&harmonic).map(|(g, h)| g - h).collect();
    }
    Some(harmonic)
}

/// Solves the symmetric system `a · x = b` (7 unknowns) by nalgebra's LU with partial
/// pivoting; `None` when it is singular (a pivot below 1e-12 of the largest diagonal entry).
fn solve_small(a: [[f64; 7]; 7], b: [f64; 7]) -> Option<[f64; 7]> {
    let m = nalgebra::SMatrix::<f64, 7, 7>::from_fn(|r, k| a[r][k]);
    let scale = m.diagonal().amax();
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let lu = m.lu();
    if lu.u().diagonal().iter().any(|p| p.abs() <= 1e-12 * scale) {
        return None;
    }
    let x = lu.solve(&nalgebra::SVector::<f64, 7>::from(b))?;
    let x: [f64; 7] = x.into();
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn check_lambda(lambda: f64) -> Result<(), ResponseError> {
    if !(lambda.is_finite() && lambda > 0.0 && lambda <= 1e6) {
        return Err(ResponseError::BadOption(format!(
            "lambda = {lambda} (use a positive smoothness weight up to 1e6; 10 is typical)"
        )));
    }
    Ok(())
}

/// Solves all three channels from given samples and `ln Δt_j` with the hat fit (the seed's).
pub fn calibrate_samples(
    samples: Samples,
    log_times: &[f64],
    lambda: f64,
    solver: Solver,
) -> Result<Calibration, ResponseError> {
    calibrate_samples_fit(samples, log_times, lambda, solver, Fit::Hat)
}

/// Solves all three channels from given samples and `ln Δt_j` as `opts` says (its λ, solver,
/// fit and hat margin; its sampling is not used).
pub fn calibrate_samples_with(
    samples: Samples,
    log_times: &[f64],
    opts: &CalibrateOptions,
) -> Result<Calibration, ResponseError> {
    let m = opts.hat_margin;
    if !(m.is_finite() && (0.0..127.0).contains(&m)) {
        return Err(ResponseError::BadOption(format!(
            "hat margin = {m} (use 0 up to 127 codes; colour-hdri's hat is 2.55)"
        )));
    }
    let cut = opts.outlier_sigmas;
    if !(cut.is_finite() && cut > 0.0) {
        return Err(ResponseError::BadOption(format!(
            "outlier cut = {cut} standard deviations (use a positive number; 4 is typical)"
        )));
    }
    solve_all(
        samples,
        log_times,
        opts.lambda,
        opts.solver,
        opts.fit,
        cut,
        m,
    )
}

/// Solves all three channels from given samples and `ln Δt_j` with the given fit.
pub fn calibrate_samples_fit(
    samples: Samples,
    log_times: &[f64],
    lambda: f64,
    solver: Solver,
    fit: Fit,
) -> Result<Calibration, ResponseError> {
    solve_all(samples, log_times, lambda, solver, fit, OUTLIER_SIGMAS, 0.0)
}

/// [`calibrate_samples_fit`] with the hat's ends moved in by `margin` codes ([`hat_margin`])
/// and the noise-weighted fit's outlier cut given (`cut`, standard deviations).
fn solve_all(
    samples: Samples,
    log_times: &[f64],
    lambda: f64,
    solver: Solver,
    fit: Fit,
    cut: f64,
    margin: f64,
) -> Result<Calibration, ResponseError> {
    check_lambda(lambda)?;
    if log_times.len() != samples.frames || samples.frames < 2 {
        return Err(ResponseError::TooFewFrames(samples.frames));
    }
    let solve = |c: usize| {
        let once = |w: Option<&[f64]>| match solver {
            Solver::Schur => solve_schur_weighted(&samples, log_times, lambda, c, w, margin),
            Solver::DenseSvd => solve_dense_svd_weighted(&samples, log_times, lambda, c, w, margin),
        };
        let mut x = once(None)?;
        if fit == Fit::Noise {
            for _ in 0..IRLS_ITERATIONS {
                let w = noise_weights(&samples, log_times, c, &x.0, &x.1, cut);
                x = once(Some(&w))?;
            }
        }
        Ok::<_, ResponseError>(x)
    };
    #[cfg(feature = "parallel")]
    let solved: Vec<_> = {
        use rayon::prelude::*;
        (0..3).into_par_iter().map(solve).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let solved: Vec<_> = (0..3).map(solve).collect();

    let mut raw: [Vec<f64>; 3] = Default::default();
    let mut lne: [Vec<f64>; 3] = Default::default();
    let mut fixed: [Vec<f64>; 3] = Default::default();
    let mut fixes = [0usize; 3];
    for (c, r) in solved.into_iter().enumerate() {
        let (g, e) = r?;
        let (m, n) = make_monotonic(&g);
        fixed[c] = m;
        fixes[c] = n;
        raw[c] = g;
        lne[c] = e;
    }
    Ok(Calibration {
        response: Response::from_curves(fixed)?,
        raw_curves: raw,
        monotonic_fixes: fixes,
        samples,
        log_irradiance: lne,
        log_times: log_times.to_vec(),
        lambda,
        grid_alone: false,
        wide_step: false,
    })
}

/// The smoothness weight λ of the seed's method and of the default.
pub const SEED_LAMBDA: f64 = 30.0;
/// The smoothness weight λ of [`CalibrateOptions::covering`] (on the tuning brackets: mean
/// sky ratio to the oracle 1.06–1.08 at 5–9 frames with λ 100, 1.03–1.06 at 150, 1.04–1.06 at
/// 200 but the dim ground lost to the default calibration's on 20 of 96 brackets, against 9 at
/// 150).
pub const COVERING_LAMBDA: f64 = 150.0;

/// The smoothness weight λ of [`CalibrateOptions::noise_fit`].
pub const NOISE_FIT_LAMBDA: f64 = 100.0;

/// Reweighting passes of the noise-weighted fit ([`Fit::Noise`]) after the hat solve.
pub const IRLS_ITERATIONS: usize = 3;
/// Observations whose residual exceeds this many of their code's standard deviations get no
/// weight in the next pass of the noise-weighted fit (a pixel that moved, a flicker).
pub const OUTLIER_SIGMAS: f64 = 4.0;
/// The outlier cut of [`CalibrateOptions::covering`]. At 4 (the noise fit's) the covering fit
/// drops banterle_room's 1/1000 s frame wholesale (it reads 0.35–0.40 stops longer than
/// listed) and that set's frames agree only 8 % better than OpenCV's (median frame), against
/// 26 % at 5 or 6; on the oracle's brackets of 5–9 frames 5 costs at most 0.01 in the mean sky
/// ratio (tuning, held-out and fresh seeds), 6 up to 0.015 (docs/accuracy.md, "Sixth round").
pub const COVERING_OUTLIER_SIGMAS: f64 = 5.0;
/// Width, in codes, of the bands in which the noise-weighted fit measures the residuals' spread.
const NOISE_BAND: usize = 8;
/// Fewest residuals for a band to measure its own spread; sparser bands borrow their
/// neighbours'.
const NOISE_BAND_MIN: usize = 8;
/// The weight falls linearly to zero over this many codes next to 0 and 255 (a code there may
/// be clipped, whatever the spread of the rest of its band says).
const NOISE_TAPER: f64 = 8.0;
/// A band's standard deviation is taken as at least this fraction of the median band's (so a
/// band that by chance fits too well does not take over the curve).
const NOISE_FLOOR: f64 = 0.25;
/// Codes within this many of 255 are checked for clipping by the noise-weighted fit. A pixel
/// clipped in a frame can still read a few codes below 255 there — noise added after the clip
/// (read noise, JPEG), or a patch mean over pixels on both sides of it — while its light is
/// beyond the curve's end; on a long bracket such observations pile up just under 255 (a
/// bright sky clipped in every longer frame) and pull the curve's top up, by 0.4–0.8 stops at
/// code 248 on the oracle's noisy 3-EV brackets. A clip only ever reads darker than the light,
/// so the test is one-sided: an observation here whose shorter frames (codes below the band,
/// inverse-variance weighted) put the pixel more than [`CLIP_SIGMAS`] of its code's standard
/// deviations brighter than the curve reads it gets no weight (docs/accuracy.md, "Fourteenth
/// round").
const CLIP_BAND: f64 = 48.0;
/// The fewest frames with which the clipping test ([`CLIP_BAND`]) runs: the long brackets
/// whose clipped observations pile up, where the covering calibration is the default
/// ([`COVERING_FROM_FRAMES`]). On 3–4 frames it moved the oracle's mean sky ratios by ±0.003
/// only, and on two frames it read two 2 × 3 EV brackets 23–33 % worse and one 8 % better
/// (docs/accuracy.md, "Fourteenth round").
const CLIP_FROM_FRAMES: usize = COVERING_FROM_FRAMES;
/// The one-sided cut of the clipping test ([`CLIP_BAND`]), in standard deviations of the code's
/// band. Low, because the curve it is measured against is the one the clipped observations
/// pulled up: at 2 the top of 9416's curve (9 × 3 EV, 16-bit) kept 0.21 stops of error, at 1.5
/// 0.06 (0.42 without the test); an honest observation beyond 1.5 σ (7 % of them) costs the
/// top of the curve little.
const CLIP_SIGMAS: f64 = 1.5;
/// …and at most this many times the median band's: the toe and the shoulder, where the
/// residuals are widest, keep a third of the middle's weight. Without the ceiling the ends are
/// left to the smoothness term, and on the oracle's tuning brackets the dim ground's error
/// doubled (0.262 against 0.121 stops mean, 1.47 against 0.51 worst).
const NOISE_CEILING: f64 = 3.0;

/// The data-row weights of the next pass of the noise-weighted fit of channel `c`, from the
/// current solution `(g, ln E)`: the residuals `g(Z_ij) − ln E_i − ln Δt_j` are gathered in
/// bands of [`NOISE_BAND`] codes, each band's standard deviation is measured robustly
/// (1.4826 × the median absolute residual), interpolated linearly between band centres to a
/// `σ(z)` per code, kept within [`NOISE_FLOOR`] and [`NOISE_CEILING`] × the median band's, and an observation is
/// weighted `taper(z) / σ(z)` — inverse standard deviation, so the least squares is the
/// maximum-likelihood fit for Gaussian noise of that spread — or 0 beyond `cut` standard
/// deviations ([`CalibrateOptions::outlier_sigmas`]), or 0 for a code within [`CLIP_BAND`] of
/// 255 that its shorter frames show clipped ([`CLIP_SIGMAS`]).
/// The weights are scaled so that their root mean square equals the hat's over the same
/// observations, which keeps λ's meaning.
fn noise_weights(
    samples: &Samples,
    lt: &[f64],
    c: usize,
    g: &[f64],
    e: &[f64],
    cut: f64,
) -> Vec<f64> {
    let p = samples.frames;
    let n = samples.count();
    let nb = LEVELS.div_ceil(NOISE_BAND);
    let g_at = |z: f32| {
        let (z0, f0, f1) = split(z);
        f0 * g[z0] + f1 * g[z0 + 1]
    };
    let mut resid = vec![f64::NAN; n * p];
    let mut bands: Vec<Vec<f64>> = vec![Vec::new(); nb];
    for i in 0..n {
        for j in 0..p {
            let z = samples.z(i, j, c);
            if hat_f(z as f64) <= 0.0 {
                continue;
            }
            let r = g_at(z) - e[i] - lt[j];
            resid[i * p + j] = r;
            bands[(z as usize).min(LEVELS - 1) / NOISE_BAND].push(r.abs());
        }
    }
    let mut sigma_b: Vec<Option<f64>> = bands
        .iter_mut()
        .map(|b| {
            (b.len() >= NOISE_BAND_MIN).then(|| {
                b.sort_by(f64::total_cmp);
                1.4826 * b[b.len() / 2]
            })
        })
        .collect();
    let mut measured: Vec<f64> = sigma_b.iter().flatten().copied().collect();
    if measured.is_empty() {
        // Too few observations to measure any spread: keep the hat.
        return (0..n * p)
            .map(|k| hat_f(samples.values[k][c] as f64))
            .collect();
    }
    measured.sort_by(f64::total_cmp);
    let floor = (NOISE_FLOOR * measured[measured.len() / 2]).max(1e-6);
    // Bands without enough residuals take the nearest measured band's spread.
    let known: Vec<usize> = (0..nb).filter(|&b| sigma_b[b].is_some()).collect();
    for b in 0..nb {
        if sigma_b[b].is_none() {
            let k = *known
                .iter()
                .min_by_key(|&&k| k.abs_diff(b))
                .expect("measured is not empty");
            sigma_b[b] = sigma_b[k];
        }
    }
    let ceil = NOISE_CEILING * measured[measured.len() / 2];
    let sigma_b: Vec<f64> = sigma_b
        .into_iter()
        .map(|s| s.unwrap_or(floor).clamp(floor, ceil.max(floor)))
        .collect();
    let sigma = |z: f64| {
        let x = z / NOISE_BAND as f64 - 0.5;
        let b0 = (x.floor().max(0.0) as usize).min(nb - 1);
        let b1 = (b0 + 1).min(nb - 1);
        let f = (x - b0 as f64).clamp(0.0, 1.0);
        sigma_b[b0] * (1.0 - f) + sigma_b[b1] * f
    };
    // Observations near the top that read darker than the pixel's shorter frames say are
    // clipped ones (see `CLIP_BAND`): no weight; on long brackets only (`CLIP_FROM_FRAMES`).
    if p >= CLIP_FROM_FRAMES {
        for i in 0..n {
            for j in 0..p {
                let k = i * p + j;
                let z = samples.values[k][c] as f64;
                if resid[k].is_nan() || z < 255.0 - CLIP_BAND {
                    continue;
                }
                // The exposure the shorter frames give, each weighted by its inverse variance;
                // their own codes in the band are left out (they may be clipped too).
                let (mut sw, mut swv) = (0.0, 0.0);
                for (jj, &ltj) in lt.iter().enumerate().take(p) {
                    let zz = samples.values[i * p + jj][c];
                    let h = hat_f(zz as f64);
                    if ltj >= lt[j] || zz as f64 >= 255.0 - CLIP_BAND || h <= 0.0 {
                        continue;
                    }
                    let wv = ((h / NOISE_TAPER).min(1.0) / sigma(zz as f64)).powi(2);
                    sw += wv;
                    swv += wv * (g_at(zz) - ltj);
                }
                if sw > 0.0 && swv / sw + lt[j] - g_at(z as f32) > CLIP_SIGMAS * sigma(z) {
                    resid[k] = f64::INFINITY;
                }
            }
        }
    }
    let mut w = vec![0.0; n * p];
    let (mut sw2, mut sh2) = (0.0, 0.0);
    for (k, wk) in w.iter_mut().enumerate() {
        let r = resid[k];
        if r.is_nan() {
            continue;
        }
        let z = samples.values[k][c] as f64;
        let s = sigma(z);
        if r.abs() > cut * s {
            continue;
        }
        *wk = (hat_f(z) / NOISE_TAPER).min(1.0) / s;
        sw2 += *wk * *wk;
        sh2 += hat_f(z).powi(2);
    }
    if sw2 > 0.0 {
        let scale = (sh2 / sw2).sqrt();
        for v in &mut w {
            *v *= scale;
        }
    }
    w
}

/// Leave-one-out residuals of curve `g` (one channel's, 256 entries, `ln` units) on samples it
/// was not fitted to (a held-out draw, [`crate::sampling::sample_held_out`]), channel `c`:
/// for every observation `Z_ij` in `1..=254`, `g(Z_ij) − ln Δt_j − ln Ê_i` where `ln Ê_i` is the
/// hat-weighted mean of `g(Z_ik) − ln Δt_k` over the sample's *other* frames (so a wrong
/// curve cannot agree with itself). Returns `(Z_ij, residual)` pairs; observations whose other
/// frames carry no weight are left out. `g` is interpolated linearly between codes.
pub fn held_out_residuals(samples: &Samples, lt: &[f64], g: &[f64], c: usize) -> Vec<(f32, f64)> {
    let p = samples.frames.min(lt.len());
    let g_at = |z: f32| {
        let (z0, f0, f1) = split(z);
        f0 * g[z0] + f1 * g[z0 + 1]
    };
    let mut out = Vec::new();
    let mut v = vec![(0f64, 0f64); p];
    for i in 0..samples.count() {
        let (mut sw, mut swv) = (0f64, 0f64);
        for (j, vj) in v.iter_mut().enumerate() {
            let z = samples.z(i, j, c);
            let w = if (1.0..=254.0).contains(&z) {
                hat_f(z as f64)
            } else {
                0.0
            };
            *vj = (w, g_at(z) - lt[j]);
            sw += w;
            swv += w * vj.1;
        }
        for (j, &(w, vote)) in v.iter().enumerate() {
            let z = samples.z(i, j, c);
            if !(1.0..=254.0).contains(&z) || sw - w <= 1e-9 {
                continue;
            }
            out.push((z, vote - (swv - w * vote) / (sw - w)));
        }
    }
    out
}

/// Running max above the gauge, running min below it; returns the curve and changed count.
fn make_monotonic(g: &[f64]) -> (Vec<f64>, usize) {
    let mut m = g.to_vec();
    let mut n = 0;
    for z in GAUGE + 1..LEVELS {
        if m[z] < m[z - 1] {
            m[z] = m[z - 1];
            n += 1;
        }
    }
    for z in (0..GAUGE).rev() {
        if m[z] > m[z + 1] {
            m[z] = m[z + 1];
            n += 1;
        }
    }
    (m, n)
}

/// The smoothness rows' weights: the hat ([`hat`] when `margin` is 0, else [`hat_margin`]).
/// Where a margin zeroes the hat, a weight of [`END_SMOOTHNESS`] keeps those codes of `g` tied
/// to their neighbours (no data row sees them, so without it the system is singular).
fn hat_table(margin: f64) -> [f64; LEVELS] {
    let mut w = [0.0; LEVELS];
    for (z, v) in w.iter_mut().enumerate() {
        *v = if margin == 0.0 {
            hat(z as u8)
        } else {
            hat_margin(z as f64, margin).max(END_SMOOTHNESS)
        };
    }
    w
}

/// The smallest smoothness weight with a hat margin (see [`hat_table`]): small beside the
/// hat's 1–127, so the measured part of the curve does not feel it.
const END_SMOOTHNESS: f64 = 1e-3;

/// Lower-triangular Cholesky factor of a row-major `n × n` SPD matrix, in place (the upper
/// triangle is left as it was and never read again).
///
/// Envelope (skyline) form: `L` has no entries left of a row's first non-zero in `A`, so each
/// dot product starts at the later of the two rows' first non-zeros. A code couples only to
/// the codes its pixels take in the neighbouring exposures, so the rows of the 256 × 256
/// Schur complement start well right of column 0 and this skips a good part of the `n³/6`.
fn cholesky(a: &mut [f64], n: usize) -> bool {
    let max_diag = (0..n).map(|i| a[i * n + i]).fold(0.0f64, f64::max);
    let tiny = max_diag * 1e-14;
    let first: Vec<usize> = (0..n)
        .map(|i| (0..=i).find(|&k| a[i * n + k] != 0.0).unwrap_or(i))
        .collect();
    for j in 0..n {
        let (_, rest) = a.split_at_mut(j * n);
        let (upto, below) = rest.split_at_mut(n);
        let fj = first[j];
        let d = upto[j] - dot(&upto[fj..j], &upto[fj..j]);
        // Also catches NaN: a NaN pivot is not greater than anything.
        if d.partial_cmp(&tiny) != Some(std::cmp::Ordering::Greater) {
            return false;
        }
        let d = d.sqrt();
        upto[j] = d;
        let inv = 1.0 / d;
        let rowj = &upto[..j];
        for i in j + 1..n {
            let rowi = &mut below[(i - j - 1) * n..(i - j) * n];
            let f = fj.max(first[i]);
            if f > j {
                continue; // row i's envelope starts right of column j: L[i][j] = 0
            }
            rowi[j] = (rowi[j] - dot(&rowi[f..j], &rowj[f..j])) * inv;
        }
    }
    true
}

/// Dot product with four independent accumulators so the compiler can vectorise it.
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ac, ar) = a.split_at(a.len() / 4 * 4);
    let (bc, br) = b.split_at(ac.len());
    for (x, y) in ac.chunks_exact(4).zip(bc.chunks_exact(4)) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ar.iter().zip(br) {
        s += x * y;
    }
    s
}

fn cholesky_solve(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        b[i] = (b[i] - dot(&l[i * n..i * n + i], &b[..i])) / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[k * n + i] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
}

/// One data row of a sample: `a0·g(z0) + a1·g(z0+1) − w·ln E_i = w·ln Δt_j`.
#[derive(Clone, Copy)]
struct Row {
    z0: usize,
    a0: f64,
    a1: f64,
    w: f64,
}

/// The data rows of channel `c`; each observation's weight is `weights[i·P + j]` when given,
/// else the hat (with its ends moved in by `margin`) at its code.
fn rows_of(samples: &Samples, c: usize, weights: Option<&[f64]>, margin: f64) -> Vec<Row> {
    let p = samples.frames;
    let mut rows = Vec::with_capacity(samples.count() * p);
    for i in 0..samples.count() {
        for j in 0..p {
            let z = samples.z(i, j, c);
            let w = weights.map_or_else(|| hat_margin(z as f64, margin), |w| w[i * p + j]);
            let (z0, f0, f1) = split(z);
            rows.push(Row {
                z0,
                a0: w * f0,
                a1: w * f1,
                w,
            });
        }
    }
    rows
}

/// The per-channel arrow-structured normal equations, factored.
struct Schur<'a> {
    lt: &'a [f64],
    lambda: f64,
    p: usize,
    w: [f64; LEVELS],
    rows: Vec<Row>,
    /// `D_i = Σ_j w_ij²`.
    d: Vec<f64>,
    /// Cholesky factor of `S`.
    l: Vec<f64>,
}

impl<'a> Schur<'a> {
    fn new(
        samples: &Samples,
        lt: &'a [f64],
        lambda: f64,
        c: usize,
        weights: Option<&[f64]>,
        margin: f64,
    ) -> Result<Self, ResponseError> {
        let w = hat_table(margin);
        let p = samples.frames;
        let rows = rows_of(samples, c, weights, margin);
        let mut s = vec![0.0; LEVELS * LEVELS];
        for z in 1..LEVELS - 1 {
            let a = lambda * w[z];
            let co = [a, -2.0 * a, a];
            for u in 0..3 {
                for v in 0..3 {
                    s[(z - 1 + u) * LEVELS + z - 1 + v] += co[u] * co[v];
                }
            }
        }
        let gw = gauge_weight(lambda);
        s[GAUGE * LEVELS + GAUGE] += gw * gw;
        let mut d = Vec::with_capacity(samples.count());
        // `u` collects the sample's column of A_gE (entries −a·w) as (z, a·w) pairs.
        let mut u: Vec<(usize, f64)> = Vec::with_capacity(2 * p);
        for sample_rows in rows.chunks_exact(p) {
            u.clear();
            let mut sum = 0.0;
            for r in sample_rows {
                s[r.z0 * LEVELS + r.z0] += r.a0 * r.a0;
                if r.a1 != 0.0 {
                    s[r.z0 * LEVELS + r.z0 + 1] += r.a0 * r.a1;
                    s[(r.z0 + 1) * LEVELS + r.z0] += r.a0 * r.a1;
                    s[(r.z0 + 1) * LEVELS + r.z0 + 1] += r.a1 * r.a1;
                    u.push((r.z0 + 1, r.a1 * r.w));
                }
                u.push((r.z0, r.a0 * r.w));
                sum += r.w * r.w;
            }
            d.push(sum);
            if sum > 0.0 {
                let inv = 1.0 / sum;
                for &(z1, v1) in &u {
                    for &(z2, v2) in &u {
                        s[z1 * LEVELS + z2] -= v1 * v2 * inv;
                    }
                }
            }
        }
        if !cholesky(&mut s, LEVELS) {
            return Err(ResponseError::Singular { channel: c });
        }
        Ok(Self {
            lt,
            lambda,
            p,
            w,
            rows,
            d,
            l: s,
        })
    }

    /// Solves the normal equations `AᵀA x = (rg, re)` for `x = (g, ln E)`.
    fn solve(&self, mut rg: Vec<f64>, re: &[f64]) -> (Vec<f64>, Vec<f64>) {
        for ((sample_rows, &di), &rei) in self.rows.chunks_exact(self.p).zip(&self.d).zip(re) {
            if di > 0.0 {
                // r_g −= A_gE · D⁻¹ · r_E, with A_gE entries −a·w.
                let k = rei / di;
                for r in sample_rows {
                    rg[r.z0] += r.a0 * r.w * k;
                    if r.a1 != 0.0 {
                        rg[r.z0 + 1] += r.a1 * r.w * k;
                    }
                }
            }
        }
        cholesky_solve(&self.l, LEVELS, &mut rg);
        let g = rg;
        let e = self
            .rows
            .chunks_exact(self.p)
            .zip(&self.d)
            .zip(re)
            .map(|((sample_rows, &di), &rei)| {
                if di > 0.0 {
                    let mut s = rei;
                    for r in sample_rows {
                        s += r.w * (r.a0 * g[r.z0] + r.a1 * g[(r.z0 + 1).min(LEVELS - 1)]);
                    }
                    s / di
                } else {
                    0.0
                }
            })
            .collect();
        (g, e)
    }

    /// `Aᵀ (b − A x)`, split into the `g` and `ln E` parts.
    fn normal_residual(&self, g: &[f64], e: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let mut rg = vec![0.0; LEVELS];
        let mut re = vec![0.0; e.len()];
        for ((sample_rows, rei), &ei) in self.rows.chunks_exact(self.p).zip(re.iter_mut()).zip(e) {
            for (r, &lt) in sample_rows.iter().zip(self.lt) {
                let g1 = if r.a1 != 0.0 { g[r.z0 + 1] } else { 0.0 };
                let rho = r.w * lt - (r.a0 * g[r.z0] + r.a1 * g1 - r.w * ei);
                rg[r.z0] += r.a0 * rho;
                if r.a1 != 0.0 {
                    rg[r.z0 + 1] += r.a1 * rho;
                }
                *rei -= r.w * rho;
            }
        }
        for z in 1..LEVELS - 1 {
            let a = self.lambda * self.w[z];
            let rho = -a * (g[z - 1] - 2.0 * g[z] + g[z + 1]);
            rg[z - 1] += a * rho;
            rg[z] -= 2.0 * a * rho;
            rg[z + 1] += a * rho;
        }
        let gw = gauge_weight(self.lambda);
        rg[GAUGE] -= gw * gw * g[GAUGE];
        (rg, re)
    }
}

/// Weight of the gauge row `g(128) = 0`. Any positive weight gives the same least-squares
/// solution — shifting all of `g` and `ln E` together costs nothing in the other rows, so the
/// optimum meets the gauge exactly — but a weight of 1 beside smoothness rows of `λ · 127`
/// leaves that shift direction with a tiny singular value, and the dense SVD then drifts along
/// it by up to 1e-3. Matching the largest smoothness weight keeps both solvers exact.
fn gauge_weight(lambda: f64) -> f64 {
    lambda * 127.0
}

/// Most refinement steps after the first Schur solve.
const REFINEMENT_STEPS: usize = 4;

/// Solves one channel by the Schur complement (the default). Returns `(g, ln E)`: 256 values
/// of `g` and one `ln E_i` per sample (0 where a sample has no weighted observation).
pub fn solve_schur(
    samples: &Samples,
    log_times: &[f64],
    lambda: f64,
    channel: usize,
) -> Result<(Vec<f64>, Vec<f64>), ResponseError> {
    solve_schur_weighted(samples, log_times, lambda, channel, None, 0.0)
}

/// [`solve_schur`] with each observation's data-row weight given (`weights[i·P + j]`, ≥ 0)
/// instead of the hat at its code; the smoothness rows keep the hat.
fn solve_schur_weighted(
    samples: &Samples,
    log_times: &[f64],
    lambda: f64,
    channel: usize,
    weights: Option<&[f64]>,
    margin: f64,
) -> Result<(Vec<f64>, Vec<f64>), ResponseError> {
    check_inputs(samples, log_times, lambda, channel)?;
    let sys = Schur::new(samples, log_times, lambda, channel, weights, margin)?;
    let n = samples.count();
    let (rg, re) = sys.normal_residual(&vec![0.0; LEVELS], &vec![0.0; n]);
    let (mut g, mut e) = sys.solve(rg, &re);
    // Refinement on the full least-squares residual (CSNE): each step gains roughly the
    // digits that squaring the condition number lost; stop once the correction is at
    // rounding level.
    for _ in 0..REFINEMENT_STEPS {
        let (rg, re) = sys.normal_residual(&g, &e);
        let (dg, de) = sys.solve(rg, &re);
        let mut change = 0.0f64;
        for (a, b) in g.iter_mut().zip(&dg) {
            *a += b;
            change = change.max(b.abs());
        }
        for (a, b) in e.iter_mut().zip(&de) {
            *a += b;
            change = change.max(b.abs());
        }
        if change < 1e-12 {
            break;
        }
    }
    Ok((g, e))
}

fn check_inputs(
    samples: &Samples,
    log_times: &[f64],
    lambda: f64,
    channel: usize,
) -> Result<(), ResponseError> {
    check_lambda(lambda)?;
    if channel > 2 {
        return Err(ResponseError::BadOption(format!(
            "channel {channel} (use 0, 1 or 2)"
        )));
    }
    if samples.frames < 2 || log_times.len() != samples.frames {
        return Err(ResponseError::TooFewFrames(log_times.len()));
    }
    // Positions, when there are any (histogram samples have none), must match the values.
    let positioned = samples.positions.is_empty()
        || samples.values.len() == samples.positions.len() * samples.frames;
    if !samples.values.len().is_multiple_of(samples.frames) || !positioned {
        return Err(ResponseError::BadOption(
            "samples.values must hold one RGB value per sample and frame".into(),
        ));
    }
    if let Some(t) = log_times.iter().find(|t| !t.is_finite()) {
        return Err(ResponseError::BadOption(format!(
            "log exposure time {t} is not finite"
        )));
    }
    Ok(())
}

/// The seed's solver: the full `(N·P + 255) × (256 + N)` system by dense SVD (nalgebra),
/// minimum-norm least squares. Slow; kept as the reference that [`solve_schur`] is tested
/// against. Returns `(g, ln E)` like [`solve_schur`].
pub fn solve_dense_svd(
    samples: &Samples,
    log_times: &[f64],
    lambda: f64,
    channel: usize,
) -> Result<(Vec<f64>, Vec<f64>), ResponseError> {
    solve_dense_svd_weighted(samples, log_times, lambda, channel, None, 0.0)
}

/// [`solve_dense_svd`] with given data-row weights (see [`solve_schur_weighted`]).
fn solve_dense_svd_weighted(
    samples: &Samples,
    log_times: &[f64],
    lambda: f64,
    channel: usize,
    weights: Option<&[f64]>,
    margin: f64,
) -> Result<(Vec<f64>, Vec<f64>), ResponseError> {
    check_inputs(samples, log_times, lambda, channel)?;
    let n = samples.count();
    let p = samples.frames;
    let w = hat_table(margin);
    let rows = n * p + (LEVELS - 2) + 1;
    let cols = LEVELS + n;
    let mut a = nalgebra::DMatrix::<f64>::zeros(rows, cols);
    let mut b = nalgebra::DVector::<f64>::zeros(rows);
    let mut k = 0;
    for i in 0..n {
        for (j, &lt) in log_times.iter().enumerate() {
            let z = samples.z(i, j, channel);
            let wz = weights.map_or_else(|| hat_margin(z as f64, margin), |w| w[i * p + j]);
            let (z0, f0, f1) = split(z);
            a[(k, z0)] += wz * f0;
            if f1 != 0.0 {
                a[(k, z0 + 1)] += wz * f1;
            }
            a[(k, LEVELS + i)] = -wz;
            b[k] = wz * lt;
            k += 1;
        }
    }
    for z in 1..LEVELS - 1 {
        let l = lambda * w[z];
        a[(k, z - 1)] = l;
        a[(k, z)] = -2.0 * l;
        a[(k, z + 1)] = l;
        k += 1;
    }
    a[(k, GAUGE)] = gauge_weight(lambda);
    let svd = a.svd(true, true);
    let max_sv = svd.singular_values.max();
    let x = svd
        .solve(&b, max_sv * 1e-12)
        .map_err(|_| ResponseError::Singular { channel })?;
    let g = x.rows(0, LEVELS).iter().copied().collect();
    let e = x.rows(LEVELS, n).iter().copied().collect();
    Ok((g, e))
}

/// How much the recovered response varies with the sampling seed.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stability {
    /// Seeds used (`opts.sampling.seed + k`).
    pub seeds: Vec<u64>,
    /// Per channel and code, the standard deviation of `g(z)` across runs (natural log).
    pub spread: [Vec<f64>; 3],
    /// RMS of `spread` over `z = 10..=245` and the three channels.
    pub rms_spread: f64,
    /// Largest `spread` over `z = 10..=245`.
    pub max_spread: f64,
    /// The threshold applied to `rms_spread` ([`STABILITY_THRESHOLD`]).
    pub threshold: f64,
    /// `rms_spread <= threshold`.
    pub stable: bool,
}

/// Calibrates `runs` times (seeds `seed, seed+1, …`) and reports the spread of `g`.
pub fn stability(
    frames: &[Frame],
    circle: Option<Circle>,
    opts: &CalibrateOptions,
    runs: usize,
) -> Result<Stability, ResponseError> {
    if !(2..=1000).contains(&runs) {
        return Err(ResponseError::BadOption(format!(
            "runs = {runs} (use 2..=1000; 5-10 is typical)"
        )));
    }
    let seeds: Vec<u64> = (0..runs as u64)
        .map(|k| opts.sampling.seed.wrapping_add(k))
        .collect();
    let mut curves = Vec::with_capacity(runs);
    for &seed in &seeds {
        let mut o = opts.clone();
        o.sampling.seed = seed;
        curves.push(calibrate(frames, circle, &o)?.response);
    }
    Ok(spread_of(&curves, seeds))
}

fn spread_of(curves: &[Response], seeds: Vec<u64>) -> Stability {
    let k = curves.len() as f64;
    let mut spread: [Vec<f64>; 3] = Default::default();
    let (mut sum2, mut cnt, mut max) = (0.0, 0.0, 0.0f64);
    for (c, sp) in spread.iter_mut().enumerate() {
        *sp = (0..LEVELS)
            .map(|z| {
                let mean = curves.iter().map(|r| r.g[c][z]).sum::<f64>() / k;
                let var = curves
                    .iter()
                    .map(|r| (r.g[c][z] - mean).powi(2))
                    .sum::<f64>()
                    / (k - 1.0);
                var.sqrt()
            })
            .collect();
        for &s in &sp[10..=245] {
            sum2 += s * s;
            cnt += 1.0;
            max = max.max(s);
        }
    }
    let rms = (sum2 / cnt).sqrt();
    Stability {
        seeds,
        spread,
        rms_spread: rms,
        max_spread: max,
        threshold: STABILITY_THRESHOLD,
        stable: rms <= STABILITY_THRESHOLD,
    }
}

/// One row of [`sample_count_experiment`].
#[derive(Debug, Clone, PartialEq)]
pub struct SampleCountPoint {
    /// Samples requested (exactly, no automatic raise).
    pub samples: usize,
    /// Mean number actually used over the runs.
    pub used: f64,
    /// The curve from the first seed.
    pub response: Response,
    /// Seed-to-seed spread at this sample count.
    pub stability: Stability,
}

/// The seed's §9.2 experiment: calibrate with each sample count (the automatic raise is off
/// so `N` is as given), `runs` seeds each, and report the curves and their spread, which falls
/// as `N` grows.
pub fn sample_count_experiment(
    frames: &[Frame],
    circle: Option<Circle>,
    opts: &CalibrateOptions,
    counts: &[usize],
    runs: usize,
) -> Result<Vec<SampleCountPoint>, ResponseError> {
    if !(2..=1000).contains(&runs) {
        return Err(ResponseError::BadOption(format!(
            "runs = {runs} (use 2..=1000; 5-10 is typical)"
        )));
    }
    let mut out = Vec::with_capacity(counts.len());
    for &n in counts {
        let mut curves = Vec::with_capacity(runs);
        let mut used = 0usize;
        let seeds: Vec<u64> = (0..runs as u64)
            .map(|k| opts.sampling.seed.wrapping_add(k))
            .collect();
        for &seed in &seeds {
            // Resolved first, so the sample count applies to the calibration used.
            let mut o = opts.for_frames(frames.len());
            o.sampling.samples = n;
            o.sampling.auto_raise = false;
            o.sampling.seed = seed;
            let cal = calibrate(frames, circle, &o)?;
            used += cal.samples.report.used;
            curves.push(cal.response);
        }
        out.push(SampleCountPoint {
            samples: n,
            used: used as f64 / runs as f64,
            response: curves[0].clone(),
            stability: spread_of(&curves, seeds),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_small_spd_system() {
        let mut a = vec![4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let orig = a.clone();
        assert!(cholesky(&mut a, 3));
        let mut b = vec![1.0, 2.0, 3.0];
        cholesky_solve(&a, 3, &mut b);
        for i in 0..3 {
            let r: f64 = (0..3).map(|k| orig[i * 3 + k] * b[k]).sum();
            assert!((r - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
    }

    #[test]
    fn monotonic_fix_counts_and_flattens_dips() {
        let mut g: Vec<f64> = (0..256).map(|z| z as f64 / 100.0).collect();
        g[250] = 0.0;
        g[3] = 5.0;
        let (m, n) = make_monotonic(&g);
        assert_eq!(n, 2);
        assert!(m.windows(2).all(|w| w[1] >= w[0]));
    }

    /// An sRGB-like curve (not in the smooth model's span), gauged at code 128.
    fn smooth_curve() -> Vec<f64> {
        let lin = |z: usize| {
            let v = (z as f64 + 0.5) / 255.5;
            if v <= 0.04045 {
                v / 12.92
            } else {
                ((v + 0.055) / 1.055).powf(2.4)
            }
        };
        let g0 = lin(GAUGE).ln();
        (0..LEVELS).map(|z| lin(z).ln() - g0).collect()
    }

    /// RMS over codes 24..=254 of `a − b`, its mean removed (natural log units).
    fn rms_from_24(a: &[f64], b: &[f64]) -> f64 {
        let d: Vec<f64> = (24..=254).map(|z| a[z] - b[z]).collect();
        let m = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
    }

    #[test]
    fn step_periodic_correction_removes_an_injected_periodic_error() {
        let truth = smooth_curve();
        let step = 3.0 * std::f64::consts::LN_2;
        let w = std::f64::consts::TAU / step;
        let bent: Vec<f64> = truth
            .iter()
            .map(|&g| g + 0.1 * (w * g + 0.7).sin())
            .collect();
        let before = rms_from_24(&bent, &truth);
        assert!(before > 0.06, "{before}");
        let fixed = remove_step_periodic(&bent, step, STEP_PERIODIC_LO);
        let after = rms_from_24(&fixed, &truth);
        println!("injected 0.1-ln sinusoid: RMS {before:.4} -> {after:.4} ln (codes 24-254)");
        assert!(after < 0.02, "RMS {before:.4} -> {after:.4} ln");
        assert_eq!(fixed[GAUGE], bent[GAUGE]);
        assert!(fixed.windows(2).all(|p| p[1] >= p[0]));
        // Continuous at the toe: no step larger than the curve's own there.
        for z in 1..=STEP_PERIODIC_LO {
            let (d, t) = (fixed[z] - fixed[z - 1], bent[z] - bent[z - 1]);
            assert!((d - t).abs() < 0.02, "code {z}: slope {d} against {t}");
        }
    }

    #[test]
    fn step_periodic_correction_leaves_a_smooth_curve_alone() {
        let truth = smooth_curve();
        let fixed = remove_step_periodic(&truth, 3.0 * std::f64::consts::LN_2, STEP_PERIODIC_LO);
        let worst = (0..LEVELS)
            .map(|z| (fixed[z] - truth[z]).abs())
            .fold(0.0, f64::max);
        println!("no periodic error: worst change {worst:.5} ln");
        assert!(worst < 0.01, "worst change {worst} ln");
        // Nothing to fit: unchanged.
        assert_eq!(remove_step_periodic(&truth, f64::NAN, 24), truth);
        assert_eq!(remove_step_periodic(&truth[..30], 2.0, 24), truth[..30]);
    }

    #[test]
    fn wide_step_is_the_mean_step_from_2_5_ev() {
        let l2 = std::f64::consts::LN_2;
        let three: Vec<f64> = (0..8).map(|j| j as f64 * 3.0 * l2).collect();
        assert!((mean_step_ev(&three) - 3.0).abs() < 1e-12);
        assert!(is_wide_step(&three));
        let two: Vec<f64> = (0..5).map(|j| j as f64 * 2.0 * l2).collect();
        assert!(!is_wide_step(&two));
        assert!(is_wide_step(&[0.0, 2.5 * l2]));
        assert_eq!(mean_step_ev(&[0.0]), 0.0);
        assert_eq!(mean_step_ev(&[]), 0.0);
    }

    #[test]
    fn step_periodic_is_the_covering_methods_and_asked_for_wins() {
        // The default applies it where it resolves to the covering calibration (5+ frames),
        // not below (joined); no other method applies it; no method writes it.
        let auto = CalibrateOptions::default();
        assert!(auto.for_frames(5).step_periodic_applies(5));
        assert!(auto.for_frames(9).step_periodic_applies(9));
        assert!(!auto.for_frames(4).step_periodic_applies(4));
        assert!(!auto.for_frames(2).step_periodic_applies(2));
        assert!(CalibrateOptions::covering().step_periodic_applies(5));
        assert!(!CalibrateOptions::covering().step_periodic_applies(4));
        for o in [
            CalibrateOptions::default(),
            CalibrateOptions::robust(),
            CalibrateOptions::covering(),
            CalibrateOptions::joined(),
            CalibrateOptions::noise_fit(),
            CalibrateOptions::colour_hdri(),
        ] {
            assert!(o.step_periodic.is_none());
            if o.sampling.cover == 0 || o.toe_from_grid.is_some() {
                assert!(!o.step_periodic_applies(9));
            }
            let json = serde_json::to_string(&o).unwrap();
            assert!(!json.contains("step_periodic"), "{json}");
            let back: CalibrateOptions = serde_json::from_str(&json).unwrap();
            assert_eq!(back, o);
        }
        assert_eq!(auto.for_frames(8).method_name(), "covering");
        // Asked for, either way, it wins over the method's rule.
        let ask = |v: bool| CalibrateOptions {
            step_periodic: Some(v),
            ..CalibrateOptions::default()
        };
        assert!(ask(true).for_frames(8).step_periodic_applies(8));
        assert!(ask(true).for_frames(3).step_periodic_applies(3));
        assert!(!ask(false).for_frames(8).step_periodic_applies(8));
        assert_eq!(
            ask(false).for_frames(8).method_name(),
            "covering (options changed)"
        );
        // An ask the rule would grant anyway changes nothing, and is named so.
        assert_eq!(ask(true).for_frames(8).method_name(), "covering");
        assert_eq!(ask(false).for_frames(3).method_name(), "joined");
        assert_eq!(
            ask(true).for_frames(3).method_name(),
            "joined (options changed)"
        );
        let covering_ask = CalibrateOptions {
            step_periodic: Some(true),
            ..CalibrateOptions::covering()
        };
        assert_eq!(covering_ask.for_frames(7).method_name(), "covering");
        assert_eq!(
            covering_ask.for_frames(4).method_name(),
            "covering (options changed)"
        );
        assert!(covering_ask.for_frames(4).step_periodic_applies(4));
        for v in [true, false] {
            let json = serde_json::to_string(&ask(v)).unwrap();
            assert!(json.contains(&format!("\"step_periodic\":{v}")), "{json}");
            assert_eq!(
                serde_json::from_str::<CalibrateOptions>(&json).unwrap(),
                ask(v)
            );
        }
    }

    #[test]
    fn linear_response_is_exact_at_16_bit() {
        let r = Response::linear();
        assert!((r.g16(0, 257 * 128) - 0.0).abs() < 1e-12);
        assert!((r.g16(1, 257 * 64) - 0.5f64.ln()).abs() < 1e-12);
        assert!(r.is_linear());
    }

    #[test]
    fn interpolated_16_bit_matches_8_bit_at_code_centres() {
        let g: Vec<f64> = (0..256).map(|z| (z as f64 * 0.02).sinh()).collect();
        let r = Response::from_curves([g.clone(), g.clone(), g.clone()]).unwrap();
        for z in [0usize, 17, 128, 255] {
            assert!((r.g16(2, (z * 257) as u16) - g[z]).abs() < 1e-12);
        }
    }
}
