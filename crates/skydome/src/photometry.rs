//! Absolute calibration: from relative radiance to Radiance's photometric units.
//!
//! A merged bracket knows radiance only up to one constant. A measurement beside the camera
//! fixes it, as building-science practice does (Inanici 2006; Pierson et al., LEUKOS 2019):
//! - a **spot luminance** reading (cd/m²) of a patch of the scene: the mean luminance of that
//!   patch in the dome is scaled to the reading;
//! - a **horizontal illuminance** reading (lux) beside the camera: the dome's horizontal
//!   illuminance (θ ≤ 90°, cosine-weighted) is scaled to the reading.
//!
//! Luminance and illuminance are computed the way Radiance's tools compute them
//! ([`crate::image::radiance_luminance`]: 179 × (0.265 R + 0.670 G + 0.065 B)), so after the scale
//! the values are Radiance's W·sr⁻¹·m⁻² and `evalglare`, `pvalue -o` and `falsecolor` read
//! cd/m² and lux from them directly. With both readings the luminance sets the scale (it is the
//! more local measurement) and the disagreement of the illuminance is reported: a large one
//! points at vignetting, a clipped sun, or a meter that saw a different sky.

use serde::{Deserialize, Serialize};

use crate::image::{radiance_luminance, Circle, HdrImage, PixelPoint};

/// A spot-meter reading: the luminance of the patch of radius `radius_px` around `pixel`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpotLuminance {
    /// Centre of the metered patch, pixels of the input photos (origin top-left).
    pub pixel: PixelPoint,
    /// Radius of the patch in pixels (pixels whose centres lie within it are averaged).
    pub radius_px: f64,
    /// The reading, cd/m².
    pub cd_per_m2: f64,
}

/// Measurements that set the absolute scale.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Reference {
    /// A spot luminance reading.
    pub luminance: Option<SpotLuminance>,
    /// Horizontal illuminance measured beside the camera, lux (needs a fish-eye lens).
    pub illuminance_lux: Option<f64>,
}

impl Reference {
    /// True when no measurement is given.
    pub fn is_empty(&self) -> bool {
        self.luminance.is_none() && self.illuminance_lux.is_none()
    }
}

/// Errors of the absolute calibration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhotometryError {
    /// A reading that is not a positive finite number.
    #[error("{what} {value} is not a positive reading")]
    BadReading {
        /// Which reading.
        what: &'static str,
        /// The value.
        value: f64,
    },
    /// The metered patch holds no pixel of the image.
    #[error("the metered patch at ({x:.1}, {y:.1}) radius {r:.1} px is outside the image")]
    PatchOutside {
        /// Column.
        x: f64,
        /// Row.
        y: f64,
        /// Radius.
        r: f64,
    },
    /// The dome (or patch) is black, so no scale makes it match the reading.
    #[error("the {what} is zero in the merged image, so it cannot be scaled to the reading")]
    Black {
        /// What is black.
        what: &'static str,
    },
}

/// What the calibration did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PhotometryReport {
    /// The factor the relative radiance was multiplied by.
    pub scale: f64,
    /// What set the scale: "luminance" or "illuminance" (a reading), [`FROM_PROFILE`] (the
    /// camera profile's absolute constant with EXIF time, ISO and f-number) or
    /// [`FROM_METER_EQUATION`] (the reflected-light meter equation on EXIF, an estimate).
    pub from: &'static str,
    /// The metered patch's luminance after scaling, cd/m² (equals the reading when it set the
    /// scale).
    pub patch_luminance_cd_m2: Option<f64>,
    /// The dome's horizontal illuminance after scaling, lux.
    pub horizontal_illuminance_lux: Option<f64>,
    /// With both readings: (dome's illuminance after the luminance scale) / (measured
    /// illuminance) − 1, in percent.
    pub disagreement_percent: Option<f64>,
    /// The stated uncertainty of the scale, percent, when it is an estimate (±30 for the
    /// meter equation, or the profile's constant's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty_percent: Option<f64>,
}

/// [`PhotometryReport::from`] of a scale from the camera profile's absolute constant.
pub const FROM_PROFILE: &str = "camera profile";

/// [`PhotometryReport::from`] of a scale from the reflected-light meter equation.
pub const FROM_METER_EQUATION: &str = "exif meter equation";

fn positive(what: &'static str, value: f64) -> Result<f64, PhotometryError> {
    match value.is_finite() && value > 0.0 {
        true => Ok(value),
        false => Err(PhotometryError::BadReading { what, value }),
    }
}

/// The mean Radiance luminance (relative units) of the pixels whose centres lie within the
/// spot's patch.
pub fn patch_luminance(img: &HdrImage, spot: &SpotLuminance) -> Result<f64, PhotometryError> {
    let r = positive("patch radius (px)", spot.radius_px)?;
    let (cx, cy) = (spot.pixel.x, spot.pixel.y);
    let outside = PhotometryError::PatchOutside { x: cx, y: cy, r };
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(outside);
    }
    let (xs, ys) = Circle { cx, cy, r }.pixel_bounds(img.width, img.height);
    let (mut sum, mut n) = (0.0, 0usize);
    for y in ys {
        for x in xs.clone() {
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            if dx * dx + dy * dy <= r * r {
                let p = img.pixel(x, y);
                sum += radiance_luminance(p.map(f64::from));
                n += 1;
            }
        }
    }
    match n {
        0 => Err(outside),
        _ => Ok(sum / n as f64),
    }
}

/// The scale that makes the relative radiance absolute, from `reference`: `patch` is the
/// metered patch's relative luminance ([`patch_luminance`]) and `illuminance` the dome's
/// relative horizontal illuminance, each when the matching reading is given.
pub fn absolute_scale(
    reference: &Reference,
    patch: Option<f64>,
    illuminance: Option<f64>,
) -> Result<PhotometryReport, PhotometryError> {
    let from_lum = match (reference.luminance, patch) {
        (Some(s), Some(p)) => {
            let cd = positive("luminance (cd/m²)", s.cd_per_m2)?;
            if !(p.is_finite() && p > 0.0) {
                return Err(PhotometryError::Black {
                    what: "metered patch",
                });
            }
            Some(cd / p)
        }
        _ => None,
    };
    let from_ill = match (reference.illuminance_lux, illuminance) {
        (Some(lux), Some(e)) => {
            let lux = positive("illuminance (lux)", lux)?;
            if !(e.is_finite() && e > 0.0) {
                return Err(PhotometryError::Black { what: "dome" });
            }
            Some(lux / e)
        }
        _ => None,
    };
    let (scale, from) = match (from_lum, from_ill) {
        (Some(k), _) => (k, "luminance"),
        (None, Some(k)) => (k, "illuminance"),
        (None, None) => (1.0, "none"),
    };
    Ok(PhotometryReport {
        scale,
        from,
        patch_luminance_cd_m2: patch.map(|p| p * scale),
        horizontal_illuminance_lux: illuminance.map(|e| e * scale),
        disagreement_percent: match (from_lum, from_ill) {
            (Some(kl), Some(ki)) => Some(100.0 * (kl / ki - 1.0)),
            _ => None,
        },
        uncertainty_percent: None,
    })
}

/// Radiance-luminance statistics of an image ([`radiance_luminance`] of every pixel with a
/// finite, non-negative value): cd/m² for an absolute map. `min`, `max` and `mean` are exact;
/// `median` and `p99` are resolved to 1/64 of a stop (about 1 %).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LuminanceSummary {
    /// Smallest.
    pub min: f64,
    /// Median.
    pub median: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
    /// Mean.
    pub mean: f64,
}

/// Histogram bins of a positive `f32` by its bits: exponent and the top 6 bits of the
/// mantissa, i.e. 1/64-octave bins in order of value, with no logarithm per pixel.
const BIN_SHIFT: u32 = 17;

/// [`LuminanceSummary`] of `img`; `None` when no pixel has a valid value. One pass over the
/// pixels with a histogram for the percentiles (an exact sort of a 6 MP map cost more than
/// the rest of `skydome info`).
pub fn luminance_summary(img: &HdrImage) -> Option<LuminanceSummary> {
    let mut hist = vec![0u64; (u32::MAX >> 1 >> BIN_SHIFT) as usize + 1];
    let (mut n, mut sum) = (0u64, 0.0f64);
    let (mut min, mut max) = (f64::INFINITY, 0.0f64);
    for p in img.pixels() {
        let v = radiance_luminance(p.map(f64::from));
        if !(v.is_finite() && v >= 0.0) {
            continue;
        }
        n += 1;
        sum += v;
        min = min.min(v);
        max = max.max(v);
        hist[((v as f32).to_bits() >> BIN_SHIFT) as usize] += 1;
    }
    if n == 0 {
        return None;
    }
    let at = |q: f64| {
        let rank = ((q * n as f64).floor() as u64).min(n - 1);
        let mut seen = 0u64;
        for (bin, &c) in hist.iter().enumerate() {
            seen += c;
            if seen > rank {
                // The middle of the bin, kept within the exact extremes.
                let mid = f32::from_bits(((bin as u32) << BIN_SHIFT) | (1 << (BIN_SHIFT - 1)));
                return f64::from(mid).clamp(min, max);
            }
        }
        max
    };
    Some(LuminanceSummary {
        min,
        median: at(0.5),
        p99: at(0.99),
        max,
        mean: sum / n as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img() -> HdrImage {
        let mut i = HdrImage::new(10, 10);
        for y in 0..10 {
            for x in 0..10 {
                let v = (1 + x + 10 * y) as f32;
                i.set_pixel(x, y, [v, v, v]);
            }
        }
        i
    }

    #[test]
    fn patch_mean_is_radiance_luminance_of_the_disc() {
        let spot = SpotLuminance {
            pixel: PixelPoint { x: 4.5, y: 4.5 },
            radius_px: 0.1,
            cd_per_m2: 100.0,
        };
        // Only pixel (4, 4): value 45 in every channel, luminance 179 × 45.
        let l = patch_luminance(&img(), &spot).unwrap();
        assert!((l - 179.0 * 45.0).abs() < 1e-9, "{l}");
        let wide = SpotLuminance {
            radius_px: 1.2,
            ..spot
        };
        // The 3×3 block around (4, 4) minus nothing (corners at 1.41 > 1.2): a plus of 5.
        let l = patch_luminance(&img(), &wide).unwrap();
        assert!((l - 179.0 * 45.0).abs() < 1e-9, "{l}");
        let off = SpotLuminance {
            pixel: PixelPoint { x: -50.0, y: 3.0 },
            ..spot
        };
        assert!(matches!(
            patch_luminance(&img(), &off),
            Err(PhotometryError::PatchOutside { .. })
        ));
    }

    #[test]
    fn summary_of_radiance_luminance() {
        let s = luminance_summary(&img()).unwrap();
        assert!((s.min - 179.0).abs() < 1e-9 && (s.max - 179.0 * 100.0).abs() < 1e-6);
        // Percentiles to 1/64 stop (1.1 %).
        assert!((s.median / (179.0 * 51.0) - 1.0).abs() < 0.011, "{s:?}");
        assert!((s.p99 / (179.0 * 100.0) - 1.0).abs() < 0.011, "{s:?}");
        assert!((s.mean - 179.0 * 50.5).abs() < 1e-6, "{s:?}");
        assert!(luminance_summary(&HdrImage::new(0, 0)).is_none());
    }

    #[test]
    fn luminance_wins_and_the_disagreement_is_reported() {
        let reference = Reference {
            luminance: Some(SpotLuminance {
                pixel: PixelPoint { x: 0.0, y: 0.0 },
                radius_px: 1.0,
                cd_per_m2: 2000.0,
            }),
            illuminance_lux: Some(50_000.0),
        };
        let r = absolute_scale(&reference, Some(20.0), Some(550.0)).unwrap();
        assert_eq!((r.scale, r.from), (100.0, "luminance"));
        assert_eq!(r.patch_luminance_cd_m2, Some(2000.0));
        assert_eq!(r.horizontal_illuminance_lux, Some(55_000.0));
        assert!((r.disagreement_percent.unwrap() - 10.0).abs() < 1e-9);
        let only_lux = Reference {
            luminance: None,
            ..reference
        };
        let r = absolute_scale(&only_lux, None, Some(500.0)).unwrap();
        assert_eq!((r.scale, r.from), (100.0, "illuminance"));
        assert!(absolute_scale(&only_lux, None, Some(0.0)).is_err());
        let bad = Reference {
            illuminance_lux: Some(-3.0),
            luminance: None,
        };
        assert!(absolute_scale(&bad, None, Some(1.0)).is_err());
    }
}
