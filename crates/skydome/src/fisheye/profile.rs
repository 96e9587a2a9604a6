//! The lens profile: where the optical axis is, how rays map to radii, how well that was
//! fitted, and the lens's fall-off (vignetting) with its fit and removal. Stored as JSON by
//! [`LensProfile::to_json`] and read back by [`LensProfile::from_json`].

use serde::{Deserialize, Serialize};

use super::{check_fov, FisheyeError, LensFit, LensKind, ModelFit, Projection};
use crate::image::{Circle, HdrImage};

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
    /// The lens's radial fall-off (vignetting), when measured; the merge divides it out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vignetting: Option<Vignetting>,
}

/// Radial fall-off `V(θ) = 1 + a₁θ² + a₂θ⁴ + a₃θ⁶` (θ in radians from the optical axis,
/// `V(0) = 1`): the fraction of the on-axis response a ray at θ gets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Vignetting {
    /// `[a₁, a₂, a₃]`.
    pub coefficients: [f64; 3],
    /// RMS residual of the fit, in relative value.
    pub rms: f64,
    /// Number of measurements fitted.
    pub samples: usize,
}

impl Vignetting {
    /// `V(θ)`, θ in radians, floored at 0.01 (so dividing by it stays finite).
    pub fn at(&self, theta: f64) -> f64 {
        let t2 = theta * theta;
        let [a1, a2, a3] = self.coefficients;
        (1.0 + t2 * (a1 + t2 * (a2 + t2 * a3))).max(0.01)
    }

    /// `V` at 30°, 60° and 90°, for reports.
    pub fn at_30_60_90(&self) -> [f64; 3] {
        [30f64, 60.0, 90.0].map(|d| self.at(d.to_radians()))
    }

    /// Fits `V` to `(angle in degrees, relative value)` measurements (the value at 0° is 1; the
    /// usual procedure rotates the camera in front of a fixed uniform target) by linear least
    /// squares on `V − 1`. Needs at least 3 measurements at distinct angles above 0°.
    pub fn fit(points: &[(f64, f64)]) -> Result<Self, FisheyeError> {
        let usable: Vec<(f64, f64)> = points
            .iter()
            .filter(|(a, _)| *a > 0.0)
            .map(|&(a, v)| (a.to_radians(), v))
            .collect();
        for (i, &(a, v)) in points.iter().enumerate() {
            if !(a.is_finite() && (0.0..180.0).contains(&a) && v.is_finite() && v > 0.0) {
                return Err(FisheyeError::BadSample {
                    index: i,
                    angle_deg: a,
                    radius_px: v,
                });
            }
        }
        let mut distinct: Vec<f64> = usable.iter().map(|p| p.0).collect();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup();
        if distinct.len() < 3 {
            return Err(FisheyeError::BadParameter {
                what: "vignetting measurements at distinct angles",
                value: distinct.len() as f64,
                hint: "measure the fall-off at 3 or more angles above 0°",
            });
        }
        let basis = |t: f64| {
            let t2 = t * t;
            [t2, t2 * t2, t2 * t2 * t2]
        };
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atb = nalgebra::Vector3::<f64>::zeros();
        for &(t, v) in &usable {
            let b = basis(t);
            for i in 0..3 {
                atb[i] += b[i] * (v - 1.0);
                for j in 0..3 {
                    ata[(i, j)] += b[i] * b[j];
                }
            }
        }
        let x = ata.lu().solve(&atb).ok_or(FisheyeError::BadParameter {
            what: "vignetting fit",
            value: f64::NAN,
            hint: "the measurements do not determine a fall-off; spread them over the field",
        })?;
        let coefficients = [x[0], x[1], x[2]];
        let mut v = Vignetting {
            coefficients,
            rms: 0.0,
            samples: usable.len(),
        };
        let rss: f64 = usable.iter().map(|&(t, m)| (v.at(t) - m).powi(2)).sum();
        v.rms = (rss / usable.len() as f64).sqrt();
        Ok(v)
    }
}

/// Divides the lens's fall-off out of `img` (pixels in the lens's frame: its circle's centre is
/// the optical axis); pixels beyond the projection's reach are left as they are.
pub fn devignette(img: &mut HdrImage, lens: &LensProfile, v: &Vignetting) {
    let (cx, cy) = (lens.circle.cx, lens.circle.cy);
    let limit = lens.projection.theta_limit();
    let w = img.width;
    for (y, row) in img.data.chunks_exact_mut(3 * w.max(1)).enumerate() {
        let dy = y as f64 + 0.5 - cy;
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let rho = (x as f64 + 0.5 - cx).hypot(dy);
            if let Some(t) = lens.projection.theta_within(rho, limit) {
                let k = (1.0 / v.at(t)) as f32;
                px.iter_mut().for_each(|c| *c *= k);
            }
        }
    }
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
            vignetting: None,
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
            vignetting: None,
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
