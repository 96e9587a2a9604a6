//! The streamed intake: a bracket of encoded photos whose dome is a plain crop (the case of
//! [`super::merge_window`]) is read one frame at a time (a few at once with the `parallel`
//! feature, as many as the memory budget holds beside the best-exposed frame), never all of it
//! decoded at once: a phone's nine 12 MP frames are 330 MB decoded,
//! which a phone's browser tab cannot hold beside everything else.
//!
//! Two passes over the encoded bytes (a JPEG is a tenth of its decoded size):
//!
//! 1. **scan**: each frame is decoded and oriented, and kept only as every 7th pixel (all that
//!    the bracket's checks read), and the frame the lens circle is
//!    detected on (the best exposed, [`bracket::best_exposed`]) whole. The checks then run on
//!    the thumbnails and give the bracket, the circle is detected and the window to merge is
//!    known.
//! 2. **gather**: each frame is decoded again (the best-exposed frame is still at hand) and
//!    gives what the rest of the run reads of it: its part inside the window, its share of the
//!    clipped-pixel flags of the whole photo, the shortest frame's pixels at its ceiling, and
//!    the calibration sampler's values at every position it can reach ([`sampling::plan`]).
//!    When sampling needs positions the plan could not know (the top-up after the grid's
//!    quotas, which depends on what was accepted), the frames are read once more for them.
//!
//! Every value is computed by the same code from the same pixels as on the whole frames, so
//! the output is the same bytes. A photo that does not decode ends the run with the error the
//! whole frames' reading gives (the first such photo in the order given, by the same decoder),
//! without decoding the rest. Anything else unusual — a RAW or 16-bit frame, frames that
//! disagree in orientation, a frame left out of the bracket, a refusal, the circle not found —
//! makes [`intake`] return `None`, and [`super::run`] reads the whole frames as before (whose
//! errors are then the ones the user sees).
//!
//! Reading the photos twice costs time (about 1.6× the CPU on a 9 × 12 MP bracket), so it is
//! done only when memory needs it: when [`Options::frame_memory_budget`] is set and the photos
//! decoded at once would exceed it ([`streams_input`]).

use crate::bracket::{self, Bracket, DecodedFrame, Exposure, OrientationPolicy, Pixels};
use crate::exposures::ExposureSource;
use crate::fisheye::{self, CircleFit, LensProfile};
use crate::merge::{ClippedFlags, Weighting, BLACK, CLIPPED_HIGH, CLIPPED_LOW};
use crate::noise;
use crate::pipeline::options::{AbsoluteMode, EncodedFrame, Frames, Input, LensSource};
use crate::pipeline::options::{Options, ResponseSource};
use crate::pipeline::progress::{Reporter, Stage};
use crate::pipeline::{
    at_ceiling, calibrated_on, lens_of, merge_window, plain_crop, window_pixels, Calibrated,
    PipelineError, Window,
};
use crate::response;
use crate::sampling::{self, Gathered, Missing, SampleOptions, Samples};

/// Rounds of reading the frames again for positions sampling asked for, before the run gives
/// up streaming (and reads the whole frames).
const MAX_GATHER_ROUNDS: usize = 4;

/// What the streamed intake hands the run.
pub(super) struct Intake {
    /// The bracket; its frames carry no pixels (their size, name and exposure are kept).
    pub br: Bracket,
    pub lens: Option<(LensProfile, Option<CircleFit>)>,
    pub calibrated: Calibrated,
    pub prepared: Prepared,
}

/// What the merge reads: the frames' parts inside the window, and the whole photo's flags and
/// ceiling pixels.
pub(super) struct Prepared {
    /// The frames' parts inside the window, in the bracket's order.
    pub parts: Vec<bracket::Frame>,
    pub flags: ClippedFlags,
    /// [`super::shortest_at_ceiling`] of the whole frames.
    pub at_ceiling: Vec<u32>,
    /// For the noise-aware merge: the pixels of each frame that the noise fit reads
    /// ([`noise::sampled_pixels`]; `width` their count, `height` 1), in the bracket's order, so
    /// that the fit gives the whole frames' model. Empty for other weightings.
    pub noise_samples: Vec<bracket::Frame>,
}

/// Whether `options` let a run read the frames one at a time: a plain crop to the dome (see
/// [`super::merge_window`]) with a lens, no alignment and no absolute scale without a reading.
pub fn streams(options: &Options) -> bool {
    // No absolute scale without a reading (which merges the whole photo): none asked for, or
    // the profile's constant, when there is none.
    let relative = match options.absolute {
        AbsoluteMode::None => true,
        AbsoluteMode::Profile => !matches!(
            &options.response,
            ResponseSource::Profile(p) if p.absolute.is_some()
        ),
        AbsoluteMode::Exif => false,
    };
    // Histogram samples (`SampleOptions::histogram`) need every pixel of every frame.
    let histogram =
        matches!(&options.response, ResponseSource::Calibrate(c) if c.sampling.histogram);
    plain_crop(options)
        && !options.align
        // Measuring exposures reads every frame's pixels against the others'.
        && options.exposures == ExposureSource::Listed
        && relative
        && !histogram
        && options.lens != LensSource::None
}

/// Whether [`super::run`] reads `input` one photo at a time: its photos are encoded (JPEG, PNG
/// or TIFF), the options allow it ([`streams`]) and set a budget
/// ([`Options::frame_memory_budget`]) that the photos decoded at once ([`decoded_size`])
/// would exceed. Anything unusual found on the way (a RAW or 16-bit photo, see the module
/// docs) still makes the run read the whole photos.
pub fn streams_input(input: &Input, options: &Options) -> bool {
    match (&input.frames, options.frame_memory_budget) {
        (Frames::Encoded(frames), Some(budget)) => {
            frames.len() >= 2 && streams(options) && decoded_size(frames) > budget
        }
        _ => false,
    }
}

/// The bytes `frames` take decoded at once as 8-bit RGB (3 bytes a pixel; 6 for a 16-bit
/// photo), from each file's header (dimensions only, nothing decoded). A photo whose header
/// does not read counts for nothing (decoding it will report the error).
pub fn decoded_size(frames: &[EncodedFrame]) -> u64 {
    frames
        .iter()
        .map(|f| header_size(&f.bytes).unwrap_or(0))
        .sum()
}

/// How many photos the streamed intake decodes at once (one per thread of the pool with the
/// `parallel` feature) so that they and the best-exposed photo it keeps stay within `budget`
/// bytes, photos of at most `frame_bytes` decoded: at least one.
fn group_size(budget: u64, frame_bytes: u64) -> usize {
    let fit = (budget / frame_bytes.max(1)).saturating_sub(1);
    usize::try_from(fit)
        .unwrap_or(usize::MAX)
        .clamp(1, threads())
}

/// The decoded size of one encoded photo from its header, `None` when it does not read.
fn header_size(bytes: &[u8]) -> Option<u64> {
    use image::ImageDecoder;
    let decoder = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .ok()?
        .into_decoder()
        .ok()?;
    let (w, h) = decoder.dimensions();
    let sample = match decoder.color_type().bytes_per_pixel() / decoder.color_type().channel_count()
    {
        1 => 1,
        _ => 2,
    };
    Some(u64::from(w) * u64::from(h) * 3 * sample)
}

/// One frame decoded and oriented, with its exposure and where it came in the input.
struct Decoded {
    frame: DecodedFrame,
    /// The oriented size.
    size: (usize, usize),
}

/// Reads `input` one frame at a time when it and `options` allow (see the module docs);
/// `None` when the run should read the whole frames.
pub(super) fn intake(
    input: &Input,
    options: &Options,
    progress: &mut Reporter<'_>,
) -> Result<Option<Intake>, PipelineError> {
    let Frames::Encoded(frames) = &input.frames else {
        return Ok(None);
    };
    if !streams_input(input, options) {
        return Ok(None);
    }
    let times = input.times.as_deref();
    if times.is_some_and(|t| t.len() != frames.len()) {
        return Ok(None);
    }
    progress.at(Stage::Decoding, 0.0)?;
    let largest = frames
        .iter()
        .filter_map(|f| header_size(&f.bytes))
        .max()
        .unwrap_or(0);
    let at_once = group_size(options.frame_memory_budget.unwrap_or(u64::MAX), largest);
    let Some(scan) = scan(frames, input, at_once, progress)? else {
        return Ok(None);
    };
    let Scan {
        thumbs,
        exposures,
        best,
    } = scan;
    let Ok(mut br) =
        bracket::assemble_thumbnails(thumbs, times, input.orientation, options.black_level)
    else {
        return Ok(None);
    };
    if br.frames.len() != frames.len() {
        return Ok(None);
    }
    progress.at(Stage::Decoding, 1.0)?;
    // The input index of each frame of the bracket (exposures differ by 1/6 stop at least).
    let mut order = Vec::with_capacity(br.frames.len());
    for f in &mut br.frames {
        let Some(i) = exposures.iter().position(|e| *e == f.exposure) else {
            return Ok(None);
        };
        order.push(i);
        f.pixels = Pixels::U8(Vec::new());
    }
    let (w, h) = (br.width(), br.height());
    let Some((best_index, best_pixels)) = best else {
        return Ok(None);
    };

    progress.at(Stage::Lens, 0.0)?;
    let detect = || {
        fisheye::detect_circle_rgb8(&best_pixels, w, h).map_err(|e| PipelineError::CircleNotFound {
            frame: String::new(),
            reason: e.to_string(),
        })
    };
    let Ok(lens) = lens_of(&options.lens, detect) else {
        return Ok(None);
    };
    let Some((profile, _)) = lens.as_ref() else {
        return Ok(None);
    };
    let Some(window) = merge_window(options, profile, (w, h), true, false) else {
        return Ok(None);
    };
    progress.at(Stage::Lens, 1.0)?;

    progress.at(Stage::Calibrating, 0.0)?;
    let circle = options.calibration_circle.or(Some(profile.circle));
    let plan = match &options.response {
        ResponseSource::Calibrate(o) => {
            // The calibration this bracket's frame count asks for (the default's covering
            // one from five frames, the joined one below): its draws decide what is gathered
            // (a joined calibration's own and its grid toe's).
            let o = o.for_frames(br.frames.len());
            let draws: Vec<SampleOptions> = std::iter::once(o.sampling.clone())
                .chain(response::toe_sampling(&o))
                .collect();
            let mut positions = Vec::new();
            for d in &draws {
                match sampling::plan((w, h), br.frames.len(), circle, d) {
                    Ok(p) => positions.push((p, d.patch)),
                    Err(_) => return Ok(None),
                }
            }
            Some((positions, o))
        }
        ResponseSource::Profile(_) => None,
    };
    let mut gathered = Vec::new();
    if let Some((positions, _)) = &plan {
        for (p, patch) in positions {
            gathered.push(Gathered::new(p, br.frames.len(), *patch, (w, h)));
        }
    }
    // The merge fits the noise model unless a profile's stands in for the fit.
    let profile_noise = match &options.response {
        ResponseSource::Profile(p) => p.noise_estimate().is_some(),
        ResponseSource::Calibrate(_) => false,
    };
    let fits_noise = options.weighting == Weighting::Noise && !profile_noise;
    let mut gather = Gather {
        window,
        black_level: options.black_level,
        acc: vec![0u8; w * h],
        parts: Vec::with_capacity(br.frames.len()),
        at_ceiling: Vec::new(),
        size: (w, h),
        noise_samples: fits_noise.then(Vec::new),
    };
    let mut best = Some(best_pixels);
    let read = |i: usize| -> Option<Vec<u8>> {
        let d = decode_oriented(&frames[i], input).ok()??;
        match d.frame.pixels {
            Pixels::U8(v) if d.size == (w, h) => Some(v),
            _ => None,
        }
    };
    let all: Vec<usize> = (0..order.len()).collect();
    for group in all.chunks(at_once) {
        // The best-exposed frame is at hand already: it is taken rather than decoded.
        let done = in_parallel(group, |&j| (order[j] != best_index).then(|| read(order[j])));
        for (d, &j) in done.into_iter().zip(group) {
            let Some(px) = d.unwrap_or_else(|| best.take()) else {
                return Ok(None);
            };
            let px = Pixels::U8(px);
            for g in gathered.iter_mut() {
                g.add_frame(j, &px);
            }
            gather.add(j, &br.frames[j].name, br.frames[j].exposure, &px);
        }
        progress.at(
            Stage::Calibrating,
            0.9 * gather.parts.len() as f64 / order.len() as f64,
        )?;
    }
    drop(best);

    let calibrated = match plan {
        None => match &options.response {
            ResponseSource::Profile(prof) => match prof.response() {
                Ok(r) => Calibrated {
                    response: r,
                    profile: None,
                    sampling: None,
                    method: None,
                    from: "profile",
                    warnings: Vec::new(),
                    exposures: None,
                    wide_step: false,
                },
                Err(_) => return Ok(None),
            },
            ResponseSource::Calibrate(_) => return Ok(None),
        },
        Some((_, o)) => {
            // One draw from what was gathered, reading the frames again for the positions
            // it finds missing (`None`: the draw fails; the outer `None`: a frame did not
            // decode again, or too many rounds).
            let mut draw = |opts: &SampleOptions| -> Option<Option<Samples>> {
                let mut rounds = 0;
                loop {
                    match sampling::sample_from(&gathered, (w, h), circle, opts) {
                        Err(_) => return Some(None),
                        Ok(Ok(s)) => return Some(Some(s)),
                        Ok(Err(Missing(more))) => {
                            rounds += 1;
                            if rounds > MAX_GATHER_ROUNDS {
                                return None;
                            }
                            let mut g = Gathered::new(&more, order.len(), opts.patch, (w, h));
                            for group in all.chunks(at_once) {
                                let done = in_parallel(group, |&j| read(order[j]));
                                for (d, &j) in done.into_iter().zip(group) {
                                    g.add_frame(j, &Pixels::U8(d?));
                                }
                            }
                            gathered.push(g);
                        }
                    }
                }
            };
            let cal = match response::toe_sampling(&o) {
                None => match draw(&o.sampling) {
                    Some(Some(samples)) => {
                        response::calibrate_with_samples(&br.frames, samples, &o)
                    }
                    _ => return Ok(None),
                },
                Some(toe) => {
                    let Some(Some(grid)) = draw(&toe) else {
                        return Ok(None);
                    };
                    let Some(own) = draw(&o.sampling) else {
                        return Ok(None);
                    };
                    // The own draw failing is not the run's error: the grid curve stands in.
                    let own = own.ok_or(response::ResponseError::NoSamples {
                        clipped: 0,
                        edge: 0,
                        non_monotonic: 0,
                    });
                    response::calibrate_joined_with_samples(&br.frames, own, grid, &o)
                }
            };
            drop(gathered);
            match cal {
                Ok(cal) => calibrated_on(cal, &br, o.method_name()),
                Err(_) => return Ok(None),
            }
        }
    };
    progress.at(Stage::Calibrating, 1.0)?;
    let prepared = gather.finish();
    Ok(Some(Intake {
        br,
        lens,
        calibrated,
        prepared,
    }))
}

/// What the scan keeps.
struct Scan {
    /// The frames as decoded, their pixels the oriented frames' thumbnails.
    thumbs: Vec<DecodedFrame>,
    /// Each frame's exposure, in input order.
    exposures: Vec<Exposure>,
    /// The best-exposed frame (input index, oriented 8-bit pixels).
    best: Option<(usize, Vec<u8>)>,
}

/// The first pass (see the module docs); `None` when the run should read the whole frames.
fn scan(
    frames: &[EncodedFrame],
    input: &Input,
    at_once: usize,
    progress: &mut Reporter<'_>,
) -> Result<Option<Scan>, PipelineError> {
    let mut thumbs = Vec::with_capacity(frames.len());
    let mut exposures = Vec::with_capacity(frames.len());
    // (well-exposed count, relative exposure, input index, pixels)
    let mut best: Option<(usize, f64, usize, Vec<u8>)> = None;
    let indices: Vec<usize> = (0..frames.len()).collect();
    for group in indices.chunks(at_once) {
        let done = in_parallel(group, |&i| decode_oriented(&frames[i], input));
        for (d, &i) in done.into_iter().zip(group) {
            let Some(Decoded { mut frame, .. }) = d? else {
                return Ok(None);
            };
            let time_s = match (input.times.as_deref(), frame.exif_time_s) {
                (Some(t), _) => t[i],
                (None, Some(t)) => t,
                (None, None) => return Ok(None),
            };
            let exposure = Exposure {
                time_s,
                iso: frame.iso,
                f_number: frame.f_number,
            };
            let Pixels::U8(px) = std::mem::replace(&mut frame.pixels, Pixels::U8(Vec::new()))
            else {
                return Ok(None);
            };
            // `bracket::best_exposed`'s count and its choice: the most, and of equals the
            // last in exposure order.
            let well = px
                .iter()
                .step_by(7)
                .filter(|&&z| (20..=235).contains(&z))
                .count();
            let rel = exposure.relative();
            frame.pixels = Pixels::U8(bracket::every_7th_pixel(&px));
            let better = best
                .as_ref()
                .is_none_or(|b| well > b.0 || (well == b.0 && rel > b.1));
            if better {
                best = Some((well, rel, i, px));
            }
            thumbs.push(frame);
            exposures.push(exposure);
        }
        progress.at(
            Stage::Decoding,
            0.9 * thumbs.len() as f64 / frames.len() as f64,
        )?;
    }
    Ok(Some(Scan {
        thumbs,
        exposures,
        best: best.map(|(_, _, i, px)| (i, px)),
    }))
}

/// `f` decoded (8 or 16 bits) and oriented as the bracket will be (its EXIF orientation
/// applied unless the input ignores it); `None` for a RAW photo (read whole), the decoder's
/// error when it does not decode.
fn decode_oriented(
    f: &EncodedFrame,
    input: &Input,
) -> Result<Option<Decoded>, bracket::BracketError> {
    let (mut frame, colour) = bracket::decode_raw(&f.name, &f.bytes, &input.decode)?;
    if colour.is_some() {
        return Ok(None);
    }
    let o = frame.info.orientation;
    let size = match input.orientation {
        OrientationPolicy::Apply if o != 1 => {
            let px = std::mem::replace(&mut frame.pixels, Pixels::U8(Vec::new()));
            let (ow, oh, px) = bracket::orient(frame.width, frame.height, px, o);
            frame.pixels = px;
            (ow, oh)
        }
        _ => (frame.width, frame.height),
    };
    Ok(Some(Decoded { frame, size }))
}

/// The threads of the pool.
#[cfg(feature = "parallel")]
fn threads() -> usize {
    rayon::current_num_threads().max(1)
}

/// One thread without the `parallel` feature.
#[cfg(not(feature = "parallel"))]
fn threads() -> usize {
    1
}

/// `f` on every item, in parallel with the `parallel` feature, results in order.
fn in_parallel<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync + Send) -> Vec<R> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        items.iter().map(f).collect()
    }
}

/// The second pass's products, frame by frame.
struct Gather {
    window: Window,
    black_level: u8,
    /// Per pixel: bits 0–2, the channel is at or below the black level or at full scale in
    /// every frame so far; bits 3–5, the channel is at full scale in the shortest frame.
    acc: Vec<u8>,
    parts: Vec<bracket::Frame>,
    at_ceiling: Vec<u32>,
    size: (usize, usize),
    /// [`Prepared::noise_samples`], when the merge is noise-aware.
    noise_samples: Option<Vec<bracket::Frame>>,
}

impl Gather {
    /// Takes frame `j` of the bracket (`0` the shortest; frames come in order).
    fn add(&mut self, j: usize, name: &str, exposure: Exposure, px: &Pixels) {
        let Pixels::U8(v) = px else {
            return;
        };
        let black = self.black_level;
        let extreme = |z: u8| (z <= black || z == u8::MAX) as u8;
        if j == 0 {
            self.at_ceiling = at_ceiling(px);
            for (a, p) in self.acc.iter_mut().zip(v.chunks_exact(3)) {
                let ext = extreme(p[0]) | extreme(p[1]) << 1 | extreme(p[2]) << 2;
                let max = (p[0] == u8::MAX) as u8
                    | ((p[1] == u8::MAX) as u8) << 1
                    | ((p[2] == u8::MAX) as u8) << 2;
                *a = ext | max << 3;
            }
        } else {
            for (a, p) in self.acc.iter_mut().zip(v.chunks_exact(3)) {
                let ext = extreme(p[0]) | extreme(p[1]) << 1 | extreme(p[2]) << 2;
                *a &= ext | 0b11_1000;
            }
        }
        if let Some(samples) = self.noise_samples.as_mut() {
            let kept = noise::sampled_pixels(v);
            samples.push(bracket::Frame {
                name: name.to_string(),
                width: kept.len() / 3,
                height: 1,
                pixels: Pixels::U8(kept),
                exposure,
            });
        }
        let w = self.window;
        self.parts.push(bracket::Frame {
            name: name.to_string(),
            width: w.width,
            height: w.height,
            pixels: window_pixels(px, self.size.0, w),
            exposure,
        });
    }

    /// The merge's inputs; the flags as [`crate::merge::clipped_flags`] gives them on the whole
    /// frames.
    fn finish(self) -> Prepared {
        let mut acc = self.acc;
        let (mut high, mut low, mut black) = (0usize, 0usize, 0usize);
        for a in acc.iter_mut() {
            // Per channel the merge's flag: CLIPPED_HIGH where the shortest frame is at full
            // scale, else CLIPPED_LOW, where the channel is extreme in every frame.
            let e = |c: u8| -> u8 {
                let ext = (*a >> c) & 1;
                let max = (*a >> (3 + c)) & 1;
                ext * (CLIPPED_LOW - max)
            };
            let (e0, e1, e2) = (e(0), e(1), e(2));
            let mut flag = e0 | e1 | e2;
            high += (flag & CLIPPED_HIGH) as usize;
            low += (flag >> 1) as usize;
            if e0 & e1 & e2 & CLIPPED_LOW != 0 {
                flag |= BLACK;
                black += 1;
            }
            *a = flag;
        }
        Prepared {
            parts: self.parts,
            flags: ClippedFlags {
                mask: acc,
                high,
                low,
                black,
            },
            at_ceiling: self.at_ceiling,
            noise_samples: self.noise_samples.unwrap_or_default(),
        }
    }
}
