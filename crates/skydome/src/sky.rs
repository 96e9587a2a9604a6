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

use serde::{Deserialize, Serialize};
use time::OffsetDateTime;

use crate::fisheye::{LensProfile, Projection};
use crate::image::PixelPoint;
// Radiance's luminance formula lives beside the pixels; re-exported where the sky's users look.
use crate::image::{luminance, Circle, HdrImage, RgbImage};
pub use crate::image::{radiance_luminance, RADIANCE_EFFICACY};

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

/// How the phone lay while taking the sky photos (which camera looked at the zenith).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DevicePose {
    /// Lying screen-down, the rear camera (with the clip-on lens) looking at the zenith — the
    /// seed's setup.
    #[default]
    ScreenDown,
    /// Lying screen-up, the front camera looking at the zenith; images stored unmirrored (if the
    /// phone saved a mirrored selfie, use a mirroring [`ImageOrientation`]).
    ScreenUp,
}

crate::named_enum!(DevicePose, "device pose", [ScreenDown => "screen-down", ScreenUp => "screen-up"]);

/// EXIF orientation: how the stored pixels must be transformed to display the image upright
/// (in the phone's natural orientation). Values are the EXIF tag (274) numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ImageOrientation {
    /// 1: stored upright.
    #[default]
    Normal = 1,
    /// 2: mirror left–right to display.
    MirrorHorizontal = 2,
    /// 3: rotate 180°.
    Rotate180 = 3,
    /// 4: mirror top–bottom.
    MirrorVertical = 4,
    /// 5: mirror left–right then rotate 270° clockwise (transpose).
    Transpose = 5,
    /// 6: rotate 90° clockwise to display (portrait shots from a landscape sensor).
    Rotate90 = 6,
    /// 7: mirror left–right then rotate 90° clockwise (transverse).
    Transverse = 7,
    /// 8: rotate 270° clockwise (90° anticlockwise) to display.
    Rotate270 = 8,
}

impl ImageOrientation {
    /// From the EXIF tag value (1..=8).
    pub fn from_exif(tag: u16) -> Result<Self, SkyError> {
        Ok(match tag {
            1 => Self::Normal,
            2 => Self::MirrorHorizontal,
            3 => Self::Rotate180,
            4 => Self::MirrorVertical,
            5 => Self::Transpose,
            6 => Self::Rotate90,
            7 => Self::Transverse,
            8 => Self::Rotate270,
            other => return Err(SkyError::BadOrientation(other)),
        })
    }

    /// The EXIF tag value.
    pub fn exif(self) -> u16 {
        self as u16
    }

    /// Linear map of pixel offsets (x right, y down) from stored to displayed: `[[a, b], [c, d]]`
    /// with `displayed = (a·x + b·y, c·x + d·y)`.
    pub fn stored_to_displayed(self) -> [[f64; 2]; 2] {
        match self {
            Self::Normal => [[1.0, 0.0], [0.0, 1.0]],
            Self::MirrorHorizontal => [[-1.0, 0.0], [0.0, 1.0]],
            Self::Rotate180 => [[-1.0, 0.0], [0.0, -1.0]],
            Self::MirrorVertical => [[1.0, 0.0], [0.0, -1.0]],
            Self::Transpose => [[0.0, 1.0], [1.0, 0.0]],
            // 90° clockwise on screen (y down): the top (0,−1) goes to the right (1,0).
            Self::Rotate90 => [[0.0, -1.0], [1.0, 0.0]],
            Self::Transverse => [[0.0, -1.0], [-1.0, 0.0]],
            Self::Rotate270 => [[0.0, 1.0], [-1.0, 0.0]],
        }
    }
}

/// Everything needed to map pixels of a fish-eye sky image to sky directions and back.
#[derive(Debug, Clone, PartialEq)]
pub struct SkyGeometry {
    cx: f64,
    cy: f64,
    projection: Projection,
    theta_max: f64,
    theta_limit: f64,
    north_azimuth_deg: f64,
    pose: DevicePose,
    orientation: ImageOrientation,
    // Camera basis in ENU: image-right, image-down (displayed image) and optical axis.
    right: [f64; 3],
    down: [f64; 3],
    axis: [f64; 3],
    // Stored → displayed offset map and its inverse.
    to_disp: [[f64; 2]; 2],
    to_stored: [[f64; 2]; 2],
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn neg(a: [f64; 3]) -> [f64; 3] {
    [-a[0], -a[1], -a[2]]
}

impl SkyGeometry {
    /// Geometry of an image taken through `lens` (optical centre = the lens circle's centre, in
    /// stored pixels), with the phone's top edge at compass azimuth `north_azimuth_deg` (degrees
    /// from true north towards east, as the compass reported it), lying in `pose`, stored with
    /// EXIF `orientation`. Directions are mapped up to `θ = fov/2` of the lens.
    pub fn new(
        lens: &LensProfile,
        north_azimuth_deg: f64,
        pose: DevicePose,
        orientation: ImageOrientation,
    ) -> Result<Self, SkyError> {
        lens.validate()?;
        if !north_azimuth_deg.is_finite() {
            return Err(SkyError::BadParameter {
                what: "north azimuth (degrees)",
                value: north_azimuth_deg,
                hint: "give the compass azimuth of the phone's top edge in degrees",
            });
        }
        let a = north_azimuth_deg.to_radians();
        let y_dev = [a.sin(), a.cos(), 0.0];
        let (right, down, axis) = match pose {
            DevicePose::ScreenDown => {
                let z_dev = [0.0, 0.0, -1.0];
                let x_dev = cross(y_dev, z_dev);
                (x_dev, neg(y_dev), neg(z_dev))
            }
            DevicePose::ScreenUp => {
                let z_dev = [0.0, 0.0, 1.0];
                let x_dev = cross(y_dev, z_dev);
                (neg(x_dev), neg(y_dev), z_dev)
            }
        };
        let m = orientation.stored_to_displayed();
        // Every EXIF map is orthogonal, so its inverse is its transpose.
        let inv = [[m[0][0], m[1][0]], [m[0][1], m[1][1]]];
        Ok(SkyGeometry {
            cx: lens.circle.cx,
            cy: lens.circle.cy,
            projection: lens.projection,
            theta_max: (0.5 * lens.fov_deg.to_radians()).min(lens.projection.theta_limit()),
            theta_limit: lens.projection.theta_limit(),
            north_azimuth_deg,
            pose,
            orientation,
            right,
            down,
            axis,
            to_disp: m,
            to_stored: inv,
        })
    }

    /// The same geometry for a phone that was not lying level: the camera basis is rebuilt from
    /// the accelerometer (`Level::Gravity`, with the compass azimuth and pose given to [`new`])
    /// or rotated by a tilt of the optical axis (`Level::Tilt`). Errors for a reading that
    /// cannot be a phone looking up (zero, the top edge vertical, the camera facing the ground).
    ///
    /// [`new`]: SkyGeometry::new
    pub fn with_level(&self, level: &Level) -> Result<SkyGeometry, SkyError> {
        let (right, down, axis) = match *level {
            Level::Gravity(g) => self.basis_from_gravity(g)?,
            Level::Tilt {
                tilt_deg,
                azimuth_deg,
            } => {
                if !(tilt_deg.is_finite()
                    && (0.0..90.0).contains(&tilt_deg)
                    && azimuth_deg.is_finite())
                {
                    return Err(SkyError::BadParameter {
                        what: "tilt (degrees)",
                        value: tilt_deg,
                        hint: "give the optical axis's tilt from the zenith, 0 to 90°, and a finite azimuth",
                    });
                }
                let (t, a) = (tilt_deg.to_radians(), azimuth_deg.to_radians());
                // Rotate about the horizontal axis k = up × (towards a), taking up to a.
                let k = [-a.cos(), a.sin(), 0.0];
                let rot = |v: [f64; 3]| -> [f64; 3] {
                    let (c, s) = (t.cos(), t.sin());
                    let kv = cross(k, v);
                    let kd = dot(k, v) * (1.0 - c);
                    [0, 1, 2].map(|i| v[i] * c + kv[i] * s + k[i] * kd)
                };
                (rot(self.right), rot(self.down), rot(self.axis))
            }
        };
        Ok(SkyGeometry {
            right,
            down,
            axis,
            ..self.clone()
        })
    }

    /// (right, down, axis) in ENU from the accelerometer's up vector `g` in the phone's axes.
    #[allow(clippy::type_complexity)]
    fn basis_from_gravity(&self, g: [f64; 3]) -> Result<([f64; 3], [f64; 3], [f64; 3]), SkyError> {
        let bad = |hint| SkyError::BadParameter {
            what: "gravity vector",
            value: g[0].hypot(g[1]).hypot(g[2]),
            hint,
        };
        let norm = |v: [f64; 3]| -> Option<[f64; 3]> {
            let n = dot(v, v).sqrt();
            (n.is_finite() && n > 1e-9).then(|| v.map(|x| x / n))
        };
        let u = norm(g).ok_or_else(|| {
            bad("give the accelerometer's reading at rest, x,y,z in the phone's axes")
        })?;
        // The top edge's horizontal direction, in the phone's axes.
        let h = norm([-u[1] * u[0], 1.0 - u[1] * u[1], -u[1] * u[2]])
            .filter(|_| u[1].abs() < 0.99)
            .ok_or_else(|| {
                bad("the phone stood on its edge: the top edge must not point up or down")
            })?;
        let w = cross(h, u);
        let a = self.north_azimuth_deg.to_radians();
        let (rh, rw) = ([a.sin(), a.cos(), 0.0], [a.cos(), -a.sin(), 0.0]);
        let world = |v: [f64; 3]| -> [f64; 3] {
            let (ph, pw, pu) = (dot(v, h), dot(v, w), dot(v, u));
            [0, 1, 2].map(|i| ph * rh[i] + pw * rw[i] + if i == 2 { pu } else { 0.0 })
        };
        let (x, y, z) = (
            world([1.0, 0.0, 0.0]),
            world([0.0, 1.0, 0.0]),
            world([0.0, 0.0, 1.0]),
        );
        let basis = match self.pose {
            DevicePose::ScreenDown => (x, neg(y), neg(z)),
            DevicePose::ScreenUp => (neg(x), neg(y), z),
        };
        if basis.2[2] <= 0.0 {
            return Err(bad(
                "the camera faced the ground: check the device pose (screen-down or screen-up)",
            ));
        }
        Ok(basis)
    }

    /// The same geometry for an image whose optical centre is at `(cx, cy)` — e.g. after
    /// [`crate::fisheye::crop_dome`], pass its `horizon.cx, horizon.cy`.
    pub fn with_centre(&self, cx: f64, cy: f64) -> SkyGeometry {
        SkyGeometry {
            cx,
            cy,
            ..self.clone()
        }
    }

    /// Optical centre in stored pixels `(x, y)`.
    pub fn centre(&self) -> (f64, f64) {
        (self.cx, self.cy)
    }

    /// The radial projection (pixels, radians).
    pub fn projection(&self) -> &Projection {
        &self.projection
    }

    /// Largest zenith-side angle from the optical axis that is mapped, radians.
    pub fn theta_max(&self) -> f64 {
        self.theta_max
    }

    /// Compass azimuth of the phone's top edge, degrees.
    pub fn north_azimuth_deg(&self) -> f64 {
        self.north_azimuth_deg
    }

    /// The pose.
    pub fn pose(&self) -> DevicePose {
        self.pose
    }

    /// The stored image's EXIF orientation.
    pub fn orientation(&self) -> ImageOrientation {
        self.orientation
    }

    /// The 180° horizon circle (`θ = 90°` from the optical axis) in stored pixels.
    pub fn horizon_circle(&self) -> Circle {
        Circle {
            cx: self.cx,
            cy: self.cy,
            r: self.projection.radius(std::f64::consts::FRAC_PI_2),
        }
    }

    /// Pixel of an ENU unit vector, continuous coordinates; `None` beyond the lens's field.
    #[inline]
    pub fn vector_to_pixel(&self, v: [f64; 3]) -> Option<(f64, f64)> {
        let (a, b, c) = (dot(v, self.right), dot(v, self.down), dot(v, self.axis));
        let rho = a.hypot(b);
        let theta = rho.atan2(c);
        if theta > self.theta_max + 1e-12 {
            return None;
        }
        let r = self.projection.radius(theta);
        let (ux, uy) = if rho > 0.0 {
            (a / rho, b / rho)
        } else {
            (0.0, 0.0)
        };
        let (dx, dy) = (r * ux, r * uy);
        let m = &self.to_stored;
        Some((
            self.cx + m[0][0] * dx + m[0][1] * dy,
            self.cy + m[1][0] * dx + m[1][1] * dy,
        ))
    }

    /// ENU unit vector seen at continuous pixel position `(x, y)`; `None` outside the lens's field.
    #[inline]
    pub fn pixel_to_vector(&self, x: f64, y: f64) -> Option<[f64; 3]> {
        let (sx, sy) = (x - self.cx, y - self.cy);
        let m = &self.to_disp;
        let dx = m[0][0] * sx + m[0][1] * sy;
        let dy = m[1][0] * sx + m[1][1] * sy;
        let rho = dx.hypot(dy);
        let theta = self.projection.theta_within(rho, self.theta_limit)?;
        if theta > self.theta_max + 1e-12 {
            return None;
        }
        let (st, ct) = theta.sin_cos();
        let (ux, uy) = if rho > 0.0 {
            (dx / rho, dy / rho)
        } else {
            (0.0, 0.0)
        };
        let mut v = [0.0; 3];
        for (i, vi) in v.iter_mut().enumerate() {
            *vi = st * (ux * self.right[i] + uy * self.down[i]) + ct * self.axis[i];
        }
        Some(v)
    }

    /// Where a sky direction lands in the stored image; `None` beyond the lens's field of view.
    pub fn direction_to_pixel(&self, d: &Direction) -> Option<PixelPoint> {
        self.vector_to_pixel(d.to_vector())
            .map(|(x, y)| PixelPoint { x, y })
    }

    /// The sky direction seen at a stored pixel position (e.g. the user's tap on the sun);
    /// `None` outside the lens's field of view.
    pub fn pixel_to_direction(&self, p: PixelPoint) -> Option<Direction> {
        self.pixel_to_vector(p.x, p.y).map(Direction::from_vector)
    }

    /// Radiance's view options (`VIEW=`) for a square image centred on the optical axis that
    /// extends `half_extent_px` pixels from the centre to each edge, in this lens's projection:
    /// the view type (`-vta` equidistant, `-vts` stereographic, `-vth` orthographic), the
    /// view direction `-vd` (the optical axis, `0 0 1` for an upward view) and up vector `-vu`
    /// (the world direction of the image's top edge: `0 1 0` when north is at the top) in
    /// Radiance's usual world frame (`+X` east, `+Y` north, `+Z` up — the frame of `gensky` and
    /// `gendaylit`), and `-vh`/`-vv` the angle the image spans edge to edge. `None` when Radiance
    /// has no view type for the projection (equisolid, polynomial: write the angular map
    /// instead), or when the stored image is mirrored (a Radiance view never is).
    pub fn radiance_view(&self, half_extent_px: f64) -> Option<String> {
        use crate::fisheye::LensKind;
        let kind = self.projection.kind();
        let t = match kind {
            LensKind::Equidistant => "a",
            LensKind::Stereographic => "s",
            LensKind::Orthographic => "h",
            LensKind::Equisolid | LensKind::Polynomial => return None,
        };
        let fov = match self.projection.theta(half_extent_px) {
            Some(theta) => 2.0 * theta.to_degrees(),
            // A hemispherical view holds at most 180°; the image is at most a pixel wider.
            None if kind == LensKind::Orthographic => 180.0,
            None => return None,
        };
        let world = |sx: f64, sy: f64| -> [f64; 3] {
            let m = &self.to_disp;
            let (dx, dy) = (m[0][0] * sx + m[0][1] * sy, m[1][0] * sx + m[1][1] * sy);
            let mut v = [0.0; 3];
            for (i, vi) in v.iter_mut().enumerate() {
                *vi = dx * self.right[i] + dy * self.down[i];
            }
            v
        };
        let (vd, vu, right) = (self.axis, world(0.0, -1.0), world(1.0, 0.0));
        if dot(cross(vd, vu), right) < 0.5 {
            return None;
        }
        let n = |x: f64| {
            let r = (x * 1e6).round() / 1e6;
            crate::image::fmt_num(if r == 0.0 { 0.0 } else { r })
        };
        let v3 = |v: [f64; 3]| format!("{} {} {}", n(v[0]), n(v[1]), n(v[2]));
        let fov = n(fov);
        Some(format!(
            "-vt{t} -vp 0 0 0 -vd {} -vu {} -vh {fov} -vv {fov}",
            v3(vd),
            v3(vu)
        ))
    }

    /// The geometry of a `width × height` picture from its Radiance `VIEW=` options, when it is
    /// an upward fish-eye skydome (or Radiance) can integrate: a square picture, `-vta`,
    /// `-vts` or `-vth`, `-vd 0 0 1`, a horizontal `-vu` (its azimuth is the top edge's, north
    /// for `0 1 0`) and `-vh` = `-vv` (the angle the picture spans edge to edge). `None`
    /// otherwise. The inverse of [`SkyGeometry::radiance_view`] for the views it writes.
    pub fn from_radiance_view(view: &str, width: usize, height: usize) -> Option<SkyGeometry> {
        use crate::fisheye::{LensKind, LensProfile};
        let tokens: Vec<&str> = view.split_whitespace().collect();
        let (mut kind, mut vd, mut vu, mut vh, mut vv) = (None, None, [0.0, 1.0, 0.0], None, None);
        let num = |i: usize| tokens.get(i).and_then(|t| t.parse::<f64>().ok());
        let vec3 = |i: usize| Some([num(i)?, num(i + 1)?, num(i + 2)?]);
        for (i, t) in tokens.iter().enumerate() {
            match *t {
                "-vta" => kind = Some(LensKind::Equidistant),
                "-vts" => kind = Some(LensKind::Stereographic),
                "-vth" => kind = Some(LensKind::Orthographic),
                t if t.starts_with("-vt") => return None,
                "-vd" => vd = vec3(i + 1),
                "-vu" => vu = vec3(i + 1)?,
                "-vh" => vh = num(i + 1),
                "-vv" => vv = num(i + 1),
                _ => {}
            }
        }
        let (kind, vd, vh, vv) = (kind?, vd?, vh?, vv?);
        let len = (vd[0] * vd[0] + vd[1] * vd[1] + vd[2] * vd[2]).sqrt();
        let upward = len > 0.0 && (vd[2] / len - 1.0).abs() < 1e-9;
        let level_up = vu[2].abs() < 1e-9 && vu[0].hypot(vu[1]) > 0.0;
        if !(upward && level_up && width == height && width > 0 && (vh - vv).abs() < 1e-6) {
            return None;
        }
        let half = 0.5 * width as f64;
        let circle = crate::image::Circle {
            cx: half,
            cy: half,
            r: half,
        };
        let lens = LensProfile::from_fov(circle, vh, kind).ok()?;
        let north = vu[0].atan2(vu[1]).to_degrees();
        SkyGeometry::new(
            &lens,
            north,
            DevicePose::ScreenDown,
            ImageOrientation::Normal,
        )
        .ok()
    }

    /// The north point: where true north meets the horizon (for `#NORTH=`), stored pixels.
    pub fn north_point(&self) -> PixelPoint {
        self.compass_point(0.0)
    }

    /// The point of the horizon circle at azimuth `azimuth_deg`, stored pixels.
    pub fn compass_point(&self, azimuth_deg: f64) -> PixelPoint {
        let v = Direction::new(azimuth_deg, 0.0).to_vector();
        // θ = 90° is inside every supported lens (fov ≥ 180°); fall back to the raw projection
        // for narrower lenses so the marker still shows where north would be.
        self.vector_to_pixel(v)
            .map(|(x, y)| PixelPoint { x, y })
            .unwrap_or_else(|| {
                let r = self.projection.radius(std::f64::consts::FRAC_PI_2);
                let (a, b) = (dot(v, self.right), dot(v, self.down));
                let m = &self.to_stored;
                PixelPoint {
                    x: self.cx + r * (m[0][0] * a + m[0][1] * b),
                    y: self.cy + r * (m[1][0] * a + m[1][1] * b),
                }
            })
    }
}

/// How the phone lay, when not level (see [`SkyGeometry::with_level`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// The accelerometer's reading at rest, `[x, y, z]` in the phone's own axes (`x` towards its
    /// right edge, `y` its top edge, `z` out of the screen), any unit. It points **up**, away
    /// from the ground, as Android's gravity sensor and Chrome's
    /// `DeviceMotionEvent.accelerationIncludingGravity` report it: lying screen-down it is
    /// `(0, 0, −9.81)`.
    Gravity([f64; 3]),
    /// The optical axis tilted `tilt_deg` degrees from the zenith towards compass azimuth
    /// `azimuth_deg`.
    Tilt {
        /// Tilt of the optical axis from the zenith, degrees, `0..90`.
        tilt_deg: f64,
        /// Azimuth the axis leans towards, degrees from north towards east.
        azimuth_deg: f64,
    },
}

/// A detected sun.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SunDetection {
    /// Centroid of the sun blob, pixels.
    pub pixel: PixelPoint,
    /// Confidence in `[0, 1]` (see the module docs).
    pub confidence: f64,
    /// Blob area in pixels.
    pub area_px: usize,
    /// Peak (blurred) luminance over the dome's median luminance.
    pub peak_to_background: f64,
}

/// Finds the sun in a radiance image inside `region` (usually the horizon circle).
/// Returns `None` when no compact outstanding blob exists (overcast, sun hidden).
pub fn detect_sun(img: &HdrImage, region: &Circle) -> Option<SunDetection> {
    let luma: Vec<f32> = img.pixels().map(luminance).collect();
    detect_sun_luma(&luma, img.width, img.height, region)
        .ok()
        .flatten()
}

/// [`detect_sun`] on an 8-bit frame (codes used as they are: pick a mid exposure where the sun
/// is saturated but the sky is not).
pub fn detect_sun_u8(img: &RgbImage<u8>, region: &Circle) -> Option<SunDetection> {
    let luma: Vec<f32> = img
        .data
        .chunks_exact(3)
        .map(|c| luminance([f32::from(c[0]), f32::from(c[1]), f32::from(c[2])]))
        .collect();
    detect_sun_luma(&luma, img.width, img.height, region)
        .ok()
        .flatten()
}

/// [`detect_sun`] on a luminance buffer (`width * height`, row-major, origin top-left).
/// Errors only when the buffer size is wrong or the region is not a finite positive circle.
pub fn detect_sun_luma(
    luma: &[f32],
    width: usize,
    height: usize,
    region: &Circle,
) -> Result<Option<SunDetection>, SkyError> {
    crate::image::check_samples(luma.len(), width, height, 1)?;
    if !(region.r.is_finite() && region.r > 0.0 && region.cx.is_finite() && region.cy.is_finite()) {
        return Err(SkyError::BadParameter {
            what: "sun search radius (px)",
            value: region.r,
            hint: "give the dome's horizon circle",
        });
    }
    // Bounding box of the region inside the frame.
    let x0 = (region.cx - region.r).floor().max(0.0) as usize;
    let y0 = (region.cy - region.r).floor().max(0.0) as usize;
    let x1 = ((region.cx + region.r).ceil().max(0.0) as usize).min(width);
    let y1 = ((region.cy + region.r).ceil().max(0.0) as usize).min(height);
    if x1 <= x0 || y1 <= y0 {
        return Ok(None);
    }
    let (bw, bh) = (x1 - x0, y1 - y0);
    // Box blur of radius b over region pixels (outside pixels do not count).
    let b = ((region.r / 150.0).round() as usize).max(1);
    let raw = |x: usize, y: usize| {
        let v = luma[(y0 + y) * width + x0 + x];
        if v.is_finite() {
            v.max(0.0)
        } else {
            0.0
        }
    };
    let blurred = region_box_mean(luma, width, (x0, y0, bw, bh), region, b);
    let Some((background, peak)) = median_and_peak(&blurred) else {
        return Ok(None);
    };
    let bg = background.max(peak * 1e-9).max(f32::MIN_POSITIVE);
    let ratio = f64::from(peak / bg);
    if !(peak > 0.0 && ratio >= 2.0) {
        return Ok(None);
    }
    let t = background + 0.5 * (peak - background);

    // 8-connected components above t.
    let mut label = vec![0u32; bw * bh];
    let mut comps: Vec<(f64, Vec<usize>)> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..bw * bh {
        if label[start] != 0 || blurred[start].is_nan() || blurred[start] < t {
            continue;
        }
        let id = comps.len() as u32 + 1;
        label[start] = id;
        stack.push(start);
        let mut members = Vec::new();
        let mut energy = 0.0f64;
        while let Some(i) = stack.pop() {
            members.push(i);
            energy += f64::from(blurred[i] - t);
            let (x, y) = (i % bw, i / bw);
            for ny in y.saturating_sub(1)..(y + 2).min(bh) {
                for nx in x.saturating_sub(1)..(x + 2).min(bw) {
                    let j = ny * bw + nx;
                    if label[j] == 0 && blurred[j] >= t {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        // Saturated plateaus have zero energy above t; count area so they still rank.
        comps.push((
            energy + 1e-6 * f64::from(peak - background) * members.len() as f64,
            members,
        ));
    }
    comps.sort_by(|a, b| b.0.total_cmp(&a.0));
    let Some((best_energy, members)) = comps.first() else {
        return Ok(None);
    };
    let runner_up = comps.get(1).map_or(0.0, |c| c.0);

    // Shape is judged around the blob's centroid; the sun's centre is the centroid of its core
    // (raw values within the top tenth of the blob's range): the sky's gradient and glare skew
    // the aureole around a clipped sun, not its saturated core.
    let core = members
        .iter()
        .map(|&i| raw(i % bw, i / bw))
        .fold(background, f32::max);
    let centroid = |floor: f32| {
        let (mut sx, mut sy, mut sw) = (0.0f64, 0.0f64, 0.0f64);
        for &i in members {
            let (x, y) = (i % bw, i / bw);
            let w = f64::from((raw(x, y) - floor).max(0.0)) + 1e-12;
            sx += w * (x as f64 + 0.5);
            sy += w * (y as f64 + 0.5);
            sw += w;
        }
        (sx / sw, sy / sw)
    };
    let (mx, my) = centroid(background);
    let (sun_x, sun_y) = centroid(background + 0.9 * (core - background));
    let rmax = members
        .iter()
        .map(|&i| ((i % bw) as f64 + 0.5 - mx).hypot((i / bw) as f64 + 0.5 - my))
        .fold(0.0f64, f64::max)
        + 0.5;
    let area = members.len() as f64;
    let compactness = (area / (std::f64::consts::PI * rmax * rmax)).min(1.0);
    let r_eq = (area / std::f64::consts::PI).sqrt() / region.r;
    let size = ((0.20 - r_eq) / 0.12).clamp(0.0, 1.0);
    let contrast = (ratio.log10() / 2.0).clamp(0.0, 1.0);
    let ambiguity = 1.0 - (runner_up / best_energy).clamp(0.0, 1.0);
    let confidence = compactness * size * contrast * ambiguity;
    if confidence < 0.15 {
        return Ok(None);
    }
    Ok(Some(SunDetection {
        pixel: PixelPoint {
            x: x0 as f64 + sun_x,
            y: y0 as f64 + sun_y,
        },
        confidence,
        area_px: members.len(),
        peak_to_background: ratio,
    }))
}

/// The median (the `n/2`-th smallest, as `select_nth_unstable`) and the largest of the
/// non-NaN values (all non-negative and finite here), or `None` for fewer than 16.
///
/// Exact, in two passes instead of a copy and a selection of millions of values: for
/// non-negative floats the bit patterns sort as the values do, so a histogram of the top 16
/// bits finds the bin holding the median, and only that bin's values are selected among.
fn median_and_peak(values: &[f32]) -> Option<(f32, f32)> {
    let mut hist = vec![0u32; 1 << 16];
    let (mut n, mut peak) = (0usize, 0.0f32);
    for &v in values.iter().filter(|v| !v.is_nan()) {
        hist[(v.to_bits() >> 16) as usize] += 1;
        n += 1;
        peak = crate::fastmath::max(v, peak);
    }
    if n < 16 {
        return None;
    }
    let mut rank = n / 2;
    let mut bin = 0;
    for (b, &count) in hist.iter().enumerate() {
        if rank < count as usize {
            bin = b as u32;
            break;
        }
        rank -= count as usize;
    }
    let mut in_bin: Vec<f32> = values
        .iter()
        .copied()
        .filter(|v| !v.is_nan() && v.to_bits() >> 16 == bin)
        .collect();
    let median = *in_bin.select_nth_unstable_by(rank, f32::total_cmp).1;
    Some((median, peak))
}

/// Mean of the pixels of `region` in the `(2b + 1)²` window around each pixel of the box
/// `x0..x0 + bw`, `y0..y0 + bh` (row-major, `bw * bh`; outside pixels `NaN` and not counted;
/// non-finite values count as 0, negative ones are clamped to 0).
///
/// Separable running sums (per row a prefix sum over the row's inside span, then per column a
/// sliding sum over `2b + 1` rows, both in `f64`): two operations per pixel instead of the
/// window's `(2b + 1)²` — a 12 MP dome has `b = 11`, 529 — which made the sun search cost more
/// than decoding the frames. Row bands run in parallel with the `parallel` feature.
fn region_box_mean(
    luma: &[f32],
    width: usize,
    (x0, y0, bw, bh): (usize, usize, usize, usize),
    region: &Circle,
    b: usize,
) -> Vec<f32> {
    // Each row's inside pixels form one span `lo..hi` (box coordinates): the circle is convex.
    let spans: Vec<(usize, usize)> = (0..bh)
        .map(|y| {
            let (a, e) = region.row_span(y0 + y, x0 + bw);
            let (lo, hi) = (a.max(x0) - x0, e.max(x0) - x0);
            (lo, hi.max(lo))
        })
        .collect();
    let raw = |v: f32| if v.is_finite() { v.max(0.0) } else { 0.0 };
    // Horizontal window sums over each row's span (the counts follow from the spans).
    let mut hsum = vec![0.0f32; bw * bh];
    let horizontal = |(y, row): (usize, &mut [f32])| {
        let (lo, hi) = spans[y];
        if hi <= lo {
            return;
        }
        let src = &luma[(y0 + y) * width + x0..][..bw];
        let mut prefix = Vec::with_capacity(hi - lo + 1);
        let mut acc = 0.0f64;
        prefix.push(0.0f64);
        for &v in &src[lo..hi] {
            acc += f64::from(raw(v));
            prefix.push(acc);
        }
        for (x, o) in row.iter_mut().enumerate() {
            let a = x.saturating_sub(b).max(lo);
            let e = (x + b + 1).min(hi);
            if e > a {
                *o = (prefix[e - lo] - prefix[a - lo]) as f32;
            }
        }
    };
    // Vertical sliding sums over 2b + 1 rows, each band of rows starting its own window.
    let count = |x: usize, y: usize| {
        let (lo, hi) = spans[y];
        let a = x.saturating_sub(b).max(lo);
        let e = (x + b + 1).min(hi);
        e.saturating_sub(a)
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        hsum.par_chunks_mut(bw).enumerate().for_each(horizontal);
    }
    #[cfg(not(feature = "parallel"))]
    hsum.chunks_mut(bw).enumerate().for_each(horizontal);

    const BAND: usize = 64;
    let hsum_ref = &hsum;
    let mut out = vec![f32::NAN; bw * bh];
    let vertical = |(k, band): (usize, &mut [f32])| {
        let ys = k * BAND;
        let mut s = vec![0.0f64; bw];
        let mut n = vec![0usize; bw];
        let window = |y: usize| y.saturating_sub(b)..(y + b + 1).min(bh);
        for yy in window(ys) {
            for x in 0..bw {
                s[x] += f64::from(hsum_ref[yy * bw + x]);
                n[x] += count(x, yy);
            }
        }
        for (r, row) in band.chunks_exact_mut(bw).enumerate() {
            let y = ys + r;
            if r > 0 {
                // Slide: row y + b enters, row y − b − 1 leaves.
                if y + b < bh {
                    let add = &hsum_ref[(y + b) * bw..][..bw];
                    for x in 0..bw {
                        s[x] += f64::from(add[x]);
                        n[x] += count(x, y + b);
                    }
                }
                if y > b {
                    let sub = &hsum_ref[(y - b - 1) * bw..][..bw];
                    for x in 0..bw {
                        s[x] -= f64::from(sub[x]);
                        n[x] -= count(x, y - b - 1);
                    }
                }
            }
            let (lo, hi) = spans[y];
            for x in lo..hi {
                row[x] = (s[x] / n[x] as f64) as f32;
            }
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(BAND * bw).enumerate().for_each(vertical);
    }
    #[cfg(not(feature = "parallel"))]
    out.chunks_mut(BAND * bw).enumerate().for_each(vertical);
    out
}

/// Atmospheric refraction applied to the computed sun (the photo shows the refracted, apparent
/// sun; refraction lifts it by ≈0.5° at the horizon and ≈0.01° at 45°).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Refraction {
    /// Geometric (true) position, no refraction.
    None,
    /// Standard atmosphere: 1013.25 hPa, 15 °C.
    #[default]
    Standard,
    /// Given conditions.
    Atmosphere {
        /// Pressure in hPa (millibar), (0, 2000].
        pressure_hpa: f64,
        /// Air temperature in °C, (−273, 100].
        temperature_c: f64,
    },
}

/// Where the photos were taken.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Site {
    /// Latitude in degrees, north positive, `[−90, 90]`.
    pub latitude_deg: f64,
    /// Longitude in degrees, east positive, `[−180, 180]`.
    pub longitude_deg: f64,
    /// Height above sea level in metres (parallax only).
    pub height_m: f64,
    /// Refraction model.
    pub refraction: Refraction,
}

/// The sun's topocentric direction at `time` (any UTC offset; converted to UTC) seen from
/// `site`, by NREL SPA. `delta_t_s` is TT − UT1 in seconds; `None` uses the Espenak–Meeus
/// estimate for the year (off by at most a few seconds for recent years, which moves the sun by
/// under 0.0001°).
pub fn sun_ephemeris(
    time: OffsetDateTime,
    site: &Site,
    delta_t_s: Option<f64>,
) -> Result<Direction, SkyError> {
    use solar_positioning::{time::JulianDate, Location, RefractionCorrection, SolarPositions};
    let utc = time.to_offset(time::UtcOffset::UTC);
    let second = f64::from(utc.second()) + f64::from(utc.nanosecond()) * 1e-9;
    let delta_t = match delta_t_s {
        Some(d) => d,
        None => {
            let year = f64::from(utc.year()) + (f64::from(utc.ordinal()) - 0.5) / 365.25;
            solar_positioning::delta_t::estimate(year)
                .map_err(|e| SkyError::Ephemeris(e.to_string()))?
        }
    };
    let jd = JulianDate::from_utc(
        utc.year(),
        u32::from(u8::from(utc.month())),
        u32::from(utc.day()),
        u32::from(utc.hour()),
        u32::from(utc.minute()),
        second,
        delta_t,
    )
    .map_err(|e| SkyError::Ephemeris(e.to_string()))?;
    let refraction = match site.refraction {
        Refraction::None => None,
        Refraction::Standard => Some(RefractionCorrection::standard()),
        Refraction::Atmosphere {
            pressure_hpa,
            temperature_c,
        } => Some(
            RefractionCorrection::new(pressure_hpa, temperature_c)
                .map_err(|e| SkyError::Ephemeris(e.to_string()))?,
        ),
    };
    let pos = SolarPositions::new()
        .at_from_julian(
            jd,
            Location {
                latitude: site.latitude_deg,
                longitude: site.longitude_deg,
            },
            site.height_m,
            refraction,
        )
        .map_err(|e| SkyError::Ephemeris(e.to_string()))?;
    Ok(Direction::new(pos.azimuth(), 90.0 - pos.zenith_angle()))
}

/// Agreement between a detected (or tapped) sun and the computed one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SunCrossCheck {
    /// Great-circle angle between the two, degrees.
    pub angle_deg: f64,
    /// `computed − detected` azimuth wrapped to `(−180, 180]` degrees: add it to the compass
    /// (north) azimuth to make the azimuths agree.
    pub compass_error_deg: f64,
    /// `computed − detected` elevation, degrees (a tilted phone or a wrong lens model shows here).
    pub elevation_error_deg: f64,
}

/// Compares a detected sun with the ephemeris sun (see the module docs).
pub fn cross_check(detected: &Direction, computed: &Direction) -> SunCrossCheck {
    let mut d = (computed.azimuth_deg - detected.azimuth_deg).rem_euclid(360.0);
    if d > 180.0 {
        d -= 360.0;
    }
    SunCrossCheck {
        angle_deg: detected.angle_to(computed),
        compass_error_deg: d,
        elevation_error_deg: computed.elevation_deg - detected.elevation_deg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window mean the way it reads: every window pixel tested, summed in `f64`.
    fn box_mean_by_definition(
        luma: &[f32],
        width: usize,
        (x0, y0, bw, bh): (usize, usize, usize, usize),
        region: &Circle,
        b: usize,
    ) -> Vec<f32> {
        let inside = |x: usize, y: usize| region.contains_pixel(x0 + x, y0 + y);
        let mut out = vec![f32::NAN; bw * bh];
        for y in 0..bh {
            for x in 0..bw {
                if !inside(x, y) {
                    continue;
                }
                let (mut s, mut n) = (0.0f64, 0.0f64);
                for yy in y.saturating_sub(b)..(y + b + 1).min(bh) {
                    for xx in x.saturating_sub(b)..(x + b + 1).min(bw) {
                        if inside(xx, yy) {
                            let v = luma[(y0 + yy) * width + x0 + xx];
                            s += if v.is_finite() {
                                f64::from(v.max(0.0))
                            } else {
                                0.0
                            };
                            n += 1.0;
                        }
                    }
                }
                out[y * bw + x] = (s / n) as f32;
            }
        }
        out
    }

    #[test]
    fn median_by_histogram_is_the_selected_median() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for n in [16usize, 17, 100, 4097, 100_000] {
            for spread in [1.0f32, 1e-3, 1e6] {
                let v: Vec<f32> = (0..n)
                    .map(|i| {
                        state ^= state << 13;
                        state ^= state >> 7;
                        state ^= state << 17;
                        match i % 50 {
                            0 => f32::NAN,
                            1 => 0.0,
                            // Ties: many equal values.
                            2..=9 => 0.5 * spread,
                            _ => (state % 1_000_000) as f32 / 1e6 * spread,
                        }
                    })
                    .collect();
                let mut finite: Vec<f32> = v.iter().copied().filter(|x| !x.is_nan()).collect();
                let mid = finite.len() / 2;
                let want = *finite.select_nth_unstable_by(mid, f32::total_cmp).1;
                let peak = finite.iter().copied().fold(0.0f32, f32::max);
                let want = (finite.len() >= 16).then_some((want, peak));
                assert_eq!(median_and_peak(&v), want, "n {n} spread {spread}");
            }
        }
        assert_eq!(median_and_peak(&[1.0; 15]), None);
        assert_eq!(median_and_peak(&[f32::NAN; 40]), None);
    }

    #[test]
    fn running_box_mean_equals_the_window_mean_by_definition() {
        // Circles centred on and off pixel corners, cut by the frame's edges or not, windows
        // from 1 to wider than the circle; values over 12 decades with NaN, ∞ and negatives.
        let (w, h) = (157usize, 131usize);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let luma: Vec<f32> = (0..w * h)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                match state % 97 {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    2 => -3.0,
                    k => 10f32.powf((k as f32 / 8.0) - 6.0),
                }
            })
            .collect();
        let circles = [
            Circle {
                cx: 78.5,
                cy: 65.5,
                r: 60.0,
            },
            Circle {
                cx: 70.0,
                cy: 60.0,
                r: 80.3,
            },
            Circle {
                cx: 10.2,
                cy: 120.7,
                r: 33.3,
            },
            Circle {
                cx: 150.0,
                cy: 3.0,
                r: 4.6,
            },
            Circle {
                cx: 40.5,
                cy: 40.5,
                r: 0.7,
            },
        ];
        for region in &circles {
            let x0 = (region.cx - region.r).floor().max(0.0) as usize;
            let y0 = (region.cy - region.r).floor().max(0.0) as usize;
            let x1 = ((region.cx + region.r).ceil() as usize).min(w);
            let y1 = ((region.cy + region.r).ceil() as usize).min(h);
            let bx = (x0, y0, x1 - x0, y1 - y0);
            for b in [1, 2, 5, 11, 200] {
                let fast = region_box_mean(&luma, w, bx, region, b);
                let slow = box_mean_by_definition(&luma, w, bx, region, b);
                for (i, (f, s)) in fast.iter().zip(&slow).enumerate() {
                    assert_eq!(
                        f.is_nan(),
                        s.is_nan(),
                        "inside test at {i}, {region:?}, b {b}"
                    );
                    if !s.is_nan() {
                        assert!(
                            (f - s).abs() <= 1e-5 * s.abs() + 1e-30,
                            "{f} vs {s} at {i}, {region:?}, b {b}"
                        );
                    }
                }
            }
        }
    }
}
