//! The camera profile: what calibrating one camera found — its response curves
//! ([`crate::response`]), its noise model ([`crate::noise`]) and the merge weighting it suggests
//! ([`crate::merge`]) — made once per device and reused by every merge, stored as JSON by
//! [`CameraProfile::to_json`] and read back (validated) by [`CameraProfile::from_json`].
//!
//! It sits above the response, noise and merge modules because it holds a piece of each (see
//! the layer table in the crate documentation).

use crate::bracket::Frame;
use crate::merge::Weighting;
use crate::noise::{self, FromPrior, NoiseEstimate, NoiseModel};
use crate::response::{Calibration, Response, ResponseError};

/// Current [`CameraProfile`] format version (defined beside [`ResponseError::Version`], which
/// names it).
pub use crate::response::PROFILE_VERSION;

/// A camera response stored as JSON.
///
/// ```json
/// { "version": 1, "linear": false,
///   "g": [[…256 values, R…], […G…], […B…]],
///   "lambda": 10.0, "weighting": "hat", "samples": 128, "seed": 0,
///   "make": "Canon", "model": "EOS 5D Mark II", "iso": 100.0, "date": "2024-05-01" }
/// ```
/// - `version`: format version, currently 1; readers reject others.
/// - `linear`: true for a known-linear response (then `g` is [`Response::linear`]'s).
/// - `g`: per channel (R, G, B), 256 natural-log values `g(z) = ln exposure`, non-decreasing,
///   `g(128) = 0` for calibrated curves.
/// - `lambda`, `weighting`, `samples` (used), `seed`: how it was made.
/// - `make`, `model`, `iso`, `date`: where it came from (free text; `date` as the CLI writes it).
/// - `absolute` (optional, see [`AbsoluteConstant`]): the camera's absolute constant, which
///   makes every later merge with this profile absolute from EXIF exposure data alone.
/// - `noise` (optional, see [`NoiseModel`]) and `noise_from_prior` (optional, see
///   [`FromPrior`]): the noise model a merge with this profile uses instead of fitting one to
///   its frames, and which of its parameters the calibration bracket could not measure.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraProfile {
    /// Format version ([`PROFILE_VERSION`]).
    pub version: u32,
    /// Known-linear response.
    #[serde(default)]
    pub linear: bool,
    /// Curves R, G, B (256 values each, natural log).
    pub g: [Vec<f64>; 3],
    /// Smoothness weight used.
    pub lambda: f64,
    /// Merge weighting recommended with this profile.
    pub weighting: Weighting,
    /// Samples used.
    pub samples: usize,
    /// Sampling seed.
    pub seed: u64,
    /// Camera make.
    pub make: Option<String>,
    /// Camera model.
    pub model: Option<String>,
    /// ISO speed of the calibration bracket.
    pub iso: Option<f64>,
    /// Calibration date.
    pub date: Option<String>,
    /// The camera's noise model (see [`crate::noise`]) for [`Weighting::Noise`], when known.
    /// Optional: profiles written before it existed load without it, and the merge then
    /// estimates it from the bracket.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<Box<NoiseModel>>,
    /// Which parameters of [`noise`](Self::noise) are the prior's ([`NoiseModel::default`]),
    /// because the bracket it was fitted on could not measure them (on real JPEG brackets
    /// typically the white balance). Optional: absent, every parameter counts as measured
    /// (profiles written before it existed stored a model only when it was fully fitted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_from_prior: Option<FromPrior>,
    /// The camera's absolute constant, when it was measured (a meter reading) or estimated
    /// (the reflected-light meter equation). Optional: profiles without it load as before and
    /// their merges stay relative.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absolute: Option<AbsoluteConstant>,
}

/// How a camera's [`AbsoluteConstant`] was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AbsoluteFrom {
    /// A horizontal illuminance reading beside the camera (lux).
    Illuminance,
    /// A spot luminance reading (cd/m²).
    Luminance,
    /// The reflected-light meter equation `L = K·N²/(t·S)` with `K` =
    /// [`METER_CONSTANT_K`] (no meter; ±[`METER_EQUATION_UNCERTAINTY_PERCENT`] %).
    Exif,
}

crate::named_enum!(AbsoluteFrom, "absolute constant source", [
    Illuminance => "illuminance",
    Luminance => "luminance",
    Exif => "exif"
]);

/// The reflected-light meter calibration constant `K` of ISO 2720, cd·s/m² per ISO: a meter
/// reading luminance `L` sets `t·S/N² = K/L`, which a camera renders as mid-grey.
pub const METER_CONSTANT_K: f64 = 12.5;

/// The uncertainty, percent, of a constant estimated from [`METER_CONSTANT_K`]: cameras place
/// mid-grey differently (K from 10.6 to 13.4 between makers, exposure compensation in the tone
/// curve, ISO ratings within ⅓ stop).
pub const METER_EQUATION_UNCERTAINTY_PERCENT: f64 = 30.0;

/// The 8-bit code a camera's JPEG gives mid-grey: 118, where ISO 12232's standard output
/// sensitivity puts an 18 % grey (0.461 of full scale in sRGB).
pub const MID_GREY_CODE: u8 = 118;

/// The camera's absolute constant: Radiance radiance (W·sr⁻¹·m⁻², Radiance's RGB; luminance =
/// 179 × (0.265 R + 0.670 G + 0.065 B) cd/m²) per unit of the merge's relative radiance, the
/// merge having divided every frame by its relative exposure `t·(ISO/100)/N²` (time in s, ISO
/// speed, f-number, from EXIF). It belongs to this profile's response curves: the merge's
/// relative radiance is defined by them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AbsoluteConstant {
    /// W·sr⁻¹·m⁻² per unit of relative radiance at `t·(ISO/100)/N²` = 1 s (finite, > 0).
    pub radiance_per_unit: f64,
    /// How it was found.
    pub from: AbsoluteFrom,
    /// Its stated uncertainty, percent, when it is an estimate (the meter equation's 30).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty_percent: Option<f64>,
    /// The capture it was found on (EXIF DateTimeOriginal), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub date: Option<String>,
}

impl AbsoluteConstant {
    /// The constant the reflected-light meter equation gives a camera of response `response`:
    /// a frame at `t`, ISO `S`, f-number `N` renders the luminance `K·N²/(t·S)` as
    /// [`MID_GREY_CODE`] in every channel, so its relative radiance there is
    /// `exp g(118) / (t·S/100/N²)` and the constant is `(K/100) / (179 · Y(exp g(118)))`,
    /// whatever the frame's settings. `None` when the curve gives no positive luminance.
    pub fn from_meter_equation(response: &Response) -> Option<Self> {
        let z = MID_GREY_CODE as usize;
        let rgb = [0, 1, 2].map(|c| response.curve(c)[z].exp());
        let y = crate::image::radiance_luminance(rgb);
        let k = METER_CONSTANT_K / 100.0 / y;
        (k.is_finite() && k > 0.0).then_some(Self {
            radiance_per_unit: k,
            from: AbsoluteFrom::Exif,
            uncertainty_percent: Some(METER_EQUATION_UNCERTAINTY_PERCENT),
            date: None,
        })
    }
}

impl CameraProfile {
    /// A profile for a known-linear response.
    pub fn linear() -> Self {
        Self {
            version: PROFILE_VERSION,
            linear: true,
            g: Response::linear().curves().clone(),
            lambda: 0.0,
            weighting: Weighting::Hat,
            samples: 0,
            seed: 0,
            make: None,
            model: None,
            iso: None,
            date: None,
            noise: None,
            noise_from_prior: None,
            absolute: None,
        }
    }

    /// The profile of a calibration (camera fields empty: [`crate::pipeline::describe_camera`]
    /// fills them from EXIF; no noise model: the merge estimates it).
    pub fn from_calibration(cal: &Calibration) -> Self {
        Self {
            version: PROFILE_VERSION,
            linear: false,
            g: cal.response.curves().clone(),
            lambda: cal.lambda,
            weighting: Weighting::Hat,
            samples: cal.report().used,
            seed: cal.report().seed,
            make: None,
            model: None,
            iso: None,
            date: None,
            noise: None,
            noise_from_prior: None,
            absolute: None,
        }
    }

    /// Pretty-printed JSON.
    pub fn to_json(&self) -> String {
        // Serialising plain numbers and strings cannot fail; non-finite values (which JSON
        // cannot hold) become null and are rejected by `from_json`.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Parses and validates a profile (version, lengths, finiteness, monotonicity).
    pub fn from_json(s: &str) -> Result<Self, ResponseError> {
        // Read the version first so an old/new file gets the version message, not a field error.
        let v: serde_json::Value =
            serde_json::from_str(s).map_err(|e| ResponseError::Json(e.to_string()))?;
        let found = v.get("version").and_then(|x| x.as_u64());
        match found {
            Some(n) if n == PROFILE_VERSION as u64 => {}
            Some(n) => {
                return Err(ResponseError::Version {
                    found: n.min(u32::MAX as u64) as u32,
                })
            }
            None => return Err(ResponseError::Json("missing \"version\" field".into())),
        }
        let p: CameraProfile =
            serde_json::from_value(v).map_err(|e| ResponseError::Json(e.to_string()))?;
        p.response()?;
        if !(p.lambda.is_finite() && p.lambda >= 0.0) {
            return Err(ResponseError::BadOption(format!(
                "profile lambda {} is not a non-negative number",
                p.lambda
            )));
        }
        if let Some(a) = &p.absolute {
            let k = a.radiance_per_unit;
            if !(k.is_finite() && k > 0.0) {
                return Err(ResponseError::BadOption(format!(
                    "profile absolute constant {k} is not a positive number"
                )));
            }
        }
        Ok(p)
    }

    /// Stores the noise model of `est` (a fit from the frames, [`noise::estimate`]) with what
    /// came from the prior, so that merges with this profile use it and do not fit their own
    /// ([`Weighting::Noise`], the consistency test, the standard error). A fit that measured
    /// nothing (every parameter the prior's: too few pixels well exposed in two frames) is not
    /// stored: a merge then fits its own bracket, which may show more.
    pub fn set_noise(&mut self, est: &NoiseEstimate) {
        if est.from_prior == FromPrior::ALL || !est.model.is_valid() {
            return;
        }
        self.noise = Some(Box::new(est.model));
        self.noise_from_prior = est.from_prior.any().then_some(est.from_prior);
    }

    /// Fits the noise model to `frames` (sorted shortest first) with this profile's response
    /// and a black level of `black` (8-bit codes), and stores it ([`set_noise`](Self::set_noise)),
    /// as `skydome calibrate` does. Returns the fit. `wide_step`: the calibration's
    /// step-periodic correction applied ([`crate::response::Calibration::wide_step`]), so the
    /// model is fitted as a merge right after that calibration fits it
    /// ([`noise::estimate_for_calibration`]: from code [`noise::WIDE_STEP_NOISE_LO`] up) and a
    /// later merge with this profile weighs its pixels the same way.
    pub fn estimate_noise(
        &mut self,
        frames: &[Frame],
        black: u8,
        wide_step: bool,
    ) -> Result<NoiseEstimate, ResponseError> {
        let est =
            noise::estimate_for_calibration(frames, &self.response()?, black, None, wide_step);
        self.set_noise(&est);
        Ok(est)
    }

    /// The stored noise model as the merge reports it: the model, with
    /// [`NoiseEstimate::from_prior`] and [`NoiseEstimate::fitted`] from `noise_from_prior`.
    /// `None` without a valid model.
    pub fn noise_estimate(&self) -> Option<NoiseEstimate> {
        let model = **self.noise.as_ref()?;
        if !model.is_valid() {
            return None;
        }
        let mut est = NoiseEstimate::given(model);
        if let Some(p) = self.noise_from_prior {
            est.from_prior = p;
            est.fitted = !p.any();
        }
        Some(est)
    }

    /// [`noise_estimate`](Self::noise_estimate) for a bracket shot at ISO speed `iso`: a model
    /// measured at the profile's [`iso`](Self::iso) has its electrons at code 128 scaled by
    /// `profile ISO / iso` (a higher ISO is a higher gain: the same code holds proportionally
    /// fewer electrons, so its shot noise is larger), with read noise (electrons) and JPEG code
    /// noise (codes) kept, and [`NoiseEstimate::scaled_from_iso`] set. Unscaled when either ISO
    /// is unknown, not a positive number, or the two are equal.
    pub fn noise_estimate_at_iso(&self, iso: Option<f64>) -> Option<NoiseEstimate> {
        let mut est = self.noise_estimate()?;
        let (Some(from), Some(to)) = (self.iso, iso) else {
            return Some(est);
        };
        let valid = |v: f64| v.is_finite() && v > 0.0;
        if valid(from) && valid(to) && from != to {
            for c in &mut est.model.channels {
                c.electrons_at_gauge *= from / to;
            }
            est.scaled_from_iso = Some(from);
        }
        Some(est)
    }

    /// The response this profile describes (validated).
    pub fn response(&self) -> Result<Response, ResponseError> {
        if self.linear {
            return Ok(Response::linear());
        }
        Response::from_curves(self.g.clone())
    }
}
