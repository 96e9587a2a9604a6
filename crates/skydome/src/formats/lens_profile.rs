//! The lens-profile JSON format: where the optical axis is, how rays map to radii, how well
//! that was fitted.

use serde::{Deserialize, Serialize};

use crate::fisheye::{check_fov, FisheyeError, LensFit, LensKind, ModelFit, Projection};
use crate::image::Circle;

/// The lens-profile JSON version this build writes and reads.
pub const LENS_PROFILE_VERSION: u32 = 1;

/// A lens profile: where the optical axis is, how rays map to radii, and how well that was fitted.
/// Serialised as JSON (see [`LensProfile::to_json`]), e.g.
/// `{"version":1,"circle":{"cx":150.2,"cy":141.0,"r":130.1},"fov_deg":235.0,
///   "projection":{"model":"stereographic","f_px":39.5},"rms_px":0.0,"max_px":0.0,"candidates":[]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LensProfile {
    /// Always [`LENS_PROFILE_VERSION`].
    pub version: u32,
    /// The visible image circle in pixels; its centre is the optical axis.
    pub circle: Circle,
    /// Full field of view across the visible circle, degrees (235 for the seed's clip-on lens).
    pub fov_deg: f64,
    /// The radial projection, pixels and radians.
    pub projection: Projection,
    /// RMS radial residual of the fit, pixels (0 when the profile came from fov + circle).
    pub rms_px: f64,
    /// Largest radial residual of the fit, pixels.
    pub max_px: f64,
    /// Every model tried, for the report.
    #[serde(default)]
    pub candidates: Vec<ModelFit>,
}

impl LensProfile {
    /// A profile from a detected circle and the lens's nominal field of view, with the named
    /// model (one point cannot tell models apart). `rms_px`/`max_px` are zero.
    pub fn from_fov(circle: Circle, fov_deg: f64, kind: LensKind) -> Result<Self, FisheyeError> {
        let projection = Projection::from_fov(kind, fov_deg, circle.r)?;
        let p = LensProfile {
            version: LENS_PROFILE_VERSION,
            circle,
            fov_deg,
            projection,
            rms_px: 0.0,
            max_px: 0.0,
            candidates: Vec::new(),
        };
        p.validate()?;
        Ok(p)
    }

    /// A profile from a fit of measurements around the optical centre `(cx, cy)` (pixels).
    /// The visible circle's radius is the fitted `r(fov/2)`.
    pub fn from_fit(cx: f64, cy: f64, fov_deg: f64, fit: &LensFit) -> Result<Self, FisheyeError> {
        check_fov(fov_deg)?;
        let projection = fit.best.projection;
        projection.validate(0.5 * fov_deg.to_radians())?;
        let p = LensProfile {
            version: LENS_PROFILE_VERSION,
            circle: Circle {
                cx,
                cy,
                r: projection.radius(0.5 * fov_deg.to_radians()),
            },
            fov_deg,
            projection,
            rms_px: fit.best.rms_px,
            max_px: fit.best.max_px,
            candidates: fit.candidates.clone(),
        };
        p.validate()?;
        Ok(p)
    }

    /// Checks version, finite centre, positive radius, field of view in (0°, 360°) and that the
    /// projection is valid and monotonic up to `fov/2`.
    pub fn validate(&self) -> Result<(), FisheyeError> {
        if self.version != LENS_PROFILE_VERSION {
            return Err(FisheyeError::Version(self.version));
        }
        check_fov(self.fov_deg)?;
        for (what, v) in [("circle.cx", self.circle.cx), ("circle.cy", self.circle.cy)] {
            if !v.is_finite() {
                return Err(FisheyeError::BadParameter {
                    what,
                    value: v,
                    hint: "the circle centre must be a finite pixel position",
                });
            }
        }
        if !(self.circle.r.is_finite() && self.circle.r > 0.0) {
            return Err(FisheyeError::BadParameter {
                what: "circle.r",
                value: self.circle.r,
                hint: "the circle radius must be a positive number of pixels",
            });
        }
        self.projection.validate(0.5 * self.fov_deg.to_radians())
    }

    /// Pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, FisheyeError> {
        Ok(serde_json::to_string_pretty(self)?)
    }

    /// Parses and validates a profile.
    pub fn from_json(text: &str) -> Result<Self, FisheyeError> {
        let p: LensProfile = serde_json::from_str(text)?;
        p.validate()?;
        Ok(p)
    }

    /// The radius in pixels at which the lens images `theta_deg` degrees off-axis (e.g. 90 for
    /// the horizon), or an error when the model cannot image that angle.
    pub fn radius_at_deg(&self, theta_deg: f64) -> Result<f64, FisheyeError> {
        let t = theta_deg.to_radians();
        if !(t.is_finite() && t >= 0.0 && t <= self.projection.theta_limit()) {
            return Err(FisheyeError::AngleOutOfModel {
                model: self.projection.kind(),
                theta_deg,
                limit_deg: self.projection.theta_limit().to_degrees(),
            });
        }
        Ok(self.projection.radius(t))
    }
}
