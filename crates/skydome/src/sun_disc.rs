//! The clipped sun: the solar disc put back into a dome whose sun clipped even in the shortest
//! exposure.
//!
//! The solar disc (half-angle 0.2665°, solid angle ≈ 6.8·10⁻⁵ sr) is ~10⁹ cd/m² at noon, some
//! 13 stops beyond what a phone bracket metered on the sky holds; its pixels merge to the
//! clipping level, a lower bound that lights a scene with almost no direct light. The disc is
//! replaced by one of the true solar solid angle at the sun's direction whose luminance makes
//! the direct part right, in this order of preference:
//! 1. **measured**: a global horizontal illuminance reading `E` beside the camera on an
//!    absolute dome — direct horizontal = `E` − the dome's horizontal illuminance without the
//!    disc, so the dome's illuminance equals the reading;
//! 2. **the clear-sky model's direct normal illuminance** (an absolute dome without an
//!    illuminance reading);
//! 3. **the clear-sky model's direct-to-diffuse ratio** times the dome's own diffuse
//!    illuminance (a relative dome, or one scaled by an illuminance reading alone, which then
//!    sets the total).
//!
//! The model is the IES clear sky (IES Lighting Handbook; IES RP-21): direct normal
//! `127.5 klx · exp(−0.21 · m)` with `m` the Kasten–Young (1989) air mass, diffuse horizontal
//! `0.8 + 15.5 · sin(h)^0.5 klx`. Real clear skies scatter around it with turbidity: take its
//! direct part as uncertain by about ±25 % ([`MODEL_UNCERTAINTY_PERCENT`]), more for hazy
//! skies and low suns; a measured illuminance avoids it.
//!
//! The disc is grey (equal R, G, B, as Radiance's `gendaylit` writes its sun) and is rasterised
//! by supersampling each pixel it touches: a pixel covered by fraction `c` keeps `1 − c` of its
//! merged value. Nothing else changes: the clipped aureole around the disc stays a lower bound.
//! Its luminance needs float data beyond half's 65504: RGBE `.hdr` or float32 EXR.

use serde::{Deserialize, Serialize};

use crate::image::{radiance_luminance, Circle, HdrImage, PixelPoint, RADIANCE_EFFICACY};
use crate::merge::CLIPPED_HIGH;
use crate::reproject::HorizontalWeight;
use crate::sky::{Direction, SkyGeometry};

/// Angular radius of the solar disc, degrees (mean Earth–Sun distance).
pub const SUN_HALF_ANGLE_DEG: f64 = 0.2665;

/// Solid angle of the solar disc, steradians: `2π (1 − cos 0.2665°)` ≈ 6.80·10⁻⁵.
pub fn sun_solid_angle_sr() -> f64 {
    std::f64::consts::TAU * (1.0 - SUN_HALF_ANGLE_DEG.to_radians().cos())
}

/// The stated uncertainty of the clear-sky model's direct part, percent.
pub const MODEL_UNCERTAINTY_PERCENT: f64 = 25.0;

/// The model's name as reports and headers state it.
pub const MODEL_NAME: &str = "IES clear sky";

/// Relative optical air mass at solar elevation `elevation_deg` (Kasten & Young 1989); finite
/// down to the horizon (≈ 38 at 0°).
pub fn air_mass(elevation_deg: f64) -> f64 {
    let h = elevation_deg.max(0.0);
    1.0 / (h.to_radians().sin() + 0.50572 * (h + 6.07995).powf(-1.6364))
}

/// Direct normal illuminance of the IES clear sky at solar elevation `elevation_deg`, lux;
/// 0 for a sun at or below the horizon.
pub fn clear_sky_direct_normal_lux(elevation_deg: f64) -> f64 {
    if elevation_deg <= 0.0 {
        return 0.0;
    }
    127_500.0 * (-0.21 * air_mass(elevation_deg)).exp()
}

/// Diffuse horizontal illuminance of the IES clear sky at solar elevation `elevation_deg`,
/// lux (the sky without the sun).
pub fn clear_sky_diffuse_horizontal_lux(elevation_deg: f64) -> f64 {
    800.0 + 15_500.0 * elevation_deg.max(0.0).to_radians().sin().sqrt()
}

/// Where the direct part came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DirectSource {
    /// The illuminance reading minus the dome's diffuse part.
    MeasuredIlluminance,
    /// The clear-sky model's direct normal illuminance (absolute dome).
    ModelDirectNormal,
    /// The clear-sky model's direct-to-diffuse ratio times the dome's diffuse part.
    ModelRatio,
}

impl DirectSource {
    /// A phrase for reports and headers (ASCII, as a Radiance header wants).
    pub fn describe(self) -> String {
        match self {
            DirectSource::MeasuredIlluminance => "the measured illuminance".into(),
            DirectSource::ModelDirectNormal => format!(
                "the {MODEL_NAME} model's direct normal illuminance (+/-{MODEL_UNCERTAINTY_PERCENT:.0} %)"
            ),
            DirectSource::ModelRatio => format!(
                "the {MODEL_NAME} model's direct/diffuse ratio (+/-{MODEL_UNCERTAINTY_PERCENT:.0} %)"
            ),
        }
    }
}

/// A pixel the disc touches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscPixel {
    /// Column, row (origin top-left).
    pub x: usize,
    /// Row.
    pub y: usize,
    /// Fraction of the pixel the disc covers, `0..=1` (a hair over 1 can remain from the
    /// scaling to the exact solid angle).
    pub coverage: f64,
    /// The pixel's horizontal weight `cos θ · dω` (sr), see
    /// [`horizontal_weight`](crate::reproject::horizontal_weight).
    pub weight: f64,
}

/// The pixels of a `width × height` dome in geometry `geom` that the solar disc centred on
/// `sun` covers, with their coverage; empty when the sun is outside the image or below the
/// horizon. Coverage is found by supersampling and scaled so that the covered solid angle is
/// exactly [`sun_solid_angle_sr`].
pub fn disc_pixels(
    geom: &SkyGeometry,
    width: usize,
    height: usize,
    sun: &Direction,
) -> Vec<DiscPixel> {
    let Some(c) = geom.direction_to_pixel(sun) else {
        return Vec::new();
    };
    if sun.elevation_deg <= 0.0 {
        return Vec::new();
    }
    let proj = *geom.projection();
    let (ox, oy) = geom.centre();
    let alpha = SUN_HALF_ANGLE_DEG.to_radians();
    let rho = (c.x - ox).hypot(c.y - oy);
    let theta = proj.theta_within(rho, proj.theta_limit()).unwrap_or(0.0);
    // The disc's half-extent in pixels, radially and around the centre.
    let radial = proj.derivative(theta) * alpha;
    let tangential = match theta > 1e-6 {
        true => rho / theta.sin() * alpha,
        false => radial,
    };
    let extent = radial.max(tangential);
    let reach = extent + 1.5;
    // At least ~16 sub-samples across the disc's radius.
    let k = ((16.0 / extent).ceil() as usize).clamp(8, 64);
    let sun_v = sun.to_vector();
    let cos_a = alpha.cos();
    let around = Circle {
        cx: c.x,
        cy: c.y,
        r: reach,
    };
    let (xs, ys) = around.pixel_bounds(width, height);
    let hw = HorizontalWeight::new(&proj);
    let mut out = Vec::new();
    for y in ys {
        for x in xs.clone() {
            let mut inside = 0usize;
            for j in 0..k {
                for i in 0..k {
                    let sx = x as f64 + (i as f64 + 0.5) / k as f64;
                    let sy = y as f64 + (j as f64 + 0.5) / k as f64;
                    if let Some(v) = geom.pixel_to_vector(sx, sy) {
                        let d = v[0] * sun_v[0] + v[1] * sun_v[1] + v[2] * sun_v[2];
                        if d >= cos_a {
                            inside += 1;
                        }
                    }
                }
            }
            if inside > 0 {
                let (dx, dy) = (x as f64 + 0.5 - ox, y as f64 + 0.5 - oy);
                out.push(DiscPixel {
                    x,
                    y,
                    coverage: inside as f64 / (k * k) as f64,
                    weight: hw.at(dx.hypot(dy)),
                });
            }
        }
    }
    // Solid angle per pixel is weight / cos θ; scale the coverage to the disc's true solid angle.
    let cos_sun = sun.elevation_deg.to_radians().sin();
    let covered: f64 = out.iter().map(|p| p.coverage * p.weight).sum::<f64>() / cos_sun;
    if covered > 0.0 {
        let s = sun_solid_angle_sr() / covered;
        for p in &mut out {
            // A hair over 1 where the sampling fell short: the disc's light is what counts.
            p.coverage *= s;
        }
    }
    out
}

/// True when a pixel flagged [`CLIPPED_HIGH`] (clipped even in the shortest exposure) lies
/// within `radius_px` of `centre` in a row-major `width × height` flag mask.
pub fn clipped_near(
    mask: &[u8],
    width: usize,
    height: usize,
    centre: PixelPoint,
    radius_px: f64,
) -> bool {
    if mask.len() != width * height || !(centre.x.is_finite() && centre.y.is_finite()) {
        return false;
    }
    let r = radius_px.max(0.5);
    let around = Circle {
        cx: centre.x,
        cy: centre.y,
        r,
    };
    let (xs, ys) = around.pixel_bounds(width, height);
    ys.into_iter().any(|y| {
        xs.clone().any(|x| {
            let (dx, dy) = (x as f64 + 0.5 - centre.x, y as f64 + 0.5 - centre.y);
            dx * dx + dy * dy <= r * r && mask[y * width + x] & CLIPPED_HIGH != 0
        })
    })
}

/// The horizontal illuminance the disc's pixels contribute now (their merged values weighted
/// by coverage), in the dome's luminance units.
pub fn disc_illuminance(img: &HdrImage, disc: &[DiscPixel]) -> f64 {
    disc.iter()
        .map(|p| {
            let v = img.pixel(p.x, p.y).map(f64::from);
            p.coverage * p.weight * radiance_luminance(v)
        })
        .sum()
}

/// Paints the disc with luminance `luminance` (the dome's luminance units: cd/m² for an
/// absolute dome): each pixel becomes `(1 − c) · merged + c · sun`, grey.
pub fn paint_disc(img: &mut HdrImage, disc: &[DiscPixel], luminance: f64) {
    let grey = luminance / RADIANCE_EFFICACY;
    for p in disc {
        let old = img.pixel(p.x, p.y);
        let c = p.coverage;
        let new = old.map(|v| ((1.0 - c).max(0.0) * f64::from(v) + c * grey) as f32);
        img.set_pixel(p.x, p.y, new);
    }
}

/// What the reconstruction did, for the report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SunDiscReport {
    /// The disc's centre.
    pub direction: Direction,
    /// The disc's luminance (cd/m² on an absolute dome, relative units otherwise).
    pub luminance: f64,
    /// Direct normal illuminance of the disc (lux on an absolute dome).
    pub direct_normal: f64,
    /// Direct horizontal illuminance of the disc.
    pub direct_horizontal: f64,
    /// The dome's horizontal illuminance without the disc (the diffuse part, with whatever
    /// clipped aureole surrounds the sun as a lower bound).
    pub diffuse_horizontal: f64,
    /// Where the direct part came from.
    pub from: DirectSource,
    /// True when the values are absolute (cd/m², lux).
    pub absolute: bool,
    /// Pixels the disc touches.
    pub pixels: usize,
}

impl SunDiscReport {
    /// The header comment line (`#SUN_DISC= …`) that marks a reconstructed sun.
    pub fn header_line(&self) -> String {
        let unit = |u: &str| {
            if self.absolute {
                format!(" {u}")
            } else {
                " (relative)".into()
            }
        };
        format!(
            "#SUN_DISC= reconstructed: the sun clipped in every frame; a {:.4} deg disc at azimuth {:.2} elevation {:.2} deg of luminance {}{} (direct normal {}{}) from {}",
            2.0 * SUN_HALF_ANGLE_DEG,
            self.direction.azimuth_deg,
            self.direction.elevation_deg,
            crate::image::fmt_num(round_sig(self.luminance)),
            unit("cd/m2"),
            crate::image::fmt_num(round_sig(self.direct_normal)),
            unit("lux"),
            self.from.describe()
        )
    }
}

/// Six significant digits: header text that does not depend on the last bits of the float
/// arithmetic (native and wasm builds write the same header).
fn round_sig(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let e = v.abs().log10().floor() as i32 - 5;
    let m = 10f64.powi(-e);
    (v * m).round() / m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fisheye::{LensKind, LensProfile};
    use crate::image::Circle;
    use crate::sky::{DevicePose, ImageOrientation};

    fn dome(size: usize, kind: LensKind) -> SkyGeometry {
        let half = size as f64 / 2.0;
        let lens = LensProfile::from_fov(
            Circle {
                cx: half,
                cy: half,
                r: half,
            },
            180.0,
            kind,
        )
        .expect("lens");
        SkyGeometry::new(&lens, 0.0, DevicePose::ScreenDown, ImageOrientation::Normal)
            .expect("geom")
    }

    #[test]
    fn solar_constants() {
        assert!(
            (sun_solid_angle_sr() - 6.80e-5).abs() < 0.01e-5,
            "{}",
            sun_solid_angle_sr()
        );
        assert!((air_mass(90.0) - 1.0).abs() < 1e-3);
        assert!((air_mass(30.0) - 1.995).abs() < 0.01, "{}", air_mass(30.0));
        assert!((air_mass(0.0) - 38.0).abs() < 0.2, "{}", air_mass(0.0));
        // IES clear sky: ~103 klx direct normal at the zenith, ~16 klx diffuse.
        assert!((clear_sky_direct_normal_lux(90.0) - 103_300.0).abs() < 200.0);
        assert!((clear_sky_diffuse_horizontal_lux(90.0) - 16_300.0).abs() < 1.0);
        assert_eq!(clear_sky_direct_normal_lux(-1.0), 0.0);
    }

    #[test]
    fn the_disc_covers_the_solar_solid_angle_whatever_the_pixel_size() {
        for (size, kind, el) in [
            (256, LensKind::Equidistant, 45.0),
            (1024, LensKind::Equidistant, 10.0),
            (3000, LensKind::Equisolid, 70.0),
            (512, LensKind::Stereographic, 89.9),
        ] {
            let g = dome(size, kind);
            let sun = Direction::new(123.0, el);
            let disc = disc_pixels(&g, size, size, &sun);
            assert!(!disc.is_empty());
            let sr: f64 = disc.iter().map(|p| p.coverage * p.weight).sum::<f64>()
                / sun.elevation_deg.to_radians().sin();
            assert!(
                (sr / sun_solid_angle_sr() - 1.0).abs() < 1e-9,
                "{size} {kind:?} {el}: {sr}"
            );
            // Painting a luminance L gives a horizontal illuminance L · Ω · sin(h).
            let mut img = HdrImage::new(size, size);
            paint_disc(&mut img, &disc, 1e9);
            let e = radiance_luminance(crate::reproject::horizontal_irradiance_fisheye(&img, &g));
            let want = 1e9 * sun_solid_angle_sr() * el.to_radians().sin();
            assert!(
                (e / want - 1.0).abs() < 0.01,
                "{size} {kind:?} {el}: {e} vs {want}"
            );
            // The centre of the painted disc is where the sun is.
            let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
            for p in &disc {
                sx += p.coverage * (p.x as f64 + 0.5);
                sy += p.coverage * (p.y as f64 + 0.5);
                sw += p.coverage;
            }
            let at = g.direction_to_pixel(&sun).expect("in view");
            assert!(
                (sx / sw - at.x).hypot(sy / sw - at.y) < 0.25,
                "{size} {kind:?} {el}"
            );
        }
    }

    #[test]
    fn clipped_near_looks_only_within_the_radius() {
        let mut mask = vec![0u8; 100];
        mask[5 * 10 + 7] = CLIPPED_HIGH;
        let at = |x, y| PixelPoint { x, y };
        assert!(clipped_near(&mask, 10, 10, at(7.5, 5.5), 0.5));
        assert!(clipped_near(&mask, 10, 10, at(6.0, 5.5), 2.0));
        assert!(!clipped_near(&mask, 10, 10, at(3.0, 5.5), 2.0));
        assert!(!clipped_near(&mask, 10, 9, at(7.5, 5.5), 2.0), "wrong size");
    }

    #[test]
    fn header_numbers_are_rounded() {
        assert_eq!(round_sig(123_456_789.0), 123_457_000.0);
        assert_eq!(round_sig(0.000_123_456_78), 0.000_123_457);
    }
}
