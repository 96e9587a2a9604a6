//! Fish-eye lens geometry, one concept per module: radial projections `r(θ)` (`projection`),
//! lens fitting from measurements (`fit`), the visible image circle (`circle`) and the crop
//! to the 180° sky-dome (`crop`), the lens profile with its vignetting (`profile`, stored as
//! JSON) and the fall-off measured on flat fields (`flat_field`).
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

mod circle;
mod crop;
mod fit;
mod flat_field;
mod profile;
mod projection;

pub(crate) use circle::detect_circle_rgb8;
pub use circle::{detect_circle, detect_circle_luma, CircleFit};
pub use crop::{crop_dome, crop_dome_from, crop_dome_owned, dome_crop_box, DomeCrop};
pub use fit::{fit_projection, parse_angle_radius_csv, AngleRadius, LensFit, ModelFit};
pub use flat_field::{flat_field_falloff, RING_DEG};
pub use profile::{devignette, LensProfile, Vignetting, LENS_PROFILE_VERSION};
pub use projection::{LensKind, Projection};

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
    #[error(transparent)]
    BufferSize(#[from] crate::image::BufferSizeError),
    /// No boundary between housing and image was found.
    #[error("no lens circle found ({points} boundary points): use the best-exposed frame, or give the circle by hand")]
    NoCircle {
        /// Boundary points found.
        points: usize,
    },
    /// A circle was found, but what surrounds it is not a lens housing: its corners are not dark
    /// against the circle's inside (a test pattern, a round object in an ordinary photo).
    #[error("a circle was found but no dark lens housing around it (the corners are at {housing_percent:.0} % of the circle's level): not a fish-eye picture circle; give the circle by hand if it is one")]
    NoHousing {
        /// The corners' level as a percentage of the median level inside the circle.
        housing_percent: f64,
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
    /// A line of a lens-measurement CSV is not an `angle_deg,radius_px` pair.
    #[error("line {line}: expected 'angle_deg,radius_px', got '{text}'")]
    BadCsvLine {
        /// Line number, from 1.
        line: usize,
        /// The line.
        text: String,
    },
    /// A lens profile JSON could not be read or written.
    #[error("lens profile JSON: {0}; fix the file or regenerate it with `skydome lens`")]
    Json(#[from] serde_json::Error),
    /// The lens profile has a version this build does not know.
    #[error("lens profile version {0} is not supported (this build reads version {LENS_PROFILE_VERSION}): regenerate it")]
    Version(u32),
}

pub(crate) fn check_fov(fov_deg: f64) -> Result<(), FisheyeError> {
    if !(fov_deg.is_finite() && fov_deg > 0.0 && fov_deg < 360.0) {
        return Err(FisheyeError::BadParameter {
            what: "field of view (degrees)",
            value: fov_deg,
            hint: "give the lens's full field of view in degrees, e.g. 235",
        });
    }
    Ok(())
}
