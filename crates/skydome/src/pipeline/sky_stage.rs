//! The sky stage of the pipeline: crop, north, the sun, Radiance `VIEW=`, the equirectangular
//! map and the overlay marks, on a merged fish-eye radiance map.

use serde::Serialize;
use time::OffsetDateTime;

use super::{default_equirect_width, Options, PipelineError, SunMode};
use crate::bracket::Bracket;
use crate::fisheye::{self, CircleFit, LensProfile};
use crate::formats::{HdrMeta, PixelPoint, SunMark};
use crate::image::{Circle, HdrImage};
use crate::overlay::OverlayMarks;
use crate::reproject::{self, MapProjection, ReprojectOptions};
use crate::sky::{self, Direction, ImageOrientation, Site, SkyGeometry, SunCrossCheck};

/// A detected sun further than this from the computed one is reported as a warning (degrees):
/// beyond a few solar diameters, and about what a phone compass near a magnet errs by.
pub const SUN_DISAGREEMENT_WARN_DEG: f64 = 2.0;

/// How the sun in the output was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SunSource {
    /// Tapped by the user.
    Tap,
    /// Computed from time and place.
    Ephemeris,
    /// Detected in the image.
    Detected,
}

impl std::fmt::Display for SunSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SunSource::Tap => "tap",
            SunSource::Ephemeris => "ephemeris",
            SunSource::Detected => "detected",
        })
    }
}

/// What the fish-eye processing found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GeometryReport {
    /// The lens profile used.
    pub lens: LensProfile,
    /// The detected circle, when it was detected.
    pub detected_circle: Option<CircleFit>,
    /// Crop radius in input pixels, when cropped.
    pub crop_radius_px: Option<f64>,
    /// The horizon circle in the output image.
    pub horizon: Circle,
    /// North point in the output image (when north was given).
    pub north: Option<PixelPoint>,
    /// The sun in the output image.
    pub sun: Option<SunMark>,
    /// How the sun was found.
    pub sun_source: Option<SunSource>,
    /// Confidence of the detection, `0..=1`.
    pub sun_confidence: Option<f64>,
    /// The computed (ephemeris) sun direction, when time and place are known.
    pub sun_ephemeris: Option<Direction>,
    /// Agreement between the detected (or tapped) and the computed sun.
    pub sun_cross_check: Option<SunCrossCheck>,
}

/// The sky stage's results.
pub(super) struct SkyResult {
    pub image: HdrImage,
    pub meta: HdrMeta,
    pub equirect: Option<HdrImage>,
    pub marks: OverlayMarks,
    pub report: GeometryReport,
    pub warnings: Vec<String>,
}

/// The geometry of the (possibly cropped) output and where input pixels land in it.
struct Framed {
    image: HdrImage,
    geom: SkyGeometry,
    /// Input pixel position of output pixel (0, 0).
    offset: (f64, f64),
    crop_radius: Option<f64>,
}

impl Framed {
    /// An input-photo pixel position in the output image.
    fn shift(&self, p: PixelPoint) -> PixelPoint {
        PixelPoint {
            x: p.x - self.offset.0,
            y: p.y - self.offset.1,
        }
    }
}

/// Runs the sky stage on `radiance` (the merged, uncropped photo).
pub(super) fn apply(
    o: &Options,
    br: &Bracket,
    (lens, detected): (LensProfile, Option<CircleFit>),
    radiance: HdrImage,
) -> Result<SkyResult, PipelineError> {
    let s = &o.sky;
    let orient = ImageOrientation::from_exif(br.pixel_orientation)?;
    let full = SkyGeometry::new(&lens, s.north_deg.unwrap_or(0.0), s.pose, orient)?;
    let f = frame(radiance, &lens, full, s.crop.then_some(s.fov_out_deg))?;
    let horizon = f.geom.horizon_circle();
    let north = s.north_deg.map(|_| f.geom.north_point());
    let ephemeris = ephemeris(o, br)?;
    let (sun_px, source, confidence) = find_sun(s.sun, &f, &horizon, ephemeris.as_ref());
    let sun_dir = sun_px.and_then(|p| f.geom.pixel_to_direction(p));
    let cross = match (source, &sun_dir, &ephemeris) {
        (Some(SunSource::Detected | SunSource::Tap), Some(d), Some(e)) => {
            Some(sky::cross_check(d, e))
        }
        _ => None,
    };
    let mut warnings = Vec::new();
    if let Some(c) = cross.filter(|c| c.angle_deg >= SUN_DISAGREEMENT_WARN_DEG) {
        warnings.push(format!(
            "detected sun is {:.1}° from the computed one; a compass error of {:+.1}° would explain the azimuth",
            c.angle_deg, c.compass_error_deg
        ));
    }
    // An azimuth means something only when north is known, or the position came from it.
    let azimuth_known = s.north_deg.is_some() || source == Some(SunSource::Ephemeris);
    let sun = sun_px.map(|pixel| SunMark {
        pixel,
        azimuth_deg: sun_dir.filter(|_| azimuth_known).map(|d| d.azimuth_deg),
        elevation_deg: sun_dir.map(|d| d.elevation_deg),
    });
    let view = s
        .crop
        .then(|| fisheye::radiance_view(lens.projection.kind(), s.fov_out_deg))
        .flatten();
    let equirect = match &o.products.equirect {
        Some(e) => Some(reproject::reproject(
            &f.image,
            &f.geom,
            &MapProjection::Equirect {
                width: e.width.unwrap_or_else(|| default_equirect_width(horizon.r)),
                centre_azimuth_deg: 90.0,
            },
            &ReprojectOptions {
                ground: e.ground,
                ..ReprojectOptions::default()
            },
        )?),
        None => None,
    };
    let visible = Circle {
        cx: lens.circle.cx - f.offset.0,
        cy: lens.circle.cy - f.offset.1,
        r: lens.circle.r,
    };
    Ok(SkyResult {
        meta: HdrMeta {
            sun,
            north,
            view,
            ..HdrMeta::default()
        },
        equirect,
        marks: OverlayMarks {
            visible: Some(visible),
            horizon: Some(horizon),
            north,
            sun: sun_px,
        },
        report: GeometryReport {
            lens,
            detected_circle: detected,
            crop_radius_px: f.crop_radius,
            horizon,
            north,
            sun,
            sun_source: sun_px.and(source),
            sun_confidence: confidence,
            sun_ephemeris: ephemeris,
            sun_cross_check: cross,
        },
        image: f.image,
        warnings,
    })
}

/// Crops to the dome of `crop_fov_deg` when given, moving the geometry's centre with it.
fn frame(
    radiance: HdrImage,
    lens: &LensProfile,
    full: SkyGeometry,
    crop_fov_deg: Option<f64>,
) -> Result<Framed, PipelineError> {
    Ok(match crop_fov_deg {
        Some(fov) => {
            let c = fisheye::crop_dome(&radiance, lens, fov)?;
            Framed {
                geom: full.with_centre(c.horizon.cx, c.horizon.cy),
                offset: (c.offset_x as f64, c.offset_y as f64),
                crop_radius: Some(c.crop_radius_px),
                image: c.image,
            }
        }
        None => Framed {
            image: radiance,
            geom: full,
            offset: (0.0, 0.0),
            crop_radius: None,
        },
    })
}

/// The capture time: the given one, else EXIF's.
fn capture_time(o: &Options, br: &Bracket) -> Result<Option<OffsetDateTime>, PipelineError> {
    match &o.sky.time {
        Some(t) => crate::bracket::parse_iso8601(t)
            .map(Some)
            .ok_or_else(|| PipelineError::BadTime(t.clone())),
        None => Ok(br.info.capture_time()),
    }
}

/// The computed sun direction when time and place are known (given values win over EXIF);
/// an error only when the ephemeris sun was asked for and cannot be computed.
fn ephemeris(o: &Options, br: &Bracket) -> Result<Option<Direction>, PipelineError> {
    let time = capture_time(o, br)?;
    let lat = o.sky.latitude_deg.or(br.info.gps_latitude_deg);
    let lon = o.sky.longitude_deg.or(br.info.gps_longitude_deg);
    let dir = match (time, lat, lon) {
        (Some(t), Some(lat), Some(lon)) => Some(sky::sun_ephemeris(
            t,
            &Site {
                latitude_deg: lat,
                longitude_deg: lon,
                height_m: 0.0,
                refraction: sky::Refraction::Standard,
            },
            None,
        )?),
        _ => None,
    };
    if o.sky.sun == SunMode::Ephemeris && dir.is_none() {
        return Err(PipelineError::NoEphemeris);
    }
    Ok(dir)
}

/// The sun in output pixels, how it was found, and the detection's confidence.
fn find_sun(
    mode: SunMode,
    f: &Framed,
    horizon: &Circle,
    ephemeris: Option<&Direction>,
) -> (Option<PixelPoint>, Option<SunSource>, Option<f64>) {
    match mode {
        SunMode::None => (None, None, None),
        SunMode::Tap(p) => (Some(f.shift(p)), Some(SunSource::Tap), None),
        SunMode::Ephemeris => (
            ephemeris.and_then(|d| f.geom.direction_to_pixel(d)),
            Some(SunSource::Ephemeris),
            None,
        ),
        SunMode::Auto => match sky::detect_sun(&f.image, horizon) {
            Some(d) => (Some(d.pixel), Some(SunSource::Detected), Some(d.confidence)),
            None => (None, None, None),
        },
    }
}
