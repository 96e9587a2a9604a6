//! The fish-eye options of `skydome merge`, mapped onto the library's pipeline options (lens,
//! sky, equirectangular map, overlay). The rules themselves live in `skydome::pipeline`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use skydome::fisheye::{LensKind, LensProfile};
use skydome::formats::PixelPoint;
use skydome::image::Circle;
use skydome::pipeline::{EquirectOptions, LensSource, Products, SkyOptions, SunDisc, SunMode};
use skydome::reproject::Ground;
use skydome::sky::{DevicePose, Level};

/// The map files `skydome merge` writes besides the dome (one capture, named files; `skydome
/// batch` names its own).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct MapOutputs {
    /// Also write an equirectangular (lat-long, 2:1) map of the dome (.hdr or .exr).
    #[arg(long, value_name = "FILE")]
    pub equirect: Option<PathBuf>,
    /// Also write the 180° dome as Radiance's angular fish-eye (`VIEW= -vta`, north up, east
    /// left), whatever the lens's projection: the dome Radiance's tools (evalglare) read.
    #[arg(long, value_name = "FILE")]
    pub angular: Option<PathBuf>,
    /// Also write a preview with the circles, north (blue) and sun (yellow) drawn on it (.png/.jpg).
    #[arg(long, value_name = "FILE")]
    pub overlay: Option<PathBuf>,
}

impl MapOutputs {
    /// Output paths given.
    pub fn outputs(&self) -> Vec<&PathBuf> {
        [
            self.equirect.as_ref(),
            self.angular.as_ref(),
            self.overlay.as_ref(),
        ]
        .into_iter()
        .flatten()
        .collect()
    }
}

/// Fish-eye options of `skydome merge` and `skydome batch`.
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
    /// Compass azimuth of the phone's top edge, degrees from true north towards east; or
    /// `from-sun`: set it from the observed sun and the ephemeris (needs time and place).
    #[arg(long, allow_hyphen_values = true, value_name = "DEG|from-sun", value_parser = parse_north)]
    pub north: Option<North>,
    /// With --north from-sun: the compass's reading, reported against the sun's north.
    #[arg(long, allow_hyphen_values = true, value_name = "DEG")]
    pub compass: Option<f64>,
    /// How the phone lay: screen-down (rear camera looks up, the usual) or screen-up.
    #[arg(long, default_value = "screen-down", value_parser = parse_pose)]
    pub device_pose: DevicePose,
    /// The phone's accelerometer reading at rest, x,y,z in its own axes (x right edge, y top
    /// edge, z out of the screen; pointing up, as Android and Chrome report it): levels a
    /// tilted dome.
    #[arg(long, allow_hyphen_values = true, value_name = "X,Y,Z", value_parser = parse_gravity, conflicts_with = "tilt")]
    pub gravity: Option<[f64; 3]>,
    /// Tilt of the optical axis from the zenith, degrees (with --tilt-azimuth): levels the dome.
    #[arg(long, value_name = "DEG")]
    pub tilt: Option<f64>,
    /// Compass azimuth the optical axis leans towards, degrees (with --tilt).
    #[arg(
        long,
        allow_hyphen_values = true,
        value_name = "DEG",
        default_value_t = 0.0
    )]
    pub tilt_azimuth: f64,
    /// The sun: `auto` (detect the brightest blob), `none`, `ephemeris` (from time and place),
    /// or `X,Y` (a pixel of the input photos, origin top-left).
    #[arg(long, default_value = "auto", value_parser = parse_sun)]
    pub sun: SunMode,
    /// A sun clipped even in the shortest frame: `reconstruct` replaces it by the solar disc
    /// whose luminance makes the direct light right (from --illuminance with --luminance, else
    /// the IES clear-sky model, ±25 %), marked `#SUN_DISC=` in the header; `keep` leaves the
    /// clipped values (a lower bound).
    #[arg(long, default_value = "reconstruct", value_parser = parse_sun_disc)]
    pub sun_disc: SunDisc,
    /// Capture time for the ephemeris, ISO 8601 with offset (default: EXIF DateTimeOriginal + OffsetTime).
    #[arg(long, value_name = "ISO8601")]
    pub time: Option<String>,
    /// Latitude in degrees, north positive (default: EXIF GPS).
    #[arg(long, allow_hyphen_values = true)]
    pub lat: Option<f64>,
    /// Longitude in degrees, east positive (default: EXIF GPS).
    #[arg(long, allow_hyphen_values = true)]
    pub lon: Option<f64>,
    /// Width of the equirectangular map in pixels (default: about 4× the horizon radius).
    #[arg(long)]
    pub equirect_width: Option<usize>,
    /// Lower hemisphere of the equirectangular map: black, mirror, or a constant R,G,B radiance.
    #[arg(long, default_value = "black", value_parser = parse_ground)]
    pub ground: Ground,
}

fn parse_gravity(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected X,Y,Z"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("'{s}': expected three numbers X,Y,Z")),
    }
}

/// `--north`: a compass azimuth or `from-sun`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum North {
    /// Degrees from true north towards east.
    Deg(f64),
    /// From the sun and the ephemeris.
    FromSun,
}

fn parse_north(s: &str) -> Result<North, String> {
    match s {
        "from-sun" => Ok(North::FromSun),
        _ => match s.trim().parse::<f64>() {
            Ok(d) if d.is_finite() => Ok(North::Deg(d)),
            _ => Err(format!("'{s}': expected degrees (e.g. 37) or from-sun")),
        },
    }
}

/// Parses `screen-down` or `screen-up`.
pub fn parse_pose(s: &str) -> Result<DevicePose, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Parses `reconstruct` or `keep`.
pub fn parse_sun_disc(s: &str) -> Result<SunDisc, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Parses a lens projection name.
pub fn parse_kind(s: &str) -> Result<LensKind, String> {
    s.parse::<LensKind>().map_err(|e| e.to_string())
}

fn parse_sun(s: &str) -> Result<SunMode, String> {
    match s {
        "auto" => Ok(SunMode::Auto),
        "none" => Ok(SunMode::None),
        "ephemeris" => Ok(SunMode::Ephemeris),
        _ => match s
            .split_once(',')
            .map(|(x, y)| (x.trim().parse(), y.trim().parse()))
        {
            Some((Ok(x), Ok(y))) if f64::is_finite(x) && f64::is_finite(y) => {
                Ok(SunMode::Tap(PixelPoint { x, y }))
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

    /// The lens source: a profile file, circle detection (or the given `circle`), or none.
    pub fn lens_source(&self, circle: Option<Circle>) -> Result<LensSource> {
        Ok(match (&self.lens, self.fisheye) {
            (Some(p), _) => LensSource::Profile(read_lens(p)?),
            (None, true) => LensSource::Detect {
                model: self.lens_model,
                fov_deg: self.fov,
                circle,
            },
            (None, false) => LensSource::None,
        })
    }

    /// The sky options.
    pub fn sky(&self) -> SkyOptions {
        SkyOptions {
            crop: self.crop,
            fov_out_deg: self.fov_out,
            north_deg: match self.north {
                Some(North::Deg(d)) => Some(d),
                Some(North::FromSun) => self.compass,
                None => None,
            },
            north_from_sun: self.north == Some(North::FromSun),
            level: match (self.gravity, self.tilt) {
                (Some(g), _) => Some(Level::Gravity(g)),
                (None, Some(t)) => Some(Level::Tilt {
                    tilt_deg: t,
                    azimuth_deg: self.tilt_azimuth,
                }),
                (None, None) => None,
            },
            pose: self.device_pose,
            // Without a lens there is no sky geometry; `auto` then simply finds nothing.
            sun: if self.enabled() {
                self.sun
            } else {
                SunMode::None
            },
            time: self.time.clone(),
            time_zone: None,
            latitude_deg: self.lat,
            longitude_deg: self.lon,
            sun_disc: self.sun_disc,
        }
    }

    /// Adds the maps to `products`: the overlay, the angular dome and the equirectangular map
    /// (with this width and ground) when asked for.
    pub fn products(
        &self,
        products: Products,
        overlay: bool,
        angular: bool,
        equirect: bool,
    ) -> Products {
        Products {
            overlay,
            angular,
            equirect: equirect.then_some(EquirectOptions {
                width: self.equirect_width,
                ground: self.ground,
            }),
            ..products
        }
    }
}

/// Reads and validates a lens profile (JSON).
pub fn read_lens(p: &std::path::Path) -> Result<LensProfile> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
    LensProfile::from_json(&text).with_context(|| p.display().to_string())
}
