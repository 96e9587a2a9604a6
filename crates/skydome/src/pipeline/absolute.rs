//! A camera made absolute once (issue 22): the scale of a dome without a meter reading, from the
//! camera profile's [`AbsoluteConstant`] or the reflected-light meter equation, and the
//! constant a merge with a reading (or the meter equation) gives its camera profile.
//!
//! The merge divides every frame by its relative exposure `t·(ISO/100)/N²` (see
//! [`crate::bracket::Exposure::relative`]), so its relative radiance is the same for one scene
//! whatever the capture's settings, and one constant per camera (per response curve) makes
//! every capture absolute — provided every frame's EXIF gives ISO and f-number (a missing one
//! counts as ISO 100 or f/1, which is right for ratios inside a bracket but not between
//! captures). Frames of one bracket may differ in ISO or aperture: each frame is divided by
//! its own.

use super::{AbsoluteMode, Options, PipelineError, ResponseSource};
use crate::bracket::Bracket;
use crate::camera::{AbsoluteConstant, AbsoluteFrom, CameraProfile};
use crate::photometry::{PhotometryReport, FROM_METER_EQUATION, FROM_PROFILE};
use crate::response::Response;

/// A scale to apply without a reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ConstantScale {
    /// Radiance per unit of relative radiance.
    pub scale: f64,
    /// [`FROM_PROFILE`] or [`FROM_METER_EQUATION`].
    pub from: &'static str,
    /// Stated uncertainty, percent.
    pub uncertainty_percent: Option<f64>,
}

/// What is missing for an absolute scale from EXIF: `None` when every frame has its ISO speed
/// and f-number (the time every frame has), else a phrase naming the frames and the values.
pub(super) fn missing_exposure_data(br: &Bracket) -> Option<String> {
    let no_iso: Vec<&str> = br
        .frames
        .iter()
        .filter(|f| f.exposure.iso.is_none())
        .map(|f| f.name.as_str())
        .collect();
    let no_n: Vec<&str> = br
        .frames
        .iter()
        .filter(|f| f.exposure.f_number.is_none())
        .map(|f| f.name.as_str())
        .collect();
    let say = |names: &[&str], what: &str| match names.len() {
        0 => None,
        1 => Some(format!("{} has no {what}", names[0])),
        _ => Some(format!("{} have no {what}", names.join(", "))),
    };
    let parts: Vec<String> = [say(&no_iso, "ISO speed"), say(&no_n, "f-number")]
        .into_iter()
        .flatten()
        .collect();
    (!parts.is_empty()).then(|| {
        format!(
            "{} in EXIF (an absolute dome without a meter needs the exposure time, ISO and f-number of every frame)",
            parts.join("; ")
        )
    })
}

/// The scale for a dome without a meter reading ([`Options::absolute`]), and the warnings:
/// `None` with a reading (it wins), with [`AbsoluteMode::None`], or with a profile that has
/// no constant. A profile's constant on frames without their EXIF exposure data (or on a RAW
/// bracket, whose linear response is not the profile's) gives a warning and a relative dome;
/// [`AbsoluteMode::Exif`], asked for outright, refuses such frames.
pub(super) fn scale_without_reading(
    o: &Options,
    br: &Bracket,
    response: &Response,
    raw: bool,
) -> Result<(Option<ConstantScale>, Vec<String>), PipelineError> {
    if !o.reference.is_empty() {
        return Ok((None, Vec::new()));
    }
    match o.absolute {
        AbsoluteMode::None => Ok((None, Vec::new())),
        AbsoluteMode::Profile => {
            let constant = match &o.response {
                ResponseSource::Profile(CameraProfile {
                    absolute: Some(c), ..
                }) => c,
                _ => return Ok((None, Vec::new())),
            };
            let why_not = match (raw, missing_exposure_data(br)) {
                (true, _) => Some(
                    "the bracket is RAW, whose linear response is not the profile's".to_string(),
                ),
                (false, m) => m,
            };
            if let Some(why) = why_not {
                let w = format!(
                    "the camera profile has an absolute constant, but {why}: the dome is relative"
                );
                return Ok((None, vec![w]));
            }
            Ok((
                Some(ConstantScale {
                    scale: constant.radiance_per_unit,
                    from: FROM_PROFILE,
                    uncertainty_percent: constant.uncertainty_percent,
                }),
                Vec::new(),
            ))
        }
        AbsoluteMode::Exif => {
            if raw {
                return Err(PipelineError::AbsoluteExif(
                    "a RAW bracket has no JPEG tone curve placing mid-grey".into(),
                ));
            }
            if let Some(m) = missing_exposure_data(br) {
                return Err(PipelineError::AbsoluteExif(m));
            }
            let c = AbsoluteConstant::from_meter_equation(response).ok_or_else(|| {
                PipelineError::AbsoluteExif(
                    "the response curve gives mid-grey no positive radiance".into(),
                )
            })?;
            Ok((
                Some(ConstantScale {
                    scale: c.radiance_per_unit,
                    from: FROM_METER_EQUATION,
                    uncertainty_percent: c.uncertainty_percent,
                }),
                Vec::new(),
            ))
        }
    }
}

/// The constant this merge gives its camera profile: the final absolute scale when a reading
/// or the meter equation set it, every frame has its EXIF exposure data and the bracket is
/// not RAW; `Err` with the reason otherwise (`Ok(None)` when the dome is not absolute or its
/// scale came from the profile itself).
pub(super) fn constant_for_profile(
    br: &Bracket,
    raw: bool,
    photometry: Option<&PhotometryReport>,
) -> Result<Option<AbsoluteConstant>, String> {
    let Some(p) = photometry else {
        return Ok(None);
    };
    let from = match p.from {
        "illuminance" => AbsoluteFrom::Illuminance,
        "luminance" => AbsoluteFrom::Luminance,
        FROM_METER_EQUATION => AbsoluteFrom::Exif,
        _ => return Ok(None),
    };
    if raw {
        return Err("the bracket is RAW (the constant belongs to a JPEG response curve)".into());
    }
    if let Some(m) = missing_exposure_data(br) {
        return Err(m);
    }
    Ok(Some(AbsoluteConstant {
        radiance_per_unit: p.scale,
        from,
        uncertainty_percent: p.uncertainty_percent,
        date: br.info.datetime_original.clone(),
    }))
}
