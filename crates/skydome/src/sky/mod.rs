//! Sky geometry: the mapping between fish-eye pixels and sky directions (azimuth, elevation),
//! the north point, and the sun (tapped, detected, or computed from time and place).
//!
//! # Conventions
//! - World frame **ENU**: `x` = east, `y` = north, `z` = up (unit vectors `[e, n, u]`).
//! - Azimuth from true north towards east (0° = N, 90° = E), elevation above the horizon; both in
//!   **degrees** at the API ([`Direction`]), radians inside.
//! - Pixels: origin top-left, `x` right, `y` down, centres at `+0.5` ([`crate::image`]); pixel
//!   positions refer to the image **as stored** (before any EXIF rotation is applied).
//!
//! # From pixels to the sky, derived
//! The phone's own axes (Android's sensor frame) are `X` = towards its right edge, `Y` = towards
//! its top edge, `Z` = out of the screen. The compass azimuth `A` the phone reports is that of
//! `Y` projected on the horizon. Lying flat, `Y = (sin A, cos A, 0)`, `Z = ±up`, `X = Y × Z`.
//! Displayed upright in the phone's natural (portrait) orientation, a rear-camera image (looking
//! along `−Z`) has image-right = `X` and image-up = `Y`; an unmirrored front-camera image
//! (looking along `+Z`) has image-right = `−X`, image-up = `Y`. Both bases
//! `(right, down, axis)` are right-handed, so both poses give the **same** picture of the sky:
//!
//! > Phone lying screen-down (rear camera looking at the zenith), top edge pointing at compass
//! > azimuth `A`: the displayed image shows the sky direction of azimuth `A` at the **top**,
//! > `A + 90°` on the **left**, `A + 180°` at the bottom and `A − 90°` on the right. With `A = 0`:
//! > north at the top, **east on the left**, west on the right (a map seen from below).
//! > In formulas, a ray at zenith angle `θ` and azimuth `φ` lands at
//! > `x = cx − r(θ)·sin(φ − A)`, `y = cy − r(θ)·cos(φ − A)`, and north sits at
//! > `(cx − r(90°)·sin(−A), cy − r(90°)·cos(A))`.
//!
//! The stored pixels relate to the displayed image by the EXIF orientation
//! ([`ImageOrientation`], tags 1–8: rotations by 90/180/270° and mirrors). Only its linear part
//! matters because offsets are taken from the optical centre, which the transform carries along.
//! Phones lying flat cannot tell which edge is up from gravity, so the tag they write is often
//! stale: let the user override it. The seed's Listing 2 rotates the north point by the compass
//! angle with a π written as 3.143 (a 0.03 % angle error) and ignores the orientation tag; here
//! the mapping is the rotation above, exact, and tested against the closed form.
//!
//! # Sun
//! - Tap: [`SkyGeometry::pixel_to_direction`] on the tapped pixel.
//! - Detection ([`detect_sun`]): luminance, a small box blur, background = median and peak = max
//!   inside the dome; pixels above half-way between them form 8-connected blobs; the blob with
//!   the most energy above the threshold wins and its centroid (weighted by unblurred luminance
//!   above background) is the sun. Confidence = compactness (area over the area of the smallest
//!   centred disc holding it) × size (1 up to an equivalent radius of 8 % of the dome radius,
//!   0 from 20 %: glare around a clipped sun in an 8-bit frame grows well past the 0.53° disc) × contrast (`log10(peak/background)/2`, capped at 1) × ambiguity
//!   (`1 − runner-up energy / winner energy`). `None` when the peak is less than twice the
//!   background or the confidence is below 0.15 — an overcast sky or a sun behind a building
//!   has no compact outstanding blob.
//! - Ephemeris ([`sun_ephemeris`]): NREL's Solar Position Algorithm (Reda & Andreas, *Solar
//!   Energy* 76 (2004) 577–589) through the `solar-positioning` crate, topocentric, with optional
//!   refraction; ±0.0003° over −2000…6000.
//! - Cross-check ([`cross_check`]): the angle between detected and computed sun, and the compass
//!   error `computed azimuth − detected azimuth`: adding it to the north azimuth rotates every
//!   decoded azimuth by the same amount (in either handedness), so the two agree in azimuth.

mod ephemeris;
mod geometry;
mod sun;

pub use ephemeris::{cross_check, sun_ephemeris, Refraction, Site, SunCrossCheck};
// Radiance's luminance formula lives beside the pixels; re-exported where the sky's users look.
pub use crate::image::{radiance_luminance, RADIANCE_EFFICACY};
pub use geometry::{DevicePose, ImageOrientation, Level, SkyGeometry};
pub use sun::{
    detect_sun, detect_sun_luma, detect_sun_u8, find_sun, SunClues, SunDetection, SUN_BRIGHT_RATIO,
    SUN_CORE_MAX_DEG,
};

use serde::{Deserialize, Serialize};

/// Errors from sky geometry, sun detection and ephemeris.
#[derive(Debug, thiserror::Error)]
pub enum SkyError {
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
    /// An EXIF orientation tag outside 1..=8.
    #[error("EXIF orientation {0} is not one of 1..=8: pass the tag from the file or 1 for none")]
    BadOrientation(u16),
    /// The sample buffer does not match the stated size.
    #[error(transparent)]
    BufferSize(#[from] crate::image::BufferSizeError),
    /// The lens profile is unusable.
    #[error(transparent)]
    Lens(#[from] crate::fisheye::FisheyeError),
    /// The solar-position algorithm refused the inputs.
    #[error("sun position: {0}; check the capture time (years −2000…6000) and the location")]
    Ephemeris(String),
}

/// A direction in the sky: azimuth from true north towards east and elevation above the horizon,
/// both in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Direction {
    /// Azimuth in degrees from true north towards east, `[0, 360)`.
    pub azimuth_deg: f64,
    /// Elevation above the horizon in degrees, `[−90, 90]`.
    pub elevation_deg: f64,
}

impl Direction {
    /// A direction from azimuth and elevation in degrees (azimuth is wrapped into `[0, 360)`).
    pub fn new(azimuth_deg: f64, elevation_deg: f64) -> Direction {
        Direction {
            azimuth_deg: azimuth_deg.rem_euclid(360.0),
            elevation_deg,
        }
    }

    /// Unit vector in ENU (`[east, north, up]`).
    pub fn to_vector(&self) -> [f64; 3] {
        let (sa, ca) = self.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = self.elevation_deg.to_radians().sin_cos();
        [ce * sa, ce * ca, se]
    }

    /// The direction of an ENU vector (need not be unit length; zero gives the zenith).
    pub fn from_vector(v: [f64; 3]) -> Direction {
        let h = v[0].hypot(v[1]);
        if h == 0.0 && v[2] == 0.0 {
            return Direction::new(0.0, 90.0);
        }
        Direction::new(v[0].atan2(v[1]).to_degrees(), v[2].atan2(h).to_degrees())
    }

    /// Great-circle angle to another direction, degrees (robust for tiny angles).
    pub fn angle_to(&self, other: &Direction) -> f64 {
        let a = self.to_vector();
        let b = other.to_vector();
        let cross = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let s = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
        let c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        s.atan2(c).to_degrees()
    }
}
