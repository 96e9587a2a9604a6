//! The fish-eye part of `skydome merge` (and the `lens` command's detection): lens circle and
//! model, 180° crop, north, sun, equirectangular map and overlay.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use skydome::bracket::{Bracket, Pixels};
use skydome::fisheye::{self, CircleFit, LensKind, LensProfile};
use skydome::formats::{HdrMeta, PixelPoint, SunMark};
use skydome::image::{Circle, RgbImage};
use skydome::overlay::{self, OverlayMarks};
use skydome::reproject::{self, Ground, MapProjection, ReprojectOptions};
use skydome::sky::{self, DevicePose, Direction, ImageOrientation, Site, SkyGeometry};
use skydome::HdrImage;

/// Fish-eye options of `skydome merge`.
#[derive(Debug, Clone, clap::Args)]
pub struct GeometryArgs {
    /// A lens profile from `skydome lens fit`.
    #[arg(long, value_name = "lens.json")]
    pub lens: Option<PathBuf>,
    /// The photos are fish-eye: detect the image circle (or take --circle) and model the lens
    /// with --lens-model and --fov.
    #[arg(long)]
    pub fisheye: bool,
    /// Lens projection when no --lens profile is given.
    #[arg(long, value_parser = parse_kind, default_value = "stereographic")]
    pub lens_model: LensKind,
    /// Full field of view of the lens across its visible circle, degrees.
    #[arg(long, default_value_t = 235.0)]
    pub fov: f64,
    /// Crop to the sky-dome: a square image whose circle is the horizon (θ = fov-out/2).
    #[arg(long)]
    pub crop: bool,
    /// Field of view kept by --crop, degrees.
    #[arg(long, default_value_t = 180.0)]
    pub fov_out: f64,
    /// Compass azimuth of the phone's top edge, degrees from true north towards east.
    #[arg(long, allow_hyphen_values = true, value_name = "DEG")]
    pub north: Option<f64>,
    /// How the phone lay: screen-down (rear camera looks up, the usual) or screen-up.
    #[arg(long, value_enum, default_value_t = PoseArg::ScreenDown)]
    pub device_pose: PoseArg,
    /// The sun: `auto` (detect the brightest blob), `none`, `ephemeris` (from time and place),
    /// or `X,Y` (a pixel of the input photos, origin top-left).
    #[arg(long, default_value = "auto", value_parser = parse_sun)]
    pub sun: SunArg,
    /// Capture time for the ephemeris, ISO 8601 with offset (default: EXIF DateTimeOriginal + OffsetTime).
    #[arg(long, value_name = "ISO8601")]
    pub time: Option<String>,
    /// Latitude in degrees, north positive (default: EXIF GPS).
    #[arg(long, allow_hyphen_values = true)]
    pub lat: Option<f64>,
    /// Longitude in degrees, east positive (default: EXIF GPS).
    #[arg(long, allow_hyphen_values = true)]
    pub lon: Option<f64>,
    /// Also write an equirectangular (lat-long, 2:1) map of the dome (.hdr or .exr).
    #[arg(long, value_name = "FILE")]
    pub equirect: Option<PathBuf>,
    /// Width of the equirectangular map in pixels (default: about 4× the horizon radius).
    #[arg(long)]
    pub equirect_width: Option<usize>,
    /// Lower hemisphere of the equirectangular map: black, mirror, or a constant R,G,B radiance.
    #[arg(long, default_value = "black", value_parser = parse_ground)]
    pub ground: Ground,
    /// Also write a preview with the circles, north (blue) and sun (yellow) drawn on it (.png/.jpg).
    #[arg(long, value_name = "FILE")]
    pub overlay: Option<PathBuf>,
}

/// Device pose on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PoseArg {
    /// Screen down, rear camera up.
    ScreenDown,
    /// Screen up, front camera up.
    ScreenUp,
}

/// How to find the sun.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SunArg {
    /// Detect it.
    Auto,
    /// No sun.
    None,
    /// From date, time and place.
    Ephemeris,
    /// A pixel of the input photos.
    Pixel(f64, f64),
}

/// Parses a lens projection name.
pub fn parse_kind(s: &str) -> Result<LensKind, String> {
    s.parse::<LensKind>().map_err(|e| e.to_string())
}

fn parse_sun(s: &str) -> Result<SunArg, String> {
    match s {
        "auto" => Ok(SunArg::Auto),
        "none" => Ok(SunArg::None),
        "ephemeris" => Ok(SunArg::Ephemeris),
        _ => match s
            .split_once(',')
            .map(|(x, y)| (x.trim().parse(), y.trim().parse()))
        {
            Some((Ok(x), Ok(y))) if f64::is_finite(x) && f64::is_finite(y) => {
                Ok(SunArg::Pixel(x, y))
            }
            _ => Err(format!(
                "'{s}': expected auto, none, ephemeris or X,Y in pixels"
            )),
        },
    }
}

/// Parses `black`, `mirror` or `R,G,B` for the lower hemisphere.
pub fn parse_ground(s: &str) -> Result<Ground, String> {
    match s {
        "black" => Ok(Ground::Black),
        "mirror" => Ok(Ground::MirrorSky),
        _ => {
            let v: Vec<f32> = s
                .split(',')
                .map(|t| t.trim().parse::<f32>())
                .collect::<Result<_, _>>()
                .map_err(|_| format!("'{s}': expected black, mirror or R,G,B"))?;
            match v[..] {
                [r, g, b] if v.iter().all(|x| x.is_finite() && *x >= 0.0) => {
                    Ok(Ground::Constant([r, g, b]))
                }
                _ => Err(format!(
                    "'{s}': expected black, mirror or three non-negative R,G,B values"
                )),
            }
        }
    }
}

impl GeometryArgs {
    /// True when any fish-eye processing was asked for.
    pub fn enabled(&self) -> bool {
        self.lens.is_some() || self.fisheye
    }

    /// Refuses fish-eye options given without a lens.
    pub fn check(&self) -> Result<()> {
        if !self.enabled()
            && (self.crop
                || self.north.is_some()
                || self.equirect.is_some()
                || self.overlay.is_some())
        {
            bail!("--crop, --north, --equirect and --overlay need --lens lens.json or --fisheye");
        }
        Ok(())
    }

    /// Output paths this part writes.
    pub fn outputs(&self) -> Vec<&PathBuf> {
        [self.equirect.as_ref(), self.overlay.as_ref()]
            .into_iter()
            .flatten()
            .collect()
    }
}

/// What the fish-eye processing found, for the summary.
#[derive(Debug, Serialize)]
pub struct GeometryReport {
    /// The lens profile used.
    pub lens: LensProfile,
    /// The detected circle, when it was detected.
    pub detected_circle: Option<CircleFit>,
    /// Crop radius in input pixels, when cropped.
    pub crop_radius_px: Option<f64>,
    /// The horizon circle in the output image.
    pub horizon: Circle,
    /// North point in the output image.
    pub north: Option<PixelPoint>,
    /// The sun in the output image.
    pub sun: Option<SunMark>,
    /// How the sun was found.
    pub sun_source: Option<&'static str>,
    /// Confidence of the detection.
    pub sun_confidence: Option<f64>,
    /// The computed (ephemeris) sun direction.
    pub sun_ephemeris: Option<Direction>,
    /// Agreement between detected and computed sun.
    pub sun_cross_check: Option<sky::SunCrossCheck>,
}

/// The fish-eye results of a merge.
pub struct Geometry {
    /// The output radiance (cropped when asked).
    pub image: HdrImage,
    /// Header additions (sun, north, view).
    pub meta: HdrMeta,
    /// The equirectangular map, when asked.
    pub equirect: Option<HdrImage>,
    /// Overlay marks in output pixels.
    pub marks: OverlayMarks,
    /// The summary.
    pub report: GeometryReport,
}

/// The 8-bit version of the frame with the most well-exposed pixels (codes 20..=235).
pub fn best_exposed(br: &Bracket) -> RgbImage<u8> {
    let to8 = |p: &Pixels| -> Vec<u8> {
        match p {
            Pixels::U8(v) => v.clone(),
            Pixels::U16(v) => v.iter().map(|&x| (x >> 8) as u8).collect(),
        }
    };
    let best = br
        .frames
        .iter()
        .max_by_key(|f| {
            to8(&f.pixels)
                .iter()
                .step_by(7)
                .filter(|&&z| (20..=235).contains(&z))
                .count()
        })
        .map(|f| to8(&f.pixels))
        .unwrap_or_default();
    RgbImage {
        width: br.width(),
        height: br.height(),
        data: best,
    }
}

/// The lens profile: from a file, or from the detected (or given) circle and the nominal model.
pub fn lens_profile(
    a: &GeometryArgs,
    br: &Bracket,
    circle: Option<Circle>,
) -> Result<(LensProfile, Option<CircleFit>)> {
    if let Some(p) = &a.lens {
        let text =
            std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
        let lens = LensProfile::from_json(&text).with_context(|| p.display().to_string())?;
        return Ok((lens, None));
    }
    let (circle, fit) = match circle {
        Some(c) => (c, None),
        None => {
            let fit = fisheye::detect_circle(&best_exposed(br))
                .context("cannot find the fish-eye image circle; give it with --circle CX,CY,R")?;
            (fit.circle, Some(fit))
        }
    };
    let lens = LensProfile::from_fov(circle, a.fov, a.lens_model).context("lens model")?;
    Ok((lens, fit))
}

/// Reads and validates a lens profile (JSON).
pub fn read_lens(p: &std::path::Path) -> Result<LensProfile> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
    LensProfile::from_json(&text).with_context(|| p.display().to_string())
}

/// Runs the fish-eye stage on a merged radiance map.
pub fn apply(
    a: &GeometryArgs,
    br: &Bracket,
    (lens, detected): (LensProfile, Option<CircleFit>),
    radiance: HdrImage,
    orientation: u16,
) -> Result<Geometry> {
    let pose = match a.device_pose {
        PoseArg::ScreenDown => DevicePose::ScreenDown,
        PoseArg::ScreenUp => DevicePose::ScreenUp,
    };
    let orient = ImageOrientation::from_exif(orientation).context("EXIF orientation")?;
    let full_geom =
        SkyGeometry::new(&lens, a.north.unwrap_or(0.0), pose, orient).context("sky geometry")?;

    // Sun position in input pixels, from a tap, before any crop.
    let tapped = match a.sun {
        SunArg::Pixel(x, y) => Some(PixelPoint { x, y }),
        _ => None,
    };

    let (image, geom, offset, crop_radius) = if a.crop {
        let c = fisheye::crop_dome(&radiance, &lens, a.fov_out).context("crop")?;
        let g = full_geom.with_centre(c.horizon.cx, c.horizon.cy);
        (
            c.image,
            g,
            (c.offset_x as f64, c.offset_y as f64),
            Some(c.crop_radius_px),
        )
    } else {
        (radiance, full_geom, (0.0, 0.0), None)
    };
    let shift = |p: PixelPoint| PixelPoint {
        x: p.x - offset.0,
        y: p.y - offset.1,
    };
    let horizon = geom.horizon_circle();
    let north = a.north.map(|_| geom.north_point());

    // The ephemeris sun, when time and place are known.
    let time = match &a.time {
        Some(t) => Some(skydome::bracket::parse_iso8601(t).with_context(|| {
            format!("--time '{t}': expected ISO 8601 with offset, e.g. 2026-06-21T12:30:00+02:00")
        })?),
        None => br.info.capture_time(),
    };
    let lat = a.lat.or(br.info.gps_latitude_deg);
    let lon = a.lon.or(br.info.gps_longitude_deg);
    let ephemeris = match (time, lat, lon) {
        (Some(t), Some(lat), Some(lon)) => Some(
            sky::sun_ephemeris(
                t,
                &Site {
                    latitude_deg: lat,
                    longitude_deg: lon,
                    height_m: 0.0,
                    refraction: sky::Refraction::Standard,
                },
                None,
            )
            .context("sun ephemeris")?,
        ),
        _ => None,
    };
    if a.sun == SunArg::Ephemeris && ephemeris.is_none() {
        bail!("--sun ephemeris needs the capture time (EXIF or --time) and place (EXIF GPS or --lat/--lon)");
    }

    let (sun_px, sun_source, confidence) = match a.sun {
        SunArg::None => (None, None, None),
        SunArg::Pixel(..) => (tapped.map(shift), Some("tap"), None),
        SunArg::Ephemeris => (
            ephemeris.as_ref().and_then(|d| geom.direction_to_pixel(d)),
            Some("ephemeris"),
            None,
        ),
        SunArg::Auto => match sky::detect_sun(&image, &horizon) {
            Some(d) => (Some(d.pixel), Some("detected"), Some(d.confidence)),
            None => (None, None, None),
        },
    };
    let sun_dir = sun_px.and_then(|p| geom.pixel_to_direction(p));
    let cross = match (a.sun, &sun_dir, &ephemeris) {
        (SunArg::Auto | SunArg::Pixel(..), Some(d), Some(e)) => Some(sky::cross_check(d, e)),
        _ => None,
    };
    let sun = sun_px.map(|pixel| SunMark {
        pixel,
        // Azimuth means something only when north is known (or the position came from it).
        azimuth_deg: sun_dir
            .filter(|_| a.north.is_some() || a.sun == SunArg::Ephemeris)
            .map(|d| d.azimuth_deg),
        elevation_deg: sun_dir.map(|d| d.elevation_deg),
    });

    let view = (a.crop && (a.fov_out - 180.0).abs() < 1e-9)
        .then(|| match lens.projection.kind() {
            LensKind::Equidistant => Some("-vta -vh 180 -vv 180"),
            LensKind::Stereographic => Some("-vts -vh 180 -vv 180"),
            LensKind::Orthographic => Some("-vth -vh 180 -vv 180"),
            _ => None,
        })
        .flatten()
        .map(str::to_string);
    let meta = HdrMeta {
        sun,
        north,
        view,
        ..HdrMeta::default()
    };

    let equirect = match &a.equirect {
        Some(_) => {
            let width = a
                .equirect_width
                .unwrap_or_else(|| ((4.0 * horizon.r).round() as usize).clamp(64, 8192) & !1);
            Some(
                reproject::reproject(
                    &image,
                    &geom,
                    &MapProjection::Equirect {
                        width,
                        centre_azimuth_deg: 90.0,
                    },
                    &ReprojectOptions {
                        ground: a.ground,
                        ..ReprojectOptions::default()
                    },
                )
                .context("equirectangular map")?,
            )
        }
        None => None,
    };
    let visible = Circle {
        cx: lens.circle.cx - offset.0,
        cy: lens.circle.cy - offset.1,
        r: lens.circle.r,
    };
    Ok(Geometry {
        image,
        meta,
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
            crop_radius_px: crop_radius,
            horizon,
            north,
            sun,
            sun_source: sun_px.and(sun_source),
            sun_confidence: confidence,
            sun_ephemeris: ephemeris,
            sun_cross_check: cross,
        },
    })
}

/// A tone-mapped preview of `image` with `marks` drawn on it, encoded for `path`.
pub fn overlay_picture(
    path: &std::path::Path,
    image: &HdrImage,
    marks: &OverlayMarks,
) -> Result<Vec<u8>> {
    let tm = crate::pictures::default_tonemap(marks.visible);
    let mut rgb =
        skydome::tonemap::tonemap_u8(image, &tm).with_context(|| path.display().to_string())?;
    overlay::draw_overlay(&mut rgb, marks);
    crate::pictures::encode_rgb8(path, &rgb)
}
