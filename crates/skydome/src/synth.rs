//! Synthetic fish-eye brackets with known answers, for tests, benchmarks and demos.
//!
//! [`generate`] renders a radiance map whose every value is known, photographs it with a
//! simulated camera whose response is known, and returns both:
//!
//! 1. **Scene** ([`scene`]): an equidistant fish-eye of a 235° lens (zenith angle
//!    `θ = 117.5° · r / R` inside the image circle of radius `R`, centred; black housing —
//!    radiance 0 — outside). Above the horizon a blue sky brightening towards the horizon and
//!    around the sun, fractal clouds (seeded value noise), and a sun disc of radius 2.5° with
//!    radiance 2¹¹ (far above what any default exposure holds); below the horizon dim ground
//!    (≈ 2⁻⁶) with darker "tree" silhouettes (≈ 2⁻⁸). About 19 stops inside the circle.
//!    Radiance is relative: a clear zenith is ≈ 0.5–1.
//! 2. **Sensor**: normalised exposure `X = L · Δt · k` with `k = 0.25 / base_time_s`
//!    (EV 0 puts the zenith sky at `X ≈ 0.2`), then photon shot noise (Gaussian with variance
//!    `X · full_well` electrons) and read noise (`read_noise` electrons r.m.s.), clipping to
//!    `[0, 1]`.
//! 3. **Response** ([`Crf`]): `I = f(X) = X^p (1 + s) / (X^p + s)` with `p = 1/γ` — a gamma
//!    curve with a soft shoulder, `f(0) = 0`, `f(1) = 1` — with different `(γ, s)` per channel;
//!    then 8-bit quantisation `Z = round(255 · I)` and optional JPEG compression (the `image`
//!    crate's encoder and decoder, 4:2:0 chroma).
//!
//! The true log-inverse response is `g(z) = ln f⁻¹(max(z, ½) / 255)` ([`Crf::g`]); a recovered
//! curve equals it up to an additive constant (the gauge), which comparisons remove.
//!
//! [`film_scan`] makes a different kind of bracket: a twin of the classic 16-frame film-scan
//! bracket (pedestal, scan artefact, little above the pedestal in the short frames).
//!
//! Everything random is drawn from [`SplitMix64`] with the given seed, so a seed always gives
//! the same bracket.

use crate::bracket::{Exposure, Frame, Pixels};
use crate::image::{Circle, HdrImage};
use crate::sampling::SplitMix64;

mod film_scan;
pub use film_scan::{
    film_pedestal, film_scan, FilmScanBracket, FilmScanFrame, FilmScanOptions, FILM_EXPONENT,
};

/// Errors from the generator.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A parameter is out of range.
    #[error("invalid synthetic bracket option: {0}")]
    BadOption(String),
    /// The JPEG round trip failed.
    #[error("JPEG round trip failed: {0} (try jpeg_quality = None)")]
    Jpeg(String),
}

/// A camera response `I = X^p (1 + s) / (X^p + s)`, `p = 1/γ`, mapping normalised exposure
/// `X ∈ [0, 1]` to normalised intensity `I ∈ [0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Crf {
    /// Gamma γ (> 0).
    pub gamma: f64,
    /// Shoulder `s` (> 0; smaller = stronger roll-off near white).
    pub shoulder: f64,
}

impl Crf {
    /// `f(X)`.
    pub fn forward(&self, x: f64) -> f64 {
        let xp = x.max(0.0).powf(1.0 / self.gamma);
        xp * (1.0 + self.shoulder) / (xp + self.shoulder)
    }

    /// `f⁻¹(I)` for `I ∈ [0, 1]`.
    pub fn inverse(&self, i: f64) -> f64 {
        let i = i.clamp(0.0, 1.0);
        (i * self.shoulder / (1.0 + self.shoulder - i)).powf(self.gamma)
    }

    /// The true `g(z) = ln f⁻¹(max(z, ½) / 255)` for the 256 codes.
    pub fn g(&self) -> Vec<f64> {
        self.g_with_black(0.0)
    }

    /// The true `g` when codes are `b + (255 − b) · f(X)` (a black level `b`):
    /// `g(z) = ln f⁻¹(max(z − b, ½) / (255 − b))`; flat at and below the black level, where a
    /// code says only "no more than this".
    pub fn g_with_black(&self, b: f64) -> Vec<f64> {
        (0..256)
            .map(|z| self.inverse((z as f64 - b).max(0.5) / (255.0 - b)).ln())
            .collect()
    }
}

/// Generator options.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SynthOptions {
    /// Width in pixels (16..=16384).
    pub width: usize,
    /// Height in pixels (16..=16384).
    pub height: usize,
    /// Exposure values of the frames relative to `base_time_s` (`Δt = base · 2^EV`); sorted
    /// ascending in the output.
    pub evs: Vec<f64>,
    /// Shutter time of EV 0, seconds.
    pub base_time_s: f64,
    /// Seed for clouds and noise.
    pub seed: u64,
    /// Render a fish-eye circle (black housing outside) instead of filling the frame.
    pub fisheye: bool,
    /// JPEG quality 1..=100, or `None` for lossless 8-bit frames.
    pub jpeg_quality: Option<u8>,
    /// Full-well capacity in electrons (> 0): `X = 1` collects this many.
    pub full_well: f64,
    /// Add photon shot noise (variance = electrons collected).
    pub shot_noise: bool,
    /// Read noise in electrons r.m.s.; 0 disables it.
    pub read_noise: f64,
    /// Per-channel responses (R, G, B).
    pub crf: [Crf; 3],
    /// Black level, 8-bit code (0..=64): codes are `b + (255 − b) · f(X)`, as a film scan or a
    /// camera that lifts its blacks gives. 0 = none (the default).
    #[serde(default)]
    pub black_level: f64,
}

impl Default for SynthOptions {
    /// The reference accuracy bracket of `docs/accuracy.md`: 512 × 512 fish-eye, EV −2, 0, +2
    /// around 1/250 s, seed 1, JPEG quality 97, a low-noise sensor (full well 400 000 e⁻, read
    /// noise 1 e⁻; a phone-like 4000 e⁻ / 3 e⁻ is far noisier), γ = 2.0 / 2.2 / 2.5 with
    /// shoulders 0.5 / 0.8 / 1.2.
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            evs: vec![-2.0, 0.0, 2.0],
            base_time_s: 1.0 / 250.0,
            seed: 1,
            fisheye: true,
            jpeg_quality: Some(97),
            full_well: 400_000.0,
            shot_noise: true,
            read_noise: 1.0,
            crf: [
                Crf {
                    gamma: 2.0,
                    shoulder: 0.5,
                },
                Crf {
                    gamma: 2.2,
                    shoulder: 0.8,
                },
                Crf {
                    gamma: 2.5,
                    shoulder: 1.2,
                },
            ],
            black_level: 0.0,
        }
    }
}

/// A generated bracket and its ground truth.
#[derive(Debug, Clone)]
pub struct SynthBracket {
    /// True radiance (relative units; 0 outside the circle).
    pub truth: HdrImage,
    /// The frames, shortest exposure first.
    pub frames: Vec<Frame>,
    /// The true `g` per channel ([`Crf::g`]), up to the gauge constant.
    pub true_g: [Vec<f64>; 3],
    /// The image circle, when `fisheye`.
    pub circle: Option<Circle>,
    /// `k` in `X = L · Δt · k`.
    pub exposure_scale: f64,
}

/// Radiance of the sun disc relative to the zenith sky.
pub const SUN_RADIANCE: f32 = 2048.0;

fn check(opts: &SynthOptions) -> Result<(), SynthError> {
    let bad = |m: String| Err(SynthError::BadOption(m));
    if !(16..=16384).contains(&opts.width) || !(16..=16384).contains(&opts.height) {
        return bad(format!(
            "size {}x{} (use 16..=16384 per side)",
            opts.width, opts.height
        ));
    }
    if opts.evs.is_empty()
        || opts.evs.len() > 32
        || opts.evs.iter().any(|e| !e.is_finite() || e.abs() > 20.0)
    {
        return bad("evs must hold 1..=32 finite values within ±20".into());
    }
    let mut e = opts.evs.clone();
    e.sort_by(f64::total_cmp);
    if e.windows(2).any(|w| w[1] - w[0] < 1e-6) {
        return bad("evs must be distinct".into());
    }
    if !(opts.base_time_s.is_finite() && opts.base_time_s > 0.0) {
        return bad(format!(
            "base_time_s = {} (use a positive time)",
            opts.base_time_s
        ));
    }
    if matches!(opts.jpeg_quality, Some(q) if q == 0 || q > 100) {
        return bad("jpeg_quality must be 1..=100".into());
    }
    let sensor_ok = opts.full_well.is_finite()
        && opts.full_well >= 1.0
        && opts.read_noise.is_finite()
        && opts.read_noise >= 0.0;
    if !sensor_ok {
        return bad(
            "full_well must be >= 1 electron and read_noise finite and non-negative".into(),
        );
    }
    for c in &opts.crf {
        if !(c.gamma.is_finite()
            && c.gamma > 0.05
            && c.gamma < 20.0
            && c.shoulder.is_finite()
            && c.shoulder > 0.0)
        {
            return bad(format!(
                "response {c:?} (use 0.05 < gamma < 20, shoulder > 0)"
            ));
        }
    }
    if !(opts.black_level.is_finite() && (0.0..=64.0).contains(&opts.black_level)) {
        return bad(format!(
            "black_level = {} (use 0..=64 codes)",
            opts.black_level
        ));
    }
    Ok(())
}

/// Renders the bracket. See the module docs for the model.
pub fn generate(opts: &SynthOptions) -> Result<SynthBracket, SynthError> {
    check(opts)?;
    let (w, h) = (opts.width, opts.height);
    let circle = opts.fisheye.then(|| Circle {
        cx: w as f64 / 2.0,
        cy: h as f64 / 2.0,
        r: 0.48 * w.min(h) as f64,
    });
    let truth = scene(w, h, opts.seed, circle);
    let frames = photograph(&truth, opts)?;
    Ok(SynthBracket {
        truth,
        frames,
        true_g: opts.crf.map(|c| c.g_with_black(opts.black_level)),
        circle,
        exposure_scale: 0.25 / opts.base_time_s,
    })
}

/// Photographs a radiance map `truth` with the simulated camera of `opts` (its size, exposures,
/// sensor noise, responses, black level and JPEG quality; `truth` replaces the built-in scene,
/// whose `width`/`height` are ignored): radiance `L` collects `X = L · Δt · k` of the full well,
/// `k = 0.25 / base_time_s`, so `L = 4` fills it at the base time. Scale `truth` first to
/// place the scene in the bracket. Frames come shortest exposure first.
pub fn photograph(truth: &HdrImage, opts: &SynthOptions) -> Result<Vec<Frame>, SynthError> {
    photograph_bits(truth, opts, false)
}

/// As [`photograph`], but 16-bit lossless frames: the code is `round(257 · (b + (255 − b) ·
/// f(X)))` on the 0..=65535 scale (a 16-bit value `257 · z` is the 8-bit code `z`). JPEG cannot
/// hold 16 bits, so `opts.jpeg_quality` must be `None`. The true `g` at a 16-bit value `v` is
/// `ln f⁻¹(max(v/257 − b, ½)/(255 − b))`.
pub fn photograph_16bit(truth: &HdrImage, opts: &SynthOptions) -> Result<Vec<Frame>, SynthError> {
    if opts.jpeg_quality.is_some() {
        return Err(SynthError::BadOption(
            "16-bit frames cannot be JPEG: set jpeg_quality = None".into(),
        ));
    }
    photograph_bits(truth, opts, true)
}

fn photograph_bits(
    truth: &HdrImage,
    opts: &SynthOptions,
    sixteen: bool,
) -> Result<Vec<Frame>, SynthError> {
    check(&SynthOptions {
        width: truth.width.clamp(16, 16384),
        height: truth.height.clamp(16, 16384),
        ..opts.clone()
    })?;
    let (w, h) = (truth.width, truth.height);
    let k = 0.25 / opts.base_time_s;
    let mut evs = opts.evs.clone();
    evs.sort_by(f64::total_cmp);
    let mut rng = SplitMix64::new(opts.seed ^ 0x5EED_0FC0_FFEE);
    let mut frames = Vec::with_capacity(evs.len());
    for ev in evs {
        let t = opts.base_time_s * ev.exp2();
        let gain = t * k;
        let mut codes = Vec::with_capacity(truth.data.len());
        let mut codes16 = Vec::with_capacity(if sixteen { truth.data.len() } else { 0 });
        for (i, &l) in truth.data.iter().enumerate() {
            let x = l as f64 * gain;
            let mut e = x * opts.full_well;
            let shot = if opts.shot_noise { e.max(0.0) } else { 0.0 };
            let var = shot + opts.read_noise * opts.read_noise;
            if var > 0.0 {
                e += var.sqrt() * rng.normal();
            }
            let xn = e / opts.full_well;
            let v = opts.crf[i % 3].forward(xn.clamp(0.0, 1.0));
            let b = opts.black_level;
            if sixteen {
                codes16.push((257.0 * (b + (255.0 - b) * v)).round().clamp(0.0, 65535.0) as u16);
            } else {
                codes.push((b + (255.0 - b) * v).round().clamp(0.0, 255.0) as u8);
            }
        }
        if sixteen {
            frames.push(Frame {
                name: format!("synth16_ev{ev:+}.png"),
                width: w,
                height: h,
                pixels: Pixels::U16(codes16),
                exposure: Exposure {
                    time_s: t,
                    iso: None,
                    f_number: None,
                },
            });
            continue;
        }
        let (codes, ext) = match opts.jpeg_quality {
            Some(q) => (jpeg_round_trip(&codes, w, h, q)?, "jpg"),
            None => (codes, "png"),
        };
        frames.push(Frame {
            name: format!("synth_ev{ev:+}.{ext}"),
            width: w,
            height: h,
            pixels: Pixels::U8(codes),
            exposure: Exposure {
                time_s: t,
                iso: None,
                f_number: None,
            },
        });
    }
    Ok(frames)
}

/// JPEG-encodes 8-bit RGB at quality `q` and decodes it again.
pub fn jpeg_round_trip(rgb: &[u8], w: usize, h: usize, q: u8) -> Result<Vec<u8>, SynthError> {
    let (wu, hu) = (
        u32::try_from(w).map_err(|e| SynthError::Jpeg(e.to_string()))?,
        u32::try_from(h).map_err(|e| SynthError::Jpeg(e.to_string()))?,
    );
    let mut buf = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, q)
        .encode(rgb, wu, hu, image::ExtendedColorType::Rgb8)
        .map_err(|e| SynthError::Jpeg(e.to_string()))?;
    let img = image::load_from_memory_with_format(&buf, image::ImageFormat::Jpeg)
        .map_err(|e| SynthError::Jpeg(e.to_string()))?;
    Ok(img.to_rgb8().into_raw())
}

/// Hash-based lattice value in `[0, 1)`.
fn lattice(seed: u64, x: i64, y: i64) -> f64 {
    let mut r = SplitMix64::new(
        seed ^ (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F),
    );
    r.next_f64()
}

/// Smooth value noise, 5 octaves, roughly in `[0, 1]`.
fn fbm(seed: u64, x: f64, y: f64) -> f64 {
    let (mut sum, mut amp, mut freq, mut norm) = (0.0, 1.0, 1.0, 0.0);
    for o in 0..5u64 {
        let (px, py) = (x * freq, y * freq);
        let (x0, y0) = (px.floor(), py.floor());
        let (fx, fy) = (px - x0, py - y0);
        let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
        let s = seed.wrapping_add(o * 7919);
        let (xi, yi) = (x0 as i64, y0 as i64);
        let a = lattice(s, xi, yi);
        let b = lattice(s, xi + 1, yi);
        let c = lattice(s, xi, yi + 1);
        let d = lattice(s, xi + 1, yi + 1);
        let v = a + (b - a) * sx + (c - a) * sy + (a - b - c + d) * sx * sy;
        sum += amp * v;
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

/// The true radiance map (see the module docs). With `circle = None` the projection still uses
/// the frame's inscribed circle, but every pixel is scene: the corners, beyond 117.5°, are ground.
pub fn scene(width: usize, height: usize, seed: u64, circle: Option<Circle>) -> HdrImage {
    scene_with_sun(width, height, seed, circle, 45.0, 2.3)
}

/// As [`scene`] with the sun's disc centred at zenith angle `sun_zenith_deg` (degrees, 0 =
/// image centre) and image angle `sun_angle_rad` (radians, measured from the +x axis towards
/// +y, pixel origin top-left). [`scene`] uses 45° and 2.3 rad.
pub fn scene_with_sun(
    width: usize,
    height: usize,
    seed: u64,
    circle: Option<Circle>,
    sun_zenith_deg: f64,
    sun_angle_rad: f64,
) -> HdrImage {
    let mut img = HdrImage::new(width, height);
    let c = circle.unwrap_or(Circle {
        cx: width as f64 / 2.0,
        cy: height as f64 / 2.0,
        r: 0.5 * width.min(height) as f64,
    });
    let deg = std::f64::consts::PI / 180.0;
    let max_theta = 117.5 * deg;
    let (sun_theta, sun_phi) = (sun_zenith_deg * deg, sun_angle_rad);
    let sun = [
        sun_theta.sin() * sun_phi.cos(),
        sun_theta.sin() * sun_phi.sin(),
        sun_theta.cos(),
    ];
    let sun_r = 2.5 * deg;
    for y in 0..height {
        for x in 0..width {
            if circle.is_some() && !c.contains_pixel(x, y) {
                continue;
            }
            let dx = (x as f64 + 0.5 - c.cx) / c.r;
            let dy = (y as f64 + 0.5 - c.cy) / c.r;
            let rho = (dx * dx + dy * dy).sqrt();
            let theta = rho * max_theta;
            let phi = dy.atan2(dx);
            let dir = [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ];
            let cos_g = (dir[0] * sun[0] + dir[1] * sun[1] + dir[2] * sun[2]).clamp(-1.0, 1.0);
            let gamma = cos_g.acos();
            let rgb: [f64; 3] = if theta > 90.0 * deg {
                // Ground: dim, with tree silhouettes along some azimuths near the horizon.
                let trees = fbm(seed ^ 0x7EE5, phi * 3.0 + 10.0, 0.5) > 0.55 && theta < 100.0 * deg;
                let base = if trees { 0.004 } else { 0.016 };
                let tex = 0.7 + 0.6 * fbm(seed ^ 0x6404, dx * 20.0 + 5.0, dy * 20.0 + 5.0);
                [base * tex * 1.1, base * tex, base * tex * 0.8]
            } else if gamma < sun_r {
                [SUN_RADIANCE as f64; 3]
            } else {
                let horizon = 1.0 + 1.5 * (theta / (90.0 * deg)).powi(4);
                let aureole = 1.0 + 8.0 * (-gamma / (6.0 * deg)).exp() + 0.5 * cos_g * cos_g;
                let l = 0.5 * horizon * aureole;
                let white = ((theta / (90.0 * deg)).powi(3) * 0.6).min(0.6);
                let sky = [l * (0.45 + white), l * (0.7 + white * 0.5), l * 1.0];
                let n = fbm(seed, dx * 3.0 + 20.0, dy * 3.0 + 20.0);
                let cover = ((n - 0.52) / 0.08).clamp(0.0, 1.0);
                if cover > 0.0 {
                    let shade = 0.6 + 2.4 * fbm(seed ^ 0xC10D, dx * 8.0, dy * 8.0);
                    let cl = 1.6 * shade * (1.0 + 3.0 * (-gamma / (15.0 * deg)).exp());
                    [
                        sky[0] * (1.0 - cover) + cl * cover,
                        sky[1] * (1.0 - cover) + cl * cover,
                        sky[2] * (1.0 - cover) + cl * 1.05 * cover,
                    ]
                } else {
                    sky
                }
            };
            img.set_pixel(x, y, [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32]);
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crf_inverse_undoes_forward() {
        let c = Crf {
            gamma: 2.2,
            shoulder: 0.8,
        };
        for x in [0.0, 1e-4, 0.01, 0.3, 0.99, 1.0] {
            assert!((c.inverse(c.forward(x)) - x).abs() < 1e-12 * (1.0 + x));
        }
        assert!((c.forward(1.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn absurd_options_are_errors() {
        let o = SynthOptions {
            width: 0,
            ..Default::default()
        };
        assert!(generate(&o).is_err());
        let o = SynthOptions {
            evs: vec![0.0, 0.0],
            ..Default::default()
        };
        assert!(generate(&o).is_err());
    }
}

// ---------------------------------------------------------------------------------------------
// RAW (DNG) brackets
// ---------------------------------------------------------------------------------------------

/// XYZ → linear sRGB (D65): as a DNG `ColorMatrix` (illuminant D65) it makes camera RGB equal
/// Rec.709, so a synthetic RAW bracket's truth compares directly with the merged radiance.
pub const XYZ_TO_REC709: [f64; 9] = [
    3.240_454_2,
    -1.537_138_5,
    -0.498_531_4,
    -0.969_266_0,
    1.876_010_8,
    0.041_556_0,
    0.055_643_4,
    -0.204_025_9,
    1.057_225_2,
];

/// The camera of [`raw_bracket`]: a Bayer sensor written as uncompressed DNG.
#[derive(Debug, Clone, PartialEq)]
pub struct RawSynthOptions {
    /// Exposure offsets in stops (EV) from `base_time_s`, any order; frames come shortest first.
    pub evs: Vec<f64>,
    /// Shutter time at EV 0, seconds.
    pub base_time_s: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Electrons at the white level.
    pub full_well: f64,
    /// Read noise, electrons r.m.s.
    pub read_noise: f64,
    /// Black and white level, raw units (white ≤ 65535).
    pub black: u16,
    /// White level.
    pub white: u16,
    /// The 2 × 2 CFA pattern (0 R, 1 G, 2 B), row-major.
    pub cfa: [u8; 4],
    /// `ColorMatrix1` (XYZ → camera, illuminant D65), `None` to write none.
    pub colour_matrix: Option<[f64; 9]>,
    /// `AsShotNeutral`, `None` to write none.
    pub neutral: Option<[f64; 3]>,
    /// ISO and f-number written to EXIF.
    pub iso: u16,
    /// f-number.
    pub f_number: f64,
}

impl Default for RawSynthOptions {
    /// A phone-like sensor: EV −2, 0, +2 around 1/250 s, 6000 e⁻ at white, 3 e⁻ read noise,
    /// 10-bit-like levels in a 12-bit range (black 256, white 4095), RGGB, camera RGB =
    /// Rec.709 ([`XYZ_TO_REC709`]), neutral white balance, ISO 100, f/1.8.
    fn default() -> Self {
        Self {
            evs: vec![-2.0, 0.0, 2.0],
            base_time_s: 1.0 / 250.0,
            seed: 1,
            full_well: 6000.0,
            read_noise: 3.0,
            black: 256,
            white: 4095,
            cfa: [0, 1, 1, 2],
            colour_matrix: Some(XYZ_TO_REC709),
            neutral: Some([1.0, 1.0, 1.0]),
            iso: 100,
            f_number: 1.8,
        }
    }
}

/// Photographs `truth` (camera RGB radiance, relative units) with a simulated Bayer sensor and
/// writes each frame as an uncompressed DNG (the `tiff` crate writes the tags). Radiance `L`
/// gives the raw value `v = L · Δt · k`, `k = 0.25 / base_time_s` (1 = white), with Gaussian
/// photon shot noise (variance = electrons) and read noise, quantised to integer raw units
/// and clipped at the white level. Returns `(file name, DNG bytes)`, shortest exposure first.
pub fn raw_bracket(
    truth: &HdrImage,
    opts: &RawSynthOptions,
) -> Result<Vec<(String, Vec<u8>)>, SynthError> {
    let (w, h) = (truth.width, truth.height);
    if w < 4 || h < 4 || opts.white <= opts.black || opts.evs.is_empty() {
        return Err(SynthError::BadOption(
            "RAW bracket needs at least 4 × 4 pixels, one EV and white above black".into(),
        ));
    }
    let k = 0.25 / opts.base_time_s;
    let mut evs = opts.evs.clone();
    evs.sort_by(f64::total_cmp);
    let mut rng = SplitMix64::new(opts.seed ^ 0x0DA7_A5EE_D0F0_0D00);
    let range = f64::from(opts.white - opts.black);
    let mut out = Vec::with_capacity(evs.len());
    for ev in evs {
        let t = opts.base_time_s * ev.exp2();
        let mut raw = vec![0u16; w * h];
        for y in 0..h {
            for x in 0..w {
                let c = usize::from(opts.cfa[(y & 1) * 2 + (x & 1)]);
                let l = f64::from(truth.data[3 * (y * w + x) + c]).max(0.0);
                let e = l * t * k * opts.full_well;
                let sd = (e + opts.read_noise * opts.read_noise).sqrt();
                let v = (e + sd * rng.normal()) / opts.full_well;
                let r = (f64::from(opts.black) + v * range).round();
                raw[y * w + x] = r.clamp(0.0, f64::from(opts.white)) as u16;
            }
        }
        let bytes = encode_dng(&raw, w, h, opts, t).map_err(SynthError::BadOption)?;
        out.push((format!("raw_ev{ev:+}.dng"), bytes));
    }
    Ok(out)
}

/// One CFA frame as an uncompressed 16-bit DNG with its exposure in an EXIF IFD.
fn encode_dng(
    raw: &[u16],
    w: usize,
    h: usize,
    opts: &RawSynthOptions,
    time_s: f64,
) -> Result<Vec<u8>, String> {
    use tiff::encoder::{colortype::Gray16, Rational, SRational, TiffEncoder};
    use tiff::tags::Tag;
    let err = |e: tiff::TiffError| format!("writing the DNG: {e}");
    let rational = |v: f64| Rational {
        n: (v * 1_000_000.0).round() as u32,
        d: 1_000_000,
    };
    let mut buf = std::io::Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut buf).map_err(err)?;
        let exif = {
            let mut d = enc.extra_directory().map_err(err)?;
            d.write_tag(Tag::Unknown(33434), rational(time_s))
                .map_err(err)?;
            d.write_tag(Tag::Unknown(33437), rational(opts.f_number))
                .map_err(err)?;
            d.write_tag(Tag::Unknown(34855), opts.iso).map_err(err)?;
            d.finish_with_offsets().map_err(err)?.offset
        };
        let mut img = enc.new_image::<Gray16>(w as u32, h as u32).map_err(err)?;
        let e = img.encoder();
        e.write_tag(Tag::PhotometricInterpretation, 32803u16)
            .map_err(err)?;
        e.write_tag(Tag::Unknown(50706), &[1u8, 4, 0, 0][..])
            .map_err(err)?;
        e.write_tag(Tag::Unknown(33421), &[2u16, 2][..])
            .map_err(err)?;
        e.write_tag(Tag::Unknown(33422), &opts.cfa[..])
            .map_err(err)?;
        e.write_tag(Tag::Unknown(50714), opts.black).map_err(err)?;
        e.write_tag(Tag::Unknown(50717), opts.white).map_err(err)?;
        if let Some(m) = opts.colour_matrix {
            let m: Vec<SRational> = m
                .iter()
                .map(|v| SRational {
                    n: (v * 10_000.0).round() as i32,
                    d: 10_000,
                })
                .collect();
            e.write_tag(Tag::Unknown(50721), &m[..]).map_err(err)?;
            e.write_tag(Tag::Unknown(50778), 21u16).map_err(err)?;
        }
        if let Some(n) = opts.neutral {
            let n: Vec<Rational> = n.iter().map(|&v| rational(v)).collect();
            e.write_tag(Tag::Unknown(50728), &n[..]).map_err(err)?;
        }
        e.write_tag(Tag::ExifDirectory, exif).map_err(err)?;
        img.write_data(raw).map_err(err)?;
    }
    Ok(buf.into_inner())
}
