//! The bracket's checks: what [`assemble`] refuses or warns about before anything downstream
//! sees the frames.

#[cfg(feature = "parallel")]
use rayon::prelude::*;

use super::decode::orient;
use super::{
    bin16, Bracket, BracketError, CaptureInfo, DecodedFrame, Exposure, Frame, NamedPair,
    OrientationPolicy, Pixels,
};

/// Validates decoded frames and turns them into a sorted [`Bracket`].
///
/// `times`, when given, are exposure times in seconds in the order of `decoded` and override
/// EXIF; otherwise every frame needs an EXIF `ExposureTime`. The checks run in the order listed
/// here; the first that fails gives the error.
pub fn assemble(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
) -> Result<Bracket, BracketError> {
    assemble_with_black_level(decoded, times, orientation, 0)
}

/// [`assemble`] for frames whose black level the caller knows: `black_level` is an 8-bit code
/// (0 = not known; 16-bit frames compare at `257 ×` it). Codes up to it, and up to the
/// pedestal's noise above it, say nothing about the exposure, so the check for frames that
/// carry the same picture looks only above them.
pub fn assemble_with_black_level(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
    black_level: u8,
) -> Result<Bracket, BracketError> {
    assemble_impl(decoded, times, orientation, black_level, false, false).map(|(b, _)| b)
}

/// [`assemble_with_black_level`] for a bracket whose exposures are then measured from the photos
/// ([`crate::exposures`]): neighbours that carry the same picture are not refused (they are
/// one exposure, whatever their listed times say), and are not judged darker when longer.
/// Returns the bracket and, per neighbouring pair of its frames (`k`, `k + 1`), whether the two
/// carry the same picture.
pub fn assemble_for_measuring(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
    black_level: u8,
) -> Result<(Bracket, Vec<bool>), BracketError> {
    assemble_impl(decoded, times, orientation, black_level, false, true)
}

/// [`assemble_with_black_level`] on frames that are already oriented and carry only every
/// 7th pixel ([`every_7th_pixel`]): every check below reads those pixels alone, so the bracket (its
/// order, the frames left out, the warnings, the refusals) is the one the whole frames give,
/// while the whole frames never have to be in memory together. Each frame's `width` and
/// `height` are its stored (pre-orientation) size, as decoded. The frames of the result carry
/// the thumbnails as their pixels.
pub(crate) fn assemble_thumbnails(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
    black_level: u8,
) -> Result<Bracket, BracketError> {
    assemble_impl(decoded, times, orientation, black_level, true, false).map(|(b, _)| b)
}

/// The samples of every 7th pixel (pixels 0, 7, 14, … in row-major order, all three channels)
/// of an oriented frame's interleaved RGB samples `v`: all that [`assemble`]'s checks read, a
/// frame's thumbnail for [`assemble_thumbnails`].
pub(crate) fn every_7th_pixel<T: Copy>(v: &[T]) -> Vec<T> {
    v.chunks(3).step_by(7).flatten().copied().collect()
}

fn assemble_impl(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
    black_level: u8,
    thumbs: bool,
    keep_identical: bool,
) -> Result<(Bracket, Vec<bool>), BracketError> {
    at_least_two(decoded.len())?;
    if let Some(t) = times {
        one_valid_time_per_frame(t, decoded.len())?;
    }
    frames_agree_in_size_depth_and_orientation(&decoded, orientation)?;
    let mut warnings = settings_that_differ(&decoded);
    let (frames, info) = oriented_and_sorted_by_exposure(decoded, times, orientation, thumbs)?;
    neighbours_at_least_a_sixth_stop_apart(&frames)?;
    let (frames, checks) = frames_that_inform(frames, black_level, &mut warnings, thumbs)?;
    // Identical first: frames that carry the same picture wherever both show one are the same
    // scene, whatever a few moving blocks say (a camera that ignored the bracket while
    // something changed in a corner would otherwise be called two scenes).
    let mut checks = checks;
    if keep_identical {
        // One picture is one exposure: nothing to refuse, and no order to judge.
        for c in checks.iter_mut().filter(|c| c.identical) {
            c.darker_when_longer = false;
        }
    } else {
        no_identical_neighbours(&frames, &checks)?;
    }
    one_scene(&frames, &checks)?;
    no_frame_darker_when_exposed_longer(&frames, &checks)?;
    let identical = checks.iter().map(|c| c.identical).collect();
    let pixel_orientation = match orientation {
        OrientationPolicy::Apply => 1,
        OrientationPolicy::Ignore => info.orientation,
    };
    let bracket = Bracket {
        frames,
        info,
        warnings,
        pixel_orientation,
    };
    Ok((bracket, identical))
}

/// A bracket needs two frames at least.
fn at_least_two(frames: usize) -> Result<(), BracketError> {
    match frames < 2 {
        true => Err(BracketError::TooFewFrames(frames)),
        false => Ok(()),
    }
}

/// Times given by the caller: one per frame, each finite and positive.
fn one_valid_time_per_frame(times: &[f64], frames: usize) -> Result<(), BracketError> {
    if times.len() != frames {
        return Err(BracketError::TimesCount {
            given: times.len(),
            frames,
        });
    }
    match times.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        Some(v) => Err(BracketError::BadTime {
            file: "exposure times".into(),
            value: v.to_string(),
        }),
        None => Ok(()),
    }
}

/// Every frame has the first frame's size and bit depth, and (when orientation is applied) its
/// EXIF orientation. A refusal names every frame that differs.
fn frames_agree_in_size_depth_and_orientation(
    decoded: &[DecodedFrame],
    orientation: OrientationPolicy,
) -> Result<(), BracketError> {
    let first = &decoded[0];
    let rest = &decoded[1..];
    let sizes: Vec<(String, usize, usize)> = rest
        .iter()
        .filter(|d| (d.width, d.height) != (first.width, first.height))
        .map(|d| (d.name.clone(), d.width, d.height))
        .collect();
    if !sizes.is_empty() {
        return Err(BracketError::SizeMismatch {
            files: sizes,
            first: first.name.clone(),
            w0: first.width,
            h0: first.height,
        });
    }
    let depths: Vec<(String, u32)> = rest
        .iter()
        .filter(|d| d.pixels.bit_depth() != first.pixels.bit_depth())
        .map(|d| (d.name.clone(), d.pixels.bit_depth()))
        .collect();
    if !depths.is_empty() {
        return Err(BracketError::DepthMismatch {
            files: depths,
            first: first.name.clone(),
            bits0: first.pixels.bit_depth(),
        });
    }
    let turned: Vec<(String, u16)> = rest
        .iter()
        .filter(|d| d.info.orientation != first.info.orientation)
        .map(|d| (d.name.clone(), d.info.orientation))
        .collect();
    if orientation == OrientationPolicy::Apply && !turned.is_empty() {
        return Err(BracketError::OrientationMismatch {
            files: turned,
            first: first.name.clone(),
            o0: first.info.orientation,
        });
    }
    Ok(())
}

/// Warnings for settings that should not differ within a bracket (ISO, aperture, white
/// balance) and for a colour profile that is not sRGB.
fn settings_that_differ(decoded: &[DecodedFrame]) -> Vec<String> {
    let mut warnings = Vec::new();
    differing(decoded, "ISO", |d| d.iso, &mut warnings);
    differing(
        decoded,
        "aperture (f-number)",
        |d| d.f_number,
        &mut warnings,
    );
    differing(
        decoded,
        "white balance mode",
        |d| d.info.white_balance.map(f64::from),
        &mut warnings,
    );
    if let Some(p) = decoded.iter().find_map(|d| d.non_srgb_icc.as_ref()) {
        warnings.push(format!(
            "embedded ICC profile '{p}' is not sRGB: pixel values are not sRGB (the response calibration absorbs the tone curve, but colours stay in that profile's primaries)"
        ));
    }
    warnings
}

/// The frames with their exposure (the caller's time, else EXIF's: a frame with neither is
/// refused), oriented as the policy says, sorted by relative exposure (shortest first); and the
/// capture metadata of the middle exposure.
fn oriented_and_sorted_by_exposure(
    decoded: Vec<DecodedFrame>,
    times: Option<&[f64]>,
    orientation: OrientationPolicy,
    thumbs: bool,
) -> Result<(Vec<Frame>, CaptureInfo), BracketError> {
    if times.is_none() {
        let missing: Vec<String> = decoded
            .iter()
            .filter(|d| d.exif_time_s.is_none())
            .map(|d| d.name.clone())
            .collect();
        if !missing.is_empty() {
            return Err(BracketError::MissingExposure { files: missing });
        }
    }
    let mut frames = Vec::with_capacity(decoded.len());
    let mut infos = Vec::with_capacity(decoded.len());
    for (i, d) in decoded.into_iter().enumerate() {
        let time_s = match (times, d.exif_time_s) {
            (Some(t), _) => t[i],
            (None, Some(t)) => t,
            (None, None) => {
                return Err(BracketError::MissingExposure {
                    files: vec![d.name.clone()],
                })
            }
        };
        let exposure = Exposure {
            time_s,
            iso: d.iso,
            f_number: d.f_number,
        };
        let (width, height, pixels) = match orientation {
            // Thumbnails of oriented frames: only the size turns.
            OrientationPolicy::Apply if thumbs && d.info.orientation >= 5 => {
                (d.height, d.width, d.pixels)
            }
            OrientationPolicy::Apply if !thumbs && d.info.orientation != 1 => {
                orient(d.width, d.height, d.pixels, d.info.orientation)
            }
            _ => (d.width, d.height, d.pixels),
        };
        infos.push(d.info);
        frames.push(Frame {
            name: d.name,
            width,
            height,
            pixels,
            exposure,
        });
    }
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by(|&a, &b| {
        frames[a]
            .exposure
            .relative()
            .total_cmp(&frames[b].exposure.relative())
    });
    let mut slots: Vec<Option<Frame>> = frames.into_iter().map(Some).collect();
    let frames: Vec<Frame> = order.iter().filter_map(|&i| slots[i].take()).collect();
    let info = infos[order[order.len() / 2]].clone();
    Ok((frames, info))
}

/// No two neighbouring frames (sorted) closer than 1/6 stop in relative exposure; a refusal
/// names every such pair.
fn neighbours_at_least_a_sixth_stop_apart(frames: &[Frame]) -> Result<(), BracketError> {
    let pairs: Vec<NamedPair> = frames
        .windows(2)
        .filter(|p| (p[1].exposure.relative() / p[0].exposure.relative()).log2() < 1.0 / 6.0)
        .map(|p| named_pair(&p[0], &p[1]))
        .collect();
    match pairs.is_empty() {
        true => Ok(()),
        false => Err(BracketError::DuplicateExposure { pairs }),
    }
}

/// `b` (exposed longer) and `a`, with their exposures, for a message.
fn named_pair(a: &Frame, b: &Frame) -> NamedPair {
    NamedPair {
        file: b.name.clone(),
        e1: describe(&b.exposure),
        other: a.name.clone(),
        e2: describe(&a.exposure),
    }
}

/// The frames that inform, with the comparison of each neighbouring pair among them.
///
/// Only informative values judge the frames: neither at the bracket's black level nor clipped.
/// A frame with (almost) none — all black level or all white — adds nothing and is left out
/// with a warning, as long as two frames remain.
fn frames_that_inform(
    frames: Vec<Frame>,
    black_level: u8,
    warnings: &mut Vec<String>,
    thumbs: bool,
) -> Result<(Vec<Frame>, Vec<PairCheck>), BracketError> {
    fn looks(frames: &[Frame], thumbs: bool) -> Vec<Look<'_>> {
        frames.iter().map(|f| Look::of(f, thumbs)).collect()
    }
    let all = looks(&frames, thumbs);
    let floor = black_floor(&all);
    let dark = Dark::of(&all, floor, black_level);
    let total = frames.len();
    // Every frame's informative samples and every neighbouring pair's comparison in one go (in
    // parallel with the `parallel` feature): each is a pass over frames too big for the cache,
    // so they are run side by side rather than one after another. The pairs are compared again
    // only when a frame is left out (rare), which makes new neighbours.
    #[cfg(feature = "parallel")]
    let (counts, checks) = rayon::join(
        || informative_counts(&all, floor),
        || compare_neighbours(&all, &dark),
    );
    #[cfg(not(feature = "parallel"))]
    let (counts, checks) = (
        informative_counts(&all, floor),
        compare_neighbours(&all, &dark),
    );
    let needed: Vec<usize> = all.iter().map(informative_needed).collect();
    drop(all);
    let mut kept = Vec::with_capacity(total);
    let mut left_out = Vec::new();
    for ((f, count), needed) in frames.into_iter().zip(counts).zip(needed) {
        if count < needed {
            left_out.push(f.name);
        } else {
            kept.push(f);
        }
    }
    if kept.len() < 2 {
        return Err(BracketError::NothingToMerge {
            given: total,
            left_out,
        });
    }
    for name in left_out {
        warnings.push(format!(
            "{name}: almost every pixel is at the black level or clipped, so the frame adds nothing to the bracket; it was left out"
        ));
    }
    let checks = match kept.len() == total {
        true => checks,
        false => compare_neighbours(&looks(&kept, thumbs), &dark),
    };
    Ok((kept, checks))
}

/// Every frame shows its neighbours' scene ([`PairCheck::other_scene`]). A frame is named
/// alone only when that is certain: both its pairs are of two scenes, or (at an end of the
/// exposure order) its one pair is while its neighbour was found to show the scene of the frame
/// beyond. Otherwise the refusal names both frames of every pair of two scenes.
fn one_scene(frames: &[Frame], checks: &[PairCheck]) -> Result<(), BracketError> {
    let bad = |k: usize| checks.get(k).is_some_and(|c| c.other_scene == Some(true));
    let good = |k: usize| checks.get(k).is_some_and(|c| c.other_scene == Some(false));
    if !(0..checks.len()).any(bad) {
        return Ok(());
    }
    let last = frames.len() - 1;
    // Pair k joins frames k and k + 1.
    let odd = |k: usize| match k {
        0 => bad(0) && good(1),
        k if k == last => bad(k - 1) && k >= 2 && good(k - 2),
        k => bad(k - 1) && bad(k),
    };
    let alone: Vec<usize> = (0..=last).filter(|&k| odd(k)).collect();
    let explained = |k: usize| alone.contains(&k) || alone.contains(&(k + 1));
    let mut files = alone.clone();
    let mut others: Vec<usize> = alone
        .iter()
        .flat_map(|&k| [k.checked_sub(1), (k < last).then_some(k + 1)])
        .flatten()
        .filter(|k| !alone.contains(k))
        .collect();
    // Pairs no single frame explains: both frames, and no "others" to compare with.
    let unexplained: Vec<usize> = (0..checks.len())
        .filter(|&k| bad(k) && !explained(k))
        .collect();
    if !unexplained.is_empty() {
        files.extend(unexplained.iter().flat_map(|&k| [k, k + 1]));
        others.clear();
    }
    files.sort_unstable();
    files.dedup();
    others.sort_unstable();
    others.dedup();
    let names = |v: Vec<usize>| v.into_iter().map(|k| frames[k].name.clone()).collect();
    Err(BracketError::OtherScene {
        files: names(files),
        others: names(others),
    })
}

/// No two neighbours carry (nearly) the same picture although their exposures differ. A
/// refusal names every frame concerned, in runs of neighbours that carry one picture (a camera
/// that ignored the bracket for four shots gives one run of four).
fn no_identical_neighbours(frames: &[Frame], checks: &[PairCheck]) -> Result<(), BracketError> {
    let mut groups: Vec<Vec<String>> = Vec::new();
    let mut stops = 0f64;
    let mut start: Option<usize> = None;
    for (i, check) in checks.iter().enumerate() {
        match (check.identical, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                groups.push(frames[s..=i].iter().map(|f| f.name.clone()).collect());
                stops = stops.max(span(&frames[s], &frames[i]));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        let last = frames.len() - 1;
        groups.push(frames[s..].iter().map(|f| f.name.clone()).collect());
        stops = stops.max(span(&frames[s], &frames[last]));
    }
    match groups.is_empty() {
        true => Ok(()),
        false => Err(BracketError::IdenticalPixels { groups, stops }),
    }
}

/// Stops from `a`'s relative exposure to `b`'s.
fn span(a: &Frame, b: &Frame) -> f64 {
    (b.exposure.relative() / a.exposure.relative()).log2()
}

/// No frame is darker than its neighbour exposed shorter (the times belong to other photos).
fn no_frame_darker_when_exposed_longer(
    frames: &[Frame],
    checks: &[PairCheck],
) -> Result<(), BracketError> {
    let pairs: Vec<NamedPair> = frames
        .windows(2)
        .zip(checks)
        .filter(|(_, c)| c.darker_when_longer)
        .map(|(p, _)| named_pair(&p[0], &p[1]))
        .collect();
    match pairs.is_empty() {
        true => Ok(()),
        false => Err(BracketError::DarkerWhenLonger { pairs }),
    }
}

/// [`compare_pair`] on every neighbouring pair (in parallel with the `parallel` feature).
fn compare_neighbours(frames: &[Look<'_>], dark: &Dark) -> Vec<PairCheck> {
    let pairs: Vec<(&Look<'_>, &Look<'_>)> = frames.windows(2).map(|p| (&p[0], &p[1])).collect();
    #[cfg(feature = "parallel")]
    let checks = pairs
        .par_iter()
        .map(|&(a, b)| compare_pair(a, b, dark))
        .collect();
    #[cfg(not(feature = "parallel"))]
    let checks = pairs
        .iter()
        .map(|&(a, b)| compare_pair(a, b, dark))
        .collect();
    checks
}

/// [`informative_count`] of every frame (in parallel with the `parallel` feature).
fn informative_counts(frames: &[Look<'_>], floor: f32) -> Vec<usize> {
    #[cfg(feature = "parallel")]
    let counts = frames
        .par_iter()
        .map(|f| informative_count(f, floor))
        .collect();
    #[cfg(not(feature = "parallel"))]
    let counts = frames.iter().map(|f| informative_count(f, floor)).collect();
    counts
}

fn describe(e: &Exposure) -> String {
    let t = if e.time_s < 1.0 {
        format!("1/{:.0} s", 1.0 / e.time_s)
    } else {
        format!("{} s", e.time_s)
    };
    let mut s = t;
    if let Some(iso) = e.iso {
        s += &format!(" ISO {iso}");
    }
    if let Some(n) = e.f_number {
        s += &format!(" f/{n}");
    }
    s
}

fn differing(
    decoded: &[DecodedFrame],
    what: &str,
    key: impl Fn(&DecodedFrame) -> Option<f64>,
    warnings: &mut Vec<String>,
) {
    let vals: Vec<(String, f64)> = decoded
        .iter()
        .filter_map(|d| key(d).map(|v| (d.name.clone(), v)))
        .collect();
    if let Some((n0, v0)) = vals.first() {
        if let Some((n, v)) = vals.iter().find(|(_, v)| (v - v0).abs() > 1e-9 * v0.abs()) {
            warnings.push(format!(
                "{what} differs between frames ({n0}: {v0}, {n}: {v}); exposure accounts for it as t·ISO/N², but check the bracket was shot as intended"
            ));
        }
    }
}

/// Values (full scale 1) at most this far above the bracket's black level count as black.
const BLACK_MARGIN: f32 = 0.03;
/// Values above this count as clipped.
const CLIP_UNIT: f32 = 0.98;

/// The bracket's black level on the unit scale: the 0.5th percentile of every 21st sample of
/// every frame. 0 for most photos (a black housing or shadows); ≈ 16/255 for a film scan or a
/// camera that lifts its blacks, where "black" pixels are not 0.
fn black_floor(frames: &[Look<'_>]) -> f32 {
    // The same percentile from a histogram of the codes (one pass, no copy or selection of
    // millions of samples): frames of one bit depth, as a bracket's are.
    fn by_histogram<T: Copy + Into<usize>>(
        frames: &[Look<'_>],
        codes: impl Fn(&Pixels) -> Option<&[T]>,
        bins: usize,
        full: f32,
    ) -> Option<f32> {
        let mut hist = vec![0usize; bins];
        let mut len = 0usize;
        for f in frames {
            for &c in codes(f.pixels)?.iter().step_by(f.step(21)) {
                hist[c.into()] += 1;
                len += 1;
            }
        }
        if len == 0 {
            return Some(0.0);
        }
        let k = len / 200;
        let mut seen = 0usize;
        let code = hist.iter().position(|&n| {
            seen += n;
            seen > k
        })?;
        Some(code as f32 / full)
    }
    fn u8s(p: &Pixels) -> Option<&[u8]> {
        match p {
            Pixels::U8(v) => Some(v),
            Pixels::U16(_) => None,
        }
    }
    fn u16s(p: &Pixels) -> Option<&[u16]> {
        match p {
            Pixels::U16(v) => Some(v),
            Pixels::U8(_) => None,
        }
    }
    if let Some(v) = by_histogram(frames, u8s, 1 << 8, 255.0)
        .or_else(|| by_histogram(frames, u16s, 1 << 16, 65535.0))
    {
        return v;
    }
    let mut v: Vec<f32> = frames
        .iter()
        .flat_map(|f| (0..f.len).step_by(21).map(|i| f.unit(i)))
        .collect();
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 200;
    v.select_nth_unstable_by(k, f32::total_cmp);
    v[k]
}

/// Whether a unit value informs: above the black level by a margin and below clipping.
#[inline]
fn informative(v: f32, floor: f32) -> bool {
    v > floor + BLACK_MARGIN && v < CLIP_UNIT
}

/// Informative values among every 21st sample of a frame.
///
/// 8-bit samples are judged by a table of the 256 codes (the same verdicts as [`Pixels::unit`]'s
/// division, without one per sample).
fn informative_count(f: &Look<'_>, floor: f32) -> usize {
    match f.pixels {
        Pixels::U8(v) => {
            let inf: [bool; 256] = std::array::from_fn(|c| informative(c as f32 / 255.0, floor));
            v.iter()
                .step_by(f.step(21))
                .take(f.len.div_ceil(21))
                .filter(|&&code| inf[usize::from(code)])
                .count()
        }
        Pixels::U16(_) => (0..f.len)
            .step_by(21)
            .filter(|&i| informative(f.unit(i), floor))
            .count(),
    }
}

/// A frame with fewer informative samples (of every 21st) than this adds nothing: 0.05 % of
/// them, and at least 10; a frame too small to judge (under 100 such samples) needs none.
fn informative_needed(f: &Look<'_>) -> usize {
    let sampled = f.len.div_ceil(21);
    if sampled < 100 {
        0
    } else {
        sampled / 2000 + 10
    }
}

/// Where a bracket's values stop saying "dark" and start saying something about the exposure,
/// on the unit scale (full scale 1).
struct Dark {
    /// Per channel, the top of the pedestal's noise: a film scan or a camera that lifts its
    /// blacks puts most of a short frame on a pedestal a few codes wide, which is not picture.
    /// The bracket's black floor plus [`BLACK_MARGIN`] for brackets without a pedestal.
    pedestal: [f32; 3],
}

/// A pedestal is at most this high (8-bit codes; synthetic and real film scans sit at 12–20).
const PEDESTAL_MAX: usize = 64;
/// Values more than this many standard deviations of the pedestal's noise above it are picture.
const PEDESTAL_SIGMAS: f32 = 4.0;

impl Dark {
    /// The floor of [`black_floor`], and the pedestal of the darkest frame (`frames[0]`, the
    /// shortest exposure): per channel the mode of its codes when that mode is a low, narrow
    /// peak (≤ [`PEDESTAL_MAX`], a third of the frame within ±3 codes of it), and the spread of
    /// its lower flank (where no picture lies: picture only adds light) as the noise. The
    /// caller's `black_level` (8-bit code, 0 = unknown) raises the pedestal when higher.
    fn of(frames: &[Look<'_>], floor: f32, black_level: u8) -> Dark {
        let floor = floor + BLACK_MARGIN;
        let mut pedestal = [floor; 3];
        let Some(darkest) = frames.first() else {
            return Dark { pedestal };
        };
        for (c, p) in pedestal.iter_mut().enumerate() {
            let hist = channel_histogram(darkest, c);
            let total: usize = hist.iter().sum();
            let mode = (0..256)
                .max_by_key(|&z| (hist[z], usize::MAX - z))
                .unwrap_or(0);
            let near: usize = hist[mode.saturating_sub(3)..=(mode + 3).min(255)]
                .iter()
                .sum();
            let is_pedestal = mode > 0 && mode <= PEDESTAL_MAX && 3 * near >= total;
            let level = match is_pedestal {
                true => mode.max(usize::from(black_level)),
                false => usize::from(black_level),
            };
            if level == 0 {
                continue;
            }
            // The lower flank: half the mode's bin and everything up to 32 codes below it;
            // the code below which 31.7 % of it lies is one standard deviation down.
            let sigma = match is_pedestal {
                true => {
                    let lo = mode.saturating_sub(32);
                    let flank =
                        hist[lo..mode].iter().sum::<usize>() as f32 + hist[mode] as f32 / 2.0;
                    let mut seen = hist[mode] as f32 / 2.0;
                    let mut z = mode;
                    while z > lo && seen < 0.683 * flank {
                        z -= 1;
                        seen += hist[z] as f32;
                    }
                    (mode - z).max(1) as f32
                }
                false => 1.0,
            };
            let top = (level as f32 + (PEDESTAL_SIGMAS * sigma).max(3.0)) / 255.0;
            *p = p.max(top);
        }
        Dark { pedestal }
    }
}

/// The histogram of channel `c`'s 8-bit codes (16-bit ones binned) over a frame's samples
/// `i = c, c + 21, …` (channel `c` of every 7th pixel), read straight from the held samples
/// `c, c + step, …` (no per-sample [`Look::at`] or match on the depth).
fn channel_histogram(f: &Look<'_>, c: usize) -> [usize; 256] {
    let mut hist = [0usize; 256];
    let (step, count) = (f.step(21), f.len.saturating_sub(c).div_ceil(21));
    match f.pixels {
        Pixels::U8(v) => {
            for &code in v.iter().skip(c).step_by(step).take(count) {
                hist[usize::from(code)] += 1;
            }
        }
        Pixels::U16(v) => {
            for &code in v.iter().skip(c).step_by(step).take(count) {
                hist[usize::from(bin16(code))] += 1;
            }
        }
    }
    hist
}

/// What comparing two neighbouring frames of a bracket (`a` exposed shorter than `b`) found.
struct PairCheck {
    /// The two frames carry (nearly) the same picture: over the values that are picture in
    /// both (above the pedestal's noise and not clipped), the mean brightness differs by less
    /// than 2 % and the mean absolute difference is below 1.5 % of full scale. Frames that
    /// genuinely differ by ≥ 1/6 stop differ by ≥ 12 % in linear terms, which even a strong
    /// tone curve does not squeeze below 2 %. Judging only picture matters: a mostly black frame
    /// (a film scan's pedestal, a short exposure at night) is identical to its neighbour *where
    /// both are black*, which says nothing about the exposure.
    identical: bool,
    /// `b`, exposed longer, is clearly darker at most samples where the two differ clearly (by
    /// more than 3 % of the code range): a code never falls as exposure grows, so the times
    /// must belong to other photos. Noise, JPEG and a little motion make a few samples darker
    /// in any real bracket; a majority needs swapped times.
    darker_when_longer: bool,
    /// Whether the two frames show two scenes; `None` when too little is picture in both to
    /// tell. The frames are cut into an 8 × 8 grid of blocks; per channel, a block's mean over
    /// the samples that are picture in both frames (at least 4 of them) orders it against every
    /// other block. A longer exposure and any tone curve keep the order of two blocks that
    /// differ clearly (by 2 % of full scale in both frames); noise, JPEG, moving clouds and an
    /// unaligned hand-held bracket reverse a few (the real sets in `../shared/data`: at most
    /// 8 %); a photo of another scene or view reverses about half or more. Two scenes when more
    /// than a third of at least 100 such pairs of blocks are reversed.
    other_scene: Option<bool>,
}

/// The grid of blocks whose mean brightness orders [`PairCheck::other_scene`].
const GRID: usize = 8;

/// What [`compare_pair`] sums over the samples of every 7th pixel of two frames.
#[derive(Debug, Clone, PartialEq)]
struct PairSums {
    /// Sums of `a`'s and `b`'s unit values and of their absolute differences, over the samples
    /// that are picture in both; `count` such samples.
    sa: f64,
    sb: f64,
    sad: f64,
    count: usize,
    /// Samples where `b` is darker (brighter) than `a` by more than 0.03.
    darker: usize,
    brighter: usize,
    /// Per block of an 8 × 8 grid and channel, the sums of both frames' picture samples.
    blocks: [[[f64; 3]; 2]; GRID * GRID],
    in_block: [[usize; 3]; GRID * GRID],
}

/// [`pair_sums_with`], reading 8-bit samples through a table of their unit values (the same
/// `f32`s as [`Pixels::unit`]'s division, which costs more per sample, in WebAssembly most).
fn pair_sums(a: &Look<'_>, b: &Look<'_>, dark: &Dark) -> PairSums {
    match (a.pixels, b.pixels) {
        (Pixels::U8(va), Pixels::U8(vb)) => {
            let unit: [f32; 256] = std::array::from_fn(|c| c as f32 / 255.0);
            pair_sums_with(
                a,
                b,
                dark,
                |j| unit[usize::from(va[j])],
                |j| unit[usize::from(vb[j])],
            )
        }
        _ => pair_sums_with(a, b, dark, |j| a.pixels.unit(j), |j| b.pixels.unit(j)),
    }
}

/// Sums two frames' samples `i = 21·k + c` (channel `c` of every 7th pixel), in one pass over
/// both; `ua`/`ub` give the unit value of a held sample (see [`Look::at`]).
///
/// The pixel's column and row are carried from sample to sample and its grid block looked up,
/// so the pass divides nothing per sample (it divided four times per pixel, and once more per
/// 8-bit sample in [`Pixels::unit`]). The samples, their order and so every sum are those of
/// the per-sample formulas (`x = i / 3 % w`, `y = i / 3 / w`; a unit test compares them).
fn pair_sums_with(
    a: &Look<'_>,
    b: &Look<'_>,
    dark: &Dark,
    ua: impl Fn(usize) -> f32,
    ub: impl Fn(usize) -> f32,
) -> PairSums {
    let n = a.len.min(b.len);
    // Sums in locals (registers), the blocks' sums in arrays of the frame: written into the
    // result once, not through it per sample.
    let (mut sa, mut sb, mut sad, mut count) = (0f64, 0f64, 0f64, 0usize);
    let (mut darker, mut brighter) = (0usize, 0usize);
    let mut blocks = [[[0f64; 3]; 2]; GRID * GRID];
    let mut in_block = [[0usize; 3]; GRID * GRID];
    let (w, h) = (a.width.max(1), a.height.max(1));
    // The block column of every pixel column, and the first block of a pixel row.
    let column_block: Vec<usize> = (0..w).map(|x| (x * GRID / w).min(GRID - 1)).collect();
    let row_block = |y: usize| (y * GRID / h).min(GRID - 1) * GRID;
    // Sample i = 21·k is pixel 7·k: column x, row y. The held samples of a and b start at ja, jb.
    let (step_a, step_b) = (a.step(21), b.step(21));
    let (mut ja, mut jb, mut x, mut y) = (0usize, 0usize, 0usize, 0usize);
    let mut row = row_block(0);
    let mut i = 0;
    while i + 2 < n {
        let k = row + column_block[x];
        for c in 0..3 {
            let (va, vb) = (ua(ja + c), ub(jb + c));
            let d = vb - va;
            if d < -0.03 {
                darker += 1;
            } else if d > 0.03 {
                brighter += 1;
            }
            let picture = |v: f32| v > dark.pedestal[c] && v < CLIP_UNIT;
            if picture(va) && picture(vb) {
                sa += f64::from(va);
                sb += f64::from(vb);
                sad += f64::from((va - vb).abs());
                count += 1;
                blocks[k][0][c] += f64::from(va);
                blocks[k][1][c] += f64::from(vb);
                in_block[k][c] += 1;
            }
        }
        i += 21;
        ja += step_a;
        jb += step_b;
        x += 7;
        while x >= w {
            x -= w;
            y += 1;
            row = row_block(y);
        }
    }
    PairSums {
        sa,
        sb,
        sad,
        count,
        darker,
        brighter,
        blocks,
        in_block,
    }
}

/// Compares two frames on the samples of every 7th pixel, in one pass over both.
fn compare_pair(a: &Look<'_>, b: &Look<'_>, dark: &Dark) -> PairCheck {
    let n = a.len.min(b.len);
    let PairSums {
        sa,
        sb,
        sad,
        count,
        darker,
        brighter,
        blocks,
        in_block,
    } = pair_sums(a, b, dark);
    // Too few usable samples (frames almost all black or white): nothing to compare. As few
    // as a frame needs to be kept (0.05 % of the samples): a film scan's short frames show
    // picture only in their windows.
    let identical = count >= n / 21 / 2000 + 10 && {
        let (ma, mb) = (sa / count as f64, sb / count as f64);
        (ma - mb).abs() < 0.02 * ma.max(mb) && sad / (count as f64) < 0.015
    };
    // Every two blocks that differ clearly in both frames: ordered alike, or the other way round.
    let (mut same_order, mut reversed) = (0usize, 0usize);
    // A block's mean in a channel, where at least 4 of its samples are picture in both frames.
    let mean = |k: usize, f: usize, c: usize| {
        (in_block[k][c] >= 4).then(|| blocks[k][f][c] / in_block[k][c] as f64)
    };
    for c in 0..3 {
        let means: Vec<(f64, f64)> = (0..GRID * GRID)
            .filter_map(|k| Some((mean(k, 0, c)?, mean(k, 1, c)?)))
            .collect();
        for (i, p) in means.iter().enumerate() {
            for q in &means[i + 1..] {
                let (da, db) = (q.0 - p.0, q.1 - p.1);
                if da.abs() > 0.02 && db.abs() > 0.02 {
                    match (da > 0.0) == (db > 0.0) {
                        true => same_order += 1,
                        false => reversed += 1,
                    }
                }
            }
        }
    }
    PairCheck {
        identical,
        darker_when_longer: darker >= 100 && darker > brighter,
        other_scene: (same_order + reversed >= 100).then_some(3 * reversed > same_order + reversed),
    }
}

/// How the checks read a frame: its samples `i = 21·k + c` (channel `c` of every 7th pixel),
/// from the whole frame or from its [`thumbnail`], which holds exactly those.
struct Look<'a> {
    pixels: &'a Pixels,
    /// The whole frame's sample count (`3 · width · height`).
    len: usize,
    width: usize,
    height: usize,
    thumb: bool,
}

impl<'a> Look<'a> {
    fn of(f: &'a Frame, thumb: bool) -> Self {
        Look {
            pixels: &f.pixels,
            len: match thumb {
                true => 3 * f.width * f.height,
                false => f.pixels.len(),
            },
            width: f.width,
            height: f.height,
            thumb,
        }
    }

    /// Where the whole frame's sample `i` (channel of every 7th pixel) is held.
    #[inline]
    fn at(&self, i: usize) -> usize {
        match self.thumb {
            true => i / 21 * 3 + i % 21,
            false => i,
        }
    }

    /// The step through the held samples that is `whole` samples of the whole frame.
    fn step(&self, whole: usize) -> usize {
        match self.thumb {
            true => whole / 7,
            false => whole,
        }
    }

    #[inline]
    fn unit(&self, i: usize) -> f32 {
        self.pixels.unit(self.at(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sums as the per-sample formulas give them (the code `pair_sums` replaced).
    fn pair_sums_by_division(a: &Look<'_>, b: &Look<'_>, dark: &Dark) -> PairSums {
        let n = a.len.min(b.len);
        let mut s = PairSums {
            sa: 0.0,
            sb: 0.0,
            sad: 0.0,
            count: 0,
            darker: 0,
            brighter: 0,
            blocks: [[[0f64; 3]; 2]; GRID * GRID],
            in_block: [[0usize; 3]; GRID * GRID],
        };
        let (w, h) = (a.width.max(1), a.height.max(1));
        let mut i = 0;
        while i + 2 < n {
            let (x, y) = ((i / 3) % w, (i / 3) / w);
            let k = (y * GRID / h).min(GRID - 1) * GRID + (x * GRID / w).min(GRID - 1);
            for c in 0..3 {
                let (va, vb) = (a.unit(i + c), b.unit(i + c));
                let d = vb - va;
                if d < -0.03 {
                    s.darker += 1;
                } else if d > 0.03 {
                    s.brighter += 1;
                }
                let picture = |v: f32| v > dark.pedestal[c] && v < CLIP_UNIT;
                if picture(va) && picture(vb) {
                    s.sa += f64::from(va);
                    s.sb += f64::from(vb);
                    s.sad += f64::from((va - vb).abs());
                    s.count += 1;
                    s.blocks[k][0][c] += f64::from(va);
                    s.blocks[k][1][c] += f64::from(vb);
                    s.in_block[k][c] += 1;
                }
            }
            i += 21;
        }
        s
    }

    /// A frame of random codes (xorshift from `seed`), 8- or 16-bit, whole or as its thumbnail.
    fn random_frame(w: usize, h: usize, seed: u64, sixteen: bool, thumb: bool) -> Frame {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let n = 3 * w * h;
        let pixels = match sixteen {
            true => {
                let v: Vec<u16> = (0..n).map(|_| next() as u16).collect();
                Pixels::U16(if thumb { every_7th_pixel(&v) } else { v })
            }
            false => {
                let v: Vec<u8> = (0..n).map(|_| next() as u8).collect();
                Pixels::U8(if thumb { every_7th_pixel(&v) } else { v })
            }
        };
        Frame {
            name: format!("f{seed}"),
            width: w,
            height: h,
            pixels,
            exposure: Exposure {
                time_s: 0.01,
                iso: None,
                f_number: None,
            },
        }
    }

    #[test]
    fn the_pair_sums_histograms_and_informative_counts_are_the_per_sample_formulas() {
        let dark = Dark {
            pedestal: [0.03, 0.1, 0.25],
        };
        let mut cases = 0;
        for (w, h) in [
            (1, 1),
            (2, 3),
            (6, 4),
            (7, 9),
            (13, 11),
            (64, 37),
            (203, 17),
            (401, 9),
        ] {
            for sixteen in [false, true] {
                for thumb in [false, true] {
                    let a = random_frame(w, h, (w * h) as u64, sixteen, thumb);
                    let b = random_frame(w, h, (w * h + 1) as u64, sixteen, thumb);
                    let (la, lb) = (Look::of(&a, thumb), Look::of(&b, thumb));
                    let fast = pair_sums(&la, &lb, &dark);
                    assert_eq!(fast, pair_sums_by_division(&la, &lb, &dark), "{w}×{h}");
                    cases += usize::from(fast.count > 0);
                    for c in 0..3 {
                        let mut by_at = [0usize; 256];
                        let mut i = c;
                        while i < la.len {
                            let code = match la.pixels {
                                Pixels::U8(v) => v[la.at(i)],
                                Pixels::U16(v) => bin16(v[la.at(i)]),
                            };
                            by_at[usize::from(code)] += 1;
                            i += 21;
                        }
                        assert_eq!(channel_histogram(&la, c), by_at, "{w}×{h}");
                    }
                    for floor in [0.0, 0.05, 0.5] {
                        let by_unit = (0..la.len)
                            .step_by(21)
                            .filter(|&i| informative(la.unit(i), floor))
                            .count();
                        assert_eq!(informative_count(&la, floor), by_unit, "{w}×{h}");
                    }
                }
            }
        }
        // Every case but the 1×1 and 2×3 frames (one or a few sampled pixels) had picture.
        assert!(cases >= 24, "{cases}");
    }
}
