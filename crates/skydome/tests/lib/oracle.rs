//! The oracle: how well a bracket can be merged at all, and skydome's noise-model merge (and the
//! default hat) as a ratio to it.
//!
//! Each case is a synthetic bracket ([`skydome::synth`]) drawn from a seed: scene (clouds), sun
//! position, exposure level, sensor noise (full well 2 000–60 000 e⁻, read noise 1–6 e⁻), frame
//! count 2–9, EV spacing 1–3, JPEG quality 85–98 or none, 8- or 16-bit, fish-eye or rectangular,
//! responses with per-channel gamma 1.8–2.6 and shoulder 0.4–1.5.
//!
//! The **oracle** merges the same frames knowing everything skydome has to estimate: the true
//! response (each frame votes `g_true(Z) − ln Δt`) and inverse-variance weights from the true
//! noise at the code each frame is *expected* to read for the true radiance (shot and read
//! noise in electrons, quantisation and the JPEG noise measured against the same frames before
//! compression, carried through the true slope of `g`), no weight for a clipped or black code
//! or an expected code above 250. **skydome** calibrates its curve from the frames — nothing
//! known — with the default calibration (`response::calibrate`, 100 grid samples, hat fit) and,
//! separately, with the opt-in [`CalibrateOptions::noise_fit`] (`--method noise`: 2000
//! stratified samples, the noise-weighted fit), and merges with [`Weighting::Noise`] and the hat.
//!
//! Error: per channel, the log2 RMSE (stops) against the true radiance after one scale per
//! channel (the gauge), over the *sky*: pixels some frame reads in 10..=245 in every channel,
//! neither dim ground (truth < 0.1) nor sun (truth ≥ 50). A bracket's ratio is skydome's RMS
//! over the three channels divided by the oracle's.
//!
//! Seeds: [`TUNING_SEEDS`] were used while choosing the merge's defaults; [`HELD_OUT_SEEDS`] were
//! not looked at until the defaults were fixed, and the targets are asserted on them.

use skydome::bracket::{Frame, Pixels};
use skydome::compare::well_exposed_mask;
use skydome::image::Circle;
use skydome::merge::{merge, MergeOptions, Weighting};
use skydome::response::{calibrate, CalibrateOptions, COVERING_FROM_FRAMES};
use skydome::sampling::SplitMix64;
use skydome::synth::{photograph, photograph_16bit, scene_with_sun, Crf, SynthOptions};
use skydome::HdrImage;

/// Seeds the merge's defaults were tuned on (three brackets per frame count).
pub const TUNING_SEEDS: [u64; 3] = [1, 2, 3];
/// Seeds the targets are asserted on (never used for tuning).
pub const HELD_OUT_SEEDS: [u64; 3] = [7001, 7002, 7003];
/// More tuning seeds, drawn with the sun's zenith angle 0–87° ([`case_with_sun`]): the covering
/// calibration's λ and draw were chosen on these and [`TUNING_SEEDS`]
/// ([`calibration_candidates`]).
pub const MORE_TUNING_SEEDS: [u64; 12] = [11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22];
/// A fresh held-out set (sun zenith 0–87°, i.e. a sun 3–90° high), not looked at until the
/// covering calibration was fixed.
pub const FRESH_SEEDS: [u64; 12] = [
    9101, 9102, 9103, 9104, 9105, 9106, 9107, 9108, 9109, 9110, 9111, 9112,
];

/// Side of the synthetic frames, pixels.
const SIZE: usize = 160;

/// One synthetic bracket and everything the oracle knows about it.
pub struct Case {
    /// What was drawn, for messages.
    pub label: String,
    /// The camera.
    pub opts: SynthOptions,
    /// 16-bit frames.
    pub sixteen: bool,
    /// True radiance.
    pub truth: HdrImage,
    /// The frames, shortest first.
    pub frames: Vec<Frame>,
    /// The image circle, when fish-eye.
    pub circle: Option<Circle>,
    /// JPEG noise per channel, 8-bit codes r.m.s. (0 without JPEG), measured against the frames
    /// before compression.
    pub jpeg_noise: [f64; 3],
}

/// Draws the case of `seed` with `n` frames.
pub fn case(seed: u64, n: usize) -> Case {
    case_with_sun(seed, n, (10.0, 80.0))
}

/// [`case`] with the sun's zenith angle drawn from `zenith` (degrees; `(0, 87)` is a sun
/// height of 3–90°).
pub fn case_with_sun(seed: u64, n: usize, zenith: (f64, f64)) -> Case {
    let mut rng = SplitMix64::new(seed.wrapping_mul(0x9E37_79B9) ^ n as u64);
    let mut uni = |a: f64, b: f64| a + (b - a) * rng.next_f64();
    let spacing = [1.0, 1.5, 2.0, 3.0][(uni(0.0, 4.0) as usize).min(3)];
    let sixteen = uni(0.0, 1.0) < 0.2;
    let jpeg = (!sixteen && uni(0.0, 1.0) < 0.8).then(|| uni(85.0, 98.99) as u8);
    let fisheye = uni(0.0, 1.0) < 0.6;
    let full_well = uni(2000f64.ln(), 60000f64.ln()).exp();
    let read_noise = uni(1.0, 6.0);
    let brightness = uni(-1.0, 1.0);
    let sun = (uni(zenith.0, zenith.1), uni(0.0, std::f64::consts::TAU));
    let crf = [0, 1, 2].map(|_| Crf {
        gamma: uni(1.8, 2.6),
        shoulder: uni(0.4, 1.5),
    });
    let evs: Vec<f64> = (0..n)
        .map(|j| (j as f64 - (n - 1) as f64 / 2.0) * spacing)
        .collect();
    let opts = SynthOptions {
        width: SIZE,
        height: SIZE,
        evs,
        base_time_s: brightness.exp2() / 250.0,
        seed,
        fisheye,
        jpeg_quality: jpeg,
        full_well,
        read_noise,
        crf,
        ..SynthOptions::default()
    };
    let circle = fisheye.then(|| Circle {
        cx: SIZE as f64 / 2.0,
        cy: SIZE as f64 / 2.0,
        r: 0.48 * SIZE as f64,
    });
    let truth = scene_with_sun(SIZE, SIZE, seed, circle, sun.0, sun.1);
    let frames = if sixteen {
        photograph_16bit(&truth, &opts).unwrap()
    } else {
        photograph(&truth, &opts).unwrap()
    };
    let mut jpeg_noise = [0.0; 3];
    if jpeg.is_some() {
        // The same noise draws without the JPEG round trip.
        let plain = photograph(
            &truth,
            &SynthOptions {
                jpeg_quality: None,
                ..opts.clone()
            },
        )
        .unwrap();
        for (c, jn) in jpeg_noise.iter_mut().enumerate() {
            let (mut s, mut k) = (0f64, 0usize);
            for (f, p) in frames.iter().zip(&plain) {
                let (Pixels::U8(a), Pixels::U8(b)) = (&f.pixels, &p.pixels) else {
                    unreachable!()
                };
                for i in (c..a.len()).step_by(3) {
                    if (10..=245).contains(&b[i]) {
                        s += (a[i] as f64 - b[i] as f64).powi(2);
                        k += 1;
                    }
                }
            }
            *jn = (s / k.max(1) as f64).sqrt();
        }
    }
    let label = format!(
        "seed {seed}: {n} × {spacing} EV, {}, {}, {}, full well {full_well:.0} e⁻, read {read_noise:.1} e⁻, brightness {brightness:+.2} EV, sun at {:.0}°",
        if sixteen { "16-bit".to_string() } else { "8-bit".to_string() },
        match jpeg {
            Some(q) => format!("JPEG q{q}"),
            None => "lossless".into(),
        },
        if fisheye { "fish-eye" } else { "rectangular" },
        sun.0
    );
    Case {
        label,
        opts,
        sixteen,
        truth,
        frames,
        circle,
        jpeg_noise,
    }
}

/// The oracle merge of `case` (see the module docs).
pub fn oracle(case: &Case) -> HdrImage {
    oracle_with(case, None)
}

/// [`oracle`], with the votes `g(Z) − ln Δt` taken from `curves` (256 entries per channel,
/// interpolated linearly between codes) instead of the true curve when given; the weights are
/// the oracle's (true noise, true curve's slope) either way.
pub fn oracle_with(case: &Case, curves: Option<&[Vec<f64>; 3]>) -> HdrImage {
    let o = &case.opts;
    let b = o.black_level;
    let k = 0.25 / o.base_time_s;
    let np = case.truth.width * case.truth.height;
    let mut out = HdrImage::new(case.truth.width, case.truth.height);
    let lt: Vec<f64> = case
        .frames
        .iter()
        .map(|f| f.exposure.relative().ln())
        .collect();
    let gains: Vec<f64> = case.frames.iter().map(|f| f.exposure.time_s * k).collect();
    // The true g on the 8-bit code scale (continuous) and its slope.
    let g = |c: usize, z: f64| {
        o.crf[c]
            .inverse((z - b).max(if case.sixteen { 0.5 / 257.0 } else { 0.5 }) / (255.0 - b))
            .ln()
    };
    let quant = if case.sixteen {
        1.0 / (12.0 * 257.0 * 257.0)
    } else {
        1.0 / 12.0
    };
    for p in 0..np {
        for c in 0..3 {
            let l = case.truth.data[3 * p + c] as f64;
            let (mut num, mut den) = (0f64, 0f64);
            let mut fallback = None;
            for (j, f) in case.frames.iter().enumerate() {
                let (z, max) = match &f.pixels {
                    Pixels::U8(v) => (v[3 * p + c] as f64, 255.0),
                    Pixels::U16(v) => (v[3 * p + c] as f64 / 257.0, 255.0),
                };
                let vote = match curves {
                    None => g(c, z),
                    Some(cv) => {
                        let z0 = (z.floor() as usize).min(254);
                        let f = z - z0 as f64;
                        cv[c][z0] * (1.0 - f) + cv[c][z0 + 1] * f
                    }
                } - lt[j];
                if j == 0 {
                    fallback = Some(vote);
                }
                if z <= 0.0 || z >= max {
                    continue;
                }
                let x = l * gains[j];
                let e = x * o.full_well;
                if e <= 0.0 {
                    continue;
                }
                let ze = b + (255.0 - b) * o.crf[c].forward(x.min(1.0));
                if !(1.0..=250.0).contains(&ze) {
                    continue;
                }
                let h = 0.5;
                let slope = (g(c, (ze + h).min(255.0)) - g(c, (ze - h).max(0.0))) / (2.0 * h);
                let var = (e + o.read_noise * o.read_noise) / (e * e)
                    + slope * slope * (quant + case.jpeg_noise[c].powi(2));
                num += vote / var;
                den += 1.0 / var;
            }
            let v = if den > 0.0 {
                num / den
            } else {
                fallback.unwrap_or(0.0)
            };
            out.data[3 * p + c] = v.exp() as f32;
        }
    }
    out
}

/// skydome with nothing known: the curve calibrated from the frames with `calibration`, merged
/// with the given weighting (the default merge's without one). Where the calibration's
/// step-periodic correction applied, the noise merge's model is fitted as the pipeline fits it
/// then (`noise::estimate_for_calibration`, from code 24 up).
pub fn skydome_merge(
    case: &Case,
    calibration: &CalibrateOptions,
    weighting: Option<Weighting>,
) -> HdrImage {
    let cal = calibrate(&case.frames, case.circle, calibration).unwrap();
    let mut opts = MergeOptions::default();
    if let Some(w) = weighting {
        opts.weighting = w;
    }
    if opts.weighting == Weighting::Noise && cal.wide_step {
        let est =
            skydome::noise::estimate_for_calibration(&case.frames, &cal.response, 0, None, true);
        opts.noise = Some(est.model);
    }
    merge(&case.frames, &cal.response, &opts).unwrap().radiance
}

/// The regions errors are measured over: `[sky, dim ground, sun]` (see the module docs; the
/// ground and the sun are also restricted to pixels where both merges are finite and positive).
pub fn regions(case: &Case) -> [Vec<bool>; 3] {
    let well = well_exposed_mask(&case.frames, 10, 245).unwrap();
    let t = |p: usize| case.truth.data[3 * p + 1];
    let np = well.len();
    [
        (0..np)
            .map(|p| well[p] && (0.1..50.0).contains(&t(p)))
            .collect(),
        (0..np)
            .map(|p| well[p] && t(p) > 0.0 && t(p) < 0.1)
            .collect(),
        (0..np).map(|p| t(p) >= 1000.0).collect(),
    ]
}

/// Per channel: the mean log2 ratio to the truth over `mask` (the channel's scale) and the log2
/// RMSE about it (stops).
pub fn scale_and_rmse(a: &HdrImage, truth: &HdrImage, mask: &[bool]) -> [(f64, f64); 3] {
    [0, 1, 2].map(|c| {
        let d: Vec<f64> = mask
            .iter()
            .enumerate()
            .filter(|(p, &m)| m && truth.data[3 * p + c] > 0.0 && a.data[3 * p + c] > 0.0)
            .map(|(p, _)| (a.data[3 * p + c] as f64 / truth.data[3 * p + c] as f64).log2())
            .collect();
        if d.is_empty() {
            return (0.0, 0.0);
        }
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let rmse = (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
        (mean, rmse)
    })
}

/// RMS over the channels of the per-channel log2 RMSE.
fn rms3(e: [(f64, f64); 3]) -> f64 {
    (e.iter().map(|(_, r)| r * r).sum::<f64>() / 3.0).sqrt()
}

/// What one case measured.
#[derive(Debug, Clone, Copy)]
pub struct Measured {
    /// Frames.
    pub n: usize,
    /// Sky log2 RMSE (RMS over channels): the oracle; the noise merge and the hat on the grid
    /// calibration (`--method robust`, the default's below [`COVERING_FROM_FRAMES`] frames);
    /// the noise merge on the noise-weighted calibration (`--method noise`); the
    /// noise merge on the covering calibration (`--method covering`).
    pub sky: [f64; 5],
    /// Dim-ground log2 RMSE after the sky's scale: noise merge and hat on the grid
    /// calibration, noise merge on the noise-weighted and on the covering calibration.
    pub ground: [f64; 4],
    /// Sun: median over the disc of log2(merged / truth) after the sky's scale (a lower bound,
    /// negative; closer to zero is better), the same four merges.
    pub sun: [f64; 4],
    /// The oracle's sun (same measure): for a disc clipped in every frame, the true curve's
    /// top minus the shortest frame's `ln Δt` — the best lower bound the bracket gives.
    pub sun_oracle: f64,
    /// The default (`CalibrateOptions::default()`, noise merge): sky, dim ground and sun as
    /// above. Below [`COVERING_FROM_FRAMES`] frames the joined calibration's (merged here),
    /// from there the covering calibration's (`sky[4]`, `ground[3]`, `sun[3]`).
    pub default: [f64; 3],
}

/// Dim-ground error about the sky's per-channel scale: the RMS over channels and pixels of
/// `log2(a / truth) − scale_c`.
fn offset_rmse(a: &HdrImage, truth: &HdrImage, mask: &[bool], scale: [(f64, f64); 3]) -> f64 {
    let mut s = 0f64;
    let mut k = 0usize;
    for (p, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        for (c, sc) in scale.iter().enumerate() {
            let (v, t) = (a.data[3 * p + c] as f64, truth.data[3 * p + c] as f64);
            if v > 0.0 && t > 0.0 {
                s += ((v / t).log2() - sc.0).powi(2);
                k += 1;
            }
        }
    }
    if k == 0 {
        0.0
    } else {
        (s / k as f64).sqrt()
    }
}

/// Median over the mask and channels of `log2(a / truth) − scale_c` (0 for an empty mask).
fn median_offset(a: &HdrImage, truth: &HdrImage, mask: &[bool], scale: [(f64, f64); 3]) -> f64 {
    let mut d: Vec<f64> = Vec::new();
    for (p, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        for (c, sc) in scale.iter().enumerate() {
            let (v, t) = (a.data[3 * p + c] as f64, truth.data[3 * p + c] as f64);
            if v > 0.0 && t > 0.0 {
                d.push((v / t).log2() - sc.0);
            }
        }
    }
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// Measures one case: the oracle, the grid calibration (`--method robust`, the default's below
/// [`COVERING_FROM_FRAMES`] frames) with the noise merge and the hat, and the noise merge on
/// the noise-weighted and the covering calibrations (the default's from
/// [`COVERING_FROM_FRAMES`] frames; [`default_sky`]).
pub fn measure_case(c: Case) -> (Case, Measured) {
    let [sky, ground, sun] = regions(&c);
    let orc = oracle(&c);
    let grid = CalibrateOptions::robust();
    let def = skydome_merge(&c, &grid, Some(Weighting::Noise));
    let hat = skydome_merge(&c, &grid, Some(Weighting::Hat));
    let noise = skydome_merge(&c, &CalibrateOptions::noise_fit(), Some(Weighting::Noise));
    let cover = skydome_merge(&c, &CalibrateOptions::covering(), Some(Weighting::Noise));
    let e = |img: &HdrImage| scale_and_rmse(img, &c.truth, &sky);
    let (eo, ed, eh, en, ec) = (e(&orc), e(&def), e(&hat), e(&noise), e(&cover));
    let n = c.frames.len();
    let default = if n >= COVERING_FROM_FRAMES {
        [
            rms3(ec),
            offset_rmse(&cover, &c.truth, &ground, ec),
            median_offset(&cover, &c.truth, &sun, ec),
        ]
    } else {
        let d = skydome_merge(&c, &CalibrateOptions::default(), Some(Weighting::Noise));
        let ej = e(&d);
        [
            rms3(ej),
            offset_rmse(&d, &c.truth, &ground, ej),
            median_offset(&d, &c.truth, &sun, ej),
        ]
    };
    let m = Measured {
        default,
        n,
        sky: [rms3(eo), rms3(ed), rms3(eh), rms3(en), rms3(ec)],
        ground: [
            offset_rmse(&def, &c.truth, &ground, ed),
            offset_rmse(&hat, &c.truth, &ground, eh),
            offset_rmse(&noise, &c.truth, &ground, en),
            offset_rmse(&cover, &c.truth, &ground, ec),
        ],
        sun: [
            median_offset(&def, &c.truth, &sun, ed),
            median_offset(&hat, &c.truth, &sun, eh),
            median_offset(&noise, &c.truth, &sun, en),
            median_offset(&cover, &c.truth, &sun, ec),
        ],
        sun_oracle: median_offset(&orc, &c.truth, &sun, eo),
    };
    (c, m)
}

/// Measures every frame count 2–9 on `seeds`, printing one line per case and one summary line
/// per frame count: the mean ratio to the oracle of the default, the hat and the noise merge.
/// Returns the cases' measurements.
pub fn run_all(seeds: &[u64]) -> Vec<Measured> {
    run_all_with(seeds, case)
}

/// [`run_all`] with the cases drawn by `draw(seed, frames)`.
pub fn run_all_with(seeds: &[u64], draw: impl Fn(u64, usize) -> Case) -> Vec<Measured> {
    let mut all = Vec::new();
    for n in 2..=9 {
        let mut group = Vec::new();
        for &seed in seeds {
            let (c, m) = measure_case(draw(seed, n));
            println!(
                "{}: sky oracle {:.4} noise {:.4} ({:.3}×) hat {:.4} ({:.3}×) noise on --method noise {:.4} ({:.3}×) on --method covering {:.4} ({:.3}×); ground {:.3} / {:.3} / {:.3} / {:.3}; sun {:+.2} / {:+.2} / {:+.2} / {:+.2} (oracle {:+.2})",
                c.label,
                m.sky[0],
                m.sky[1],
                m.sky[1] / m.sky[0],
                m.sky[2],
                m.sky[2] / m.sky[0],
                m.sky[3],
                m.sky[3] / m.sky[0],
                m.sky[4],
                m.sky[4] / m.sky[0],
                m.ground[0],
                m.ground[1],
                m.ground[2],
                m.ground[3],
                m.sun[0],
                m.sun[1],
                m.sun[2],
                m.sun[3],
                m.sun_oracle
            );
            group.push(m);
        }
        let mean =
            |k: usize| group.iter().map(|m| m.sky[k] / m.sky[0]).sum::<f64>() / group.len() as f64;
        println!(
            "{n} frames: mean ratio to the oracle: default {:.3}, hat {:.3}, noise {:.3}, covering {:.3}",
            mean(1),
            mean(2),
            mean(3),
            mean(4)
        );
        all.extend(group);
    }
    all
}

/// The target for `n` frames: 1.10 up to 4 frames, 1.05 from 5 — printed next to what
/// is reached; met by the default from 5 frames, not below ([`REACHED_DEFAULT`]).
pub fn target(n: usize) -> f64 {
    if n >= 5 {
        1.05
    } else {
        1.10
    }
}

/// What the noise-model merge reaches on the held-out seeds with the grid calibration (the
/// mean ratio per frame count, every count): measured 1.04–1.26 (2 frames 1.17, 3 1.13, 4 1.12,
/// 5 1.04, 6 1.12, 7 1.08, 8 1.26, 9 1.19), against 1.37–2.45 for the hat merge.
/// The rest of the gap is the calibrated curve's own error on 3-EV and low-full-well brackets.
pub const REACHED: f64 = 1.30;

/// The same with the noise-weighted calibration (`--method noise`, opt-in): measured
/// 1.017–1.074 (2 frames 1.074, 3 1.038, 4 1.030, 5 1.026, 6 1.017, 7 1.017, 8 1.050, 9 1.054):
/// the targets ([`target`]) met at every count but 9 frames.
pub const REACHED_NOISE_FIT: f64 = 1.10;

/// The noise-model merge against the oracle on the held-out seeds (grid calibration): the mean
/// ratio per frame count within [`REACHED`] (the issue's [`target`] printed beside it), never
/// worse than the hat on any bracket's sky, on its dim ground (5 % allowance) or in its clipped
/// sun (never darker).
#[test]
fn the_noise_merge_is_within_the_oracle_targets_on_held_out_brackets() {
    let all = held_out();
    for n in 2..=9 {
        let g: Vec<&Measured> = all.iter().filter(|m| m.n == n).collect();
        let mean = g.iter().map(|m| m.sky[1] / m.sky[0]).sum::<f64>() / g.len() as f64;
        println!(
            "{n} frames: noise merge {mean:.3}× the oracle (issue target {:.2}, {})",
            target(n),
            if mean <= target(n) { "met" } else { "NOT met" }
        );
        assert!(mean <= REACHED, "{n} frames: mean ratio {mean:.3}");
        for m in g {
            assert!(m.sky[1] <= m.sky[2] * 1.01, "{n} frames: {:?}", m.sky);
        }
    }
    for m in all {
        assert!(
            m.ground[0] <= 1.05 * m.ground[1] + 0.005,
            "{} frames: dim ground {:?}",
            m.n,
            m.ground
        );
        assert!(
            m.sun[0] >= m.sun[1] - 0.01,
            "{} frames: sun {:?}",
            m.n,
            m.sun
        );
    }
}

/// The noise-weighted calibration (`--method noise`) on the same held-out brackets: the noise
/// merge on its curve within [`REACHED_NOISE_FIT`] of the oracle per frame count (sky), and no
/// bracket's sky more than 5 % worse than on the default calibration's curve. Its dim ground and
/// clipped sun are printed, not claimed: on two two-frame brackets whose ground lies below the
/// codes the samples measured, its extrapolated toe reads the ground 1.27 and 1.74 stops off
/// (default calibration 0.59 and 0.64), and on one six-frame bracket its curve's top reads the
/// clipped sun 1.6 stops low (default 0.2) — measured reasons it is opt-in, not the default.
#[test]
fn the_noise_weighted_calibration_is_within_the_oracle_targets_on_held_out_brackets() {
    let all = held_out();
    for n in 2..=9 {
        let g: Vec<&Measured> = all.iter().filter(|m| m.n == n).collect();
        let mean = g.iter().map(|m| m.sky[3] / m.sky[0]).sum::<f64>() / g.len() as f64;
        println!(
            "{n} frames: --method noise {mean:.3}× the oracle (issue target {:.2}, {})",
            target(n),
            if mean <= target(n) { "met" } else { "NOT met" }
        );
        for m in &g {
            println!(
                "{n} frames: sky {:.4} (default calibration {:.4}); sun {:+.3} ({:+.3}); dim ground {:.3} stops ({:.3})",
                m.sky[3], m.sky[1], m.sun[2], m.sun[0], m.ground[2], m.ground[0]
            );
        }
        assert!(
            mean <= REACHED_NOISE_FIT,
            "{n} frames: mean ratio {mean:.3}"
        );
        for m in g {
            assert!(m.sky[3] <= m.sky[1] * 1.05, "{n} frames: {:?}", m.sky);
        }
    }
}

/// What the covering calibration (`--method covering`) with the noise merge reaches on the
/// held-out seeds, mean ratio to the oracle per frame count 2–9: 1.049 1.033 1.032 1.025 1.001
/// 1.003 1.007 1.028 — the targets ([`target`]) met at every count (with the
/// step-periodic correction from five frames, docs/accuracy.md "Twelfth round", the 16-bit
/// noise fit, "Thirteenth round", and the clipping test from five frames, "Fourteenth round":
/// 1.001 1.006 1.034 at 7–9 frames before it; before the first two 1.050 1.033 1.039 1.025
/// 1.007 1.017 1.036 1.046).
pub const REACHED_COVERING: [f64; 8] = [1.049, 1.033, 1.032, 1.025, 1.001, 1.003, 1.007, 1.028];

/// On the fresh held-out seeds ([`FRESH_SEEDS`], suns 3–90° high): 1.017 1.013 1.032 1.041
/// 1.008 1.010 1.026 1.020 — every target met. 5–9 frames 1.029 1.008 1.008 1.030 1.021 before
/// the clipping test (docs/accuracy.md, "Fourteenth round"; 5 frames is one bracket, 9111,
/// whose noise fit tips to a model without shot noise on a curve that did not change: 1.023×
/// → 1.159×); 1.025 1.018 1.038 1.030 1.022 1.017 1.035 1.026 before the 16-bit noise fit.
/// Without the step-periodic correction 1.041 1.033 1.018 1.107 1.027 at 5–9 frames: two
/// 8 × 3 EV brackets at 1.47× and 1.58× (1.09× and 1.18× with it).
pub const REACHED_COVERING_FRESH: [f64; 8] =
    [1.017, 1.013, 1.032, 1.041, 1.008, 1.010, 1.026, 1.020];

/// What the default reaches on the fresh held-out seeds: the joined calibration's 1.022 1.018
/// 1.038 at 2–4 frames, the covering calibration's (with the step-periodic correction) from
/// five — the targets met at every count (8 frames 1.107 before the correction; 2–4
/// frames 1.024 1.024 1.051 before the 16-bit noise fit; 5–9 frames as
/// [`REACHED_COVERING_FRESH`]).
pub const REACHED_DEFAULT_FRESH: [f64; 8] =
    [1.022, 1.018, 1.038, 1.041, 1.008, 1.010, 1.026, 1.020];

/// The covering calibration against the oracle on `all`: the mean sky ratio per frame count
/// within 0.5 % of `reached` (which the docs quote), no bracket's sky worse than the noise
/// merge on the grid calibration's curve (`--method robust`) by more than the factor
/// `sky_slack`, and no clipped sun farther from the oracle's lower bound than the grid
/// calibration's by more than 0.1 stops. The dim ground is printed with the grid
/// calibration's beside it and counted, not asserted: on 2–4-frame brackets the covering
/// curve's toe still reads some dim grounds worse (see docs/accuracy.md).
fn check_covering(all: &[Measured], reached: &[f64; 8], sky_slack: f64) -> usize {
    let mut ground_losses = 0;
    for n in 2..=9 {
        let g: Vec<&Measured> = all.iter().filter(|m| m.n == n).collect();
        let mean = g.iter().map(|m| m.sky[4] / m.sky[0]).sum::<f64>() / g.len() as f64;
        println!(
            "{n} frames: --method covering {mean:.3}× the oracle (issue target {:.2}, {})",
            target(n),
            if mean <= target(n) { "met" } else { "NOT met" }
        );
        assert!(
            mean <= reached[n - 2] + 0.005,
            "{n} frames: mean ratio {mean:.3} (docs: {:.3})",
            reached[n - 2]
        );
        for m in g {
            assert!(
                m.sky[4] <= m.sky[1] * sky_slack,
                "{n} frames: sky {:?}",
                m.sky
            );
            let dist = |s: f64| (s - m.sun_oracle).abs();
            assert!(
                dist(m.sun[3]) <= dist(m.sun[0]).min(dist(m.sun[1])) + 0.1,
                "{n} frames: sun {:?} (oracle {:+.2})",
                m.sun,
                m.sun_oracle
            );
            let lost = m.ground[3] > 1.05 * m.ground[0].min(m.ground[1]) + 0.005;
            ground_losses += lost as usize;
            println!(
                "{n} frames: dim ground {:.3} stops (grid calibration {:.3} noise / {:.3} hat){}",
                m.ground[3],
                m.ground[0],
                m.ground[1],
                if lost { " LOST" } else { "" }
            );
        }
    }
    println!("dim ground lost to the grid calibration on {ground_losses} brackets");
    ground_losses
}

/// The covering calibration meets the targets on the held-out seeds (see
/// [`check_covering`]); dim ground lost on 4 of the 24 brackets (three of 2–3 frames, one of
/// 5: 0.35 stops against the grid calibration's 0.17).
#[test]
fn the_covering_calibration_meets_the_oracle_targets_on_held_out_brackets() {
    let lost = check_covering(held_out(), &REACHED_COVERING, 1.05);
    for (n, r) in (2..=9).zip(REACHED_COVERING) {
        assert!(r <= target(n), "{n} frames: {r}");
    }
    // 5 since the 16-bit noise fit: a 4-frame 16-bit bracket at 0.076 stops against the grid
    // calibration's 0.064 (0.074 against 0.066 before).
    assert!(lost <= 5, "dim ground lost on {lost} brackets (docs: 5)");
}

/// The covering calibration on the fresh held-out set (suns 3–90° high, [`FRESH_SEEDS`]):
/// within [`REACHED_COVERING_FRESH`], no bracket's sky more than 15 % worse than on the grid
/// calibration's curve; the dim ground lost on 8 of the 96 brackets, all of 2–4 frames (before
/// the step-periodic correction also one of 8: 0.22 stops against 0.18). The default
/// ([`default_sky`]) within [`REACHED_DEFAULT_FRESH`].
#[test]
fn the_covering_calibration_on_fresh_held_out_brackets() {
    let all = run_all_with(&FRESH_SEEDS, |seed, n| case_with_sun(seed, n, (0.0, 87.0)));
    let means = default_means(&all, "fresh");
    let lost = check_covering(&all, &REACHED_COVERING_FRESH, 1.15);
    assert!(lost <= 8, "dim ground lost on {lost} brackets (docs: 8)");
    for (n, (&m, &r)) in (2..=9).zip(means.iter().zip(&REACHED_DEFAULT_FRESH)) {
        assert!(m <= r + 0.005, "{n} frames: {m:.3} (docs {r:.3})");
    }
    let lost = default_ground_losses(&all);
    assert!(
        lost <= 1,
        "the default lost the dim ground on {lost} brackets of 2–4 frames"
    );
}

/// The sky error of skydome's default — the noise merge on the default calibration: the joined
/// calibration's curve below [`COVERING_FROM_FRAMES`] frames, the covering calibration's from
/// there ([`CalibrateOptions::for_frames`]).
pub fn default_sky(m: &Measured) -> f64 {
    m.default[0]
}

/// Brackets of 2–4 frames in `all` where the default (the joined calibration) reads the dim
/// ground worse than the grid calibration (`--method robust`, the default before; noise merge
/// or hat, whichever is better) by more than 5 % + 0.005 stops, printed; and asserts that no
/// clipped sun is farther from the oracle's lower bound than the grid calibration's by more
/// than 0.1 stops.
fn default_ground_losses(all: &[Measured]) -> usize {
    let mut lost = 0;
    for m in all.iter().filter(|m| m.n < COVERING_FROM_FRAMES) {
        let grid = m.ground[0].min(m.ground[1]);
        if m.default[1] > 1.05 * grid + 0.005 {
            lost += 1;
            println!(
                "{} frames: the default's dim ground {:.3} stops, the grid calibration's {grid:.3}",
                m.n, m.default[1]
            );
        }
        let dist = |s: f64| (s - m.sun_oracle).abs();
        assert!(
            dist(m.default[2]) <= dist(m.sun[0]).min(dist(m.sun[1])) + 0.1,
            "{} frames: sun {:.2} against {:?} (oracle {:+.2})",
            m.n,
            m.default[2],
            m.sun,
            m.sun_oracle
        );
    }
    lost
}

/// The default's mean sky ratio to the oracle per frame count 2–9 on `all`, printed against
/// the issue's [`target`].
fn default_means(all: &[Measured], what: &str) -> Vec<f64> {
    (2..=9)
        .map(|n| {
            let g: Vec<&Measured> = all.iter().filter(|m| m.n == n).collect();
            let mean = g.iter().map(|m| default_sky(m) / m.sky[0]).sum::<f64>() / g.len() as f64;
            println!(
                "{n} frames ({what}): the default {mean:.3}× the oracle (issue target {:.2}, {})",
                target(n),
                if mean <= target(n) { "met" } else { "NOT met" }
            );
            mean
        })
        .collect()
}

/// What the default (noise merge, default calibration) reaches on the held-out seeds, mean
/// ratio to the oracle at 2–9 frames: the joined calibration's below five frames (the grid
/// calibration's there before: 1.172 1.125 1.117), the covering calibration's from five (with
/// the step-periodic correction, the 16-bit noise fit and the clipping test; 1.087 1.059 1.049
/// 1.025 1.007 1.017 1.036 1.046 before the first two).
pub const REACHED_DEFAULT: [f64; 8] = [1.087, 1.059, 1.040, 1.025, 1.001, 1.003, 1.007, 1.028];

/// The default against the oracle on the held-out seeds: within 0.5 % of [`REACHED_DEFAULT`]
/// and the targets met at every count; below five frames (the joined calibration) no
/// dim ground read worse than on the grid calibration's curve and no clipped sun farther from
/// the oracle's bound ([`default_ground_losses`]).
#[test]
fn the_default_is_within_the_oracle_targets_on_held_out_brackets() {
    let means = default_means(held_out(), "held-out");
    for (n, (&m, &r)) in (2..=9).zip(means.iter().zip(&REACHED_DEFAULT)) {
        assert!(m <= r + 0.005, "{n} frames: {m:.3} (docs {r:.3})");
        assert!(r <= target(n), "{n} frames: {r}");
    }
    let lost = default_ground_losses(held_out());
    assert_eq!(
        lost, 0,
        "the dim ground lost on {lost} brackets of 2–4 frames"
    );
}

/// The held-out measurements, computed once for both tests.
fn held_out() -> &'static [Measured] {
    static ALL: std::sync::OnceLock<Vec<Measured>> = std::sync::OnceLock::new();
    ALL.get_or_init(|| run_all(&HELD_OUT_SEEDS))
}

/// The same measurement on the tuning seeds, printed (run with `--nocapture`); it asserts only
/// that the oracle is the floor it claims to be: no merge beats it by more than 3 %.
#[test]
fn the_oracle_is_a_floor_on_tuning_brackets() {
    let all = run_all(&TUNING_SEEDS);
    for m in &all {
        for k in 1..4 {
            assert!(m.sky[k] >= 0.97 * m.sky[0], "{} frames: {:?}", m.n, m.sky);
        }
    }
}

/// Seeds no calibration choice was made on (the hat margin and histogram sampling, issue 27
/// part 6): used only by [`calibration_choices_against_the_oracle`].
pub const CALIBRATION_CHOICE_SEEDS: [u64; 6] = [9001, 9002, 9003, 9004, 9005, 9006];

/// The calibration choices beside the default, against the oracle on brackets of 2–9 frames
/// (seeds [`CALIBRATION_CHOICE_SEEDS`]): colour-hdri's hat (ends moved in by 2.55 codes) with
/// the default samples, histogram samples (Grossberg & Nayar) with the seed's hat, and
/// colour-hdri's set-up (both). Prints, per frame count, the mean sky ratio to the oracle of
/// the hat and of the noise merge and the dim ground's error; asserts what docs/accuracy.md
/// says of them: the margin never costs more than 2 % of the sky ratio or 5 % of the ground
/// error; histogram samples are at least 20 % worse than the grid's from 3 frames (a noisy
/// frame's histogram is its scene's blurred by the noise, so the rank match drifts in the dark
/// and bright codes). About a minute in release: `cargo test --release -p skydome --test lib --
/// --ignored calibration_choices --nocapture`.
#[test]
#[ignore = "a benchmark of calibration choices (about a minute in release); see docs/accuracy.md"]
fn calibration_choices_against_the_oracle() {
    use skydome::sampling::SampleOptions;
    let base = CalibrateOptions::robust();
    let variants: [(&str, CalibrateOptions); 4] = [
        ("default", base.clone()),
        (
            "colour-hdri's hat",
            CalibrateOptions {
                hat_margin: skydome::response::COLOUR_HDRI_HAT_MARGIN,
                ..base.clone()
            },
        ),
        (
            "histogram samples",
            CalibrateOptions {
                sampling: SampleOptions::histogram_method(1000),
                ..base.clone()
            },
        ),
        ("colour-hdri", CalibrateOptions::colour_hdri()),
    ];
    let k = CALIBRATION_CHOICE_SEEDS.len() as f64;
    for n in 2..=9 {
        // Per variant: hat-merge sky ratio, noise-merge sky ratio, ground error (hat merge).
        let mut sums = [[0.0f64; 3]; 4];
        for &seed in &CALIBRATION_CHOICE_SEEDS {
            let c = case(seed, n);
            let [sky, ground, _] = regions(&c);
            let floor = rms3(scale_and_rmse(&oracle(&c), &c.truth, &sky));
            for (v, (_, o)) in variants.iter().enumerate() {
                let hat = skydome_merge(&c, o, Some(Weighting::Hat));
                let e = scale_and_rmse(&hat, &c.truth, &sky);
                let noise = skydome_merge(&c, o, Some(Weighting::Noise));
                sums[v][0] += rms3(e) / floor / k;
                sums[v][1] += rms3(scale_and_rmse(&noise, &c.truth, &sky)) / floor / k;
                sums[v][2] += offset_rmse(&hat, &c.truth, &ground, e) / k;
            }
        }
        for (v, (name, _)) in variants.iter().enumerate() {
            println!(
                "{n} frames, {name}: sky ratio hat merge {:.3}, noise merge {:.3}; ground {:.3} stops",
                sums[v][0], sums[v][1], sums[v][2]
            );
        }
        let [d, m, h, _] = sums;
        assert!(
            m[0] <= d[0] * 1.02 && m[1] <= d[1] * 1.02,
            "{n} frames: margin {m:?} vs {d:?}"
        );
        assert!(
            m[2] <= d[2] * 1.05,
            "{n} frames: margin ground {m:?} vs {d:?}"
        );
        if n >= 3 {
            assert!(h[0] >= d[0] * 1.2, "{n} frames: histogram {h:?} vs {d:?}");
        }
    }
}

/// Per channel, the calibrated curve's error against the true one (after the offset over
/// codes 64..=191), RMS over the channels, in stops: `[toe 1..=15, middle 16..=239, top
/// 240..=254, g(255)]` (the last signed, mean over channels).
pub fn curve_error(case: &Case, g: &[Vec<f64>; 3]) -> [f64; 4] {
    let o = &case.opts;
    let b = o.black_level;
    let truth = |c: usize, z: usize| {
        o.crf[c]
            .inverse(((z as f64) - b).max(0.5) / (255.0 - b))
            .ln()
    };
    let mut out = [0.0; 4];
    for (c, gc) in g.iter().enumerate() {
        let d: Vec<f64> = (0..256)
            .map(|z| (gc[z] - truth(c, z)) / std::f64::consts::LN_2)
            .collect();
        let off = d[64..192].iter().sum::<f64>() / 128.0;
        let rms = |r: std::ops::RangeInclusive<usize>| {
            let n = r.clone().count() as f64;
            (r.map(|z| (d[z] - off).powi(2)).sum::<f64>() / n).sqrt()
        };
        out[0] += rms(1..=15).powi(2) / 3.0;
        out[1] += rms(16..=239).powi(2) / 3.0;
        out[2] += rms(240..=254).powi(2) / 3.0;
        out[3] += (d[255] - off) / 3.0;
    }
    [out[0].sqrt(), out[1].sqrt(), out[2].sqrt(), out[3]]
}

/// The calibrations tried while choosing the default's (see [`calibration_candidates`]):
/// `SKYDOME_ORACLE_CANDIDATES`, `;`-separated, each a `,`-separated list of `key=value` on top
/// of [`CalibrateOptions::noise_fit`] (keys `samples`, `cover`, `stratify`, `lo`, `hi`,
/// `lambda`, `margin`, `bands`, `fit`, `patch`, `cut`, `periodic` (`1` or `0`: [`CalibrateOptions::step_periodic`] asked for or off; `covering=1` has it), `join` (`a-b`: the grid
/// calibration's toe, [`CalibrateOptions::toe_from_grid`]); `covering=1` starts again from
/// [`CalibrateOptions::covering`], so put it first); `noise_fit` alone without the variable.
/// The keys of [`Candidate`]'s wide-step rules are accepted and dropped here.
pub fn candidates() -> Vec<(String, CalibrateOptions)> {
    candidate_rules()
        .into_iter()
        .map(|c| (c.name, c.opts))
        .collect()
}

/// A calibration candidate of [`calibration_candidates`]: its options and, for the ninth
/// round (docs/accuracy.md), bench-only rules for brackets whose mean step is at least
/// `wide_from` EV (key `wide`, default 2.5; 0 applies them to every bracket).
#[derive(Debug, Clone)]
pub struct Candidate {
    /// As given in `SKYDOME_ORACLE_CANDIDATES`.
    pub name: String,
    /// The options.
    pub opts: CalibrateOptions,
    /// The mean step (EV) from which the rules below apply.
    pub wide_from: f64,
    /// `wlambda`: λ on wide-step brackets.
    pub wide_lambda: Option<f64>,
    /// `wdrop=z`: the samples refitted without their observations below code `z`.
    pub wide_drop: Option<f32>,
    /// `wtwo=z`: two stages — the curve from code `z + 32` up refitted without the
    /// observations below `z`, the whole fit's slopes below `z`, blended between
    /// ([`skydome::response::join_toe`]).
    pub wide_two_stage: Option<f32>,
    /// `wpair=z`: observations below code `z` kept only where the same sample reads
    /// `z..=230` in another frame (the toe fitted from samples read in two frames).
    pub wide_pair: Option<f32>,
    /// `wnoise=1`: on wide-step brackets the merge's noise model is fitted from code 24 up
    /// (as where [`CalibrateOptions::step_periodic`] applied) without the curve's correction,
    /// to tell the two parts of the eleventh round apart.
    pub wide_noise: bool,
    /// `both=1`: one fit on the candidate's samples and the grid calibration's samples together
    /// (the candidate's options, no join) instead of a joined toe (fifteenth round).
    pub both: bool,
}

/// [`candidates`] with their wide-step rules ([`Candidate`]).
pub fn candidate_rules() -> Vec<Candidate> {
    let spec = std::env::var("SKYDOME_ORACLE_CANDIDATES").unwrap_or_default();
    let plain = |name: &str, opts: CalibrateOptions| Candidate {
        name: name.to_string(),
        opts,
        wide_from: 2.5,
        wide_lambda: None,
        wide_drop: None,
        wide_two_stage: None,
        wide_pair: None,
        wide_noise: false,
        both: false,
    };
    let mut out = vec![plain("noise_fit", CalibrateOptions::noise_fit())];
    for cand in spec.split(';').filter(|c| !c.trim().is_empty()) {
        let mut c = plain(cand.trim(), CalibrateOptions::noise_fit());
        for kv in cand.split(',') {
            let (k, v) = kv.split_once('=').expect("key=value");
            let f: f64 = v.trim().parse().unwrap_or(f64::NAN);
            let o = &mut c.opts;
            match k.trim() {
                "samples" => o.sampling.samples = f as usize,
                "cover" => o.sampling.cover = f as usize,
                "covering" => *o = CalibrateOptions::covering(),
                "stratify" => o.sampling.stratify = f as usize,
                "lo" => o.sampling.clip_low = f as u8,
                "hi" => o.sampling.clip_high = f as u8,
                "bands" => o.sampling.code_bands = f as usize,
                "lambda" => o.lambda = f,
                "margin" => o.hat_margin = f,
                "fit" => o.fit = v.trim().parse().expect("fit"),
                "patch" => o.sampling.patch = f as usize,
                "cut" => o.outlier_sigmas = f,
                "join" => {
                    let (a, b) = v.trim().split_once('-').expect("join=a-b");
                    o.toe_from_grid = Some([
                        a.trim().parse().expect("code"),
                        b.trim().parse().expect("code"),
                    ]);
                }
                "wide" => c.wide_from = f,
                "wlambda" => c.wide_lambda = Some(f),
                "wdrop" => c.wide_drop = Some(f as f32),
                "wtwo" => c.wide_two_stage = Some(f as f32),
                "wpair" => c.wide_pair = Some(f as f32),
                "periodic" => o.step_periodic = Some(f != 0.0),
                "wnoise" => c.wide_noise = f != 0.0,
                "both" => c.both = f != 0.0,
                other => panic!("unknown key {other}"),
            }
        }
        out.push(c);
    }
    out
}

/// The mean step of a bracket, EV: `(ln Δt_last − ln Δt_first) / (P − 1) / ln 2`.
pub fn mean_step_ev(frames: &[Frame]) -> f64 {
    let lt: Vec<f64> = frames.iter().map(|f| f.exposure.relative().ln()).collect();
    skydome::response::mean_step_ev(&lt)
}

/// Calibrates `frames` with `cand` (its wide-step rules applied where the bracket's mean step
/// is at least [`Candidate::wide_from`]); `grid` is the grid calibration's curve, joined under
/// a refitted curve when the candidate joins a toe.
pub fn calibrate_candidate(
    frames: &[Frame],
    circle: Option<Circle>,
    cand: &Candidate,
    grid: &[Vec<f64>; 3],
) -> Result<skydome::response::Calibration, skydome::response::ResponseError> {
    use skydome::response::{calibrate_samples_with, join_toe, Response};
    let wide = mean_step_ev(frames) >= cand.wide_from - 1e-9;
    let mut o = cand.opts.clone();
    if let (true, Some(l)) = (wide, cand.wide_lambda) {
        o.lambda = l;
    }
    let cal = calibrate(frames, circle, &o)?;
    let cal = match cand.both {
        false => cal,
        true => {
            let mut g = CalibrateOptions::robust();
            g.sampling.seed = o.sampling.seed;
            let grid_samples = skydome::sampling::sample(frames, circle, &g.sampling)?;
            let mut s = cal.samples.clone();
            s.positions.extend_from_slice(&grid_samples.positions);
            s.values.extend_from_slice(&grid_samples.values);
            let mut plain = o.clone();
            plain.toe_from_grid = None;
            calibrate_samples_with(s, &cal.log_times, &plain)?
        }
    };
    let refit = |keep: &dyn Fn(&skydome::sampling::Samples, usize, usize, usize) -> bool| {
        let s = &cal.samples;
        let mut s2 = s.clone();
        for i in 0..s.count() {
            for j in 0..s.frames {
                for ch in 0..3 {
                    if !keep(s, i, j, ch) {
                        s2.values[i * s.frames + j][ch] = 0.0;
                    }
                }
            }
        }
        let mut plain = o.clone();
        plain.toe_from_grid = None;
        calibrate_samples_with(s2, &cal.log_times, &plain)
    };
    let full = cal.response.curves().clone();
    let mut curves = if cal.grid_alone || !wide {
        None
    } else if let Some(z) = cand.wide_drop {
        Some(
            refit(&|s, i, j, ch| s.z(i, j, ch) >= z)?
                .response
                .curves()
                .clone(),
        )
    } else if let Some(z) = cand.wide_pair {
        Some(
            refit(&|s, i, j, ch| {
                s.z(i, j, ch) >= z
                    || (0..s.frames).any(|k| k != j && (z..=230.0).contains(&s.z(i, k, ch)))
            })?
            .response
            .curves()
            .clone(),
        )
    } else if let Some(z) = cand.wide_two_stage {
        let upper = refit(&|s, i, j, ch| s.z(i, j, ch) >= z)?;
        let up = upper.response.curves();
        let (a, b) = (z as usize, z as usize + 32);
        Some([0, 1, 2].map(|ch| join_toe(&up[ch], &full[ch], a, b)))
    } else {
        None
    };
    // A refit of a joined candidate takes the grid's toe again.
    if let (Some(cv), Some([a, b])) = (curves.as_mut(), o.toe_from_grid) {
        for (ch, curve) in cv.iter_mut().enumerate() {
            *curve = join_toe(curve, &grid[ch], a as usize, b as usize);
        }
    }
    let mut cal = cal;
    if let Some(cv) = curves {
        cal.response = Response::from_curves(cv)?;
    }
    if wide && cand.wide_noise {
        cal.wide_step = true;
    }
    if cal.wide_step && std::env::var("SKYDOME_ORACLE_SHOW_PERIODIC").is_ok_and(|v| v == "1") {
        // The correction's size per channel: RMS and largest change over codes 24–254 (ln).
        let plain = calibrate(
            frames,
            circle,
            &CalibrateOptions {
                step_periodic: Some(false),
                ..o.clone()
            },
        )?;
        for ch in 0..3 {
            let (a, b) = (cal.response.curve(ch), plain.response.curve(ch));
            let d: Vec<f64> = (24..=254).map(|z| a[z] - b[z]).collect();
            let m = d.iter().sum::<f64>() / d.len() as f64;
            let rms = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
            let top = d.iter().map(|v| (v - m).abs()).fold(0.0, f64::max);
            println!("    step-periodic correction ch {ch}: RMS {rms:.4} ln, largest {top:.4} ln");
        }
    }
    Ok(cal)
}

/// The tuning benches' brackets: the seeds (`SKYDOME_ORACLE_SEEDS`, default
/// [`MORE_TUNING_SEEDS`]), whether the sun ranges over every height (the default seeds, or
/// `SKYDOME_ORACLE_WIDE_SUN=1`) and the frame counts (`SKYDOME_ORACLE_FRAMES`, default 2–9).
fn bench_selection() -> (Vec<u64>, bool, Vec<usize>) {
    let given: Option<Vec<u64>> = std::env::var("SKYDOME_ORACLE_SEEDS")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect());
    let wide = given.is_none() || std::env::var("SKYDOME_ORACLE_WIDE_SUN").is_ok_and(|v| v == "1");
    let seeds = given.unwrap_or_else(|| MORE_TUNING_SEEDS.to_vec());
    let ns: Vec<usize> = std::env::var("SKYDOME_ORACLE_FRAMES")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_else(|| (2..=9).collect());
    (seeds, wide, ns)
}

/// The toe join of the tuning benches, `SKYDOME_ORACLE_JOIN`: `z` (a hard join at code `z`)
/// or `a-b` (a blend from code `a` to `b`), as `(a, b)` within `0..=255`.
pub fn join_spec() -> Option<(usize, usize)> {
    let v = std::env::var("SKYDOME_ORACLE_JOIN").ok()?;
    let v = v.trim();
    let (a, b) = match v.split_once('-') {
        Some((a, b)) => (a.trim().parse().ok()?, b.trim().parse().ok()?),
        None => {
            let z = v.parse().ok()?;
            (z, z)
        }
    };
    Some((usize::min(a, 255), usize::min(b, 255)))
}

/// Tuning bench: every candidate calibration with the noise merge against the oracle and against
/// the default calibration (noise merge and hat merge), per bracket: sky ratio, dim ground,
/// clipped sun and the curve's toe/top errors. Seeds from `SKYDOME_ORACLE_SEEDS` (comma
/// separated; default [`MORE_TUNING_SEEDS`] with the sun's zenith 0–87°), sun zenith 0–87°
/// when `SKYDOME_ORACLE_WIDE_SUN=1`, frame counts from `SKYDOME_ORACLE_FRAMES` (default
/// 2–9); candidates from `SKYDOME_ORACLE_CANDIDATES` ([`candidates`]). With
/// `SKYDOME_ORACLE_CHOOSE=r` each candidate's channel takes the default calibration's curve
/// instead where that curve's [`toe_consistency`] on the candidate's samples is more than `r`
/// times better (a data-driven choice; both values printed). With `SKYDOME_ORACLE_JOIN=z` every
/// candidate's curve below code `z` is the default calibration's, shifted to meet it at `z` (a
/// fallback toe; docs/accuracy.md, third round); with `SKYDOME_ORACLE_JOIN=a-b` the slopes
/// `g(z+1) − g(z)` pass linearly from the default's below code `a` to the candidate's from `b`
/// up (seventh round). Candidates may carry wide-step rules ([`Candidate`], ninth round), and
/// every candidate after the first listed is also compared with that first one, per bracket
/// (losses counted and listed at the end; e.g. `covering=1;covering=1,join=128-192` compares
/// the joined calibration with the covering one). A minute or two:
/// `SKYDOME_ORACLE_CANDIDATES="cover=16,lo=1,lambda=150" cargo test --workspace --test lib --
/// --ignored oracle::calibration_candidates --nocapture`.
#[test]
#[ignore = "a tuning bench for calibration candidates; prints only"]
fn calibration_candidates() {
    let (seeds, wide, ns) = bench_selection();
    let cands = candidate_rules();
    let mut ratio_sum = vec![vec![0.0f64; ns.len()]; cands.len() + 2];
    let mut ratio_max = vec![vec![0.0f64; ns.len()]; cands.len()];
    let mut losses = vec![[0usize; 3]; cands.len()];
    // Losses against the first candidate listed (the baseline: sky 5 % worse, dim ground 5 %
    // + 0.005 stops worse, clipped sun 0.1 stop farther from the oracle's bound).
    let mut base_losses = vec![[0usize; 3]; cands.len()];
    let mut lost_lines = vec![Vec::<String>::new(); cands.len()];
    for (ni, &n) in ns.iter().enumerate() {
        for &seed in &seeds {
            let c = if wide {
                case_with_sun(seed, n, (0.0, 87.0))
            } else {
                case(seed, n)
            };
            let [sky, ground, sun] = regions(&c);
            let orc = oracle(&c);
            let eo = scale_and_rmse(&orc, &c.truth, &sky);
            let floor = rms3(eo);
            let orc_sun = median_offset(&orc, &c.truth, &sun, eo);
            let eval = |cal: &skydome::response::Calibration, w: Weighting| {
                // The merge's noise model as the pipeline fits it for this calibration
                // (from code 24 up where the step-periodic correction applied;
                // `SKYDOME_ORACLE_WIDE_NOISE=0` keeps the whole fit, to tell the two apart).
                let whole_noise =
                    std::env::var("SKYDOME_ORACLE_WIDE_NOISE").is_ok_and(|v| v == "0");
                let noise = (w == Weighting::Noise && cal.wide_step && !whole_noise).then(|| {
                    skydome::noise::estimate_for_calibration(
                        &c.frames,
                        &cal.response,
                        0,
                        None,
                        true,
                    )
                    .model
                });
                let opts = MergeOptions {
                    weighting: w,
                    noise,
                    ..MergeOptions::default()
                };
                let img = merge(&c.frames, &cal.response, &opts).unwrap().radiance;
                let e = scale_and_rmse(&img, &c.truth, &sky);
                (
                    rms3(e) / floor,
                    offset_rmse(&img, &c.truth, &ground, e),
                    median_offset(&img, &c.truth, &sun, e),
                    curve_error(&c, cal.response.curves()),
                )
            };
            let def = calibrate(&c.frames, c.circle, &CalibrateOptions::robust()).unwrap();
            let dn = eval(&def, Weighting::Noise);
            let dh = eval(&def, Weighting::Hat);
            println!("{} (oracle sun {orc_sun:+.2})", c.label);
            let line = |name: &str, r: &(f64, f64, f64, [f64; 4])| {
                println!(
                    "  {name:>14}: sky {:.3} ground {:.3} sun {:+.2} | curve toe {:.3} mid {:.3} top {:.3} g255 {:+.2}",
                    r.0, r.1, r.2, r.3[0], r.3[1], r.3[2], r.3[3]
                )
            };
            line("default+noise", &dn);
            line("default+hat", &dh);
            ratio_sum[0][ni] += dn.0 / seeds.len() as f64;
            ratio_sum[1][ni] += dh.0 / seeds.len() as f64;
            let mut base: Option<(f64, f64, f64, [f64; 4])> = None;
            for (k, cand) in cands.iter().enumerate() {
                let name = &cand.name;
                let cal =
                    match calibrate_candidate(&c.frames, c.circle, cand, def.response.curves()) {
                        Ok(cal) => cal,
                        Err(e) => {
                            println!("  {name:>14}: FAILED {e}");
                            losses[k][0] += 1;
                            ratio_sum[k + 2][ni] += 10.0 / seeds.len() as f64;
                            continue;
                        }
                    };
                let mut cal = cal;
                let choose: Option<f64> = std::env::var("SKYDOME_ORACLE_CHOOSE")
                    .ok()
                    .and_then(|v| v.trim().parse().ok());
                if let Some(ratio) = choose {
                    let lt = &cal.log_times;
                    let mut curves = cal.response.curves().clone();
                    for (ch, curve) in curves.iter_mut().enumerate() {
                        let grid = &def.response.curves()[ch];
                        let mc = toe_consistency(&cal.samples, lt, curve, ch);
                        let md = toe_consistency(&cal.samples, lt, grid, ch);
                        let md2 = toe_consistency(&def.samples, lt, grid, ch);
                        let mc2 = toe_consistency(&def.samples, lt, curve, ch);
                        println!("    ch {ch}: toe consistency on the candidate's samples: candidate {mc:.3} default {md:.3}; on the default's samples: candidate {mc2:.3} default {md2:.3}");
                        if md * ratio < mc {
                            *curve = grid.clone();
                        }
                    }
                    cal.response = skydome::response::Response::from_curves(curves).unwrap();
                }
                if let Some((za, zb)) = join_spec() {
                    let mut curves = cal.response.curves().clone();
                    for (ch, curve) in curves.iter_mut().enumerate() {
                        *curve =
                            skydome::response::join_toe(curve, &def.response.curves()[ch], za, zb);
                    }
                    cal.response = skydome::response::Response::from_curves(curves).unwrap();
                }
                let r = eval(&cal, Weighting::Noise);
                let mut flag = String::new();
                if r.0 > dn.0.min(dh.0) * 1.01 {
                    losses[k][0] += 1;
                    flag += " SKY-LOSS";
                }
                if r.1 > 1.05 * dn.1.min(dh.1) + 0.005 {
                    losses[k][1] += 1;
                    flag += " GROUND-LOSS";
                }
                let dist = |s: f64| (s - orc_sun).abs();
                if dist(r.2) > dist(dn.2).min(dist(dh.2)) + 0.1 {
                    losses[k][2] += 1;
                    flag += " SUN-LOSS";
                }
                if k == 1 {
                    base = Some(r);
                } else if let (true, Some(b)) = (k > 1, base) {
                    let mut what = Vec::new();
                    if r.0 > b.0 * 1.05 {
                        base_losses[k][0] += 1;
                        what.push(format!("sky {:.3} against {:.3}", r.0, b.0));
                    }
                    if r.1 > 1.05 * b.1 + 0.005 {
                        base_losses[k][1] += 1;
                        what.push(format!("ground {:.3} against {:.3}", r.1, b.1));
                    }
                    if dist(r.2) > dist(b.2) + 0.1 {
                        base_losses[k][2] += 1;
                        what.push(format!("sun {:+.2} against {:+.2}", r.2, b.2));
                    }
                    if !what.is_empty() {
                        flag += " BASE-LOSS";
                        lost_lines[k].push(format!("seed {seed}, {n} frames: {}", what.join(", ")));
                    }
                }
                line(name.as_str(), &r);
                if !flag.is_empty() {
                    println!("  {:>14}  {flag}", "");
                }
                ratio_sum[k + 2][ni] += r.0 / seeds.len() as f64;
                ratio_max[k][ni] = ratio_max[k][ni].max(r.0);
            }
        }
    }
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.3}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!("frames {:?}", ns);
    println!("{:>14}: {}", "default+noise", fmt(&ratio_sum[0]));
    println!("{:>14}: {}", "default+hat", fmt(&ratio_sum[1]));
    for (k, cand) in cands.iter().enumerate() {
        println!(
            "{:>14}: {}  losses sky/ground/sun(vs oracle) {:?}; against the first candidate {:?}; worst {}",
            cand.name,
            fmt(&ratio_sum[k + 2]),
            losses[k],
            base_losses[k],
            fmt(&ratio_max[k])
        );
        for l in &lost_lines[k] {
            println!("{:>16}{l}", "");
        }
    }
}

/// Diagnosis of the curve's toe on one bracket (`SKYDOME_ORACLE_SEEDS`, first seed;
/// `SKYDOME_ORACLE_FRAMES`, first count; sun zenith 0–87°): per code 1..=80 of each channel,
/// the true `g` and the default and covering curves' errors (stops, after the offset over codes
/// 64..=191), and how many sample observations read that code.
#[test]
#[ignore = "a diagnosis; prints only"]
fn toe_diagnosis() {
    let seed: u64 = std::env::var("SKYDOME_ORACLE_SEEDS")
        .ok()
        .and_then(|s| s.split(',').next().and_then(|v| v.trim().parse().ok()))
        .unwrap_or(20);
    let n: usize = std::env::var("SKYDOME_ORACLE_FRAMES")
        .ok()
        .and_then(|s| s.split(',').next().and_then(|v| v.trim().parse().ok()))
        .unwrap_or(3);
    let c = case_with_sun(seed, n, (0.0, 87.0));
    println!("{}", c.label);
    let mut cands = vec![("grid".to_string(), CalibrateOptions::robust())];
    cands.extend(candidates().into_iter().skip(1));
    cands.push(("covering".into(), CalibrateOptions::covering()));
    let cals: Vec<_> = cands
        .iter()
        .map(|(_, o)| calibrate(&c.frames, c.circle, o).unwrap())
        .collect();
    let o = &c.opts;
    let truth = |ch: usize, z: usize| {
        o.crf[ch]
            .inverse(((z as f64) - o.black_level).max(0.5) / (255.0 - o.black_level))
            .ln()
    };
    let [_, ground, _] = regions(&c);
    let long = c.frames.last().unwrap();
    for ch in 0..3 {
        // Codes the longest frame reads on the dim ground.
        let mut hist = vec![0usize; 256];
        if let Pixels::U8(v) = &long.pixels {
            for (p, _) in ground.iter().enumerate().filter(|(_, &g)| g) {
                hist[v[3 * p + ch] as usize] += 1;
            }
        }
        println!(
            "channel {ch}: names {:?}",
            cands.iter().map(|(n, _)| n).collect::<Vec<_>>()
        );
        let offs: Vec<f64> = cals
            .iter()
            .map(|cal| {
                (64..192)
                    .map(|z| cal.response.curves()[ch][z] - truth(ch, z))
                    .sum::<f64>()
                    / 128.0
            })
            .collect();
        for z in (1..=80).step_by(3) {
            let errs: Vec<String> = cals
                .iter()
                .zip(&offs)
                .map(|(cal, off)| {
                    let s = &cal.samples;
                    let k = (0..s.count())
                        .flat_map(|i| (0..s.frames).map(move |j| (i, j)))
                        .filter(|&(i, j)| (s.z(i, j, ch) as usize) == z)
                        .count();
                    format!(
                        "{:+.2} ({k})",
                        (cal.response.curves()[ch][z] - truth(ch, z) - off)
                            / std::f64::consts::LN_2
                    )
                })
                .collect();
            println!(
                "  z {z:3}: true {:+.2} ground px {:4} | {}",
                truth(ch, z) / std::f64::consts::LN_2,
                hist[z],
                errs.join("  ")
            );
        }
    }
}

/// Median |residual| (ln units) of the toe observations (codes 8..64) of channel `c` against
/// `ln E` from the same sample's well-measured observations (codes 64..=220), under curve `g`.
fn toe_consistency(s: &skydome::sampling::Samples, lt: &[f64], g: &[f64], c: usize) -> f64 {
    let g_at = |z: f32| {
        let z = (z as f64).clamp(0.0, 255.0);
        let z0 = (z.floor() as usize).min(254);
        let f = z - z0 as f64;
        g[z0] * (1.0 - f) + g[z0 + 1] * f
    };
    let mut r = Vec::new();
    for i in 0..s.count() {
        let (mut sum, mut k) = (0.0, 0usize);
        for (j, l) in lt.iter().enumerate() {
            let z = s.z(i, j, c);
            if (64.0..=220.0).contains(&z) {
                sum += g_at(z) - l;
                k += 1;
            }
        }
        if k == 0 {
            continue;
        }
        let e = sum / k as f64;
        for (j, l) in lt.iter().enumerate() {
            let z = s.z(i, j, c);
            if (8.0..64.0).contains(&z) {
                r.push((g_at(z) - l - e).abs());
            }
        }
    }
    if r.is_empty() {
        return f64::NAN;
    }
    r.sort_by(f64::total_cmp);
    r[r.len() / 2]
}

/// Per channel: the sum of squares and count of `log2(a / truth) − scale_c` over `mask`, and
/// the median of it (0 for none) — the pieces [`offset_rmse`] and [`median_offset`] pool.
fn per_channel_offsets(
    a: &HdrImage,
    truth: &HdrImage,
    mask: &[bool],
    scale: [(f64, f64); 3],
) -> [(f64, usize, f64); 3] {
    [0, 1, 2].map(|c| {
        let mut d: Vec<f64> = Vec::new();
        for (p, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
            let (v, t) = (a.data[3 * p + c] as f64, truth.data[3 * p + c] as f64);
            if v > 0.0 && t > 0.0 {
                d.push((v / t).log2() - scale[c].0);
            }
        }
        let ss = d.iter().map(|x| x * x).sum::<f64>();
        let k = d.len();
        d.sort_by(f64::total_cmp);
        (ss, k, if k == 0 { 0.0 } else { d[k / 2] })
    })
}

/// Per band of 16 codes: `count:median|r|:mean min(r², 1)` of leave-one-out residuals.
fn band_stats(res: &[(f32, f64)]) -> String {
    let mut bands: Vec<Vec<f64>> = vec![Vec::new(); 16];
    for &(z, r) in res {
        bands[((z as usize) / 16).min(15)].push(r);
    }
    bands
        .iter_mut()
        .map(|b| {
            if b.is_empty() {
                return "0:0:0".to_string();
            }
            let ms = b.iter().map(|r| (r * r).min(1.0)).sum::<f64>() / b.len() as f64;
            let mut a: Vec<f64> = b.iter().map(|r| r.abs()).collect();
            a.sort_by(f64::total_cmp);
            format!("{}:{:.5}:{:.6}", b.len(), a[a.len() / 2], ms)
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// The draw of held-out pixels for [`cross_validated_choice`]: the covering draw of single
/// pixels (2000, codes from 1), away from every calibration sample's patch.
pub fn held_out_draw(
    case: &Case,
    used: &[&skydome::sampling::Samples],
) -> skydome::sampling::Samples {
    let o = skydome::sampling::SampleOptions {
        patch: 0,
        seed: 0x5EED_CAFE,
        ..skydome::sampling::SampleOptions::covering()
    };
    skydome::sampling::sample_held_out(&case.frames, case.circle, &o, used, 1).unwrap()
}

/// The samples of `s` whose position's 8 × 8 block has parity `fold` (a checkerboard split);
/// with `away`, only those farther than 2 pixels (Chebyshev) from every position of `away`.
fn fold_of(
    s: &skydome::sampling::Samples,
    fold: usize,
    away: Option<&skydome::sampling::Samples>,
) -> skydome::sampling::Samples {
    let p = s.frames;
    let mut out = skydome::sampling::Samples {
        positions: Vec::new(),
        values: Vec::new(),
        frames: p,
        report: s.report.clone(),
    };
    for (i, &(x, y)) in s.positions.iter().enumerate() {
        if (x / 8 + y / 8) % 2 != fold {
            continue;
        }
        if let Some(a) = away {
            if a.positions
                .iter()
                .any(|&(u, v)| u.abs_diff(x) <= 2 && v.abs_diff(y) <= 2)
            {
                continue;
            }
        }
        out.positions.push((x, y));
        out.values.extend_from_slice(&s.values[i * p..(i + 1) * p]);
    }
    out.report.used = out.positions.len();
    out
}

/// Two-fold cross-validation of the three candidate curves: each fitted on one checkerboard
/// half of its own samples (default: the grid draw; covering: the covering draw; join: the
/// covering half's curve with the default half's toe below 96), its leave-one-out residuals on
/// the other half of the covering draw (away from the fitting samples), both ways; per
/// candidate and channel, the residuals pooled.
fn two_fold_residuals(
    def: &skydome::response::Calibration,
    cov: &skydome::response::Calibration,
) -> [[Vec<(f32, f64)>; 3]; 3] {
    use skydome::response::calibrate_samples_with;
    let lt = &cov.log_times;
    let mut out: [[Vec<(f32, f64)>; 3]; 3] = Default::default();
    for fold in 0..2 {
        let d = fold_of(&def.samples, fold, None);
        let cv = fold_of(&cov.samples, fold, None);
        let (Ok(fd), Ok(fc)) = (
            calibrate_samples_with(d.clone(), lt, &CalibrateOptions::default()),
            calibrate_samples_with(cv.clone(), lt, &CalibrateOptions::covering()),
        ) else {
            continue;
        };
        let mut both = d.clone();
        both.positions.extend_from_slice(&cv.positions);
        let test = fold_of(&cov.samples, 1 - fold, Some(&both));
        for ch in 0..3 {
            let gd = &fd.response.curves()[ch];
            let gc = &fc.response.curves()[ch];
            let shift = gc[96] - gd[96];
            let gj: Vec<f64> = (0..256)
                .map(|z| if z < 96 { gd[z] + shift } else { gc[z] })
                .collect();
            for (o, g) in out
                .iter_mut()
                .zip([gd.as_slice(), gc.as_slice(), gj.as_slice()])
            {
                o[ch].extend(skydome::response::held_out_residuals(&test, lt, g, ch));
            }
        }
    }
    out
}

/// Cross-validation bench (issue 27 part 4, fourth round): per bracket, the default
/// calibration, the covering calibration and the covering calibration with the default's toe
/// below code 96 (`join`), each merged with the noise model (the default also with the hat),
/// and each curve's leave-one-out residuals ([`skydome::response::held_out_residuals`]) on a
/// held-out draw of pixels ([`held_out_draw`]) and, for comparison, on the covering samples
/// (in-sample). Writes one tab-separated line per bracket (`B`) and per candidate and channel
/// (`C`: errors; `H`/`I`: held-out/in-sample residual stats per band of 16 codes) to
/// `SKYDOME_ORACLE_TSV` (default `/tmp/oracle_cv.tsv`) for choice rules to be tried on.
/// Seeds and frames as [`calibration_candidates`].
#[test]
#[ignore = "a tuning bench for a cross-validated calibration choice; writes a table"]
fn cross_validated_choice() {
    use std::io::Write;
    let (seeds, wide, ns) = bench_selection();
    let path = std::env::var("SKYDOME_ORACLE_TSV").unwrap_or_else(|_| "/tmp/oracle_cv.tsv".into());
    let mut out = std::fs::File::create(&path).unwrap();
    for &n in &ns {
        for &seed in &seeds {
            let c = if wide {
                case_with_sun(seed, n, (0.0, 87.0))
            } else {
                case(seed, n)
            };
            let [sky, ground, sun] = regions(&c);
            let orc = oracle(&c);
            let eo = scale_and_rmse(&orc, &c.truth, &sky);
            let floor = rms3(eo);
            let orc_sun = median_offset(&orc, &c.truth, &sun, eo);
            let def = calibrate(&c.frames, c.circle, &CalibrateOptions::robust()).unwrap();
            let cov = calibrate(&c.frames, c.circle, &CalibrateOptions::covering()).unwrap();
            let mut jc = cov.response.curves().clone();
            for (ch, curve) in jc.iter_mut().enumerate() {
                let grid = &def.response.curves()[ch];
                let shift = curve[96] - grid[96];
                for z in 0..96 {
                    curve[z] = grid[z] + shift;
                }
            }
            let join = skydome::response::Response::from_curves(jc).unwrap();
            let val = held_out_draw(&c, &[&def.samples, &cov.samples]);
            let lt = &cov.log_times;
            let cands: [(&str, &skydome::response::Response, Weighting); 4] = [
                ("def", &def.response, Weighting::Noise),
                ("defhat", &def.response, Weighting::Hat),
                ("cov", &cov.response, Weighting::Noise),
                ("join", &join, Weighting::Noise),
            ];
            let folds = two_fold_residuals(&def, &cov);
            let mut flines = String::new();
            for (fk, name) in folds.iter().zip(["def", "cov", "join"]) {
                for (ch, r) in fk.iter().enumerate() {
                    flines += &format!("F\t{seed}\t{n}\t{name}\t{ch}\t{}\n", band_stats(r));
                }
            }
            let mut bline = format!("B\t{seed}\t{n}\t{floor:.6}\t{orc_sun:.4}\t{}", val.count());
            let mut clines = String::new();
            for (name, resp, w) in cands {
                let opts = MergeOptions {
                    weighting: w,
                    ..MergeOptions::default()
                };
                let img = merge(&c.frames, resp, &opts).unwrap().radiance;
                let e = scale_and_rmse(&img, &c.truth, &sky);
                bline += &format!(
                    "\t{name}:{:.5}:{:.5}:{:.4}",
                    rms3(e) / floor,
                    offset_rmse(&img, &c.truth, &ground, e),
                    median_offset(&img, &c.truth, &sun, e)
                );
                let g = per_channel_offsets(&img, &c.truth, &ground, e);
                let s = per_channel_offsets(&img, &c.truth, &sun, e);
                for ch in 0..3 {
                    clines += &format!(
                        "C\t{seed}\t{n}\t{name}\t{ch}\t{:.6}\t{:.6}\t{}\t{:.4}\t{}\t{:.4}\n",
                        e[ch].1, g[ch].0, g[ch].1, g[ch].2, s[ch].1, s[ch].2
                    );
                    if w == Weighting::Noise {
                        let curve = &resp.curves()[ch];
                        let h = skydome::response::held_out_residuals(&val, lt, curve, ch);
                        let i = skydome::response::held_out_residuals(&cov.samples, lt, curve, ch);
                        clines += &format!("H\t{seed}\t{n}\t{name}\t{ch}\t{}\n", band_stats(&h));
                        clines += &format!("I\t{seed}\t{n}\t{name}\t{ch}\t{}\n", band_stats(&i));
                    }
                }
            }
            println!("{bline}");
            writeln!(out, "{bline}").unwrap();
            write!(out, "{clines}").unwrap();
            write!(out, "{flines}").unwrap();
        }
    }
}

/// The true curves of `case`, gauged like a calibrated one (`g(128) = 0`).
pub fn true_curves(case: &Case) -> [Vec<f64>; 3] {
    [0, 1, 2].map(|c| {
        let g = case.opts.crf[c].g_with_black(case.opts.black_level);
        let g0 = g[128];
        g.iter().map(|v| v - g0).collect()
    })
}

/// The true noise model of `case` in the merge's terms.
pub fn true_noise(case: &Case) -> skydome::noise::NoiseModel {
    let o = &case.opts;
    skydome::noise::NoiseModel {
        channels: [0, 1, 2].map(|c| skydome::noise::ChannelNoise {
            electrons_at_gauge: o.full_well
                * o.crf[c].inverse((128.0 - o.black_level) / (255.0 - o.black_level)),
            read_noise: o.read_noise,
            code_noise: case.jpeg_noise[c],
        }),
    }
}

/// Diagnosis of one bracket's sky error (`SKYDOME_ORACLE_SEEDS`, first seed;
/// `SKYDOME_ORACLE_FRAMES`, first count; sun zenith 0–87°; docs/accuracy.md, "Eighth
/// round"): the sky's per-channel error for every pairing of a curve (true, covering, grid)
/// with the weights (the oracle's, the noise merge's with the fitted and with the true noise
/// model, with a model fitted on the true curve and on the curve smoothed over ±8 codes, the
/// hat); where in the sky the error sits (by the longest frame reading it below code 230 and
/// by radiance); each curve against the true one code by code with the covering samples'
/// observations and residuals; and, with `SKYDOME_DIAG_REFITS` (e.g. `"lo=32;lambda=1000"`:
/// observations below code 32 dropped; λ 1000), the covering samples refitted. Release, a
/// second per bracket: `SKYDOME_ORACLE_SEEDS=9107 SKYDOME_ORACLE_FRAMES=8 cargo test --release
/// -p skydome --test lib -- --ignored --exact oracle::bracket_diagnosis --nocapture`.
#[test]
#[ignore = "a diagnosis; prints only"]
fn bracket_diagnosis() {
    let seed: u64 = std::env::var("SKYDOME_ORACLE_SEEDS")
        .ok()
        .and_then(|s| s.split(',').next().and_then(|v| v.trim().parse().ok()))
        .unwrap_or(9107);
    let n: usize = std::env::var("SKYDOME_ORACLE_FRAMES")
        .ok()
        .and_then(|s| s.split(',').next().and_then(|v| v.trim().parse().ok()))
        .unwrap_or(8);
    let c = case_with_sun(seed, n, (0.0, 87.0));
    println!("{}", c.label);
    println!(
        "  crf {:?}, jpeg noise {:?}, evs {:?}",
        c.opts.crf, c.jpeg_noise, c.opts.evs
    );
    let [sky, ground, _] = regions(&c);
    let truth = true_curves(&c);
    let mut cands: Vec<(String, CalibrateOptions)> = vec![
        ("covering".into(), CalibrateOptions::covering()),
        ("grid".into(), CalibrateOptions::robust()),
    ];
    cands.extend(candidates().into_iter().skip(1));
    let cals: Vec<_> = cands
        .iter()
        .map(|(_, o)| calibrate(&c.frames, c.circle, o).unwrap())
        .collect();
    let mut curves: Vec<(String, [Vec<f64>; 3])> = vec![("true".into(), truth.clone())];
    for ((name, _), cal) in cands.iter().zip(&cals) {
        curves.push((name.clone(), cal.response.curves().clone()));
    }
    let orc = oracle(&c);
    let eo = scale_and_rmse(&orc, &c.truth, &sky);
    let floor = rms3(eo);
    let tn = true_noise(&c);
    println!("  true noise {:?}", tn.channels);
    let mut kept: Vec<(String, HdrImage)> = Vec::new();
    let show = |name: &str, img: &HdrImage| {
        let e = scale_and_rmse(img, &c.truth, &sky);
        println!(
            "  {name:>28}: sky {:.4} ({:.3}×) per channel {:.4} {:.4} {:.4} | ground {:.3}",
            rms3(e),
            rms3(e) / floor,
            e[0].1,
            e[1].1,
            e[2].1,
            offset_rmse(img, &c.truth, &ground, e)
        );
    };
    show("oracle", &orc);
    for (name, g) in &curves {
        let resp = skydome::response::Response::from_curves(g.clone()).unwrap();
        let img = oracle_with(&c, Some(g));
        show(&format!("{name} + oracle weights"), &img);
        let fitted = merge(&c.frames, &resp, &MergeOptions::default()).unwrap();
        if name == "true" || name == "covering" {
            println!(
                "    fitted noise: {:?}",
                fitted.noise.as_ref().map(|n| n.model.channels)
            );
        }
        show(&format!("{name} + noise (fitted)"), &fitted.radiance);
        let tm = MergeOptions {
            noise: Some(tn),
            ..MergeOptions::default()
        };
        let img = merge(&c.frames, &resp, &tm).unwrap().radiance;
        show(&format!("{name} + noise (true model)"), &img);
        // The noise model fitted on the true curve, and on this curve smoothed (a moving mean
        // over ±8 codes), each merged with this curve.
        let true_resp = skydome::response::Response::from_curves(truth.clone()).unwrap();
        // (A moving mean of a non-decreasing curve is one, but its sums can round a flat toe
        // one ulp down: the running maximum keeps it a response.)
        let smooth = g.clone().map(|cv| {
            let mut top = f64::NEG_INFINITY;
            (0..256)
                .map(|z: usize| {
                    let (a, b) = (z.saturating_sub(8), (z + 8).min(255));
                    top = top.max(cv[a..=b].iter().sum::<f64>() / (b - a + 1) as f64);
                    top
                })
                .collect::<Vec<f64>>()
        });
        let smooth_resp = skydome::response::Response::from_curves(smooth).unwrap();
        for (what, r) in [("true", &true_resp), ("smoothed", &smooth_resp)] {
            let est = skydome::noise::estimate(&c.frames, r, 0, None);
            let mo = MergeOptions {
                noise: Some(est.model),
                ..MergeOptions::default()
            };
            let img = merge(&c.frames, &resp, &mo).unwrap().radiance;
            show(&format!("{name} + noise (fit on {what})"), &img);
        }
        let hm = MergeOptions {
            weighting: Weighting::Hat,
            ..MergeOptions::default()
        };
        let img = merge(&c.frames, &resp, &hm).unwrap().radiance;
        show(&format!("{name} + hat"), &img);
        kept.push((name.clone(), fitted.radiance));
    }
    // Where the sky's error sits: by the longest frame that reads the pixel below code 230 in
    // green (the frame the oracle trusts most), and by radiance (log2 of the truth, green).
    let best = |p: usize| {
        (0..n)
            .rev()
            .find(|&j| match &c.frames[j].pixels {
                Pixels::U8(v) => v[3 * p + 1] < 230,
                Pixels::U16(v) => v[3 * p + 1] < 230 * 257,
            })
            .unwrap_or(0)
    };
    let mut imgs: Vec<(&str, &HdrImage)> = vec![("oracle", &orc)];
    for (name, img) in &kept {
        imgs.push((name.as_str(), img));
    }
    let scales: Vec<[(f64, f64); 3]> = imgs
        .iter()
        .map(|(_, img)| scale_and_rmse(img, &c.truth, &sky))
        .collect();
    let total = sky.iter().filter(|&&m| m).count() as f64;
    for (title, key) in [("best frame", 0usize), ("log2 radiance", 1)] {
        println!("  sky by {title}: pixels, then per merge sum of squares / all sky pixels (stops²) and mean offset");
        let group = |p: usize| -> i64 {
            if key == 0 {
                best(p) as i64
            } else {
                (c.truth.data[3 * p + 1] as f64).log2().floor() as i64
            }
        };
        let mut keys: Vec<i64> = (0..sky.len()).filter(|&p| sky[p]).map(group).collect();
        keys.sort();
        keys.dedup();
        for k in keys {
            let mask: Vec<bool> = (0..sky.len()).map(|p| sky[p] && group(p) == k).collect();
            let np = mask.iter().filter(|&&m| m).count();
            let cells: Vec<String> = imgs
                .iter()
                .zip(&scales)
                .map(|((name, img), sc)| {
                    let pc = per_channel_offsets(img, &c.truth, &mask, *sc);
                    let ss: f64 = pc.iter().map(|x| x.0).sum::<f64>() / 3.0;
                    let mean: f64 = pc.iter().map(|x| x.2).sum::<f64>() / 3.0;
                    format!("{name} {:.5} ({:+.3})", ss / total, mean)
                })
                .collect();
            println!("    {k:3}: {np:5} px | {}", cells.join(" | "));
        }
    }
    // The curves code by code (stops, after the offset over codes 64..=191), with the first
    // candidate's (covering's) observations and final residuals per code band.
    let cal = &cals[0];
    let s = &cal.samples;
    for ch in 0..3 {
        println!(
            "  channel {ch}: curve − true (stops) for {:?}; covering observations per 8 codes: count, median |r|, share beyond 5σ (σ = 1.4826 median |r|)",
            curves.iter().skip(1).map(|(n, _)| n).collect::<Vec<_>>()
        );
        let offs: Vec<f64> = curves
            .iter()
            .map(|(_, g)| (64..192).map(|z| g[ch][z] - truth[ch][z]).sum::<f64>() / 128.0)
            .collect();
        let g = &cal.response.curves()[ch];
        let e = &cal.log_irradiance[ch];
        let mut bands: Vec<Vec<f64>> = vec![Vec::new(); 32];
        let mut by_frame: Vec<Vec<usize>> = vec![vec![0; n]; 32];
        for (i, ei) in e.iter().enumerate().take(s.count()) {
            for (j, lt) in cal.log_times.iter().enumerate() {
                let z = s.z(i, j, ch);
                if !(1.0..=254.0).contains(&z) {
                    continue;
                }
                let z0 = (z.floor() as usize).min(254);
                let f = (z - z0 as f32) as f64;
                let gz = g[z0] * (1.0 - f) + g[z0 + 1] * f;
                bands[z0 / 8].push(gz - ei - lt);
                by_frame[z0 / 8][j] += 1;
            }
        }
        for z in (0..256).step_by(8) {
            let errs: Vec<String> = curves
                .iter()
                .zip(&offs)
                .skip(1)
                .map(|((_, g), off)| {
                    format!(
                        "{:+.3}",
                        (g[ch][z] - truth[ch][z] - off) / std::f64::consts::LN_2
                    )
                })
                .collect();
            let b = &mut bands[z / 8];
            let mut a: Vec<f64> = b.iter().map(|r| r.abs()).collect();
            a.sort_by(f64::total_cmp);
            let med = if a.is_empty() { 0.0 } else { a[a.len() / 2] };
            let mean = if b.is_empty() {
                0.0
            } else {
                b.iter().sum::<f64>() / b.len() as f64
            };
            let beyond = a.iter().filter(|&&r| r > 5.0 * 1.4826 * med).count();
            println!(
                "    z {z:3}: true {:+.2} | {} | {:4} obs, mean r {:+.3} med|r| {:.3}, {beyond} beyond; frames {:?}",
                truth[ch][z] / std::f64::consts::LN_2,
                errs.join(" "),
                b.len(),
                mean,
                med,
                by_frame[z / 8]
            );
        }
    }
    let fitted_lt: Vec<String> = cal.log_times.iter().map(|v| format!("{v:.3}")).collect();
    println!("  ln Δt {}", fitted_lt.join(" "));
    // Refits of the covering samples (`SKYDOME_DIAG_REFITS`, `;`-separated, each `,`-separated
    // `key=value`: `lo` / `hi` drop observations below / above a code, `lambda`, `cut`).
    let spec = std::env::var("SKYDOME_DIAG_REFITS").unwrap_or_default();
    for r in spec.split(';').filter(|r| !r.trim().is_empty()) {
        let mut o = CalibrateOptions::covering();
        let mut s2 = cal.samples.clone();
        let (mut lo, mut hi) = (0f32, 255f32);
        for kv in r.split(',') {
            let (k, v) = kv.split_once('=').expect("key=value");
            let f: f64 = v.trim().parse().expect("number");
            match k.trim() {
                "lo" => lo = f as f32,
                "hi" => hi = f as f32,
                "lambda" => o.lambda = f,
                "cut" => o.outlier_sigmas = f,
                other => panic!("unknown key {other}"),
            }
        }
        for v in s2.values.iter_mut() {
            for z in v.iter_mut() {
                if *z < lo || *z > hi {
                    *z = 0.0;
                }
            }
        }
        let refit = skydome::response::calibrate_samples_with(s2, &cal.log_times, &o).unwrap();
        let g = refit.response.curves().clone();
        let img = merge(&c.frames, &refit.response, &MergeOptions::default())
            .unwrap()
            .radiance;
        let e = scale_and_rmse(&img, &c.truth, &sky);
        let eo2 = scale_and_rmse(&oracle_with(&c, Some(&g)), &c.truth, &sky);
        let ce = curve_error(&c, &g);
        println!(
            "  refit {r:>24}: sky {:.3}× (oracle weights {:.3}×) ground {:.3} | curve toe {:.3} mid {:.3} top {:.3}",
            rms3(e) / floor,
            rms3(eo2) / floor,
            offset_rmse(&img, &c.truth, &ground, e),
            ce[0],
            ce[1],
            ce[2]
        );
        for ch in 0..3 {
            let off = (64..192).map(|z| g[ch][z] - truth[ch][z]).sum::<f64>() / 128.0;
            let row: Vec<String> = (24..256)
                .step_by(16)
                .map(|z| {
                    format!(
                        "{:+.2}",
                        (g[ch][z] - truth[ch][z] - off) / std::f64::consts::LN_2
                    )
                })
                .collect();
            println!("      ch {ch} z 24,40..: {}", row.join(" "));
        }
    }
}

/// What the step-periodic correction would take out of a wide-step bracket's curve and what
/// was there to take (docs/accuracy.md, "Twelfth round"): per channel, the RMS over codes
/// 24–254 of the harmonic [`skydome::response::periodic_harmonic`] fits at the bracket's step
/// `P` and at periods that are not the step's (`0.6 P`, `0.75 P`, `1.25 P`), on the covering
/// curve without the correction, on the true curve and on the curve's error (covering − truth), in ln.
/// `SKYDOME_ORACLE_SEEDS` and `SKYDOME_ORACLE_FRAMES` pick the brackets (the sun over every
/// height).
#[test]
#[ignore = "diagnosis: prints the step-periodic harmonics of chosen brackets"]
fn step_periodic_diagnosis() {
    use skydome::response::{periodic_harmonic, STEP_PERIODIC_LO};
    let (seeds, _, ns) = bench_selection();
    for &n in &ns {
        for &seed in &seeds {
            let c = case_with_sun(seed, n, (0.0, 87.0));
            let step_ev = mean_step_ev(&c.frames);
            let plain = CalibrateOptions {
                step_periodic: Some(false),
                ..CalibrateOptions::covering()
            };
            let cal = calibrate(&c.frames, c.circle, &plain).unwrap();
            let o = &c.opts;
            let p = step_ev * std::f64::consts::LN_2;
            let curves = cal.response.curves();
            let fixed = [0, 1, 2].map(|ch| {
                skydome::response::remove_step_periodic(&curves[ch], p, STEP_PERIODIC_LO)
            });
            let (e0, e1) = (curve_error(&c, curves), curve_error(&c, &fixed));
            println!(
                "{} (mean step {step_ev:.2} EV): curve error toe/middle/top, stops: {:.4} {:.4} {:.4} -> {:.4} {:.4} {:.4}",
                c.label, e0[0], e0[1], e0[2], e1[0], e1[1], e1[2]
            );
            for ch in 0..3 {
                let fit = cal.response.curve(ch).to_vec();
                let truth: Vec<f64> = (0..256)
                    .map(|z| {
                        o.crf[ch]
                            .inverse(
                                ((z as f64) - o.black_level).max(0.5) / (255.0 - o.black_level),
                            )
                            .ln()
                    })
                    .collect();
                let rms =
                    |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
                let amp = |curve: &[f64], period: f64| {
                    periodic_harmonic(curve, period, STEP_PERIODIC_LO)
                        .map_or(f64::NAN, |h| rms(&h[24..=254]))
                };
                let row = |curve: &[f64]| {
                    [1.0, 0.6, 0.75, 1.25]
                        .map(|k| format!("{:.4}", amp(curve, k * p)))
                        .join(" ")
                };
                // The harmonic the correction takes out against the truth's own.
                let (hf, ht) = (
                    periodic_harmonic(&fit, p, STEP_PERIODIC_LO).unwrap_or_default(),
                    periodic_harmonic(&truth, p, STEP_PERIODIC_LO).unwrap_or_default(),
                );
                let d: Vec<f64> = (24..=254.min(hf.len().min(ht.len()).saturating_sub(1)))
                    .map(|z| hf[z] - ht[z])
                    .collect();
                println!(
                    "  ch {ch}: fit [{}]  truth [{}]  taken-out minus truth's {:.4}",
                    row(&fit),
                    row(&truth),
                    rms(&d)
                );
            }
        }
    }
}

/// 16-bit lossless brackets (docs/accuracy.md, "Thirteenth round"): the noise fit reads their
/// own values and holds their code-domain noise at zero. Before, on values binned to 256 levels
/// with that term free, it fitted about 0.9 codes of code noise and 40–70× the true electrons,
/// and the default merge of these four brackets was 1.35–1.45× the oracle; now the green
/// channel's electrons are within a factor of 5 of the truth (1.06, 1.70, 1.09 and 4.5 times
/// it; 75× before on 9418) and the merge within 15 % of the oracle (1.015, 1.086, 1.021, 1.135
/// since the clipping test; 1.013, 1.082, 1.013, 1.137 before it).
/// An 8-bit JPEG bracket's code noise is still fitted.
#[test]
fn sixteen_bit_brackets_fit_no_code_noise_and_merge_near_the_oracle() {
    use skydome::noise::estimate;
    for (seed, n) in [(9418, 8), (9415, 5), (9417, 7), (9524, 7)] {
        let c = case_with_sun(seed, n, (0.0, 87.0));
        assert!(c.label.contains("16-bit, lossless"), "{}", c.label);
        let cal = calibrate(&c.frames, c.circle, &CalibrateOptions::default()).unwrap();
        let est = estimate(&c.frames, &cal.response, 0, None);
        assert!(
            est.model.channels.iter().all(|ch| ch.code_noise == 0.0),
            "{:?}",
            est.model
        );
        let (fit, truth) = (
            est.model.channels[1].electrons_at_gauge,
            true_noise(&c).channels[1].electrons_at_gauge,
        );
        println!("seed {seed}: green {fit:.0} e⁻ at code 128 (truth {truth:.0})");
        assert!(
            !est.from_prior.gain && (0.2..5.0).contains(&(fit / truth)),
            "seed {seed}: {fit} e⁻ against {truth}"
        );
        let (_, m) = measure_case(c);
        let ratio = default_sky(&m) / m.sky[0];
        println!(
            "seed {seed}, {n} frames: the default {ratio:.3}× the oracle ({:.4} stops)",
            m.sky[0]
        );
        assert!(
            ratio <= 1.15,
            "seed {seed}, {n} frames: {ratio:.3}× the oracle"
        );
    }
    let c = case_with_sun(9107, 8, (0.0, 87.0));
    assert!(c.label.contains("8-bit, JPEG"), "{}", c.label);
    let cal = calibrate(&c.frames, c.circle, &CalibrateOptions::default()).unwrap();
    let est = estimate(&c.frames, &cal.response, 0, None);
    assert!(est.model.channels.iter().any(|ch| ch.code_noise > 0.0));
}

/// Issue 27, fourteenth round: clipped observations do not pull the curve's top up. On
/// brackets drawn after the clipping test was chosen (seeds 9701–9724, sun 3–90° high; 6, 8 and
/// 9 frames) the default calibration's top (codes 240–254, after the offset over 64–191) is
/// within 0.1 stops of the true curve on every bracket and 0.025 on average per frame count.
/// Without the test it was 0.27 / 0.24 / 0.17 stops at worst (noisy JPEG brackets 2–3 EV apart,
/// whose bright sky is clipped in every longer frame), 0.033 / 0.047 / 0.033 on average.
#[test]
fn clipped_observations_do_not_pull_the_curves_top_up() {
    for n in [6, 8, 9] {
        let tops: Vec<(u64, f64)> = (9701..=9724)
            .map(|seed| {
                let c = case_with_sun(seed, n, (0.0, 87.0));
                let cal = calibrate(&c.frames, c.circle, &CalibrateOptions::default()).unwrap();
                (seed, curve_error(&c, cal.response.curves())[2])
            })
            .collect();
        let worst = tops
            .iter()
            .copied()
            .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        let mean = tops.iter().map(|t| t.1).sum::<f64>() / tops.len() as f64;
        println!(
            "{n} frames: curve top error mean {mean:.4} stops, worst {:.3} (seed {})",
            worst.1, worst.0
        );
        assert!(
            worst.1 < 0.1,
            "{n} frames: seed {} top {:.3} stops",
            worst.0,
            worst.1
        );
        assert!(mean < 0.025, "{n} frames: mean top {mean:.4} stops");
    }
}
