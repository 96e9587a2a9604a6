//! Sky geometry: the mapping between fish-eye pixels and sky directions, the phone's pose and
//! the image's EXIF orientation, the north point (conventions in the module documentation).

use serde::{Deserialize, Serialize};

use super::{Direction, SkyError};
use crate::fisheye::{LensProfile, Projection};
use crate::image::Circle;
use crate::image::PixelPoint;

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
