//! Keyword arguments of `skydome.run` mapped onto the pipeline's [`Options`], as the command
//! line maps its flags (`skydome-cli/src/merge.rs`, `geometry.rs`): same names in snake_case,
//! same defaults. Enum values are parsed by the library's own `FromStr`, so a name means the
//! same thing in every shell.

use std::path::{Path, PathBuf};

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use skydome::fisheye::LensProfile;
use skydome::image::{Circle, PixelPoint};
use skydome::photometry::{Reference, SpotLuminance};
use skydome::pipeline::{EquirectOptions, LensSource, Options, ResponseSource, SunMode};

use crate::arrays::type_name;
use crate::errors::{error, type_error, value_error};

/// The command line's default lens projection and field of view (`--lens-model`, `--fov`).
pub const DEFAULT_LENS_MODEL: &str = "stereographic";
/// Degrees.
pub const DEFAULT_FOV: f64 = 235.0;
/// `--luminance-radius`, pixels.
pub const DEFAULT_LUMINANCE_RADIUS: f64 = 3.0;

/// The arguments of `skydome.run` besides frames, times and progress.
pub struct RunArgs<'py> {
    pub profile: Option<Bound<'py, PyAny>>,
    pub lens: Option<Bound<'py, PyAny>>,
    pub fisheye: bool,
    pub lens_model: Option<String>,
    pub fov: Option<f64>,
    pub circle: Option<(f64, f64, f64)>,
    pub crop: bool,
    pub sun: Option<Bound<'py, PyAny>>,
    pub north: Option<Bound<'py, PyAny>>,
    pub time: Option<Bound<'py, PyAny>>,
    pub lat: Option<f64>,
    pub lon: Option<f64>,
    pub illuminance: Option<f64>,
    pub luminance: Option<Vec<f64>>,
    pub weighting: String,
    pub exposures: String,
    pub preview: bool,
    pub equirect: Option<Bound<'py, PyAny>>,
}

/// The options, and the profile's path when it came from a file (for the report, as the
/// command line's `response: "profile <path>"`).
pub struct Built {
    pub options: Options,
    pub profile_path: Option<PathBuf>,
}

impl RunArgs<'_> {
    /// The pipeline options.
    pub fn build(&self) -> PyResult<Built> {
        let mut o = Options::default();
        let mut profile_path = None;
        if let Some(p) = self.profile.as_ref().filter(|p| !p.is_none()) {
            let (profile, path) = profile_arg(p)?;
            profile_path = path;
            o.response = ResponseSource::Profile(profile);
        }
        let circle = match self.circle {
            Some((cx, cy, r)) => {
                if !(cx.is_finite() && cy.is_finite() && r.is_finite() && r > 0.0) {
                    return Err(value_error(
                        "circle",
                        format!("expected (cx, cy, r) in pixels with a positive radius, got ({cx}, {cy}, {r})"),
                    ));
                }
                Some(Circle { cx, cy, r })
            }
            None => None,
        };
        o.calibration_circle = circle;
        o.weighting = self
            .weighting
            .parse()
            .map_err(|e: skydome::UnknownName| value_error("weighting", e))?;
        o.exposures = self
            .exposures
            .parse()
            .map_err(|e: skydome::UnknownName| value_error("exposures", e))?;
        let lens = self.lens.as_ref().filter(|l| !l.is_none());
        if lens.is_some() && self.fisheye {
            return Err(value_error(
                "lens",
                "give either lens= (a lens profile) or fisheye=True (detect the circle), not both",
            ));
        }
        if !self.fisheye {
            for (given, arg) in [
                (self.lens_model.is_some(), "lens_model"),
                (self.fov.is_some(), "fov"),
            ] {
                if given {
                    return Err(value_error(
                        arg,
                        "describes the nominal lens of fisheye=True; add fisheye=True (or give lens= a lens profile instead)",
                    ));
                }
            }
        }
        o.lens = match (lens, self.fisheye) {
            (Some(l), _) => LensSource::Profile(lens_arg(l)?),
            (None, true) => LensSource::Detect {
                model: self
                    .lens_model
                    .as_deref()
                    .unwrap_or(DEFAULT_LENS_MODEL)
                    .parse()
                    .map_err(|e| value_error("lens_model", e))?,
                fov_deg: self.fov.unwrap_or(DEFAULT_FOV),
                circle,
            },
            (None, false) => LensSource::None,
        };
        let has_lens = o.lens != LensSource::None;
        o.sky.crop = self.crop;
        // Without a lens there is no sky geometry; `auto` then simply finds nothing (as the
        // command line does).
        let sun = match &self.sun {
            None => SunMode::Auto,
            Some(s) => sun_arg(s)?,
        };
        o.sky.sun = match sun {
            SunMode::Auto if !has_lens => SunMode::None,
            s => s,
        };
        match self.north.as_ref().filter(|n| !n.is_none()) {
            None => {}
            Some(n) if n.is_instance_of::<PyString>() => {
                let s: String = n.extract()?;
                if s.trim().eq_ignore_ascii_case("from-sun") {
                    o.sky.north_from_sun = true;
                } else {
                    return Err(value_error(
                        "north",
                        format!("'{s}': expected degrees from true north towards east (e.g. 37.0) or 'from-sun'"),
                    ));
                }
            }
            Some(n) => {
                let d: f64 = n.extract().map_err(|_| {
                    type_error(
                        "north",
                        format!(
                            "expected degrees (a number) or 'from-sun', got {}",
                            type_name(n)
                        ),
                    )
                })?;
                if !d.is_finite() {
                    return Err(value_error("north", format!("{d} is not a finite angle")));
                }
                o.sky.north_deg = Some(d);
            }
        }
        o.sky.time = match self.time.as_ref().filter(|t| !t.is_none()) {
            None => None,
            Some(t) => Some(time_arg(t)?),
        };
        o.sky.latitude_deg = self.lat;
        o.sky.longitude_deg = self.lon;
        o.reference = Reference {
            luminance: match &self.luminance {
                None => None,
                Some(v) => Some(luminance_arg(v)?),
            },
            illuminance_lux: self.illuminance,
        };
        o.products.preview = self.preview;
        o.products.equirect = match self.equirect.as_ref().filter(|e| !e.is_none()) {
            None => None,
            Some(e) => equirect_arg(e)?,
        };
        Ok(Built {
            options: o,
            profile_path,
        })
    }
}

/// `profile`: a `CameraProfile` or the path of a camera.json.
fn profile_arg(
    p: &Bound<'_, PyAny>,
) -> PyResult<(skydome::camera::CameraProfile, Option<PathBuf>)> {
    if let Ok(c) = p.cast::<crate::profile::CameraProfile>() {
        return Ok((c.get().inner.clone(), None));
    }
    let path = crate::files::path_arg("profile", p).map_err(|_| {
        type_error(
            "profile",
            format!(
                "expected a skydome.CameraProfile or the path of a camera.json, got {}",
                type_name(p)
            ),
        )
    })?;
    let profile = crate::profile::read_profile(&path)?;
    Ok((profile, Some(path)))
}

/// `lens`: the path of a lens.json, or the same JSON as a dict.
fn lens_arg(l: &Bound<'_, PyAny>) -> PyResult<LensProfile> {
    if let Ok(d) = l.cast::<PyDict>() {
        let text = crate::profile::json_dumps(d.as_any())?;
        return LensProfile::from_json(&text).map_err(|e| value_error("lens", e));
    }
    let path = crate::files::path_arg("lens", l).map_err(|_| {
        type_error(
            "lens",
            format!(
                "expected the path of a lens.json (or its contents as a dict), got {}",
                type_name(l)
            ),
        )
    })?;
    read_lens(&path)
}

/// Reads and validates a lens profile, naming the file as the command line does.
fn read_lens(p: &Path) -> PyResult<LensProfile> {
    let text = std::fs::read_to_string(p)
        .map_err(|e| error(format!("{}: cannot read: {e}", p.display())))?;
    LensProfile::from_json(&text).map_err(|e| error(format!("{}: {e}", p.display())))
}

/// `sun`: "auto", "none", "ephemeris", or (x, y) in the input photos' pixels.
fn sun_arg(s: &Bound<'_, PyAny>) -> PyResult<SunMode> {
    if s.is_instance_of::<PyString>() {
        let t: String = s.extract()?;
        return match t.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(SunMode::Auto),
            "none" => Ok(SunMode::None),
            "ephemeris" => Ok(SunMode::Ephemeris),
            _ => Err(value_error(
                "sun",
                format!("'{t}': expected 'auto', 'none', 'ephemeris' or (x, y) in pixels"),
            )),
        };
    }
    match s.extract::<(f64, f64)>() {
        Ok((x, y)) if x.is_finite() && y.is_finite() => Ok(SunMode::Tap(PixelPoint { x, y })),
        _ => Err(type_error(
            "sun",
            format!(
                "expected 'auto', 'none', 'ephemeris' or (x, y) in pixels of the input photos, got {}",
                type_name(s)
            ),
        )),
    }
}

/// `time`: ISO 8601 text with a UTC offset, or an aware `datetime`.
fn time_arg(t: &Bound<'_, PyAny>) -> PyResult<String> {
    if t.is_instance_of::<PyString>() {
        return t.extract();
    }
    if t.hasattr("isoformat")? && t.hasattr("utcoffset")? {
        if t.call_method0("utcoffset")?.is_none() {
            return Err(value_error(
                "time",
                "the datetime has no time zone; give tzinfo (e.g. datetime.timezone.utc) so the sun's position is right",
            ));
        }
        return t.call_method0("isoformat")?.extract();
    }
    Err(type_error(
        "time",
        format!(
            "expected ISO 8601 text with a UTC offset (e.g. '2026-06-21T12:30:00+02:00') or an aware datetime, got {}",
            type_name(t)
        ),
    ))
}

/// `luminance`: (x, y, cd_per_m2) or (x, y, cd_per_m2, radius_px).
fn luminance_arg(v: &[f64]) -> PyResult<SpotLuminance> {
    let (x, y, cd, r) = match v {
        [x, y, cd] => (*x, *y, *cd, DEFAULT_LUMINANCE_RADIUS),
        [x, y, cd, r] => (*x, *y, *cd, *r),
        _ => {
            return Err(value_error(
                "luminance",
                format!(
                    "expected (x, y, cd_per_m2) or (x, y, cd_per_m2, radius_px), got {} values",
                    v.len()
                ),
            ))
        }
    };
    Ok(SpotLuminance {
        pixel: PixelPoint { x, y },
        radius_px: r,
        cd_per_m2: cd,
    })
}

/// `equirect`: True (default width) or a width in pixels.
fn equirect_arg(e: &Bound<'_, PyAny>) -> PyResult<Option<EquirectOptions>> {
    if let Ok(b) = e.cast::<pyo3::types::PyBool>() {
        return Ok(b.is_true().then(EquirectOptions::default));
    }
    match e.extract::<usize>() {
        Ok(w) if w >= 2 => Ok(Some(EquirectOptions {
            width: Some(w),
            ..EquirectOptions::default()
        })),
        _ => Err(value_error(
            "equirect",
            "expected True (about 4x the horizon radius wide) or a width in pixels (an even number)",
        )),
    }
}
