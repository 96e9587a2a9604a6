//! Measured exposures: each frame's exposure read from the photos themselves.
//!
//! The exposure times a bracket comes with (EXIF, a `--times` list, a list file) are not always
//! those the photos were taken at: EXIF rounds 1/64 s to 1/60 s, a list file can be mistyped, and
//! a camera that ignored part of a bracket (auto-exposure left on) writes the times it was asked
//! for next to photos that all carry one exposure. Ward's `hdrgen` and Photosphere estimate the
//! exposure ratios from the images when they are missing or wrong; Mitsunaga & Nayar (1999)
//! fit the response and the ratios together. This module does both, on the response the
//! pipeline already has:
//!
//! - **one step per neighbouring pair** (frames `a`, `b` in exposure order): over the pixels
//!   well exposed in both frames (codes 20..=235 and above the black level, every channel), the
//!   interquartile mean of `g(Z_b) − g(Z_a)`, the log ratio of their exposures in the response's
//!   own terms ([`pair_steps`]); a robust statistic, so moving leaves, a passing car or a few
//!   clipped pixels do not move it. Frames that carry the same picture share one exposure (a
//!   step of exactly 0);
//! - **chained** from the shortest frame, and **anchored** on the listed times where they agree
//!   with the photos ([`measure`]): the offset between measured and listed log exposures
//!   (slope 1) is their median; frames more than [`OFF_STOPS`] from it are the outliers; the
//!   inlier closest to the consensus keeps its listed time exactly (the absolute anchor an
//!   absolute dome or a profile's constant needs), every other frame its measured ratio to it;
//! - with a **given curve** (a camera profile) that is all; **calibrating on the bracket**
//!   ([`calibrate_measuring`]) alternates the curve fit on the current exposures with the
//!   measurement on the current curve, a few rounds until the exposures move by less than
//!   [`CONVERGED_STOPS`]. The curve's gauge (the exponent a response and exposures share) stays
//!   the one the listed times give the first fit.
//!
//! A self-calibrated bracket of two frames has one ratio, and its curve is fitted to that
//! ratio: nothing in the photos alone tells it apart from a curve raised to a power, so the
//! measurement there agrees with the listed ratio by construction. With three frames and more
//! the steps constrain one another (every step is measured on the same curve); with a camera
//! profile every step is measured independently.
//!
//! Exposures here are relative exposures `t · ISO / N²` ([`Exposure::relative`]), as the merge
//! uses them; log values are natural logs, reports are in stops (log₂).

use serde::{Deserialize, Serialize};

use crate::bracket::{bin16, Exposure, Frame, Pixels};
use crate::image::Circle;
use crate::response::{self, CalibrateOptions, Calibration, Response, ResponseError};

/// Which exposures the calibration and the merge use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExposureSource {
    /// The listed times (EXIF, or the caller's), as they are; frames whose photos disagree with
    /// them by more than [`OFF_STOPS`] are named in a warning.
    #[default]
    Listed,
    /// The exposures measured from the photos, anchored on the listed time of the frame that
    /// agrees best with the others; frames that carry the same picture share one exposure, and
    /// one of each such group is merged.
    Measured,
}

crate::named_enum!(ExposureSource, "exposure source", [Listed => "listed", Measured => "measured"]);

/// A frame whose measured exposure differs from its listed one by more than this many stops,
/// after the common offset, is "off" (a warning; an outlier of the anchoring fit).
pub const OFF_STOPS: f64 = 1.0 / 3.0;
/// Neighbouring frames whose measured exposures are closer than this many stops are one
/// exposure (the bracket check's 1/6 stop between listed exposures).
pub const SAME_STOPS: f64 = 1.0 / 6.0;
/// The alternation of curve fit and measurement stops when no exposure moved by more than this
/// many stops.
pub const CONVERGED_STOPS: f64 = 0.002;
/// The most rounds of curve fit and measurement.
pub const MAX_ROUNDS: usize = 24;
/// A pair needs at least this many well-exposed channel values in both frames to be measured;
/// otherwise its listed step is kept.
pub const MIN_VALUES: usize = 300;
/// Codes (8-bit; 16-bit values binned to 8 bits) from which a value counts as well exposed.
pub const WELL_LO: u8 = 20;
/// Codes up to which a value counts as well exposed.
pub const WELL_HI: u8 = 235;
/// At most about this many pixels per pair are read (a stride through larger frames): 250 000
/// cost a 12 MP bracket about 40 ms of the CLI's 0.5 s per measurement; at 65 536 the
/// interquartile mean of up to 196 608 channel values still has a standard error far below
/// the 0.02 stops the measurement is tested to.
const PIXELS_PER_PAIR: usize = 65_536;

/// One frame's listed and measured exposure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameExposure {
    /// The frame (file name).
    pub file: String,
    /// The listed exposure time, seconds.
    pub listed_s: f64,
    /// The measured exposure time, seconds (at the frame's ISO and f-number).
    pub measured_s: f64,
    /// `log₂(measured / listed)`, stops.
    pub off_stops: f64,
    /// Whether the frame disagrees with the consensus of the listed times by more than
    /// [`OFF_STOPS`].
    pub off: bool,
    /// The frame whose picture this one carries (neighbours of one exposure), if any: it
    /// shares that frame's exposure, and a measured merge leaves it out.
    pub same_as: Option<String>,
    /// Whether the step from the previous frame was measured (`false`: too few pixels well
    /// exposed in both, the listed step was kept; always `true` for the first frame).
    pub step_measured: bool,
}

/// What the measurement found, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExposureReport {
    /// Which exposures the merge used.
    pub source: ExposureSource,
    /// Every frame given, in listed exposure order (shortest first).
    pub frames: Vec<FrameExposure>,
    /// The frame whose listed time anchors the measured ones (the inlier closest to the
    /// consensus offset).
    pub anchor: String,
    /// Rounds of curve fit and measurement (0 with a given curve).
    pub rounds: usize,
}

impl ExposureReport {
    /// Warnings for the frames that are off (one line), and, for a merge on the listed times,
    /// what to do.
    pub fn warnings(&self) -> Vec<String> {
        let off: Vec<String> = self
            .frames
            .iter()
            .filter(|f| f.off)
            .map(|f| {
                format!(
                    "{} (listed {}, measured {}, {:+.2} stops)",
                    f.file,
                    fmt_time(f.listed_s),
                    fmt_time(f.measured_s),
                    f.off_stops
                )
            })
            .collect();
        let mut out = Vec::new();
        if !off.is_empty() {
            let what = match self.source {
                ExposureSource::Listed => {
                    "; merge with the measured exposures to use what the photos say"
                }
                ExposureSource::Measured => "; the measured exposures were used",
            };
            out.push(format!(
                "the photos disagree with their listed exposure times by more than 1/3 stop: {}{what}",
                off.join(", ")
            ));
        }
        if self.source == ExposureSource::Measured {
            let same: Vec<String> = self
                .frames
                .iter()
                .filter_map(|f| Some(format!("{} (as {})", f.file, f.same_as.as_ref()?)))
                .collect();
            if !same.is_empty() {
                out.push(format!(
                    "{} carry the same exposure as a neighbour; one of each was merged",
                    same.join(", ")
                ));
            }
            out.push(format!(
                "exposures measured from the photos, anchored on the listed time of {}",
                self.anchor
            ));
        }
        out
    }
}

/// `1/64 s`, `0.75 s`, `2 s`: a time as a message shows it.
fn fmt_time(t: f64) -> String {
    if t < 0.5 {
        return format!("1/{:.0} s", 1.0 / t);
    }
    let s = format!("{t:.3}");
    format!("{} s", s.trim_end_matches('0').trim_end_matches('.'))
}

/// A measurement: per frame (in the order given) the log relative exposure, anchored.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// `ln` of the measured relative exposure per frame.
    pub log_exposure: Vec<f64>,
    /// Per frame, whether it is off ([`OFF_STOPS`] from the consensus).
    pub off: Vec<bool>,
    /// The anchor frame's index.
    pub anchor: usize,
    /// Per frame, whether the step from the previous frame was measured.
    pub step_measured: Vec<bool>,
    /// Per neighbouring pair, whether the two frames are one exposure (the same picture, or
    /// measured closer than [`SAME_STOPS`]).
    pub same: Vec<bool>,
}

/// The code used to judge a value (16-bit values binned to 8 bits).
#[inline]
fn code(p: &Pixels, i: usize) -> u8 {
    match p {
        Pixels::U8(v) => v[i],
        Pixels::U16(v) => bin16(v[i]),
    }
}

/// `g_c` at sample `i` of `p`.
#[inline]
fn g_at(r: &Response, p: &Pixels, i: usize, c: usize) -> f64 {
    match p {
        Pixels::U8(v) => r.curve(c)[usize::from(v[i])],
        Pixels::U16(v) => r.g16(c, v[i]),
    }
}

/// The measured log ratio `ln(e_b / e_a)` of two frames of one scene (same size) on the
/// response `r`: the interquartile mean of `g(Z_b) − g(Z_a)` over the channel values well
/// exposed in both ([`WELL_LO`]..=[`WELL_HI`], above `black_level + 6`). `None` with fewer than
/// [`MIN_VALUES`] such values.
pub fn pair_step(a: &Frame, b: &Frame, r: &Response, black_level: u8) -> Option<f64> {
    let n = a.pixels.len().min(b.pixels.len()) / 3;
    let stride = (n / PIXELS_PER_PAIR).max(1);
    let lo = WELL_LO.max(black_level.saturating_add(6));
    let well = |z: u8| (lo..=WELL_HI).contains(&z);
    let mut d: Vec<f64> = Vec::with_capacity(3 * n / stride + 3);
    let mut p = 0;
    while p < n {
        for c in 0..3 {
            let i = 3 * p + c;
            if well(code(&a.pixels, i)) && well(code(&b.pixels, i)) {
                d.push(g_at(r, &b.pixels, i, c) - g_at(r, &a.pixels, i, c));
            }
        }
        p += stride;
    }
    interquartile_mean(&mut d)
}

/// The mean of the middle half of `d` (reordered); `None` with fewer than [`MIN_VALUES`].
fn interquartile_mean(d: &mut [f64]) -> Option<f64> {
    if d.len() < MIN_VALUES {
        return None;
    }
    let (q1, q3) = (d.len() / 4, 3 * d.len() / 4);
    d.select_nth_unstable_by(q1, f64::total_cmp);
    let upper = &mut d[q1..];
    upper.select_nth_unstable_by(q3 - q1, f64::total_cmp);
    let mid = &upper[..q3 - q1];
    Some(mid.iter().sum::<f64>() / mid.len() as f64)
}

/// [`pair_step`] of every neighbouring pair of `frames` (in order), in parallel with the
/// `parallel` feature; `same[k]` (frames `k`, `k + 1` carry one picture) gives a step of 0
/// without measuring.
pub fn pair_steps(
    frames: &[Frame],
    r: &Response,
    black_level: u8,
    same: &[bool],
) -> Vec<Option<f64>> {
    let pairs: Vec<usize> = (0..frames.len().saturating_sub(1)).collect();
    let step = |&k: &usize| match same.get(k).copied().unwrap_or(false) {
        true => Some(0.0),
        false => pair_step(&frames[k], &frames[k + 1], r, black_level),
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        pairs.par_iter().map(step).collect()
    }
    #[cfg(not(feature = "parallel"))]
    pairs.iter().map(step).collect()
}

/// Measures the exposures of `frames` (sorted by listed exposure, shortest first) on the
/// response `r`: [`pair_steps`] chained from the first frame, pairs closer than
/// [`SAME_STOPS`] made one exposure, and anchored on the listed times ([`anchor`]). `same[k]`
/// says frames `k` and `k + 1` carry the same picture (the bracket's check).
pub fn measure(frames: &[Frame], r: &Response, black_level: u8, same: &[bool]) -> Measurement {
    measure_scaled(frames, r, black_level, same, false)
}

/// [`measure`]; with `scale`, the measured log exposures are also scaled to the listed inliers'
/// ([`anchor`]), which fixes the exponent a self-calibrated curve shares with them.
fn measure_scaled(
    frames: &[Frame],
    r: &Response,
    black_level: u8,
    same: &[bool],
    scale: bool,
) -> Measurement {
    let listed: Vec<f64> = frames.iter().map(|f| f.exposure.relative().ln()).collect();
    let steps = pair_steps(frames, r, black_level, same);
    let same_stop = SAME_STOPS * std::f64::consts::LN_2;
    let mut log = Vec::with_capacity(frames.len());
    let mut step_measured = Vec::with_capacity(frames.len());
    let mut one = Vec::with_capacity(steps.len());
    for (k, &l) in listed.iter().enumerate() {
        if k == 0 {
            log.push(0.0);
            step_measured.push(true);
            continue;
        }
        let (s, measured) = match steps[k - 1] {
            Some(s) if s.abs() < same_stop => (0.0, true),
            Some(s) => (s, true),
            None => (l - listed[k - 1], false),
        };
        one.push(measured && s == 0.0);
        log.push(log[k - 1] + s);
        step_measured.push(measured);
    }
    let (log_exposure, off, anchor) = anchor(&log, &listed, scale);
    Measurement {
        log_exposure,
        off,
        anchor,
        step_measured,
        same: one,
    }
}

/// Anchors relative log exposures `m` (any offset) on the listed `l` (both natural logs): the
/// offset `l − m` of slope 1 is the median over every frame; the frames within [`OFF_STOPS`] of
/// it are the inliers. With `scale` (a self-calibrated curve, whose exponent is free: the curve
/// and the exposures can be raised to one power together), `m` is then mapped onto the
/// inliers' listed values by least squares with a slope (within 0.5..=2) when they span a stop
/// or more, so the listed times that agree with the photos fix the exponent. The frames more
/// than [`OFF_STOPS`] from their listed value after that are off; the one closest keeps its
/// listed value exactly. Returns the anchored values, the off frames and the anchor's index.
pub fn anchor(m: &[f64], l: &[f64], scale: bool) -> (Vec<f64>, Vec<bool>, usize) {
    let off_ln = OFF_STOPS * std::f64::consts::LN_2;
    let d: Vec<f64> = l.iter().zip(m).map(|(l, m)| l - m).collect();
    let b0 = median(&d);
    let inliers: Vec<usize> = (0..d.len())
        .filter(|&i| (d[i] - b0).abs() <= off_ln)
        .collect();
    let b = match inliers.is_empty() {
        true => b0,
        false => median(&inliers.iter().map(|&i| d[i]).collect::<Vec<_>>()),
    };
    let mut mapped: Vec<f64> = m.iter().map(|v| v + b).collect();
    let span = |v: &[usize]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
                (lo.min(l[i]), hi.max(l[i]))
            });
        hi - lo
    };
    if scale && inliers.len() >= 2 && span(&inliers) >= std::f64::consts::LN_2 {
        let n = inliers.len() as f64;
        let mm = inliers.iter().map(|&i| m[i]).sum::<f64>() / n;
        let ml = inliers.iter().map(|&i| l[i]).sum::<f64>() / n;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for &i in &inliers {
            sxy += (m[i] - mm) * (l[i] - ml);
            sxx += (m[i] - mm) * (m[i] - mm);
        }
        if sxx > 0.0 {
            let a = (sxy / sxx).clamp(0.5, 2.0);
            mapped = m.iter().map(|v| ml + a * (v - mm)).collect();
        }
    }
    let r: Vec<f64> = l.iter().zip(&mapped).map(|(l, m)| l - m).collect();
    let off: Vec<bool> = r.iter().map(|v| v.abs() > off_ln).collect();
    let k = (0..r.len())
        .min_by(|&i, &j| r[i].abs().total_cmp(&r[j].abs()))
        .unwrap_or(0);
    let shift = r.get(k).copied().unwrap_or(0.0);
    (mapped.iter().map(|v| v + shift).collect(), off, k)
}

/// The median of `v` (the mean of the middle two for an even count); 0 for none.
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => 0.0,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// Frame `k`'s measured exposure in `m`: the anchor keeps its listed exposure exactly (not
/// `exp(ln(listed))`, which can differ in the last bit); the others [`with_relative`].
fn measured_exposure(f: &Frame, m: &Measurement, k: usize) -> Exposure {
    match k == m.anchor {
        true => f.exposure,
        false => with_relative(f.exposure, m.log_exposure[k]),
    }
}

/// A frame's exposure with the relative exposure `exp(log_relative)` at its own ISO and
/// f-number (only the time changes).
fn with_relative(e: Exposure, log_relative: f64) -> Exposure {
    let per_second = e.relative() / e.time_s;
    Exposure {
        time_s: log_relative.exp() / per_second,
        ..e
    }
}

/// The report of a measurement of `frames` (listed exposures in the frames) for `source`.
pub fn report(
    frames: &[Frame],
    m: &Measurement,
    source: ExposureSource,
    rounds: usize,
) -> ExposureReport {
    let mut out: Vec<FrameExposure> = Vec::with_capacity(frames.len());
    let mut group_first = 0usize;
    for (k, f) in frames.iter().enumerate() {
        if k > 0 && !m.same[k - 1] {
            group_first = k;
        }
        let measured = measured_exposure(f, m, k);
        out.push(FrameExposure {
            file: f.name.clone(),
            listed_s: f.exposure.time_s,
            measured_s: measured.time_s,
            off_stops: (measured.time_s / f.exposure.time_s).log2(),
            off: m.off[k],
            same_as: (group_first != k).then(|| frames[group_first].name.clone()),
            step_measured: m.step_measured[k],
        });
    }
    ExposureReport {
        source,
        frames: out,
        anchor: frames
            .get(m.anchor)
            .map_or_else(String::new, |f| f.name.clone()),
        rounds,
    }
}

/// Applies a measurement to `frames` (the frames it was made on, in that order): every frame
/// takes its measured exposure (its time changes; ISO and f-number stay), and of each run of
/// frames of one exposure the first is kept. Returns the frames left out, in order.
pub fn apply(frames: &mut Vec<Frame>, m: &Measurement) -> Vec<Frame> {
    let mut kept = Vec::with_capacity(frames.len());
    let mut left_out = Vec::new();
    for (k, mut f) in std::mem::take(frames).into_iter().enumerate() {
        f.exposure = measured_exposure(&f, m, k);
        match k > 0 && m.same[k - 1] {
            true => left_out.push(f),
            false => kept.push(f),
        }
    }
    // Exposures measured against the listed order (a step below −1/6 stop) are put in order.
    kept.sort_by(|a, b| a.exposure.relative().total_cmp(&b.exposure.relative()));
    *frames = kept;
    left_out
}

/// The calibration [`calibrate_measuring`] makes with `opts`: `opts` with
/// [`CalibrateOptions::covering_from`] `None`. The default's covering calibration from five
/// frames is not used there: alternating with the measurement, its fit lets a wrong listed
/// time pull the curve (a 7-frame bracket with four frames of one picture measured 0.54 stops
/// off, against 0.01 with the grid calibration; a 5-frame EXIF-rounded bracket's map 0.066
/// stops from the truth against 0.037; tests/lib/exposures.rs). A named method is used as
/// asked.
pub fn measuring_options(opts: &CalibrateOptions) -> CalibrateOptions {
    CalibrateOptions {
        covering_from: None,
        ..opts.clone()
    }
}

/// Calibrates the response on `frames` (sorted by listed exposure) while measuring their
/// exposures: the curve fit ([`response::calibrate`], sampling inside `circle`) on one frame of
/// each exposure at the current exposures (the listed ones first), the measurement
/// ([`measure`]) on the fitted curve, in rounds until no exposure moves by more than
/// [`CONVERGED_STOPS`] (at most [`MAX_ROUNDS`]). `same[k]`: frames `k`, `k + 1` carry the same
/// picture. Returns the last calibration (on the last exposures), the measurement of every
/// frame against its listed exposure, and the rounds. The frames come back as they were given
/// (their order and listed exposures); only their place in memory moves between rounds.
pub fn calibrate_measuring(
    frames: &mut Vec<Frame>,
    same: &[bool],
    circle: Option<Circle>,
    opts: &CalibrateOptions,
    black_level: u8,
) -> Result<(Calibration, Measurement, usize), ResponseError> {
    let opts = &measuring_options(opts);
    let listed: Vec<f64> = frames.iter().map(|f| f.exposure.relative().ln()).collect();
    // The first fit: the listed exposures, one frame of each picture.
    let mut current = Measurement {
        log_exposure: listed,
        off: vec![false; frames.len()],
        anchor: 0,
        step_measured: vec![true; frames.len()],
        same: (0..frames.len().saturating_sub(1))
            .map(|k| same.get(k).copied().unwrap_or(false))
            .collect(),
    };
    // One round: the curve on the current exposures, the exposures on that curve.
    let mut rounds = 0;
    let round = |frames: &mut Vec<Frame>, x: &Measurement| {
        let cal = fit_on(frames, x, |fit| response::calibrate(fit, circle, opts))?;
        let m = measure_scaled(frames, &cal.response, black_level, &x.same, true);
        Ok::<_, ResponseError>((cal, m))
    };
    // The rounds converge linearly, and slowly where a wrong time is shared between the curve
    // and the exposures; every two rounds are extrapolated along their direction (SQUAREM,
    // Varadhan & Roland 2008), which keeps the fixed point and reaches it in a few rounds.
    loop {
        let (cal1, m1) = round(frames, &current)?;
        rounds += 1;
        if done(&current, &m1) || rounds >= MAX_ROUNDS {
            return Ok((cal1, m1, rounds));
        }
        if m1.same != current.same {
            current = m1;
            continue;
        }
        let (cal2, m2) = round(frames, &m1)?;
        rounds += 1;
        if done(&m1, &m2) || rounds >= MAX_ROUNDS {
            return Ok((cal2, m2, rounds));
        }
        if m2.same != m1.same {
            current = m2;
            continue;
        }
        current = extrapolated(frames, &current, &m1, &m2).unwrap_or(m2);
    }
}

/// Whether the exposures moved by less than [`CONVERGED_STOPS`] from `a` to `b`, with no
/// frames newly found to be one exposure.
fn done(a: &Measurement, b: &Measurement) -> bool {
    let moved = a
        .log_exposure
        .iter()
        .zip(&b.log_exposure)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    moved < CONVERGED_STOPS * std::f64::consts::LN_2 && a.same == b.same
}

/// The SQUAREM step from `x0` through `x1`, `x2` (two rounds), anchored on the listed times:
/// `x0 − 2α r + α² v` with `r = x1 − x0`, `v = x2 − 2 x1 + x0`, `α = −|r| / |v|` (at most −1);
/// `None` when it is not a usable bracket (not finite, or steps that fall below
/// [`SAME_STOPS`] where `x2`'s did not).
fn extrapolated(
    frames: &[Frame],
    x0: &Measurement,
    x1: &Measurement,
    x2: &Measurement,
) -> Option<Measurement> {
    let (a, b, c) = (&x0.log_exposure, &x1.log_exposure, &x2.log_exposure);
    let r: Vec<f64> = b.iter().zip(a).map(|(b, a)| b - a).collect();
    let v: Vec<f64> = (0..a.len()).map(|k| c[k] - 2.0 * b[k] + a[k]).collect();
    let norm = |u: &[f64]| u.iter().map(|x| x * x).sum::<f64>().sqrt();
    let (nr, nv) = (norm(&r), norm(&v));
    if !(nv > 0.0 && nr.is_finite()) {
        return None;
    }
    let alpha = (-nr / nv).clamp(-MAX_STRETCH, -1.0);
    let x: Vec<f64> = (0..a.len())
        .map(|k| a[k] - 2.0 * alpha * r[k] + alpha * alpha * v[k])
        .collect();
    let same_ln = SAME_STOPS * std::f64::consts::LN_2;
    let usable = x.iter().all(|v| v.is_finite())
        && (1..x.len()).all(|k| x2.same[k - 1] || x[k] - x[k - 1] >= same_ln);
    if !usable {
        return None;
    }
    let listed: Vec<f64> = frames.iter().map(|f| f.exposure.relative().ln()).collect();
    let (log_exposure, off, anchor) = anchor(&x, &listed, true);
    Some(Measurement {
        log_exposure,
        off,
        anchor,
        ..x2.clone()
    })
}

/// The longest SQUAREM step, in rounds' lengths.
const MAX_STRETCH: f64 = 50.0;

/// Runs `fit` on the frames a measured merge would use ([`apply`]: one of each exposure, at
/// the exposures of `m`, in exposure order), then puts `frames` back as they were (order and
/// exposures). Only the frames' headers move; their pixels stay where they are.
fn fit_on<R>(frames: &mut Vec<Frame>, m: &Measurement, fit: impl FnOnce(&[Frame]) -> R) -> R {
    let exposures: Vec<Exposure> = frames.iter().map(|f| f.exposure).collect();
    let mut kept: Vec<(usize, Frame)> = Vec::with_capacity(frames.len());
    let mut rest: Vec<(usize, Frame)> = Vec::new();
    for (k, mut f) in std::mem::take(frames).into_iter().enumerate() {
        f.exposure = with_relative(f.exposure, m.log_exposure[k]);
        match k > 0 && m.same[k - 1] {
            true => rest.push((k, f)),
            false => kept.push((k, f)),
        }
    }
    kept.sort_by(|a, b| a.1.exposure.relative().total_cmp(&b.1.exposure.relative()));
    let (order, fit_frames): (Vec<usize>, Vec<Frame>) = kept.into_iter().unzip();
    let out = fit(&fit_frames);
    let mut all: Vec<(usize, Frame)> = order.into_iter().zip(fit_frames).chain(rest).collect();
    all.sort_by_key(|(k, _)| *k);
    *frames = all
        .into_iter()
        .map(|(k, mut f)| {
            f.exposure = exposures[k];
            f
        })
        .collect();
    out
}
