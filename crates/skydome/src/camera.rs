//! The camera profile: what calibrating one camera found — its response curves
//! ([`crate::response`]), its noise model ([`crate::noise`]) and the merge weighting it suggests
//! ([`crate::merge`]) — made once per device and reused by every merge, stored as JSON by
//! [`CameraProfile::to_json`] and read back (validated) by [`CameraProfile::from_json`].
//!
//! It sits above the response, noise and merge modules because it holds a piece of each (see
//! the layer table in the crate documentation).

use crate::merge::Weighting;
use crate::noise::NoiseModel;
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
        Ok(p)
    }

    /// The response this profile describes (validated).
    pub fn response(&self) -> Result<Response, ResponseError> {
        if self.linear {
            return Ok(Response::linear());
        }
        Response::from_curves(self.g.clone())
    }
}
