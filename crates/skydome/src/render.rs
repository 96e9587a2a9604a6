//! Lit spheres: a small picture of a diffuse sphere and a mirror sphere on a ground plane, lit by
//! the captured dome — the quickest way to see whether a radiance map lights a scene plausibly
//! (sun direction, shadow softness, colour of the skylight).
//!
//! # Lat-long (equirectangular) convention
//! The environment is an equirectangular [`HdrImage`], normally 2:1 (any size is accepted; the
//! mapping uses normalised coordinates):
//! - column coordinate `u ∈ [0, 1)` (pixel `x` has centre `u = (x + 0.5) / width`) is azimuth
//!   `φ = 2π·(u − ¼)`, measured **from true north towards east**: `u = 0` west, `u = 0.25`
//!   north, `u = 0.5` east (the image centre), `u = 0.75` south. This is the map
//!   [`crate::reproject`] writes with its default centre azimuth of 90° (Blender's world `+X` =
//!   east at the centre, `+Y` = north), so a map from `skydome merge --equirect` lights the
//!   spheres with the sun where the dome has it;
//! - row coordinate `v ∈ [0, 1]` (pixel `y` has centre `v = (y + 0.5) / height`) is elevation
//!   `e = π/2 − π·v`: the top row is the zenith (+90°), the middle the horizon, the bottom the
//!   nadir (−90°).
//!
//! World directions are unit vectors in an east-north-up frame: `x` east, `y` north, `z` up, so
//! `d = (cos e · sin φ, cos e · cos φ, sin e)`. See [`direction_to_equirect_uv`] and
//! [`equirect_uv_to_direction`].
//!
//! # Shading
//! - **Diffuse sphere** (albedo ρ, Lambertian): radiance `ρ/π · E(n)` with the irradiance `E(n)`
//!   from the order-2 spherical-harmonic approximation of Ramamoorthi & Hanrahan (2001):
//!   `E(n) = Σ_{l≤2,m} Â_l L_lm Y_lm(n)` with `Â_0 = π`, `Â_1 = 2π/3`, `Â_2 = π/4` and the nine
//!   coefficients `L_lm = ∫ L(ω) Y_lm(ω) dω` integrated over the map with per-pixel solid angle
//!   `cos e · (2π / W) · (π / H)`. The approximation's error against the exact clamped-cosine
//!   integral is below 10 % of a directional light's peak (exact for uniform light);
//!   [`ShIrradiance`] exposes it.
//! - **Mirror sphere** (reflectance `k`): the reflected view ray looks up the map directly
//!   (bilinear, wrapping in azimuth), so the sun appears where the dome has it; rays that hit the
//!   ground or the other sphere shade those instead.
//! - **Ground plane** (z = 0, albedo ρ_g): `ρ_g/π · E(up)` with `E(up) = Σ L · max(z, 0) · dω`
//!   integrated exactly (not from the SH fit, whose error near a sun exceeds the skylight), minus the skylight the spheres block
//!   (a cap of half-angle `asin(r/d)` seen from the ground point) and minus the sun's direct
//!   irradiance where a sphere casts its shadow. The "sun" is taken as the pixels within half the
//!   brightness of the map's brightest pixel, when that pixel is ≥ 100 × the median sky.
//! - **Missing lower hemisphere**: a sky-dome capture is black below the horizon. Those exactly
//!   zero pixels are lit as the ground would be (uniform radiance `ρ_g · E(up) / π`) when the SH
//!   coefficients are computed, so the lower half of the spheres is not pitch black.
//!
//! The camera stands on the ground looking horizontally (towards [`SphereScene::view_azimuth_deg`])
//! at the two spheres of radius 1 resting on the plane, the diffuse one on the left. Each pixel
//! averages `n × n` stratified rays. The HDR result is tone-mapped with [`crate::tonemap`].
//!
//! Reference: R. Ramamoorthi, P. Hanrahan, "An Efficient Representation for Irradiance
//! Environment Maps", SIGGRAPH 2001; P. Debevec, "Rendering Synthetic Objects into Real Scenes",
//! SIGGRAPH 1998.

// Small fixed-size vector and SH-coefficient loops read as the formulas they implement when
// indexed; iterator chains over parallel arrays would hide that.
#![allow(clippy::needless_range_loop)]

use std::f64::consts::PI;

use crate::image::{luminance, HdrImage, RgbImage};
use crate::tonemap::{self, ToneMap, TonemapError};

#[cfg(feature = "parallel")]
use rayon::prelude::*;

/// Errors from rendering.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum RenderError {
    /// The environment map has no usable size.
    #[error("environment map is {width}×{height} with {len} samples; pass a lat-long HdrImage of at least 4×2 pixels (normally 2:1)")]
    BadEnvironment {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Samples present.
        len: usize,
    },
    /// A parameter out of range.
    #[error("{name} = {value} is out of range: {hint}")]
    BadParameter {
        /// Name of the parameter.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is accepted.
        hint: &'static str,
    },
    /// The environment has no light at all.
    #[error("the environment map is black; check the input radiance map")]
    Dark,
    /// Tone mapping the result failed.
    #[error(transparent)]
    Tonemap(#[from] TonemapError),
}

// ---------------------------------------------------------------------------------------------
// Directions
// ---------------------------------------------------------------------------------------------

/// Unit direction (east, north, up) for azimuth `az_deg` (from north towards east) and elevation
/// `el_deg` above the horizon, both in degrees.
pub fn direction_from_azimuth_elevation(az_deg: f64, el_deg: f64) -> [f64; 3] {
    let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
    [el.cos() * az.sin(), el.cos() * az.cos(), el.sin()]
}

/// Lat-long coordinates `(u, v)` of a direction (east, north, up; need not be unit length):
/// `u = φ / 2π + ¼` wrapped to `[0, 1)` with azimuth φ from north towards east (east at the
/// centre `u = ½`), `v = 0.5 − e/π ∈ [0, 1]`. The zero vector maps to the zenith `(¼, 0)`.
pub fn direction_to_equirect_uv(d: [f64; 3]) -> (f64, f64) {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if n.is_nan() || n <= 0.0 {
        return (0.25, 0.0);
    }
    let el = (d[2] / n).clamp(-1.0, 1.0).asin();
    let mut u = d[0].atan2(d[1]) / (2.0 * PI) + 0.25;
    if u < 0.0 {
        u += 1.0;
    }
    if u >= 1.0 {
        u -= 1.0;
    }
    (u, 0.5 - el / PI)
}

/// The inverse of [`direction_to_equirect_uv`]: unit direction (east, north, up) at lat-long
/// coordinates `(u, v)`.
pub fn equirect_uv_to_direction(u: f64, v: f64) -> [f64; 3] {
    let phi = 2.0 * PI * (u - 0.25);
    let el = PI * (0.5 - v);
    [el.cos() * phi.sin(), el.cos() * phi.cos(), el.sin()]
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline]
fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        a
    }
}

fn check_env(env: &HdrImage) -> Result<(), RenderError> {
    if env.width < 4 || env.height < 2 || env.data.len() != 3 * env.width * env.height {
        return Err(RenderError::BadEnvironment {
            width: env.width,
            height: env.height,
            len: env.data.len(),
        });
    }
    Ok(())
}

/// Bilinear look-up of the map in direction `d`, wrapping in azimuth and clamping at the poles.
pub fn sample_equirect(env: &HdrImage, d: [f64; 3]) -> [f32; 3] {
    let (u, v) = direction_to_equirect_uv(d);
    let (w, h) = (env.width, env.height);
    if w == 0 || h == 0 || env.data.len() != 3 * w * h {
        return [0.0; 3];
    }
    let fx = u * w as f64 - 0.5;
    let fy = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let x0f = fx.floor();
    let tx = (fx - x0f) as f32;
    let x0 = (x0f as i64).rem_euclid(w as i64) as usize;
    let x1 = (x0 + 1) % w;
    let y0 = fy.floor() as usize;
    let y1 = (y0 + 1).min(h - 1);
    let ty = (fy - y0 as f64) as f32;
    let p = |x: usize, y: usize| env.pixel(x, y);
    let (a, b, c, e) = (p(x0, y0), p(x1, y0), p(x0, y1), p(x1, y1));
    let mut o = [0.0; 3];
    for i in 0..3 {
        let top = a[i] + (b[i] - a[i]) * tx;
        let bot = c[i] + (e[i] - c[i]) * tx;
        o[i] = top + (bot - top) * ty;
    }
    o
}

// ---------------------------------------------------------------------------------------------
// Spherical harmonics
// ---------------------------------------------------------------------------------------------

/// The nine real SH basis functions `Y_00, Y_1-1, Y_10, Y_11, Y_2-2, Y_2-1, Y_20, Y_21, Y_22` at
/// a unit direction `(x, y, z)` (Ramamoorthi & Hanrahan's constants).
#[inline]
fn sh_basis(d: [f64; 3]) -> [f64; 9] {
    let [x, y, z] = d;
    [
        0.282_095,
        0.488_603 * y,
        0.488_603 * z,
        0.488_603 * x,
        1.092_548 * x * y,
        1.092_548 * y * z,
        0.315_392 * (3.0 * z * z - 1.0),
        1.092_548 * x * z,
        0.546_274 * (x * x - y * y),
    ]
}

/// Convolution weights `Â_l` of the clamped cosine for bands l = 0, 1, 2, per coefficient.
const SH_A: [f64; 9] = [
    PI,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
];

/// Order-2 spherical-harmonic irradiance of an environment (Ramamoorthi & Hanrahan 2001).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShIrradiance {
    /// `L_lm` per colour channel, in the order of `Y_00, Y_1-1, Y_10, Y_11, Y_2-2, Y_2-1, Y_20,
    /// Y_21, Y_22` (radiance × steradian).
    pub coeffs: [[f64; 3]; 9],
}

/// Per-row projection result: coefficients of the map, and of unit radiance over its zero
/// pixels below the horizon.
#[derive(Clone, Copy)]
struct ShAcc {
    c: [[f64; 3]; 9],
    hole: [f64; 9],
    /// Exact irradiance on an upward-facing surface, `Σ L · max(z, 0) · dω`.
    up: [f64; 3],
}

impl ShAcc {
    fn zero() -> Self {
        Self {
            c: [[0.0; 3]; 9],
            hole: [0.0; 9],
            up: [0.0; 3],
        }
    }
    fn merge(mut self, o: ShAcc) -> ShAcc {
        for i in 0..9 {
            for k in 0..3 {
                self.c[i][k] += o.c[i][k];
            }
            self.hole[i] += o.hole[i];
        }
        for k in 0..3 {
            self.up[k] += o.up[k];
        }
        self
    }
}

fn project_sh(env: &HdrImage) -> ShAcc {
    let (w, h) = (env.width, env.height);
    let dphi = 2.0 * PI / w as f64;
    let dth = PI / h as f64;
    let row = |y: usize| {
        let v = (y as f64 + 0.5) / h as f64;
        let el = PI * (0.5 - v);
        let domega = el.cos() * dphi * dth;
        let mut acc = ShAcc::zero();
        for x in 0..w {
            let d = equirect_uv_to_direction((x as f64 + 0.5) / w as f64, v);
            let b = sh_basis(d);
            let p = env.pixel(x, y);
            let p = [p[0].max(0.0), p[1].max(0.0), p[2].max(0.0)];
            let p = if p.iter().all(|v| v.is_finite()) {
                p
            } else {
                [0.0; 3]
            };
            if p == [0.0; 3] {
                if el < 0.0 {
                    for i in 0..9 {
                        acc.hole[i] += b[i] * domega;
                    }
                }
                continue;
            }
            for i in 0..9 {
                for k in 0..3 {
                    acc.c[i][k] += p[k] as f64 * b[i] * domega;
                }
            }
            if d[2] > 0.0 {
                for k in 0..3 {
                    acc.up[k] += p[k] as f64 * d[2] * domega;
                }
            }
        }
        acc
    };
    #[cfg(feature = "parallel")]
    {
        (0..h)
            .into_par_iter()
            .map(row)
            .reduce(ShAcc::zero, ShAcc::merge)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (0..h).map(row).fold(ShAcc::zero(), ShAcc::merge)
    }
}

impl ShIrradiance {
    /// Projects a lat-long environment onto the first nine SH basis functions. Negative and
    /// non-finite samples count as zero.
    pub fn from_equirect(env: &HdrImage) -> Result<Self, RenderError> {
        check_env(env)?;
        Ok(Self {
            coeffs: project_sh(env).c,
        })
    }

    /// Irradiance `E(n)` (radiance units × π sr) on a surface with unit normal `n` (east, north,
    /// up), per channel.
    pub fn irradiance(&self, n: [f64; 3]) -> [f64; 3] {
        let b = sh_basis(normalize(n));
        let mut e = [0.0; 3];
        for i in 0..9 {
            for k in 0..3 {
                e[k] += SH_A[i] * self.coeffs[i][k] * b[i];
            }
        }
        // The order-2 fit rings slightly negative opposite a strong light; light cannot.
        e.map(|v| v.max(0.0))
    }
}

// ---------------------------------------------------------------------------------------------
// Scene
// ---------------------------------------------------------------------------------------------

/// The lit-spheres picture: size, view and materials.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereScene {
    /// Output width in pixels (16..=8192).
    pub width: usize,
    /// Output height in pixels (16..=8192).
    pub height: usize,
    /// Direction the camera looks, azimuth in degrees from north towards east.
    pub view_azimuth_deg: f64,
    /// Horizontal field of view in degrees (1..=150).
    pub fov_deg: f64,
    /// Diffuse sphere albedo (0..=1); 0.18 by default, the on-set 18 % grey ball.
    pub sphere_albedo: f64,
    /// Mirror sphere reflectance (0..=1).
    pub mirror_reflectance: f64,
    /// Ground albedo (0..=1).
    pub ground_albedo: f64,
    /// Rays per pixel along each axis (1..=8); `n²` rays are averaged.
    pub samples_per_axis: usize,
}

impl Default for SphereScene {
    fn default() -> Self {
        Self {
            width: 640,
            height: 320,
            view_azimuth_deg: 0.0,
            fov_deg: 45.0,
            sphere_albedo: 0.18,
            mirror_reflectance: 0.85,
            ground_albedo: 0.2,
            samples_per_axis: 2,
        }
    }
}

/// A sphere in world coordinates (east, north, up; units of the sphere radius).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub centre: [f64; 3],
    /// Radius.
    pub radius: f64,
}

impl Sphere {
    /// Distance along the unit ray `o + t·d` to the first hit in front of `o`.
    fn hit(&self, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
        let oc = sub(o, self.centre);
        let b = dot(oc, d);
        let c = dot(oc, oc) - self.radius * self.radius;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        let t0 = -b - s;
        let t1 = -b + s;
        if t0 > 1e-9 {
            Some(t0)
        } else if t1 > 1e-9 {
            Some(t1)
        } else {
            None
        }
    }
}

/// A pinhole camera: world position and orthonormal axes; pixel `(x, y)` (origin top-left) looks
/// along `forward + (2(x)/W − 1)·tan(h/2)·right − (2(y)/H − 1)·tan(v/2)·up` for continuous pixel
/// coordinates (centres at `+0.5`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub position: [f64; 3],
    /// Viewing direction (horizontal).
    pub forward: [f64; 3],
    /// Image-right direction.
    pub right: [f64; 3],
    /// Image-up direction (world up).
    pub up: [f64; 3],
    /// `tan` of half the horizontal field of view.
    pub tan_half_h: f64,
    /// `tan` of half the vertical field of view.
    pub tan_half_v: f64,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
}

impl Camera {
    /// Unit ray direction through the continuous pixel position `(px, py)`.
    pub fn ray(&self, px: f64, py: f64) -> [f64; 3] {
        let sx = (2.0 * px / self.width as f64 - 1.0) * self.tan_half_h;
        let sy = (1.0 - 2.0 * py / self.height as f64) * self.tan_half_v;
        normalize(add(
            add(self.forward, scale(self.right, sx)),
            scale(self.up, sy),
        ))
    }

    /// Continuous pixel position of a world point, `None` when it is behind the camera.
    pub fn project(&self, p: [f64; 3]) -> Option<(f64, f64)> {
        let q = sub(p, self.position);
        let z = dot(q, self.forward);
        if z <= 1e-9 {
            return None;
        }
        let sx = dot(q, self.right) / z / self.tan_half_h;
        let sy = dot(q, self.up) / z / self.tan_half_v;
        Some((
            (sx + 1.0) * 0.5 * self.width as f64,
            (1.0 - sy) * 0.5 * self.height as f64,
        ))
    }
}

/// Camera height above the ground, distance to the spheres and their lateral offset, in sphere
/// radii: a viewpoint slightly above the sphere centres, as in a light-probe reference shot.
const EYE_HEIGHT: f64 = 1.2;
const SPHERE_DISTANCE: f64 = 6.0;
const SPHERE_OFFSET: f64 = 1.25;

impl SphereScene {
    fn validate(&self) -> Result<(), RenderError> {
        let bad = |name, value: f64, hint| Err(RenderError::BadParameter { name, value, hint });
        if !(16..=8192).contains(&self.width) {
            return bad("width", self.width as f64, "use 16..=8192 px");
        }
        if !(16..=8192).contains(&self.height) {
            return bad("height", self.height as f64, "use 16..=8192 px");
        }
        if !(self.fov_deg >= 1.0 && self.fov_deg <= 150.0) {
            return bad(
                "fov",
                self.fov_deg,
                "use a horizontal field of view of 1..=150°",
            );
        }
        if !self.view_azimuth_deg.is_finite() {
            return bad(
                "view azimuth",
                self.view_azimuth_deg,
                "use a finite azimuth in degrees",
            );
        }
        for (name, v) in [
            ("sphere albedo", self.sphere_albedo),
            ("mirror reflectance", self.mirror_reflectance),
            ("ground albedo", self.ground_albedo),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return bad(name, v, "use a value in 0..=1");
            }
        }
        if !(1..=8).contains(&self.samples_per_axis) {
            return bad(
                "samples",
                self.samples_per_axis as f64,
                "use 1..=8 rays per axis",
            );
        }
        Ok(())
    }

    /// The camera for this scene: at `(0, 0, 1.2)`, looking horizontally towards the view azimuth.
    pub fn camera(&self) -> Camera {
        let az = self.view_azimuth_deg.to_radians();
        let forward = [az.sin(), az.cos(), 0.0];
        let right = [az.cos(), -az.sin(), 0.0];
        let th = (self.fov_deg.to_radians() / 2.0).tan();
        Camera {
            position: [0.0, 0.0, EYE_HEIGHT],
            forward,
            right,
            up: [0.0, 0.0, 1.0],
            tan_half_h: th,
            tan_half_v: th * self.height as f64 / self.width as f64,
            width: self.width,
            height: self.height,
        }
    }

    fn sphere(&self, side: f64) -> Sphere {
        let cam = self.camera();
        let c = add(
            scale(cam.forward, SPHERE_DISTANCE),
            scale(cam.right, side * SPHERE_OFFSET),
        );
        Sphere {
            centre: [c[0], c[1], 1.0],
            radius: 1.0,
        }
    }

    /// The diffuse sphere (left in the picture).
    pub fn diffuse_sphere(&self) -> Sphere {
        self.sphere(-1.0)
    }

    /// The mirror sphere (right in the picture).
    pub fn mirror_sphere(&self) -> Sphere {
        self.sphere(1.0)
    }
}

/// The sun as found in the map: direction and its direct irradiance at normal incidence.
#[derive(Debug, Clone, Copy)]
struct Sun {
    dir: [f64; 3],
    irradiance: [f64; 3],
}

fn find_sun(env: &HdrImage) -> Option<Sun> {
    let (w, h) = (env.width, env.height);
    let mut lmax = 0.0f32;
    let mut upper = Vec::with_capacity(w * h / 2);
    for y in 0..h / 2 {
        for x in 0..w {
            let l = luminance(env.pixel(x, y));
            if l.is_finite() && l > 0.0 {
                lmax = lmax.max(l);
                upper.push(l);
            }
        }
    }
    if upper.is_empty() {
        return None;
    }
    let mid = upper.len() / 2;
    let median = *upper.select_nth_unstable_by(mid, f32::total_cmp).1;
    if lmax < 100.0 * median {
        return None;
    }
    let thresh = 0.5 * lmax;
    let (dphi, dth) = (2.0 * PI / w as f64, PI / h as f64);
    let mut dir = [0.0; 3];
    let mut e = [0.0; 3];
    for y in 0..h {
        let v = (y as f64 + 0.5) / h as f64;
        let domega = (PI * (0.5 - v)).cos() * dphi * dth;
        for x in 0..w {
            let p = env.pixel(x, y);
            let l = luminance(p);
            if l.is_finite() && l >= thresh {
                let d = equirect_uv_to_direction((x as f64 + 0.5) / w as f64, v);
                dir = add(dir, scale(d, l as f64 * domega));
                for k in 0..3 {
                    e[k] += p[k] as f64 * domega;
                }
            }
        }
    }
    Some(Sun {
        dir: normalize(dir),
        irradiance: e,
    })
}

struct Shader<'a> {
    env: &'a HdrImage,
    sh: ShIrradiance,
    sun: Option<Sun>,
    /// Ground irradiance without sphere occlusion, and its sky-only part (no sun).
    e_ground: [f64; 3],
    e_sky: [f64; 3],
    diffuse: Sphere,
    mirror: Sphere,
    scene: SphereScene,
}

impl Shader<'_> {
    fn ground(&self, p: [f64; 3]) -> [f64; 3] {
        let mut e = self.e_ground;
        for s in [self.diffuse, self.mirror] {
            let to = sub(s.centre, p);
            let d = dot(to, to).sqrt();
            if d <= s.radius {
                continue;
            }
            // Skylight blocked by the sphere's cap: ≈ mean sky radiance × projected cap area.
            let sin2 = (s.radius / d).powi(2);
            let cos_t = (to[2] / d).max(0.0);
            for k in 0..3 {
                e[k] -= self.e_sky[k] * sin2 * cos_t;
            }
            if let Some(sun) = self.sun {
                if sun.dir[2] > 0.0 && s.hit(p, sun.dir).is_some() {
                    for k in 0..3 {
                        e[k] -= sun.irradiance[k] * sun.dir[2];
                    }
                }
            }
        }
        let a = self.scene.ground_albedo / PI;
        e.map(|v| v.max(0.0) * a)
    }

    fn diffuse_at(&self, n: [f64; 3]) -> [f64; 3] {
        let a = self.scene.sphere_albedo / PI;
        self.sh.irradiance(n).map(|v| v * a)
    }

    /// Radiance seen along a ray; `bounce` allows one mirror reflection.
    fn trace(&self, o: [f64; 3], d: [f64; 3], bounce: bool) -> [f64; 3] {
        let mut best: Option<(f64, u8)> = None;
        for (i, s) in [self.diffuse, self.mirror].iter().enumerate() {
            if let Some(t) = s.hit(o, d) {
                if best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, i as u8));
                }
            }
        }
        let t_ground = if d[2] < 0.0 {
            -o[2] / d[2]
        } else {
            f64::INFINITY
        };
        match best {
            Some((t, i)) if t < t_ground => {
                let p = add(o, scale(d, t));
                if i == 0 {
                    self.diffuse_at(normalize(sub(p, self.diffuse.centre)))
                } else {
                    let n = normalize(sub(p, self.mirror.centre));
                    let r = sub(d, scale(n, 2.0 * dot(d, n)));
                    let k = self.scene.mirror_reflectance;
                    if bounce {
                        self.trace(add(p, scale(n, 1e-6)), r, false).map(|v| v * k)
                    } else {
                        self.sky(r).map(|v| v * k)
                    }
                }
            }
            _ if t_ground.is_finite() => self.ground(add(o, scale(d, t_ground))),
            _ => self.sky(d),
        }
    }

    fn sky(&self, d: [f64; 3]) -> [f64; 3] {
        let p = sample_equirect(self.env, d);
        [p[0] as f64, p[1] as f64, p[2] as f64]
    }
}

/// Renders the lit-spheres picture as linear HDR radiance (same units as `env`).
pub fn render_spheres_hdr(env: &HdrImage, scene: &SphereScene) -> Result<HdrImage, RenderError> {
    check_env(env)?;
    scene.validate()?;
    let acc = project_sh(env);
    // The ground uses the exact integral: the SH fit of a sun is off by up to 10 % of the sun's
    // power, more than the whole skylight, which would turn shadows black.
    let e_up = acc.up;
    if luminance(e_up.map(|v| v as f32)) <= 0.0 {
        return Err(RenderError::Dark);
    }
    // Fill the missing lower hemisphere with the ground's own reflected radiance.
    let lg = e_up.map(|v| v * scene.ground_albedo / PI);
    let mut coeffs = acc.c;
    for i in 0..9 {
        for k in 0..3 {
            coeffs[i][k] += acc.hole[i] * lg[k];
        }
    }
    let sun = find_sun(env);
    let mut e_sky = e_up;
    if let Some(s) = sun {
        for k in 0..3 {
            e_sky[k] = (e_sky[k] - s.irradiance[k] * s.dir[2].max(0.0)).max(0.0);
        }
    }
    let shader = Shader {
        env,
        sh: ShIrradiance { coeffs },
        sun,
        e_ground: e_up,
        e_sky,
        diffuse: scene.diffuse_sphere(),
        mirror: scene.mirror_sphere(),
        scene: *scene,
    };
    let cam = scene.camera();
    let n = scene.samples_per_axis;
    let inv = 1.0 / (n * n) as f64;
    let w = scene.width;
    let mut out = HdrImage::new(w, scene.height);
    let row_fn = |(y, row): (usize, &mut [f32])| {
        for x in 0..w {
            let mut sum = [0.0; 3];
            for j in 0..n {
                for i in 0..n {
                    let px = x as f64 + (i as f64 + 0.5) / n as f64;
                    let py = y as f64 + (j as f64 + 0.5) / n as f64;
                    let c = shader.trace(cam.position, cam.ray(px, py), true);
                    sum = add(sum, c);
                }
            }
            for k in 0..3 {
                row[3 * x + k] = (sum[k] * inv) as f32;
            }
        }
    };
    #[cfg(feature = "parallel")]
    out.data.par_chunks_mut(3 * w).enumerate().for_each(row_fn);
    #[cfg(not(feature = "parallel"))]
    out.data.chunks_mut(3 * w).enumerate().for_each(row_fn);
    Ok(out)
}

/// Renders the lit-spheres picture and tone-maps it to 8-bit sRGB with `tm` (its mask is
/// ignored: the picture has no dome circle).
pub fn render_spheres(
    env: &HdrImage,
    scene: &SphereScene,
    tm: &ToneMap,
) -> Result<RgbImage<u8>, RenderError> {
    let hdr = render_spheres_hdr(env, scene)?;
    let tm = ToneMap { mask: None, ..*tm };
    Ok(tonemap::tonemap_u8(&hdr, &tm)?)
}
