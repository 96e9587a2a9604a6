//! `skydome.read_hdr`, `skydome.write_hdr` and `skydome.tonemap`: the library's formats and
//! tone mapping on numpy arrays.

use numpy::{PyArray3, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use skydome::formats::exr::ExrOptions;
use skydome::formats::{self, HdrMeta};
use skydome::image::Circle;
use skydome::tonemap::{ExposureMode, ToneMap};
use skydome::{HdrImage, RgbImage};

use crate::arrays;
use crate::errors::{error, type_error, value_error};

/// Reads a radiance map: Radiance RGBE (``.hdr``, flat, old or new RLE, ``#?RADIANCE`` or
/// ``#?RGBE``) or OpenEXR, recognised by its first bytes.
///
/// Returns ``(array, header)``: float32 radiance of shape (height, width, 3), row 0 at the top,
/// already divided by the file's ``EXPOSURE=`` (Radiance's rule, stored = radiance ×
/// exposure); ``header`` the metadata dict of :attr:`Dome.header`. The array is the decoder's
/// own buffer (no copy). Raises :class:`skydome.Error` naming the file.
#[pyfunction]
#[pyo3(signature = (path))]
pub fn read_hdr<'py>(
    py: Python<'py>,
    path: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyAny>)> {
    let p = crate::files::path_arg("path", path)?;
    let file = py
        .detach(|| -> Result<formats::RadianceFile, String> {
            let bytes = crate::files::read(&p)?;
            formats::read_radiance(&bytes).map_err(|e| format!("{}: {e}", p.display()))
        })
        .map_err(error)?;
    let header = crate::dome::meta_dict(py, &file.meta)?;
    Ok((arrays::owned(py, file.image)?, header))
}

/// Writes a radiance map by the extension of ``path``: ``.hdr`` (Radiance RGBE, new-style
/// RLE) or ``.exr`` (OpenEXR half floats; float when values exceed half's range).
///
/// ``array``: float32 or float64 radiance of shape (height, width, 3), row 0 at the top;
/// copied once. ``header``: a metadata dict as :attr:`Dome.header` or :func:`read_hdr` gives
/// (unknown keys are refused); with ``exposure`` the stored values are radiance × exposure, so
/// the file reads back as the same radiance. Atomic (temporary file, then rename); an existing
/// file is replaced. The GIL is released while it encodes and writes.
#[pyfunction]
#[pyo3(signature = (path, array, header=None))]
pub fn write_hdr(
    py: Python<'_>,
    path: &Bound<'_, PyAny>,
    array: &Bound<'_, PyAny>,
    header: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let meta = match header.filter(|h| !h.is_none()) {
        None => HdrMeta::default(),
        Some(h) => meta_arg(h)?,
    };
    let scale = meta
        .exposure
        .filter(|e| e.is_finite() && *e > 0.0 && *e != 1.0)
        .map(|e| e as f32);
    let mut img = float_image("array", array)?;
    if let Some(k) = scale {
        img.data.iter_mut().for_each(|v| *v *= k);
    }
    crate::dome::save_radiance(py, path, &img, &meta, ExrOptions::default(), &[])
}

/// Tone-maps radiance to a displayable sRGB picture, as ``skydome tonemap``.
///
/// ``array``: float32/float64 radiance (height, width, 3), copied once. ``op``: "aces"
/// (default), "reinhard", "drago", "linear" or "minmax" (the seed's per-channel stretch).
/// ``exposure``: stops instead of the automatic exposure (a radiance of 2^-EV maps to 1).
/// ``key``: target display value of the log-average luminance (automatic exposure).
/// ``white_percentile``: percentile of luminance used as white (reinhard) or Lmax (drago).
/// ``bias``: Drago's bias. ``circle``: (cx, cy, r) in pixels, black outside it.
/// ``whole_frame``: expose for the whole frame, not the sky inside a detected fish-eye circle.
/// ``bits``: 8 (uint8, ordered dither) or 16 (uint16, as a 16-bit PNG holds).
///
/// Returns a uint8 (or uint16) array of shape (height, width, 3), the tone mapper's own buffer.
#[pyfunction]
#[pyo3(signature = (array, op="aces", *, exposure=None, key=0.18, white_percentile=99.5,
    bias=0.85, circle=None, whole_frame=false, bits=8))]
#[allow(clippy::too_many_arguments)]
pub fn tonemap<'py>(
    py: Python<'py>,
    array: &Bound<'py, PyAny>,
    op: &str,
    exposure: Option<f64>,
    key: f64,
    white_percentile: f64,
    bias: f64,
    circle: Option<(f64, f64, f64)>,
    whole_frame: bool,
    bits: u32,
) -> PyResult<Bound<'py, PyAny>> {
    let operator = op.parse().map_err(|e| value_error("op", e))?;
    let tm = ToneMap {
        operator,
        exposure: exposure.map_or(ExposureMode::Auto, ExposureMode::Ev),
        key,
        white_percentile,
        drago_bias: bias,
        mask: circle.map(|(cx, cy, r)| Circle { cx, cy, r }),
        auto_mask: !whole_frame,
        ..ToneMap::default()
    };
    let img = float_image("array", array)?;
    match bits {
        8 => {
            let out: RgbImage<u8> = py
                .detach(|| skydome::tonemap::tonemap_u8(&img, &tm))
                .map_err(|e| value_error("tonemap", e))?;
            Ok(arrays::owned(py, out)?.into_any())
        }
        16 => {
            let out: RgbImage<u16> = py
                .detach(|| skydome::tonemap::tonemap_u16(&img, &tm))
                .map_err(|e| value_error("tonemap", e))?;
            Ok(arrays::owned(py, out)?.into_any())
        }
        _ => Err(value_error("bits", format!("{bits}: expected 8 or 16"))),
    }
}

/// A float32/float64 (H, W, 3) array as an image (one copy).
fn float_image(arg: &str, obj: &Bound<'_, PyAny>) -> PyResult<HdrImage> {
    let Some((dtype, _)) = arrays::describe(obj) else {
        return Err(type_error(
            arg,
            format!(
                "expected a numpy float32 array of shape (height, width, 3), got {}",
                arrays::type_name(obj)
            ),
        ));
    };
    let (h, w) = arrays::rgb_shape(arg, obj)?;
    let data: Vec<f32> = if arrays::is_dtype::<f32>(obj) {
        arrays::copy_samples(obj.cast::<PyArray3<f32>>()?)
    } else if arrays::is_dtype::<f64>(obj) {
        let a = obj.cast::<PyArray3<f64>>()?.readonly();
        a.as_array().iter().map(|&v| v as f32).collect()
    } else {
        return Err(type_error(
            arg,
            format!("expected radiance as float32 or float64, got dtype {dtype}"),
        ));
    };
    HdrImage::from_vec(w, h, data).ok_or_else(|| value_error(arg, "wrong number of samples"))
}

/// A header dict as metadata; unknown keys are refused (a typo would be lost silently).
fn meta_arg(h: &Bound<'_, PyAny>) -> PyResult<HdrMeta> {
    let d = h.cast::<PyDict>().map_err(|_| {
        type_error(
            "header",
            format!(
                "expected a dict as Dome.header or read_hdr gives, got {}",
                arrays::type_name(h)
            ),
        )
    })?;
    let known = serde_json::to_value(HdrMeta::default()).map_err(|e| error(e.to_string()))?;
    for k in d.keys() {
        let k: String = k
            .extract()
            .map_err(|_| type_error("header", "keys must be strings"))?;
        if known.get(&k).is_none() {
            let names: Vec<&String> = known
                .as_object()
                .map(|o| o.keys().collect())
                .unwrap_or_default();
            return Err(value_error(
                "header",
                format!(
                    "unknown key '{k}'; expected some of: {}",
                    names
                        .iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
    }
    // Missing keys keep their defaults.
    let mut value = known;
    if let (Some(base), serde_json::Value::Object(given)) = (
        value.as_object_mut(),
        crate::pyvalue::from_py("header", d.as_any())?,
    ) {
        base.extend(given);
    }
    serde_json::from_value(value).map_err(|e| value_error("header", e))
}
