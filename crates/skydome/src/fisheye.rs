//! Fish-eye lens geometry: the visible image circle, radial projections `r(θ)`, lens fitting, lens
//! profiles and the crop to the 180° sky-dome.
//!
//! # Conventions
//! - Pixels: origin top-left, `x` right, `y` down, pixel `(x, y)` centred at `(x + 0.5, y + 0.5)`
//!   (see [`crate::image`]). Radii are in pixels of the image the lens was measured on.
//! - `θ` is the angle between a ray and the optical axis, in **radians** inside the crate; field
//!   of view and measured angles at the API boundary ([`AngleRadius`], [`LensProfile::fov_deg`])
//!   are in **degrees**. The optical axis pierces the image at the centre of the visible circle.
//!
//! # Projections
//! A circular fish-eye maps a ray at angle `θ` to a point at distance `r(θ)` from the centre, in
//! the same azimuthal direction. The classic models ([`Projection`]), each with one focal length
//! `f` in pixels, and the free polynomial:
//!
//! | model | `r(θ)` | `θ(r)` | defined for |
//! |---|---|---|---|
//! | equidistant (`f-θ`) | `f·θ` | `r/f` | `θ < π` |
//! | equisolid (equal-area) | `2f·sin(θ/2)` | `2·asin(r/2f)` | `θ ≤ π` |
//! | stereographic (the seed's assumption) | `2f·tan(θ/2)` | `2·atan(r/2f)` | `θ < π` |
//! | orthographic | `f·sin θ` | `asin(r/f)` | `θ ≤ π/2` |
//! | polynomial | `k1·θ + k3·θ³ + k5·θ⁵` | Newton on a bracket | while `r′(θ) > 0` |
//!
//! # Fitting
//! From measured `(angle, radius)` pairs (the seed's transparent-box procedure), every model is
//! fitted by linear least squares — one-parameter models in closed form `f = Σ r·g(θ) / Σ g(θ)²`,
//! the polynomial by a 3×3 normal-equation solve (nalgebra) — and the residuals reported. The
//! automatic choice minimises the small-sample Akaike criterion
//! `AICc = n·ln(RSS/n) + 2k + 2k(k+1)/(n−k−1)` with the RSS floored at `n·(0.01 px)²`, so the
//! three-parameter polynomial only wins when it explains the data clearly better than a physical
//! one-parameter model (a polynomial always fits at least as well as the equidistant model it
//! contains). From a field of view and a detected circle alone only `f` can be found, so the
//! model must be named ([`Projection::from_fov`]).
//!
//! # Image-circle detection
//! [`detect_circle`] finds the boundary between the dark lens housing and the image: the housing
//! level is the median of the four corner patches, the threshold sits 10 % of the way from it to
//! the 95th percentile (so a dark horizon still counts as image), and rays cast from a rough
//! centre are walked **inwards from the frame edge** so dark sky near the horizon or dark objects
//! inside the circle cannot stop them early. On each ray the edge is placed where the profile
//! crosses half-way between the housing level and the local image level just inside (a local
//! half-maximum, unbiased for a symmetric blur). Rays that start inside the image (the circle is
//! cut by the frame there) are dropped. A RANSAC over point triples (fixed seed, so runs repeat)
//! rejects outliers such as reflections in the housing, and a geometric (orthogonal distance)
//! Gauss–Newton fit on the inliers refines the algebraic Kåsa start, which is biased on partial
//! arcs. References: Kåsa, *IEEE Trans. Instrum. Meas.* 25 (1976); Chernov, *Circular and Linear
//! Regression* (2010), ch. 4–5.
//!
//! # Crop
//! [`crop_dome`] keeps the source's projection and resolution: it copies the square around the
//! optical axis whose inscribed circle is `θ = fov_out/2` (90° for the sky-dome) and zeroes every
//! pixel beyond it. For a 235° lens the 180° horizon sits at 0.61 (stereographic), 0.77
//! (equidistant) or 0.83 (equisolid) of the visible circle's radius, so the model matters.

use serde::{Deserialize, Serialize};

use crate::image::{Circle, HdrImage, RgbImage};

/// Errors from lens fitting, lens profiles, circle detection and cropping.
#[derive(Debug, thiserror::Error)]
pub enum FisheyeError {
    /// The image is too small or empty for circle detection.
    #[error("image is {width}x{height} pixels: circle detection needs at least 16x16")]
    ImageTooSmall {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
    /// The sample buffer does not match the stated size.
    #[error("buffer holds {got} samples but {width}x{height} needs {expected}: pass a buffer of the stated size")]
    BufferSize {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Samples expected.
        expected: usize,
        /// Samples received.
        got: usize,
    },
    /// No boundary between housing and image was found.
    #[error("no lens circle found ({points} boundary points): use the best-exposed frame, or give the circle by hand")]
    NoCircle {
        /// Boundary points found.
        points: usize,
    },
    /// Too few lens measurements for the requested model.
    #[error("{model} needs at least {needed} measurements with distinct angles > 0°, got {got}: measure more angles")]
    TooFewSamples {
        /// The model.
        model: LensKind,
        /// Measurements needed.
        needed: usize,
        /// Usable measurements given.
        got: usize,
    },
    /// A lens measurement is out of range.
    #[error("measurement {index} (angle {angle_deg}°, radius {radius_px} px) is invalid: angles must be in [0°, 180°) and radii finite and ≥ 0")]
    BadSample {
        /// Index in the slice.
        index: usize,
        /// The angle in degrees.
        angle_deg: f64,
        /// The radius in pixels.
        radius_px: f64,
    },
    /// A parameter is outside its meaningful range.
    #[error("{what} = {value} is out of range: {hint}")]
    BadParameter {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// What the user can do.
        hint: &'static str,
    },
    /// The projection cannot reach the requested angle.
    #[error("{model} projection cannot image θ = {theta_deg:.2}° (it is limited to {limit_deg:.2}°): pick another model or a smaller field of view")]
    AngleOutOfModel {
        /// The model.
        model: LensKind,
        /// The angle asked for, degrees.
        theta_deg: f64,
        /// The model's limit, degrees.
        limit_deg: f64,
    },
    /// The fitted projection is not monotonic over the field of view.
    #[error("the fitted {model} projection folds back before θ = {theta_deg:.2}°: check the measurements or pick a one-parameter model")]
    NotMonotonic {
        /// The model.
        model: LensKind,
        /// The angle, degrees.
        theta_deg: f64,
    },
    /// A lens profile JSON could not be read or written.
    #[error("lens profile JSON: {0}; fix the file or regenerate it with `skydome lens`")]
    Json(#[from] serde_json::Error),
    /// The lens profile has a version this build does not know.
    #[error("lens profile version {0} is not supported (this build reads version {LENS_PROFILE_VERSION}): regenerate it")]
    Version(u32),
}

/// The kind of radial projection, without coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LensKind {
    /// `r = f·θ`.
    Equidistant,
    /// `r = 2f·sin(θ/2)`.
    Equisolid,
    /// `r = 2f·tan(θ/2)`.
    Stereographic,
    /// `r = f·sin θ`.
    Orthographic,
    /// `r = k1·θ + k3·θ³ + k5·θ⁵`.
    Polynomial,
}

impl LensKind {
    /// All kinds, in the order fits are reported.
    pub const ALL: [LensKind; 5] = [
        LensKind::Equidistant,
        LensKind::Equisolid,
        LensKind::Stereographic,
        LensKind::Orthographic,
        LensKind::Polynomial,
    ];

    /// The lowercase name used in JSON and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            LensKind::Equidistant => "equidistant",
            LensKind::Equisolid => "equisolid",
            LensKind::Stereographic => "stereographic",
            LensKind::Orthographic => "orthographic",
            LensKind::Polynomial => "polynomial",
        }
    }

    /// `g(θ)` with `r = f·g(θ)` for the one-parameter models; `None` for the polynomial.
    fn unit_radius(self, theta: f64) -> Option<f64> {
        match self {
            LensKind::Equidistant => Some(theta),
            LensKind::Equisolid => Some(2.0 * (0.5 * theta).sin()),
            LensKind::Stereographic => Some(2.0 * (0.5 * theta).tan()),
            LensKind::Orthographic => Some(theta.sin()),
            LensKind::Polynomial => None,
        }
    }

    /// Largest `θ` (radians) the one-parameter model images monotonically.
    fn theta_limit(self) -> f64 {
        use std::f64::consts::{FRAC_PI_2, PI};
        match self {
            LensKind::Orthographic => FRAC_PI_2,
            // tan(θ/2) diverges at π; keep a margin so the radius stays finite.
            LensKind::Stereographic => PI - 1e-6,
            _ => PI,
        }
    }
}

impl std::fmt::Display for LensKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for LensKind {
    type Err = FisheyeError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        LensKind::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s.trim()))
            .ok_or(FisheyeError::BadParameter {
                what: "lens model",
                value: f64::NAN,
                hint: "use equidistant, equisolid, stereographic, orthographic or polynomial",
            })
    }
}

/// A radial fish-eye projection `r(θ)` with its coefficients; `r` in pixels, `θ` in radians from
/// the optical axis. Serialised as `{"model": "stereographic", "f_px": 81.5}` or
/// `{"model": "polynomial", "k1": …, "k3": …, "k5": …}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum Projection {
    /// `r = f·θ`; `f_px` in pixels per radian.
    Equidistant {
        /// Focal length in pixels.
        f_px: f64,
    },
    /// `r = 2f·sin(θ/2)`.
    Equisolid {
        /// Focal length in pixels.
        f_px: f64,
    },
    /// `r = 2f·tan(θ/2)`.
    Stereographic {
        /// Focal length in pixels.
        f_px: f64,
    },
    /// `r = f·sin θ`.
    Orthographic {
        /// Focal length in pixels.
        f_px: f64,
    },
    /// `r = k1·θ + k3·θ³ + k5·θ⁵` (pixels, θ in radians).
    Polynomial {
        /// Linear coefficient, pixels per radian.
        k1: f64,
        /// Cubic coefficient, pixels per radian³.
        k3: f64,
        /// Quintic coefficient, pixels per radian⁵.
        k5: f64,
    },
}

impl Projection {
    /// A one-parameter projection of the given kind with focal length `f_px` (pixels).
    /// For [`LensKind::Polynomial`] this is the equidistant polynomial `k1 = f_px`.
    pub fn with_focal(kind: LensKind, f_px: f64) -> Projection {
        match kind {
            LensKind::Equidistant => Projection::Equidistant { f_px },
            LensKind::Equisolid => Projection::Equisolid { f_px },
            LensKind::Stereographic => Projection::Stereographic { f_px },
            LensKind::Orthographic => Projection::Orthographic { f_px },
            LensKind::Polynomial => Projection::Polynomial {
                k1: f_px,
                k3: 0.0,
                k5: 0.0,
            },
        }
    }

    /// The projection of `kind` whose visible circle of radius `circle_radius_px` is the edge of
    /// a field of view of `fov_deg` degrees (θ = fov/2 there); e.g. a 235° lens images θ = 117.5°
    /// on its circle. A polynomial cannot be determined from one point: fit measurements instead.
    pub fn from_fov(
        kind: LensKind,
        fov_deg: f64,
        circle_radius_px: f64,
    ) -> Result<Projection, FisheyeError> {
        check_fov(fov_deg)?;
        if !(circle_radius_px.is_finite() && circle_radius_px > 0.0) {
            return Err(FisheyeError::BadParameter {
                what: "circle radius (px)",
                value: circle_radius_px,
                hint: "give the detected circle's radius, a positive number of pixels",
            });
        }
        let half = 0.5 * fov_deg.to_radians();
        let g = kind.unit_radius(half).ok_or(FisheyeError::TooFewSamples {
            model: LensKind::Polynomial,
            needed: 3,
            got: 1,
        })?;
        if half > kind.theta_limit() {
            return Err(FisheyeError::AngleOutOfModel {
                model: kind,
                theta_deg: half.to_degrees(),
                limit_deg: kind.theta_limit().to_degrees(),
            });
        }
        Ok(Projection::with_focal(kind, circle_radius_px / g))
    }

    /// The kind of this projection.
    pub fn kind(&self) -> LensKind {
        match self {
            Projection::Equidistant { .. } => LensKind::Equidistant,
            Projection::Equisolid { .. } => LensKind::Equisolid,
            Projection::Stereographic { .. } => LensKind::Stereographic,
            Projection::Orthographic { .. } => LensKind::Orthographic,
            Projection::Polynomial { .. } => LensKind::Polynomial,
        }
    }

    /// Distance from the optical centre in pixels of a ray at `theta` radians from the axis.
    #[inline]
    pub fn radius(&self, theta: f64) -> f64 {
        match *self {
            Projection::Equidistant { f_px } => f_px * theta,
            Projection::Equisolid { f_px } => 2.0 * f_px * (0.5 * theta).sin(),
            Projection::Stereographic { f_px } => 2.0 * f_px * (0.5 * theta).tan(),
            Projection::Orthographic { f_px } => f_px * theta.sin(),
            Projection::Polynomial { k1, k3, k5 } => {
                let t2 = theta * theta;
                theta * (k1 + t2 * (k3 + t2 * k5))
            }
        }
    }

    /// `dr/dθ` in pixels per radian.
    #[inline]
    pub fn derivative(&self, theta: f64) -> f64 {
        match *self {
            Projection::Equidistant { f_px } => f_px,
            Projection::Equisolid { f_px } => f_px * (0.5 * theta).cos(),
            Projection::Stereographic { f_px } => {
                let c = (0.5 * theta).cos();
                f_px / (c * c)
            }
            Projection::Orthographic { f_px } => f_px * theta.cos(),
            Projection::Polynomial { k1, k3, k5 } => {
                let t2 = theta * theta;
                k1 + t2 * (3.0 * k3 + 5.0 * k5 * t2)
            }
        }
    }

    /// Largest `θ` (radians) up to which `r(θ)` increases; the projection is only used below it.
    pub fn theta_limit(&self) -> f64 {
        match *self {
            Projection::Polynomial { .. } => {
                // First angle where the derivative stops being positive, on a 0.05° grid refined
                // by bisection; π when it never does.
                let step = 0.05f64.to_radians();
                let mut prev = 0.0;
                let mut t = step;
                while t <= std::f64::consts::PI {
                    if self.derivative(t) <= 0.0 {
                        let (mut lo, mut hi) = (prev, t);
                        for _ in 0..50 {
                            let mid = 0.5 * (lo + hi);
                            if self.derivative(mid) > 0.0 {
                                lo = mid;
                            } else {
                                hi = mid;
                            }
                        }
                        return lo;
                    }
                    prev = t;
                    t += step;
                }
                std::f64::consts::PI
            }
            _ => self.kind().theta_limit(),
        }
    }

    /// The inverse `θ(r)` in radians for a radius in pixels; `None` when no ray within
    /// [`Projection::theta_limit`] lands at that radius (or `r` is negative / not finite).
    #[inline]
    pub fn theta(&self, r: f64) -> Option<f64> {
        self.theta_within(r, self.theta_limit())
    }

    /// [`Projection::theta`] with the angle limit given (pass a cached
    /// [`Projection::theta_limit`]: for the polynomial it is found by a scan).
    #[inline]
    pub fn theta_within(&self, r: f64, limit: f64) -> Option<f64> {
        if !(r.is_finite() && r >= 0.0) {
            return None;
        }
        let t = match *self {
            Projection::Equidistant { f_px } => r / f_px,
            Projection::Equisolid { f_px } => {
                let s = r / (2.0 * f_px);
                if s > 1.0 {
                    return None;
                }
                2.0 * s.asin()
            }
            Projection::Stereographic { f_px } => 2.0 * (r / (2.0 * f_px)).atan(),
            Projection::Orthographic { f_px } => {
                let s = r / f_px;
                if s > 1.0 {
                    return None;
                }
                s.asin()
            }
            Projection::Polynomial { .. } => return self.polynomial_theta(r, limit),
        };
        (t.is_finite() && t <= limit + 1e-12).then_some(t)
    }

    fn polynomial_theta(&self, r: f64, limit: f64) -> Option<f64> {
        if r > self.radius(limit) {
            return None;
        }
        // Safeguarded Newton: the bracket [lo, hi] always holds the root because r(θ) increases.
        let (mut lo, mut hi) = (0.0, limit);
        let d0 = self.derivative(0.0);
        let mut t = if d0 > 0.0 {
            (r / d0).min(limit)
        } else {
            0.5 * limit
        };
        for _ in 0..60 {
            let f = self.radius(t) - r;
            if f.abs() < 1e-12 * (1.0 + r) {
                return Some(t);
            }
            if f > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let d = self.derivative(t);
            let next = t - f / d;
            t = if d > 0.0 && next > lo && next < hi {
                next
            } else {
                0.5 * (lo + hi)
            };
        }
        Some(t)
    }

    /// The same lens on an image scaled by `s` (radii and coefficients times `s`).
    pub fn scaled(&self, s: f64) -> Projection {
        match *self {
            Projection::Equidistant { f_px } => Projection::Equidistant { f_px: f_px * s },
            Projection::Equisolid { f_px } => Projection::Equisolid { f_px: f_px * s },
            Projection::Stereographic { f_px } => Projection::Stereographic { f_px: f_px * s },
            Projection::Orthographic { f_px } => Projection::Orthographic { f_px: f_px * s },
            Projection::Polynomial { k1, k3, k5 } => Projection::Polynomial {
                k1: k1 * s,
                k3: k3 * s,
                k5: k5 * s,
            },
        }
    }

    /// Checks coefficients are finite and positive (polynomial: `k1 > 0`) and that `r(θ)` is
    /// monotonic up to `theta_max` radians.
    pub fn validate(&self, theta_max: f64) -> Result<(), FisheyeError> {
        let bad = |what, value| FisheyeError::BadParameter {
            what,
            value,
            hint: "focal lengths and k1 must be finite and > 0, k3 and k5 finite",
        };
        match *self {
            Projection::Equidistant { f_px }
            | Projection::Equisolid { f_px }
            | Projection::Stereographic { f_px }
            | Projection::Orthographic { f_px } => {
                if !(f_px.is_finite() && f_px > 0.0) {
                    return Err(bad("f_px", f_px));
                }
            }
            Projection::Polynomial { k1, k3, k5 } => {
                if !(k1.is_finite() && k1 > 0.0) {
                    return Err(bad("k1", k1));
                }
                if !k3.is_finite() {
                    return Err(bad("k3", k3));
                }
                if !k5.is_finite() {
                    return Err(bad("k5", k5));
                }
            }
        }
        let limit = self.theta_limit();
        if theta_max > limit + 1e-9 {
            return Err(if self.kind() == LensKind::Polynomial {
                FisheyeError::NotMonotonic {
                    model: LensKind::Polynomial,
                    theta_deg: limit.to_degrees(),
                }
            } else {
                FisheyeError::AngleOutOfModel {
                    model: self.kind(),
                    theta_deg: theta_max.to_degrees(),
                    limit_deg: limit.to_degrees(),
                }
            });
        }
        Ok(())
    }
}

fn check_fov(fov_deg: f64) -> Result<(), FisheyeError> {
    if !(fov_deg.is_finite() && fov_deg > 0.0 && fov_deg < 360.0) {
        return Err(FisheyeError::BadParameter {
            what: "field of view (degrees)",
            value: fov_deg,
            hint: "give the lens's full field of view in degrees, e.g. 235",
        });
    }
    Ok(())
}

/// One lens measurement: a ray at `angle_deg` degrees from the optical axis landed
/// `radius_px` pixels from the image-circle centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AngleRadius {
    /// Angle from the optical axis in degrees, `[0, 180)`.
    pub angle_deg: f64,
    /// Distance from the optical centre in pixels.
    pub radius_px: f64,
}

/// One model fitted to lens measurements, with its residuals (pixels).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelFit {
    /// The fitted projection.
    pub projection: Projection,
    /// Root-mean-square radial residual in pixels.
    pub rms_px: f64,
    /// Largest absolute radial residual in pixels.
    pub max_px: f64,
    /// Small-sample Akaike information criterion used by the automatic choice (lower is better).
    pub aicc: f64,
}

/// The result of [`fit_projection`]: the chosen model and every candidate that could be fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LensFit {
    /// The chosen fit (the requested model, or the lowest AICc).
    pub best: ModelFit,
    /// All models fitted, in [`LensKind::ALL`] order (models that cannot be fitted are left out).
    pub candidates: Vec<ModelFit>,
}

/// Fits every projection model to measured `(angle°, radius px)` pairs and picks `choice`, or the
/// model with the lowest AICc when `choice` is `None` (see the module docs).
///
/// Errors on invalid samples, when fewer than one (one-parameter models) or three (polynomial)
/// distinct non-zero angles are given, and when the requested model cannot be fitted.
pub fn fit_projection(
    samples: &[AngleRadius],
    choice: Option<LensKind>,
) -> Result<LensFit, FisheyeError> {
    let mut pts = Vec::with_capacity(samples.len());
    for (index, s) in samples.iter().enumerate() {
        if !(s.angle_deg.is_finite()
            && (0.0..180.0).contains(&s.angle_deg)
            && s.radius_px.is_finite()
            && s.radius_px >= 0.0)
        {
            return Err(FisheyeError::BadSample {
                index,
                angle_deg: s.angle_deg,
                radius_px: s.radius_px,
            });
        }
        pts.push((s.angle_deg.to_radians(), s.radius_px));
    }
    let mut distinct: Vec<f64> = pts.iter().map(|p| p.0).filter(|&t| t > 0.0).collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let n_distinct = distinct.len();
    let theta_max = pts.iter().map(|p| p.0).fold(0.0, f64::max);

    let mut candidates = Vec::new();
    let mut requested_err = None;
    for kind in LensKind::ALL {
        let fitted = fit_one(kind, &pts, n_distinct, theta_max);
        match fitted {
            Ok(fit) => candidates.push(fit),
            Err(e) if Some(kind) == choice => requested_err = Some(e),
            Err(_) => {}
        }
    }
    if let Some(e) = requested_err {
        return Err(e);
    }
    let best = match choice {
        Some(kind) => candidates
            .iter()
            .find(|c| c.projection.kind() == kind)
            .copied(),
        None => candidates
            .iter()
            .min_by(|a, b| a.aicc.total_cmp(&b.aicc))
            .copied(),
    }
    .ok_or(FisheyeError::TooFewSamples {
        model: choice.unwrap_or(LensKind::Equidistant),
        needed: 1,
        got: n_distinct,
    })?;
    Ok(LensFit { best, candidates })
}

fn fit_one(
    kind: LensKind,
    pts: &[(f64, f64)],
    n_distinct: usize,
    theta_max: f64,
) -> Result<ModelFit, FisheyeError> {
    let projection = if kind == LensKind::Polynomial {
        if n_distinct < 3 {
            return Err(FisheyeError::TooFewSamples {
                model: kind,
                needed: 3,
                got: n_distinct,
            });
        }
        // Columns θ, θ³, θ⁵ are scaled by their norms first: at θ ≈ 2 rad the raw normal matrix
        // spans four orders of magnitude and loses digits needlessly.
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atb = nalgebra::Vector3::<f64>::zeros();
        for &(t, r) in pts {
            let row = nalgebra::Vector3::new(t, t.powi(3), t.powi(5));
            ata += row * row.transpose();
            atb += row * r;
        }
        let scale = nalgebra::Vector3::from_fn(|i, _| {
            let d = ata[(i, i)];
            if d > 0.0 {
                1.0 / d.sqrt()
            } else {
                1.0
            }
        });
        let s = nalgebra::Matrix3::from_diagonal(&scale);
        let k = (s * ata * s)
            .cholesky()
            .map(|c| s * c.solve(&(s * atb)))
            .ok_or(FisheyeError::TooFewSamples {
                model: kind,
                needed: 3,
                got: n_distinct,
            })?;
        Projection::Polynomial {
            k1: k[0],
            k3: k[1],
            k5: k[2],
        }
    } else {
        if n_distinct < 1 {
            return Err(FisheyeError::TooFewSamples {
                model: kind,
                needed: 1,
                got: 0,
            });
        }
        if theta_max > kind.theta_limit() {
            return Err(FisheyeError::AngleOutOfModel {
                model: kind,
                theta_deg: theta_max.to_degrees(),
                limit_deg: kind.theta_limit().to_degrees(),
            });
        }
        let (mut num, mut den) = (0.0, 0.0);
        for &(t, r) in pts {
            let g = kind.unit_radius(t).unwrap_or(t);
            num += r * g;
            den += g * g;
        }
        Projection::with_focal(kind, num / den)
    };
    projection.validate(theta_max)?;
    let n = pts.len() as f64;
    let (mut rss, mut max) = (0.0f64, 0.0f64);
    for &(t, r) in pts {
        let e = projection.radius(t) - r;
        rss += e * e;
        max = max.max(e.abs());
    }
    let k = if kind == LensKind::Polynomial {
        3.0
    } else {
        1.0
    };
    const NOISE_FLOOR_PX: f64 = 0.01;
    let rss_floored = rss.max(n * NOISE_FLOOR_PX * NOISE_FLOOR_PX);
    let small_sample = if n - k - 1.0 > 0.0 {
        2.0 * k * (k + 1.0) / (n - k - 1.0)
    } else {
        // Not enough samples for the correction: make the model unattractive but still usable
        // when asked for by name.
        1e6
    };
    Ok(ModelFit {
        projection,
        rms_px: (rss / n).sqrt(),
        max_px: max,
        aicc: n * (rss_floored / n).ln() + 2.0 * k + small_sample,
    })
}

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

/// The result of [`crop_dome`].
#[derive(Debug, Clone, PartialEq)]
pub struct DomeCrop {
    /// Square image in the source's projection and resolution; pixels beyond the crop circle
    /// (and outside the source frame) are zero.
    pub image: HdrImage,
    /// The crop circle (the horizon for 180°) in output pixel coordinates. Its centre is within
    /// half a pixel of the image centre (the copy is pixel-exact, so it is not resampled to sit
    /// exactly in the middle).
    pub horizon: Circle,
    /// Source pixel column of output column 0 (may be negative when the crop pokes out).
    pub offset_x: i64,
    /// Source pixel row of output row 0.
    pub offset_y: i64,
    /// Crop radius in source pixels: `r(fov_out/2)`.
    pub crop_radius_px: f64,
}

/// Crops a fish-eye image to the dome `θ ≤ fov_out_deg/2` around the lens's optical axis
/// (`fov_out_deg = 180` gives the sky-dome whose circle is the horizon), keeping the lens's
/// projection; everything beyond is set to zero. Errors when the lens cannot image that angle
/// or the crop would exceed 32768 pixels a side.
pub fn crop_dome(
    img: &HdrImage,
    lens: &LensProfile,
    fov_out_deg: f64,
) -> Result<DomeCrop, FisheyeError> {
    lens.validate()?;
    check_fov(fov_out_deg)?;
    let r = lens.radius_at_deg(0.5 * fov_out_deg)?;
    let half = (r + 0.5).ceil();
    if !(half.is_finite() && half <= 16384.0) {
        return Err(FisheyeError::BadParameter {
            what: "crop radius (px)",
            value: r,
            hint: "the crop would exceed 32768 px a side: check the lens profile",
        });
    }
    let n = 2 * half as usize;
    let ox = (lens.circle.cx - half).round() as i64;
    let oy = (lens.circle.cy - half).round() as i64;
    let horizon = Circle {
        cx: lens.circle.cx - ox as f64,
        cy: lens.circle.cy - oy as f64,
        r,
    };
    let mut out = HdrImage::new(n, n);
    let r2 = r * r;
    for (y, row) in out.data.chunks_exact_mut(3 * n).enumerate() {
        let sy = oy + y as i64;
        if sy < 0 || sy >= img.height as i64 {
            continue;
        }
        let dy = y as f64 + 0.5 - horizon.cy;
        let src_row = &img.data[3 * sy as usize * img.width..3 * (sy as usize + 1) * img.width];
        for x in 0..n {
            let sx = ox + x as i64;
            let dx = x as f64 + 0.5 - horizon.cx;
            if sx < 0 || sx >= img.width as i64 || dx * dx + dy * dy > r2 {
                continue;
            }
            let s = 3 * sx as usize;
            row[3 * x..3 * x + 3].copy_from_slice(&src_row[s..s + 3]);
        }
    }
    Ok(DomeCrop {
        image: out,
        horizon,
        offset_x: ox,
        offset_y: oy,
        crop_radius_px: r,
    })
}

/// A fitted image circle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CircleFit {
    /// The visible circle (centre and radius in pixels).
    pub circle: Circle,
    /// RMS orthogonal distance of the inlier boundary points from the circle, pixels.
    pub residual_px: f64,
    /// Number of boundary points that support the fit (inliers).
    pub points: usize,
    /// Number of boundary points found before outlier rejection.
    pub candidates: usize,
}

/// Detects the lens's visible image circle in an 8-bit RGB image (use the best-exposed frame).
/// Uses the per-pixel maximum of R, G and B, so a saturated-blue sky and a red sunset horizon
/// both stand out from the housing. See the module docs for the method.
pub fn detect_circle(img: &RgbImage<u8>) -> Result<CircleFit, FisheyeError> {
    let expected = 3 * img.width * img.height;
    if img.data.len() != expected {
        return Err(FisheyeError::BufferSize {
            width: img.width,
            height: img.height,
            expected,
            got: img.data.len(),
        });
    }
    let luma: Vec<u8> = img
        .data
        .chunks_exact(3)
        .map(|c| c[0].max(c[1]).max(c[2]))
        .collect();
    detect_circle_luma(&luma, img.width, img.height)
}

/// [`detect_circle`] on a single-channel 8-bit image (`width * height` samples, row-major,
/// origin top-left).
pub fn detect_circle_luma(
    luma: &[u8],
    width: usize,
    height: usize,
) -> Result<CircleFit, FisheyeError> {
    if width < 16 || height < 16 {
        return Err(FisheyeError::ImageTooSmall { width, height });
    }
    if luma.len() != width * height {
        return Err(FisheyeError::BufferSize {
            width,
            height,
            expected: width * height,
            got: luma.len(),
        });
    }
    let img = blur3(luma, width, height);
    let (housing, threshold) = housing_threshold(&img, width, height);

    // Rough centre: centroid of the pixels above threshold.
    let (mut sx, mut sy, mut cnt) = (0.0, 0.0, 0.0);
    for y in 0..height {
        for x in 0..width {
            if img[y * width + x] > threshold {
                sx += x as f64 + 0.5;
                sy += y as f64 + 0.5;
                cnt += 1.0;
            }
        }
    }
    if cnt < 16.0 {
        return Err(FisheyeError::NoCircle { points: 0 });
    }
    let mut centre = (sx / cnt, sy / cnt);
    let mut best: Option<CircleFit> = None;
    // Two passes: the centroid is biased when the circle is cut by the frame; rays cast from the
    // first fit's centre meet the boundary more squarely.
    for _ in 0..2 {
        let pts = boundary_points(&img, width, height, centre, housing, threshold);
        let fit = robust_circle_fit(&pts)?;
        centre = (fit.circle.cx, fit.circle.cy);
        best = Some(fit);
    }
    best.ok_or(FisheyeError::NoCircle { points: 0 })
}

/// 3×3 box blur in f32 (edge pixels replicate), to tame sensor noise before thresholding.
fn blur3(src: &[u8], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let ys = [y.saturating_sub(1), y, (y + 1).min(h - 1)];
        for x in 0..w {
            let xs = [x.saturating_sub(1), x, (x + 1).min(w - 1)];
            let mut s = 0u32;
            for &yy in &ys {
                for &xx in &xs {
                    s += u32::from(src[yy * w + xx]);
                }
            }
            out[y * w + x] = s as f32 / 9.0;
        }
    }
    out
}

/// Housing level (median of the four corner patches) and the image/housing threshold.
fn housing_threshold(img: &[f32], w: usize, h: usize) -> (f32, f32) {
    let p = (w.min(h) / 20).max(2);
    let mut corner = Vec::with_capacity(4 * p * p);
    for (x0, y0) in [(0, 0), (w - p, 0), (0, h - p), (w - p, h - p)] {
        for y in y0..y0 + p {
            corner.extend_from_slice(&img[y * w + x0..y * w + x0 + p]);
        }
    }
    corner.sort_by(f32::total_cmp);
    let housing = corner[corner.len() / 2];
    let noise = corner[(corner.len() * 9) / 10] - housing;
    let mut all: Vec<f32> = img.iter().step_by(3).copied().collect();
    all.sort_by(f32::total_cmp);
    let p95 = all[(all.len() * 95) / 100];
    let t = housing + (0.1 * (p95 - housing)).max(3.0 * noise + 2.0);
    (housing, t)
}

#[inline]
fn bilinear1(img: &[f32], w: usize, h: usize, x: f64, y: f64) -> f32 {
    // (x, y) in continuous pixel coordinates; centres at +0.5.
    let fx = (x - 0.5).clamp(0.0, (w - 1) as f64);
    let fy = (y - 0.5).clamp(0.0, (h - 1) as f64);
    let x0 = fx.floor() as usize;
    let y0 = fy.floor() as usize;
    let x1 = (x0 + 1).min(w - 1);
    let y1 = (y0 + 1).min(h - 1);
    let ax = (fx - x0 as f64) as f32;
    let ay = (fy - y0 as f64) as f32;
    let top = img[y0 * w + x0] * (1.0 - ax) + img[y0 * w + x1] * ax;
    let bot = img[y1 * w + x0] * (1.0 - ax) + img[y1 * w + x1] * ax;
    top * (1.0 - ay) + bot * ay
}

/// Edge points on rays walked inwards from the frame edge towards `centre`.
fn boundary_points(
    img: &[f32],
    w: usize,
    h: usize,
    centre: (f64, f64),
    housing: f32,
    threshold: f32,
) -> Vec<(f64, f64)> {
    const RAYS: usize = 720;
    const STEP: f64 = 0.5;
    let (cx, cy) = centre;
    let (wf, hf) = (w as f64, h as f64);
    let mut pts = Vec::with_capacity(RAYS);
    let mut profile = Vec::new();
    for i in 0..RAYS {
        let a = i as f64 * std::f64::consts::TAU / RAYS as f64;
        let (dx, dy) = (a.cos(), a.sin());
        // Distance from centre to the frame edge (pixel-centre box) along the ray.
        let tx = if dx > 0.0 {
            (wf - 0.5 - cx) / dx
        } else if dx < 0.0 {
            (0.5 - cx) / dx
        } else {
            f64::INFINITY
        };
        let ty = if dy > 0.0 {
            (hf - 0.5 - cy) / dy
        } else if dy < 0.0 {
            (0.5 - cy) / dy
        } else {
            f64::INFINITY
        };
        let t_edge = tx.min(ty);
        if !(t_edge.is_finite() && t_edge > 4.0) {
            continue;
        }
        // Profile sampled from the frame edge inwards.
        profile.clear();
        let n = (t_edge / STEP) as usize;
        for k in 0..=n {
            let t = t_edge - k as f64 * STEP;
            profile.push(bilinear1(img, w, h, cx + t * dx, cy + t * dy));
        }
        let Some(first) = profile.iter().position(|&v| v > threshold) else {
            continue;
        };
        // Starting inside the image means the circle is cut by the frame on this ray.
        if first < 3 {
            continue;
        }
        // Local image level just inside the crossing, then the half-way crossing.
        let inner_end = (first + 8).min(profile.len());
        let local = profile[first..inner_end]
            .iter()
            .copied()
            .fold(0.0f32, f32::max);
        let half = 0.5 * (housing + local);
        let mut k = first;
        while k > 0 && profile[k - 1] >= half {
            k -= 1;
        }
        while k < profile.len() && profile[k] < half {
            k += 1;
        }
        if k == 0 || k >= profile.len() {
            continue;
        }
        let (v0, v1) = (profile[k - 1], profile[k]);
        let frac = if v1 > v0 {
            f64::from((half - v0) / (v1 - v0))
        } else {
            0.0
        };
        let t = t_edge - ((k - 1) as f64 + frac) * STEP;
        pts.push((cx + t * dx, cy + t * dy));
    }
    pts
}

/// Algebraic (Kåsa) least-squares circle through points: minimises Σ(x²+y²+Dx+Ey+F)².
fn kasa_fit(pts: &[(f64, f64)]) -> Option<Circle> {
    if pts.len() < 3 {
        return None;
    }
    // Centre the data for conditioning.
    let n = pts.len() as f64;
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for &(x, y) in pts {
        let (u, v) = (x - mx, y - my);
        let row = nalgebra::Vector3::new(u, v, 1.0);
        ata += row * row.transpose();
        atb += row * (-(u * u + v * v));
    }
    let sol = ata.lu().solve(&atb)?;
    let (a, b) = (-0.5 * sol[0], -0.5 * sol[1]);
    let r2 = a * a + b * b - sol[2];
    (r2 > 0.0 && r2.is_finite()).then(|| Circle {
        cx: a + mx,
        cy: b + my,
        r: r2.sqrt(),
    })
}

/// Geometric circle fit (Gauss–Newton on orthogonal distances) from a starting circle.
fn geometric_fit(pts: &[(f64, f64)], start: Circle) -> Circle {
    let mut c = start;
    for _ in 0..20 {
        let mut jtj = nalgebra::Matrix3::<f64>::zeros();
        let mut jtr = nalgebra::Vector3::<f64>::zeros();
        for &(x, y) in pts {
            let (dx, dy) = (x - c.cx, y - c.cy);
            let d = (dx * dx + dy * dy).sqrt();
            if d < 1e-9 {
                continue;
            }
            let res = d - c.r;
            let j = nalgebra::Vector3::new(-dx / d, -dy / d, -1.0);
            jtj += j * j.transpose();
            jtr += j * res;
        }
        let Some(step) = jtj.lu().solve(&(-jtr)) else {
            break;
        };
        c.cx += step[0];
        c.cy += step[1];
        c.r += step[2];
        if step.norm() < 1e-6 {
            break;
        }
    }
    c
}

fn distance(c: &Circle, p: (f64, f64)) -> f64 {
    ((p.0 - c.cx).hypot(p.1 - c.cy) - c.r).abs()
}

/// RANSAC over point triples (deterministic xorshift seed) then geometric refinement on inliers.
fn robust_circle_fit(pts: &[(f64, f64)]) -> Result<CircleFit, FisheyeError> {
    if pts.len() < 8 {
        return Err(FisheyeError::NoCircle { points: pts.len() });
    }
    const ITERS: usize = 300;
    const INLIER_PX: f64 = 1.5;
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let mut best: Option<(usize, Circle)> = None;
    for _ in 0..ITERS {
        let tri = [
            pts[next(pts.len())],
            pts[next(pts.len())],
            pts[next(pts.len())],
        ];
        let Some(c) = kasa_fit(&tri) else { continue };
        let count = pts.iter().filter(|&&p| distance(&c, p) < INLIER_PX).count();
        if best.is_none_or(|(b, _)| count > b) {
            best = Some((count, c));
        }
    }
    let (_, mut circle) = best.ok_or(FisheyeError::NoCircle { points: pts.len() })?;
    let mut inliers: Vec<(f64, f64)> = Vec::new();
    // Refine, re-select inliers with a threshold that follows the spread of the residuals.
    let mut tol = INLIER_PX;
    for _ in 0..4 {
        inliers = pts
            .iter()
            .copied()
            .filter(|&p| distance(&circle, p) < tol)
            .collect();
        if inliers.len() < 8 {
            return Err(FisheyeError::NoCircle {
                points: inliers.len(),
            });
        }
        let start = kasa_fit(&inliers).unwrap_or(circle);
        circle = geometric_fit(&inliers, start);
        let rms = rms_distance(&circle, &inliers);
        tol = (3.0 * rms).clamp(0.75, INLIER_PX);
    }
    if !(circle.r.is_finite() && circle.r > 2.0) {
        return Err(FisheyeError::NoCircle {
            points: inliers.len(),
        });
    }
    Ok(CircleFit {
        circle,
        residual_px: rms_distance(&circle, &inliers),
        points: inliers.len(),
        candidates: pts.len(),
    })
}

fn rms_distance(c: &Circle, pts: &[(f64, f64)]) -> f64 {
    let s: f64 = pts.iter().map(|&p| distance(c, p).powi(2)).sum();
    (s / pts.len().max(1) as f64).sqrt()
}
