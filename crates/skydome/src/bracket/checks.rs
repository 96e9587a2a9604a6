//! The bracket's checks: what [`assemble`] refuses or warns about before anything downstream
//! sees the frames.

#[cfg(feature = "parallel")]
use rayon::prelude::*;

use super::decode::orient;
use super::{
    Bracket, BracketError, CaptureInfo, DecodedFrame, Exposure, Frame, OrientationPolicy, Pixels,
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
    at_least_two(decoded.len())?;
    if let Some(t) = times {
        one_valid_time_per_frame(t, decoded.len())?;
    }
    frames_agree_in_size_depth_and_orientation(&decoded, orientation)?;
    let mut warnings = settings_that_differ(&decoded);
    let (frames, info) = oriented_and_sorted_by_exposure(decoded, times, orientation)?;
    neighbours_at_least_a_sixth_stop_apart(&frames)?;
    let (frames, checks) = frames_that_inform(frames, &mut warnings)?;
    no_identical_neighbours(&frames, &checks)?;
    no_frame_darker_when_exposed_longer(&frames, &checks)?;
    let pixel_orientation = match orientation {
        OrientationPolicy::Apply => 1,
        OrientationPolicy::Ignore => info.orientation,
    };
    Ok(Bracket {
        frames,
        info,
        warnings,
        pixel_orientation,
    })
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
/// EXIF orientation.
fn frames_agree_in_size_depth_and_orientation(
    decoded: &[DecodedFrame],
    orientation: OrientationPolicy,
) -> Result<(), BracketError> {
    let first = &decoded[0];
    for d in &decoded[1..] {
        if (d.width, d.height) != (first.width, first.height) {
            return Err(BracketError::SizeMismatch {
                file: d.name.clone(),
                w: d.width,
                h: d.height,
                first: first.name.clone(),
                w0: first.width,
                h0: first.height,
            });
        }
        if d.pixels.bit_depth() != first.pixels.bit_depth() {
            return Err(BracketError::DepthMismatch {
                file: d.name.clone(),
                bits: d.pixels.bit_depth(),
                first: first.name.clone(),
                bits0: first.pixels.bit_depth(),
            });
        }
        if orientation == OrientationPolicy::Apply && d.info.orientation != first.info.orientation {
            return Err(BracketError::OrientationMismatch {
                file: d.name.clone(),
                o: d.info.orientation,
                first: first.name.clone(),
                o0: first.info.orientation,
            });
        }
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
) -> Result<(Vec<Frame>, CaptureInfo), BracketError> {
    let mut frames = Vec::with_capacity(decoded.len());
    let mut infos = Vec::with_capacity(decoded.len());
    for (i, d) in decoded.into_iter().enumerate() {
        let time_s = match times {
            Some(t) => t[i],
            None => d.exif_time_s.ok_or_else(|| BracketError::MissingExposure {
                file: d.name.clone(),
            })?,
        };
        let exposure = Exposure {
            time_s,
            iso: d.iso,
            f_number: d.f_number,
        };
        let (width, height, pixels) = match orientation {
            OrientationPolicy::Apply if d.info.orientation != 1 => {
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

/// No two neighbouring frames (sorted) closer than 1/6 stop in relative exposure.
fn neighbours_at_least_a_sixth_stop_apart(frames: &[Frame]) -> Result<(), BracketError> {
    for pair in frames.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let stops = (b.exposure.relative() / a.exposure.relative()).log2();
        if stops < 1.0 / 6.0 {
            return Err(BracketError::DuplicateExposure {
                file: b.name.clone(),
                e1: describe(&b.exposure),
                other: a.name.clone(),
                e2: describe(&a.exposure),
            });
        }
    }
    Ok(())
}

/// The frames that inform, with the comparison of each neighbouring pair among them.
///
/// Only informative values judge the frames: neither at the bracket's black level nor clipped.
/// A frame with (almost) none — all black level or all white — adds nothing and is left out
/// with a warning, as long as two frames remain.
fn frames_that_inform(
    frames: Vec<Frame>,
    warnings: &mut Vec<String>,
) -> Result<(Vec<Frame>, Vec<PairCheck>), BracketError> {
    let floor = black_floor(&frames);
    let total = frames.len();
    // Every frame's informative samples and every neighbouring pair's comparison in one go (in
    // parallel with the `parallel` feature): each is a pass over frames too big for the cache,
    // so they are run side by side rather than one after another. The pairs are compared again
    // only when a frame is left out (rare), which makes new neighbours.
    #[cfg(feature = "parallel")]
    let (counts, checks) = rayon::join(
        || informative_counts(&frames, floor),
        || compare_neighbours(&frames, floor),
    );
    #[cfg(not(feature = "parallel"))]
    let (counts, checks) = (
        informative_counts(&frames, floor),
        compare_neighbours(&frames, floor),
    );
    let mut kept = Vec::with_capacity(total);
    for (f, count) in frames.into_iter().zip(counts) {
        if count < informative_needed(&f) {
            warnings.push(format!(
                "{}: almost every pixel is at the black level or clipped, so the frame adds nothing to the bracket; it was left out",
                f.name
            ));
        } else {
            kept.push(f);
        }
    }
    at_least_two(kept.len())?;
    let checks = match kept.len() == total {
        true => checks,
        false => compare_neighbours(&kept, floor),
    };
    Ok((kept, checks))
}

/// No two neighbours carry (nearly) the same picture although their exposures differ.
fn no_identical_neighbours(frames: &[Frame], checks: &[PairCheck]) -> Result<(), BracketError> {
    for (pair, check) in frames.windows(2).zip(checks) {
        let (a, b) = (&pair[0], &pair[1]);
        if check.identical {
            return Err(BracketError::IdenticalPixels {
                file: b.name.clone(),
                other: a.name.clone(),
                stops: (b.exposure.relative() / a.exposure.relative()).log2(),
            });
        }
    }
    Ok(())
}

/// No frame is darker than its neighbour exposed shorter (the times belong to other photos).
fn no_frame_darker_when_exposed_longer(
    frames: &[Frame],
    checks: &[PairCheck],
) -> Result<(), BracketError> {
    for (pair, check) in frames.windows(2).zip(checks) {
        let (a, b) = (&pair[0], &pair[1]);
        if check.darker_when_longer {
            return Err(BracketError::DarkerWhenLonger {
                file: b.name.clone(),
                e1: describe(&b.exposure),
                other: a.name.clone(),
                e2: describe(&a.exposure),
            });
        }
    }
    Ok(())
}

/// [`compare_pair`] on every neighbouring pair (in parallel with the `parallel` feature).
fn compare_neighbours(frames: &[Frame], floor: f32) -> Vec<PairCheck> {
    let pairs: Vec<(&Frame, &Frame)> = frames.windows(2).map(|p| (&p[0], &p[1])).collect();
    #[cfg(feature = "parallel")]
    let checks = pairs
        .par_iter()
        .map(|&(a, b)| compare_pair(a, b, floor))
        .collect();
    #[cfg(not(feature = "parallel"))]
    let checks = pairs
        .iter()
        .map(|&(a, b)| compare_pair(a, b, floor))
        .collect();
    checks
}

/// [`informative_count`] of every frame (in parallel with the `parallel` feature).
fn informative_counts(frames: &[Frame], floor: f32) -> Vec<usize> {
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
fn black_floor(frames: &[Frame]) -> f32 {
    // The same percentile from a histogram of the codes (one pass, no copy or selection of
    // millions of samples): frames of one bit depth, as a bracket's are.
    fn by_histogram<T: Copy + Into<usize>>(
        frames: &[Frame],
        codes: impl Fn(&Pixels) -> Option<&[T]>,
        bins: usize,
        full: f32,
    ) -> Option<f32> {
        let mut hist = vec![0usize; bins];
        let mut len = 0usize;
        for f in frames {
            for &c in codes(&f.pixels)?.iter().step_by(21) {
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
        .flat_map(|f| (0..f.pixels.len()).step_by(21).map(|i| f.pixels.unit(i)))
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
fn informative_count(f: &Frame, floor: f32) -> usize {
    (0..f.pixels.len())
        .step_by(21)
        .filter(|&i| informative(f.pixels.unit(i), floor))
        .count()
}

/// A frame with fewer informative samples (of every 21st) than this adds nothing: 0.05 % of
/// them, and at least 10; a frame too small to judge (under 100 such samples) needs none.
fn informative_needed(f: &Frame) -> usize {
    let sampled = f.pixels.len().div_ceil(21);
    if sampled < 100 {
        0
    } else {
        sampled / 2000 + 10
    }
}

/// What comparing two neighbouring frames of a bracket (`a` exposed shorter than `b`) found.
struct PairCheck {
    /// The two frames carry (nearly) the same picture: over the values informative in both
    /// (neither at the black level nor clipped), the mean brightness differs by less than 2 %
    /// and the mean absolute difference is below 1.5 % of full scale. Frames that genuinely
    /// differ by ≥ 1/6 stop differ by ≥ 12 % in linear terms, which even a strong tone curve
    /// does not squeeze below 2 %. Judging only informative values matters: a mostly black frame
    /// (a film scan's black level, a short exposure at night) is identical to its neighbour
    /// *where both are black*, which says nothing about the exposure.
    identical: bool,
    /// `b`, exposed longer, is clearly darker at most samples where the two differ clearly (by
    /// more than 3 % of the code range): a code never falls as exposure grows, so the times
    /// must belong to other photos. Noise, JPEG and a little motion make a few samples darker
    /// in any real bracket; a majority needs swapped times.
    darker_when_longer: bool,
}

/// Compares two frames on the samples of every 7th pixel, in one pass over both.
fn compare_pair(a: &Frame, b: &Frame, floor: f32) -> PairCheck {
    let n = a.pixels.len().min(b.pixels.len());
    let (mut sa, mut sb, mut sad, mut count) = (0f64, 0f64, 0f64, 0usize);
    let (mut darker, mut brighter) = (0usize, 0usize);
    let mut i = 0;
    while i + 2 < n {
        for c in 0..3 {
            let (va, vb) = (a.pixels.unit(i + c), b.pixels.unit(i + c));
            let d = vb - va;
            if d < -0.03 {
                darker += 1;
            } else if d > 0.03 {
                brighter += 1;
            }
            if informative(va, floor) && informative(vb, floor) {
                sa += f64::from(va);
                sb += f64::from(vb);
                sad += f64::from((va - vb).abs());
                count += 1;
            }
        }
        i += 21;
    }
    // Too few usable samples (frames almost all black or white): nothing to compare.
    let identical = count >= n / 21 / 100 + 10 && {
        let (ma, mb) = (sa / count as f64, sb / count as f64);
        (ma - mb).abs() < 0.02 * ma.max(mb) && sad / (count as f64) < 0.015
    };
    PairCheck {
        identical,
        darker_when_longer: darker >= 100 && darker > brighter,
    }
}
