//! Ground-truth fish-eye sky domes for the geometry tests, rendered from closed forms that are
//! written independently of the library's vector code:
//! a ray at zenith angle `θ`, azimuth `φ` lands at `x = cx − r(θ)·sin(φ − A)`,
//! `y = cy − r(θ)·cos(φ − A)` for a phone lying screen-down with its top edge at compass
//! azimuth `A` (north up ⇒ east on the left), stored without EXIF rotation.
#![allow(dead_code)]

use std::path::PathBuf;

use skydome::image::{Circle, HdrImage, RgbImage};

/// Lens used to render: kind name and its closed-form `r(θ)`/`θ(r)`.
#[derive(Clone, Copy, Debug)]
pub enum Lens {
    Equidistant(f64),
    Equisolid(f64),
    Stereographic(f64),
    Orthographic(f64),
    Polynomial(f64, f64, f64),
}

impl Lens {
    pub fn r(&self, t: f64) -> f64 {
        match *self {
            Lens::Equidistant(f) => f * t,
            Lens::Equisolid(f) => 2.0 * f * (t / 2.0).sin(),
            Lens::Stereographic(f) => 2.0 * f * (t / 2.0).tan(),
            Lens::Orthographic(f) => f * t.sin(),
            Lens::Polynomial(a, b, c) => a * t + b * t.powi(3) + c * t.powi(5),
        }
    }

    pub fn theta(&self, r: f64) -> Option<f64> {
        match *self {
            Lens::Equidistant(f) => Some(r / f),
            Lens::Equisolid(f) => (r / (2.0 * f) <= 1.0).then(|| 2.0 * (r / (2.0 * f)).asin()),
            Lens::Stereographic(f) => Some(2.0 * (r / (2.0 * f)).atan()),
            Lens::Orthographic(f) => (r / f <= 1.0).then(|| (r / f).asin()),
            Lens::Polynomial(..) => {
                let (mut lo, mut hi) = (0.0f64, 2.6f64);
                if r > self.r(hi) {
                    return None;
                }
                for _ in 0..80 {
                    let m = 0.5 * (lo + hi);
                    if self.r(m) < r {
                        lo = m;
                    } else {
                        hi = m;
                    }
                }
                Some(0.5 * (lo + hi))
            }
        }
    }

    /// Focal length so the circle of radius `radius` is θ = fov/2.
    pub fn for_circle(kind: &str, fov_deg: f64, radius: f64) -> Lens {
        let t = (fov_deg / 2.0).to_radians();
        match kind {
            "equidistant" => Lens::Equidistant(radius / t),
            "equisolid" => Lens::Equisolid(radius / (2.0 * (t / 2.0).sin())),
            "stereographic" => Lens::Stereographic(radius / (2.0 * (t / 2.0).tan())),
            "orthographic" => Lens::Orthographic(radius / t.sin()),
            other => panic!("unknown lens {other}"),
        }
    }
}

/// A sky: radiance as a function of (azimuth°, elevation°).
pub type Sky<'a> = &'a (dyn Fn(f64, f64) -> [f32; 3] + Sync);

pub struct Dome {
    pub width: usize,
    pub height: usize,
    pub cx: f64,
    pub cy: f64,
    pub lens: Lens,
    /// Visible circle radius (the lens's field stops here; housing beyond).
    pub visible_r: f64,
    /// Compass azimuth of the phone's top edge, degrees.
    pub north_deg: f64,
    /// Housing radiance.
    pub housing: f32,
    /// Sub-samples per axis.
    pub ss: usize,
}

impl Dome {
    /// Direction (azimuth°, elevation°) seen at continuous pixel position, by the closed form.
    pub fn direction(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let (dx, dy) = (x - self.cx, y - self.cy);
        let rho = dx.hypot(dy);
        if rho > self.visible_r {
            return None;
        }
        let t = self.lens.theta(rho)?;
        // x = cx − r sin(φ − A), y = cy − r cos(φ − A)  ⇒  φ − A = atan2(−dx, −dy).
        let phi = (-dx).atan2(-dy).to_degrees() + self.north_deg;
        Some((phi.rem_euclid(360.0), 90.0 - t.to_degrees()))
    }

    /// Pixel of a direction by the closed form.
    pub fn pixel(&self, az_deg: f64, el_deg: f64) -> (f64, f64) {
        let r = self.lens.r((90.0 - el_deg).to_radians());
        let a = (az_deg - self.north_deg).to_radians();
        (self.cx - r * a.sin(), self.cy - r * a.cos())
    }

    pub fn render(&self, sky: Sky<'_>) -> HdrImage {
        let mut img = HdrImage::new(self.width, self.height);
        let n = self.ss.max(1);
        let inv = 1.0 / n as f64;
        for y in 0..self.height {
            for x in 0..self.width {
                let mut acc = [0.0f64; 3];
                for j in 0..n {
                    for i in 0..n {
                        let sx = x as f64 + (i as f64 + 0.5) * inv;
                        let sy = y as f64 + (j as f64 + 0.5) * inv;
                        let v = match self.direction(sx, sy) {
                            Some((az, el)) => sky(az, el),
                            None => [self.housing; 3],
                        };
                        for c in 0..3 {
                            acc[c] += f64::from(v[c]);
                        }
                    }
                }
                let k = inv * inv;
                img.set_pixel(
                    x,
                    y,
                    [
                        (acc[0] * k) as f32,
                        (acc[1] * k) as f32,
                        (acc[2] * k) as f32,
                    ],
                );
            }
        }
        img
    }
}

/// Great-circle angle in degrees between two (azimuth°, elevation°) directions.
pub fn angle_between(a: (f64, f64), b: (f64, f64)) -> f64 {
    let v = |(az, el): (f64, f64)| {
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        [ce * sa, ce * ca, se]
    };
    let (p, q) = (v(a), v(b));
    let c = [
        p[1] * q[2] - p[2] * q[1],
        p[2] * q[0] - p[0] * q[2],
        p[0] * q[1] - p[1] * q[0],
    ];
    let s = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    s.atan2(p[0] * q[0] + p[1] * q[1] + p[2] * q[2])
        .to_degrees()
}

/// A clear sky with a sun disc of `sun_radius_deg` at (`sun_az`, `sun_el`) `sun_gain` times
/// brighter than the sky, sky brightening towards the horizon, ground (el < 0) dim.
pub fn sunny_sky(
    sun_az: f64,
    sun_el: f64,
    sun_radius_deg: f64,
    sun_gain: f32,
) -> impl Fn(f64, f64) -> [f32; 3] + Sync {
    move |az, el| {
        if el < 0.0 {
            return [0.05, 0.05, 0.04];
        }
        if angle_between((az, el), (sun_az, sun_el)) <= sun_radius_deg {
            return [sun_gain; 3];
        }
        let k = (1.0 - el / 90.0) as f32;
        [0.3 + 0.4 * k, 0.45 + 0.35 * k, 0.9 + 0.1 * k]
    }
}

/// Deterministic pseudo-random noise in [−1, 1] (xorshift).
pub struct Noise(u64);

impl Noise {
    pub fn new(seed: u64) -> Self {
        Noise(seed | 1)
    }
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// An 8-bit frame of `img` at exposure `k` (code = 255·min(1, k·L)^(1/2.2)) plus ±`noise` codes.
pub fn to_u8(img: &HdrImage, k: f32, noise: f64, seed: u64) -> RgbImage<u8> {
    let mut rng = Noise::new(seed);
    let data = img
        .data
        .iter()
        .map(|&v| {
            let c = 255.0 * f64::from((k * v).clamp(0.0, 1.0)).powf(1.0 / 2.2) + noise * rng.next();
            c.round().clamp(0.0, 255.0) as u8
        })
        .collect();
    RgbImage::from_vec(img.width, img.height, data).expect("size")
}

pub use crate::common::shared_data;

/// Loads an 8-bit RGB PNG (palette images are expanded).
pub fn load_rgb8(path: &std::path::Path) -> RgbImage<u8> {
    let img = image::open(path).expect("decode").to_rgb8();
    let (w, h) = img.dimensions();
    RgbImage::from_vec(w as usize, h as usize, img.into_raw()).expect("size")
}

/// Alpnach frame path by index.
pub fn alpnach_frame(dir: &std::path::Path, i: usize) -> PathBuf {
    dir.join(format!(
        "Alpnach_20180129_11-09-20_ExposureStack_Image_{i:02}_image.png"
    ))
}

pub fn circle_close(a: &Circle, b: &Circle, tol: f64) -> bool {
    (a.cx - b.cx).abs() <= tol && (a.cy - b.cy).abs() <= tol && (a.r - b.r).abs() <= tol
}
