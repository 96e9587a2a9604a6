//! Radial fish-eye projections `r(θ)`: the classic one-parameter models and the polynomial.

use serde::{Deserialize, Serialize};

use super::{check_fov, FisheyeError};

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
    pub(crate) fn unit_radius(self, theta: f64) -> Option<f64> {
        match self {
            LensKind::Equidistant => Some(theta),
            LensKind::Equisolid => Some(2.0 * (0.5 * theta).sin()),
            LensKind::Stereographic => Some(2.0 * (0.5 * theta).tan()),
            LensKind::Orthographic => Some(theta.sin()),
            LensKind::Polynomial => None,
        }
    }

    /// Largest `θ` (radians) the one-parameter model images monotonically.
    pub(crate) fn theta_limit(self) -> f64 {
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
