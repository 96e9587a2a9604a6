//! The sky stage of the pipeline, on the merged radiance map: the lens's fall-off divided out
//! and the absolute scale applied; then, with a lens, the crop (or level dome), north, the sun
//! (found, cross-checked, and put back when it clipped), Radiance `VIEW=`, the maps and the
//! overlay marks.

use std::borrow::Cow;

use serde::Serialize;

use super::absolute::ConstantScale;
use super::progress::{Reporter, Stage};
use super::{default_equirect_width, EquirectOptions, Options, PipelineError, SunDisc, SunMode};
use crate::bracket::Bracket;
use crate::fisheye::{self, CircleFit, LensKind, LensProfile};
use crate::formats::{HdrMeta, SunMark};
use crate::image::{fmt_num, radiance_luminance, Circle, HdrImage, PixelPoint};
use crate::overlay::OverlayMarks;
use crate::photometry::{self, PhotometryReport};
use crate::reproject::{self, MapProjection, ReprojectOptions};
use crate::sky::{self, DevicePose, Direction, ImageOrientation, Site, SkyGeometry, SunCrossCheck};
use crate::sun_disc::{self, DirectSource, SunDiscReport};

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
    /// North as set from the sun, when asked.
    pub north_from_sun: Option<NorthFromSun>,
    /// True when the output was resampled to a level dome (a tilt was given): its pixels are
    /// then no shifted copy of the input's.
    pub levelled: bool,
    /// Horizontal illuminance of the dome (θ ≤ 90°, cosine-weighted), Radiance's way
    /// ([`radiance_luminance`] of the horizontal irradiance): lux when the radiance is
    /// absolute, relative units otherwise. What `evalglare -V` reports for the upward dome.
    pub horizontal_illuminance: f64,
    /// The solar disc put back in place of a sun clipped in every frame (see
    /// [`crate::sun_disc`]); `None` when the sun was not clipped, not found, or kept.
    pub sun_disc: Option<SunDiscReport>,
}

/// North set from the observed sun and the ephemeris (a clip-on lens with a magnet biases the
/// phone's compass; the sun does not).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NorthFromSun {
    /// The azimuth of the phone's top edge that puts the observed sun at the computed azimuth,
    /// degrees from true north towards east, in `0..360`.
    pub north_deg: f64,
    /// The compass's value, when one was given.
    pub compass_deg: Option<f64>,
    /// The compass's error this implies (`north_deg − compass`, in `−180..180`), degrees.
    pub compass_error_deg: Option<f64>,
    /// Elevation of the observed sun minus the computed one, degrees (a check of the lens model
    /// and the level).
    pub elevation_error_deg: f64,
}

/// North from the sun: the sun observed (tapped or detected on the uncropped dome) is matched
/// to the ephemeris sun; the compass value (or 0) is corrected by the azimuth difference.
fn north_from_sun(
    o: &Options,
    br: &Bracket,
    lens: &LensProfile,
    radiance: &HdrImage,
) -> Result<NorthFromSun, PipelineError> {
    let eph = ephemeris(o, br)?.ok_or(PipelineError::NoEphemeris)?;
    let g = full_geometry(o, br, lens)?;
    let px = match o.sky.sun {
        SunMode::Tap(p) => Some(p),
        SunMode::Auto => sky::detect_sun(radiance, &g.horizon_circle()).map(|d| d.pixel),
        SunMode::None | SunMode::Ephemeris => None,
    };
    let dir = px
        .and_then(|p| g.pixel_to_direction(p))
        .ok_or(PipelineError::NoSunForNorth)?;
    let c = sky::cross_check(&dir, &eph);
    let base = o.sky.north_deg.unwrap_or(0.0);
    Ok(NorthFromSun {
        north_deg: (base + c.compass_error_deg).rem_euclid(360.0),
        compass_deg: o.sky.north_deg,
        compass_error_deg: o.sky.north_deg.map(|_| c.compass_error_deg),
        elevation_error_deg: -c.elevation_error_deg,
    })
}

impl GeometryReport {
    /// The input-photo pixel under output pixel `p` (e.g. a tap on the preview, to pass back as
    /// [`SunMode::Tap`]): the output is the input shifted by the crop, the lens circle's centre
    /// in the input sitting at the horizon's centre in the output. `None` for a levelled
    /// (resampled) dome.
    pub fn input_pixel(&self, p: PixelPoint) -> Option<PixelPoint> {
        (!self.levelled).then_some(PixelPoint {
            x: p.x + self.lens.circle.cx - self.horizon.cx,
            y: p.y + self.lens.circle.cy - self.horizon.cy,
        })
    }
}

/// What the sky stage leaves: the dome and its absolute calibration, and with a lens what the
/// sky's geometry found.
pub(super) struct SkyOutcome {
    /// The dome: cropped or levelled as asked, its clipped sun put back.
    pub image: HdrImage,
    /// The absolute calibration, when a measurement was given, with the scale in force on
    /// [`SkyOutcome::image`] (a sun put back within an illuminance reading rescales the dome).
    pub photometry: Option<PhotometryReport>,
    /// The sky's results, with a lens.
    pub sky: Option<SkyResult>,
}

/// The sky stage's results besides the dome.
pub(super) struct SkyResult {
    /// The sun, north and `VIEW=` of the dome.
    pub meta: HdrMeta,
    pub equirect: Option<HdrImage>,
    pub angular: Option<(HdrImage, HdrMeta)>,
    pub marks: OverlayMarks,
    pub report: GeometryReport,
    pub warnings: Vec<String>,
}

/// The geometry of the (possibly cropped) output and where input pixels land in it.
struct Framed {
    image: HdrImage,
    geom: SkyGeometry,
    /// Input pixel position of output pixel (0, 0), for a plain crop.
    offset: (f64, f64),
    /// The input photo's geometry, when the output was resampled to a level dome.
    resampled_from: Option<SkyGeometry>,
    crop_radius: Option<f64>,
}

impl Framed {
    /// An input-photo pixel position in the output image (`None` when a level dome does not
    /// show it).
    fn shift(&self, p: PixelPoint) -> Option<PixelPoint> {
        match &self.resampled_from {
            Some(src) => {
                let v = src.pixel_to_vector(p.x, p.y)?;
                let (x, y) = self.geom.vector_to_pixel(v)?;
                Some(PixelPoint { x, y })
            }
            None => Some(PixelPoint {
                x: p.x - self.offset.0,
                y: p.y - self.offset.1,
            }),
        }
    }

    /// The input-photo pixel position under an output pixel position (the inverse of
    /// [`Framed::shift`]).
    fn unshift(&self, p: PixelPoint) -> Option<PixelPoint> {
        match &self.resampled_from {
            Some(src) => {
                let v = self.geom.pixel_to_vector(p.x, p.y)?;
                let (x, y) = src.vector_to_pixel(v)?;
                Some(PixelPoint { x, y })
            }
            None => Some(PixelPoint {
                x: p.x + self.offset.0,
                y: p.y + self.offset.1,
            }),
        }
    }
}

/// The sky stage on `radiance` (the merged, uncropped photo): the lens's fall-off divided out,
/// the absolute scale applied when a measurement is given, and with a lens the dome's geometry
/// ([`apply`]). `origin`: the photo's pixel (x, y) at `radiance`'s (0, 0) — not (0, 0) only when
/// the merge covered the crop's square alone, which the pipeline does only when the crop is the
/// first thing to read the pixels. `clipped`: the merge's per-pixel flags (`CLIPPED_HIGH` …) of
/// the whole photo, when computed.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    o: &Options,
    br: &Bracket,
    lens: Option<(LensProfile, Option<CircleFit>)>,
    mut radiance: HdrImage,
    origin: (i64, i64),
    clipped: Option<&[u8]>,
    constant: Option<&ConstantScale>,
    progress: &mut Reporter<'_>,
) -> Result<SkyOutcome, PipelineError> {
    if let Some((l, _)) = &lens {
        if let Some(v) = &l.vignetting {
            fisheye::devignette(&mut radiance, l, v);
        }
    }
    let photometry =
        calibrate_absolute(o, br, lens.as_ref().map(|l| &l.0), constant, &mut radiance)?;
    let Some(lens) = lens else {
        return Ok(SkyOutcome {
            image: radiance,
            photometry,
            sky: None,
        });
    };
    progress.at(Stage::Sky, 0.0)?;
    let out = apply(o, br, lens, radiance, origin, clipped, photometry)?;
    progress.at(Stage::Sky, 1.0)?;
    Ok(out)
}

/// Scales `radiance` to Radiance's absolute units when a measurement is given, else by the
/// `constant` (the camera profile's, or the meter equation's) when there is one.
fn calibrate_absolute(
    o: &Options,
    br: &Bracket,
    lens: Option<&LensProfile>,
    constant: Option<&ConstantScale>,
    radiance: &mut HdrImage,
) -> Result<Option<PhotometryReport>, PipelineError> {
    let r = &o.reference;
    if r.is_empty() {
        let Some(c) = constant else {
            return Ok(None);
        };
        let k = c.scale as f32;
        radiance.data.iter_mut().for_each(|v| *v *= k);
        let illuminance = match lens {
            Some(lens) => {
                let g = full_geometry(o, br, lens)?;
                Some(radiance_luminance(
                    reproject::horizontal_irradiance_fisheye(radiance, &g),
                ))
            }
            None => None,
        };
        return Ok(Some(PhotometryReport {
            scale: c.scale,
            from: c.from,
            patch_luminance_cd_m2: None,
            horizontal_illuminance_lux: illuminance,
            disagreement_percent: None,
            uncertainty_percent: c.uncertainty_percent,
        }));
    }
    let patch = match &r.luminance {
        Some(s) => Some(photometry::patch_luminance(radiance, s)?),
        None => None,
    };
    let illuminance = match (r.illuminance_lux, lens) {
        (Some(_), Some(lens)) => {
            let g = full_geometry(o, br, lens)?;
            Some(radiance_luminance(
                reproject::horizontal_irradiance_fisheye(radiance, &g),
            ))
        }
        _ => None,
    };
    let rep = photometry::absolute_scale(r, patch, illuminance)?;
    let k = rep.scale as f32;
    radiance.data.iter_mut().for_each(|v| *v *= k);
    Ok(Some(rep))
}

/// The sky's geometry on the merged photo: north (from the sun when asked), the crop or the
/// level dome, the sun found and, when it clipped, put back; the maps and the marks.
fn apply(
    o: &Options,
    br: &Bracket,
    (lens, detected): (LensProfile, Option<CircleFit>),
    radiance: HdrImage,
    origin: (i64, i64),
    clipped: Option<&[u8]>,
    mut photometry: Option<PhotometryReport>,
) -> Result<SkyOutcome, PipelineError> {
    let (o, north_fix) = with_north_from_sun(o, br, &lens, &radiance)?;
    let o = o.as_ref();
    let s = &o.sky;
    let full = full_geometry(o, br, &lens)?;
    let mut f = match (s.level.is_some(), s.crop) {
        (true, true) => level_dome(&radiance, &lens, full, s.fov_out_deg)?,
        _ => frame(
            radiance,
            origin,
            &lens,
            full,
            s.crop.then_some(s.fov_out_deg),
        )?,
    };
    let horizon = f.geom.horizon_circle();
    let north = s.north_deg.map(|_| f.geom.north_point());
    let sun = locate_sun(o, br, &f, &horizon, clipped)?;
    let mut warnings: Vec<String> = sun.disagreement_warning().into_iter().collect();
    warnings.extend(sun.missing_warning(&f));
    let disc = match (s.sun_disc, &sun.direction, clipped) {
        (SunDisc::Reconstruct, Some(d), Some(mask)) => {
            let mask = (mask, br.width(), br.height());
            reconstruct_sun(o, &mut f, d, mask, photometry.as_ref())
                .and_then(|r| r.map_err(|w| warnings.push(w)).ok())
        }
        _ => None,
    };
    let horizontal_illuminance =
        radiance_luminance(reproject::horizontal_irradiance_fisheye(&f.image, &f.geom));
    if let (Some(&(_, rescale)), Some(p)) = (disc.as_ref(), photometry.as_mut()) {
        p.scale *= rescale;
        p.patch_luminance_cd_m2 = p.patch_luminance_cd_m2.map(|l| l * rescale);
        p.horizontal_illuminance_lux = Some(horizontal_illuminance);
    }
    let mark = sun.mark(s.north_deg.is_some());
    // Only a crop is square and centred on the optical axis, as a Radiance view must be.
    let view = s
        .crop
        .then(|| f.geom.radiance_view(0.5 * f.image.width as f64))
        .flatten();
    let equirect = match &o.products.equirect {
        Some(e) => Some(equirect_map(&f, e, horizon.r)?),
        None => None,
    };
    let angular = match o.products.angular {
        true => Some(angular_map(
            &f,
            horizon.r,
            sun.direction,
            s.north_deg.is_some(),
        )?),
        false => None,
    };
    // A level dome is resampled: the lens's circle is no circle in it.
    let visible = f.resampled_from.is_none().then_some(Circle {
        cx: lens.circle.cx - f.offset.0,
        cy: lens.circle.cy - f.offset.1,
        r: lens.circle.r,
    });
    let sky = SkyResult {
        meta: HdrMeta {
            sun: mark,
            north,
            view,
            ..HdrMeta::default()
        },
        equirect,
        angular,
        marks: OverlayMarks {
            visible,
            horizon: Some(horizon),
            north,
            sun: sun.pixel,
        },
        report: GeometryReport {
            lens,
            detected_circle: detected,
            crop_radius_px: f.crop_radius,
            horizon,
            north,
            sun: mark,
            sun_source: sun.pixel.and(sun.source),
            sun_confidence: sun.confidence,
            sun_ephemeris: sun.ephemeris,
            sun_cross_check: sun.cross_check,
            north_from_sun: north_fix,
            levelled: f.resampled_from.is_some(),
            horizontal_illuminance,
            sun_disc: disc.map(|(d, _)| d),
        },
        warnings,
    };
    Ok(SkyOutcome {
        image: f.image,
        photometry,
        sky: Some(sky),
    })
}

/// The options with north set from the sun when [`SkyOptions::north_from_sun`](super::SkyOptions::north_from_sun)
/// asks, and how it was set.
fn with_north_from_sun<'a>(
    o: &'a Options,
    br: &Bracket,
    lens: &LensProfile,
    radiance: &HdrImage,
) -> Result<(Cow<'a, Options>, Option<NorthFromSun>), PipelineError> {
    if !o.sky.north_from_sun {
        return Ok((Cow::Borrowed(o), None));
    }
    let n = north_from_sun(o, br, lens, radiance)?;
    let mut fixed = o.clone();
    fixed.sky.north_deg = Some(n.north_deg);
    Ok((Cow::Owned(fixed), Some(n)))
}

/// The sun in the output: where (pixels and direction), how it was found, and how it compares
/// with the ephemeris.
struct SunFound {
    pixel: Option<PixelPoint>,
    direction: Option<Direction>,
    source: Option<SunSource>,
    /// Confidence of a detection.
    confidence: Option<f64>,
    /// The computed sun, when time and place are known.
    ephemeris: Option<Direction>,
    /// The detected or tapped sun against the computed one.
    cross_check: Option<SunCrossCheck>,
}

impl SunFound {
    /// The warning when the observed sun is [`SUN_DISAGREEMENT_WARN_DEG`] or more from the
    /// computed one.
    fn disagreement_warning(&self) -> Option<String> {
        let c = self
            .cross_check
            .filter(|c| c.angle_deg >= SUN_DISAGREEMENT_WARN_DEG)?;
        Some(format!(
            "detected sun is {:.1}° from the computed one; a compass error of {:+.1}° would explain the azimuth",
            c.angle_deg, c.compass_error_deg
        ))
    }

    /// The warning when time and site put the sun above the horizon, no sun was observed, and
    /// the sky around the computed sun is bright (at least [`CLEAR_AROUND_SUN_RATIO`] times
    /// the dome's median luminance within 10° of it, as around a sun in a clear sky): a sun
    /// should have been seen there. An overcast sky is dull there and gets no warning.
    fn missing_warning(&self, f: &Framed) -> Option<String> {
        let e = self.ephemeris.filter(|e| e.elevation_deg > 0.5)?;
        if self.pixel.is_some() || self.source.is_some() {
            return None;
        }
        let ratio = brightness_around(f, &e, 10.0)?;
        (ratio >= CLEAR_AROUND_SUN_RATIO).then(|| {
            format!(
                "time and site put the sun at azimuth {:.1}°, elevation {:.1}°, and the sky there is {:.0}× the dome's median, but no sun was found: a cloud or an obstacle hides it, or the time, site, north or lens is wrong",
                e.azimuth_deg, e.elevation_deg, ratio
            )
        })
    }

    /// The sun as marked in the header: an azimuth means something only when north is known,
    /// or the position came from it (the ephemeris).
    fn mark(&self, north_known: bool) -> Option<SunMark> {
        let azimuth_known = north_known || self.source == Some(SunSource::Ephemeris);
        self.pixel.map(|pixel| SunMark {
            pixel,
            azimuth_deg: self
                .direction
                .filter(|_| azimuth_known)
                .map(|d| d.azimuth_deg),
            elevation_deg: self.direction.map(|d| d.elevation_deg),
        })
    }
}

/// Finds the sun in the framed dome as [`SkyOptions::sun`](super::SkyOptions::sun) says, and
/// cross-checks an observed one with the ephemeris.
fn locate_sun(
    o: &Options,
    br: &Bracket,
    f: &Framed,
    horizon: &Circle,
    clipped: Option<&[u8]>,
) -> Result<SunFound, PipelineError> {
    let ephemeris = ephemeris(o, br)?;
    // The ephemeris guides the search only where azimuths mean something (north known).
    let prior = ephemeris
        .filter(|_| o.sky.north_deg.is_some())
        .map(|d| (d, SUN_PRIOR_RADIUS_DEG));
    let mask = clipped.map(|m| framed_mask(f, m, br.width(), br.height()));
    let clues = sky::SunClues {
        clipped: mask.as_deref(),
        prior,
    };
    let (pixel, source, confidence) = find_sun(o.sky.sun, f, horizon, ephemeris.as_ref(), &clues)?;
    let direction = pixel.and_then(|p| f.geom.pixel_to_direction(p));
    let cross_check = match (source, &direction, &ephemeris) {
        (Some(SunSource::Detected | SunSource::Tap), Some(d), Some(e)) => {
            Some(sky::cross_check(d, e))
        }
        _ => None,
    };
    Ok(SunFound {
        pixel,
        direction,
        source,
        confidence,
        ephemeris,
        cross_check,
    })
}

/// The sky within 10° of a sun this many times brighter than the dome's median counts as clear
/// around the sun (Perez clear skies: 5–30×; overcast: 1–2×).
pub const CLEAR_AROUND_SUN_RATIO: f64 = 3.0;

/// Mean luminance within `radius_deg` of `d` over the dome's median luminance (`None` when the
/// dome or the cap is empty).
fn brightness_around(f: &Framed, d: &Direction, radius_deg: f64) -> Option<f64> {
    let sun = d.to_vector();
    let cos_r = radius_deg.to_radians().cos();
    let (mut all, mut near) = (Vec::new(), (0.0f64, 0usize));
    for y in 0..f.image.height {
        for x in 0..f.image.width {
            let Some(v) = f.geom.pixel_to_vector(x as f64 + 0.5, y as f64 + 0.5) else {
                continue;
            };
            if v[2] < 0.0 {
                continue;
            }
            let l = radiance_luminance(f.image.pixel(x, y).map(f64::from));
            all.push(l);
            if v[0] * sun[0] + v[1] * sun[1] + v[2] * sun[2] >= cos_r {
                near.0 += l;
                near.1 += 1;
            }
        }
    }
    if all.is_empty() || near.1 == 0 {
        return None;
    }
    let mid = all.len() / 2;
    let median = *all.select_nth_unstable_by(mid, f64::total_cmp).1;
    (median > 0.0).then(|| near.0 / near.1 as f64 / median)
}

/// The equirectangular map of the framed dome.
fn equirect_map(
    f: &Framed,
    e: &EquirectOptions,
    horizon_r: f64,
) -> Result<HdrImage, PipelineError> {
    Ok(reproject::reproject(
        &f.image,
        &f.geom,
        &MapProjection::Equirect {
            width: e.width.unwrap_or_else(|| default_equirect_width(horizon_r)),
            centre_azimuth_deg: 90.0,
        },
        &ReprojectOptions {
            ground: e.ground,
            ..ReprojectOptions::default()
        },
    )?)
}

/// Puts the solar disc back when the sun at `sun` clipped in every frame (`mask`: the merge's
/// per-pixel flags of the `width × height` input photos). `None`: nothing to do (the sun did
/// not clip, or it is at or below the horizon, or the dome is not level); `Some(Err)`: a
/// warning why the clipped sun was kept; `Some(Ok)`: the report and the factor the whole dome
/// was scaled by to make room for the sun within an illuminance reading that set the scale
/// alone (1 otherwise).
fn reconstruct_sun(
    o: &Options,
    f: &mut Framed,
    sun: &Direction,
    (mask, width, height): (&[u8], usize, usize),
    photometry: Option<&PhotometryReport>,
) -> Option<Result<(SunDiscReport, f64), String>> {
    // The illuminance integral takes the optical axis as the zenith: true unless a tilt was
    // given without the crop that levels the dome.
    let level = o.sky.level.is_none() || f.resampled_from.is_some();
    if sun.elevation_deg <= 0.5 || !level {
        return None;
    }
    let at = f.geom.direction_to_pixel(sun)?;
    let input_at = f.unshift(at)?;
    // Clipped pixels within half a degree of the sun's centre in the input photos.
    let proj = f.geom.projection();
    let px_per_rad = proj.derivative((90.0 - sun.elevation_deg).to_radians());
    let radius = (0.5f64.to_radians() * px_per_rad).max(1.5);
    if !sun_disc::clipped_near(mask, width, height, input_at, radius) {
        return None;
    }
    let disc = sun_disc::disc_pixels(&f.geom, f.image.width, f.image.height, sun);
    if disc.is_empty() {
        return None;
    }
    let total = radiance_luminance(reproject::horizontal_irradiance_fisheye(&f.image, &f.geom));
    let mut diffuse = total - sun_disc::disc_illuminance(&f.image, &disc);
    let el = sun.elevation_deg;
    let sin_h = el.to_radians().sin();
    let model_direct = sun_disc::clear_sky_direct_normal_lux(el) * sin_h;
    let ratio = model_direct / sun_disc::clear_sky_diffuse_horizontal_lux(el);
    let reading = o.reference.illuminance_lux;
    let (direct, from, rescale) = match (photometry.map(|p| p.from), reading) {
        // Absolute from a luminance reading, and the illuminance measured: the difference.
        (Some("luminance"), Some(e)) => (e - diffuse, DirectSource::MeasuredIlluminance, 1.0),
        // Absolute without an illuminance reading (a luminance reading, the camera profile's
        // constant, the meter equation): the model's absolute direct part.
        (Some(_), None) => (model_direct, DirectSource::ModelDirectNormal, 1.0),
        // The illuminance reading alone set the scale, sun clipped: it is the total, split into
        // diffuse and direct by the model.
        (Some(_), Some(e)) => {
            let k = e / (1.0 + ratio) / diffuse;
            (e - e / (1.0 + ratio), DirectSource::ModelRatio, k)
        }
        _ => (ratio * diffuse, DirectSource::ModelRatio, 1.0),
    };
    if !(direct.is_finite() && direct > 0.0 && diffuse > 0.0 && rescale.is_finite()) {
        return Some(Err(format!(
            "the sun is clipped in every frame, but the dome without it already gives {} of the {} lux measured: the sun's disc was kept as merged (a lower bound)",
            fmt_num(diffuse.round()),
            fmt_num(reading.unwrap_or(f64::NAN).round())
        )));
    }
    if rescale != 1.0 {
        let k = rescale as f32;
        f.image.data.iter_mut().for_each(|v| *v *= k);
        diffuse *= rescale;
    }
    let weight: f64 = disc.iter().map(|p| p.coverage * p.weight).sum();
    let luminance = direct / weight;
    sun_disc::paint_disc(&mut f.image, &disc, luminance);
    Some(Ok((
        SunDiscReport {
            direction: *sun,
            luminance,
            direct_normal: direct / sin_h,
            direct_horizontal: direct,
            diffuse_horizontal: diffuse,
            from,
            absolute: photometry.is_some(),
            pixels: disc.len(),
        },
        rescale,
    )))
}

/// The geometry of the merged (uncropped) photo: the lens, north (0 when unknown), the pose and
/// the EXIF orientation still in force on the pixels.
pub(super) fn full_geometry(
    o: &Options,
    br: &Bracket,
    lens: &LensProfile,
) -> Result<SkyGeometry, PipelineError> {
    let orient = ImageOrientation::from_exif(br.pixel_orientation)?;
    let g = SkyGeometry::new(lens, o.sky.north_deg.unwrap_or(0.0), o.sky.pose, orient)?;
    Ok(match &o.sky.level {
        Some(level) => g.with_level(level)?,
        None => g,
    })
}

/// Crops to the dome of `crop_fov_deg` when given, moving the geometry's centre with it.
/// `radiance` starts at the photo's pixel `origin` (the merge's window, when only the crop's
/// square was merged; else (0, 0)).
fn frame(
    radiance: HdrImage,
    origin: (i64, i64),
    lens: &LensProfile,
    full: SkyGeometry,
    crop_fov_deg: Option<f64>,
) -> Result<Framed, PipelineError> {
    Ok(match crop_fov_deg {
        Some(fov) => {
            let c = fisheye::crop_dome_from(&radiance, origin, lens, fov)?;
            Framed {
                geom: full.with_centre(c.horizon.cx, c.horizon.cy),
                offset: (c.offset_x as f64, c.offset_y as f64),
                resampled_from: None,
                crop_radius: Some(c.crop_radius_px),
                image: c.image,
            }
        }
        None => Framed {
            image: radiance,
            geom: full,
            offset: (0.0, 0.0),
            resampled_from: None,
            crop_radius: None,
        },
    })
}

/// The dome of `fov_deg` of a tilted photo, resampled so that the zenith is at its centre: the
/// lens's own projection (equidistant for a polynomial lens) and resolution, north (as far as it
/// is known) at the top, east on the left.
fn level_dome(
    radiance: &HdrImage,
    lens: &LensProfile,
    full: SkyGeometry,
    fov_deg: f64,
) -> Result<Framed, PipelineError> {
    let kind = match lens.projection.kind() {
        LensKind::Polynomial => LensKind::Equidistant,
        k => k,
    };
    let r = lens.radius_at_deg(0.5 * fov_deg)?;
    let size = (2.0 * r.ceil()).clamp(16.0, 32768.0) as usize;
    let half = 0.5 * size as f64;
    let target = MapProjection::Fisheye {
        size,
        model: kind,
        fov_deg,
    };
    let image = reproject::reproject(radiance, &full, &target, &ReprojectOptions::default())?;
    let out_lens = LensProfile::from_fov(
        Circle {
            cx: half,
            cy: half,
            r: half,
        },
        fov_deg,
        kind,
    )?;
    let geom = SkyGeometry::new(
        &out_lens,
        0.0,
        DevicePose::ScreenDown,
        ImageOrientation::Normal,
    )?;
    Ok(Framed {
        image,
        geom,
        offset: (0.0, 0.0),
        resampled_from: Some(full),
        crop_radius: Some(r),
    })
}

/// The computed sun direction when time and place are known (given values win over EXIF);
/// an error only when the ephemeris sun was asked for and cannot be computed.
fn ephemeris(o: &Options, br: &Bracket) -> Result<Option<Direction>, PipelineError> {
    let c = super::capture::resolve(o, br)?;
    let dir = match (c.time, c.site) {
        (Some(t), Some((lat, lon))) => Some(sky::sun_ephemeris(
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
    clues: &sky::SunClues<'_>,
) -> Result<FoundSun, PipelineError> {
    Ok(match mode {
        SunMode::None => (None, None, None),
        SunMode::Tap(p) => (f.shift(p), Some(SunSource::Tap), None),
        SunMode::Ephemeris => (
            ephemeris.and_then(|d| f.geom.direction_to_pixel(d)),
            Some(SunSource::Ephemeris),
            None,
        ),
        SunMode::Auto => {
            let found = match clues.clipped {
                Some(_) => sky::find_sun(&f.image, &f.geom, clues)?,
                // Without the merge's clipping flags, the blob above half the peak.
                None => sky::detect_sun(&f.image, horizon),
            };
            match found {
                Some(d) => (Some(d.pixel), Some(SunSource::Detected), Some(d.confidence)),
                None => (None, None, None),
            }
        }
    })
}

/// The sun in output pixels, how it was found, and the detection's confidence.
type FoundSun = (Option<PixelPoint>, Option<SunSource>, Option<f64>);

/// How far from the ephemeris sun (degrees) a detection is still taken for it: a phone's
/// compass near a clip-on lens's magnet errs by up to ~10°, a lens model by a degree or two.
pub const SUN_PRIOR_RADIUS_DEG: f64 = 12.0;

/// The merge's clipped-in-every-frame flags (`mask`, per input pixel, `width × height`) on the
/// framed dome's pixels.
fn framed_mask(f: &Framed, mask: &[u8], width: usize, height: usize) -> Vec<bool> {
    let (w, h) = (f.image.width, f.image.height);
    let mut out = vec![false; w * h];
    let row = |(y, out): (usize, &mut [bool])| {
        for (x, o) in out.iter_mut().enumerate() {
            let p = PixelPoint {
                x: x as f64 + 0.5,
                y: y as f64 + 0.5,
            };
            let Some(q) = f.unshift(p) else { continue };
            if q.x < 0.0 || q.y < 0.0 {
                continue;
            }
            let (ix, iy) = (q.x as usize, q.y as usize);
            if ix < width && iy < height {
                *o = mask[iy * width + ix] & crate::merge::CLIPPED_HIGH != 0;
            }
        }
    };
    // Rows in parallel with the `parallel` feature (a level dome's rows cost trigonometry).
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(w.max(1)).enumerate().for_each(row);
    }
    #[cfg(not(feature = "parallel"))]
    out.chunks_mut(w.max(1)).enumerate().for_each(row);
    out
}

/// The upward 180° dome as Radiance's angular fish-eye (`-vta`), whatever the lens's own
/// projection: north at the top, east on the left, the horizon inscribed in a square of the
/// horizon's diameter; with `VIEW=`, and the sun (and north, when known) marked in its pixels.
fn angular_map(
    f: &Framed,
    horizon_r: f64,
    sun: Option<Direction>,
    north_known: bool,
) -> Result<(HdrImage, HdrMeta), PipelineError> {
    let size = (2.0 * horizon_r.ceil()).clamp(16.0, 32768.0) as usize;
    let target = MapProjection::Fisheye {
        size,
        model: LensKind::Equidistant,
        fov_deg: 180.0,
    };
    let image = reproject::reproject(&f.image, &f.geom, &target, &ReprojectOptions::default())?;
    let at = |d: &Direction| -> Option<PixelPoint> {
        let (x, y) = target.vector_to_pixel(d.to_vector()).ok()??;
        Some(PixelPoint { x, y })
    };
    let meta = HdrMeta {
        view: target.radiance_view(),
        sun: sun.and_then(|d| {
            Some(SunMark {
                pixel: at(&d)?,
                azimuth_deg: north_known.then_some(d.azimuth_deg),
                elevation_deg: Some(d.elevation_deg),
            })
        }),
        north: north_known.then(|| at(&Direction::new(0.0, 0.0))).flatten(),
        ..HdrMeta::default()
    };
    Ok((image, meta))
}
