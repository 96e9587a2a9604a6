//! `skydome.run` and its result, `skydome.Dome`.

use std::path::PathBuf;

use numpy::PyArray3;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use skydome::formats::exr::{ExrOptions, ExrPixelType};
use skydome::formats::{self, HdrMeta, RadianceFormat};
use skydome::pipeline;
use skydome::{HdrImage, RgbImage};

use crate::errors::{error, value_error};
use crate::frames::{self, Failure};
use crate::options::RunArgs;
use crate::profile::{finish, warn_all, CameraProfile};
use crate::progress::{self, Bridge};
use crate::pyvalue::ser_to_py;

/// The result of :func:`skydome.run`: the radiance map, its header, the report, and the
/// products asked for.
///
/// Arrays are read-only views of the dome's own buffers (no copy); ``numpy.array(a)`` makes a
/// writable copy. Pixel ``[y, x]`` is row y from the top, column x from the left; channels
/// R, G, B. Radiance is linear, in relative units unless a luminance or illuminance reading made
/// it absolute (Radiance's W·sr⁻¹·m⁻², luminance = 179 · (0.265 R + 0.670 G + 0.065 B) cd/m²).
/// A Dome pickles (for multiprocessing and Dask) and compares by value of its file contents.
#[pyclass(frozen, module = "skydome")]
pub struct Dome {
    radiance: HdrImage,
    meta: HdrMeta,
    report: serde_json::Value,
    preview: Option<RgbImage<u8>>,
    equirect: Option<(HdrImage, HdrMeta)>,
    camera_profile: Option<skydome::camera::CameraProfile>,
    /// The job's input files, never overwritten by `save`.
    inputs: Vec<PathBuf>,
}

#[pymethods]
impl Dome {
    /// Linear radiance, float32 array of shape (height, width, 3), read-only. Cropped to the
    /// 180° dome with ``crop=True`` (then north and the sun are marked in :attr:`header`).
    #[getter]
    fn radiance<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyArray3<f32>>> {
        // SAFETY: the dome is frozen: `radiance` is never changed or moved while it lives.
        unsafe { crate::arrays::view(&slf.get().radiance, slf.clone().into_any()) }
    }

    /// Width of the radiance map, pixels.
    #[getter]
    fn width(&self) -> usize {
        self.radiance.width
    }

    /// Height of the radiance map, pixels.
    #[getter]
    fn height(&self) -> usize {
        self.radiance.height
    }

    /// The report as a dict: exactly what ``skydome merge --json`` prints, less its
    /// ``written`` list (frames, response, sampling, clipped pixels, geometry with lens, sun and
    /// north, photometry, warnings, …). A new dict on every access.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::pyvalue::to_py(py, &self.report)
    }

    /// The header metadata of the radiance map as a dict: ``exposure`` (Radiance's
    /// ``EXPOSURE=``: stored = radiance × exposure; None means 1), ``capdate`` and ``gmt``
    /// (``YYYY:MM:DD HH:MM:SS``, local and UTC capture time), ``view`` (Radiance ``VIEW=`` of a
    /// cropped dome), ``sun`` (``{"pixel": {"x", "y"}, "azimuth_deg", "elevation_deg"}``, the
    /// ``#SUN=`` line), ``north`` (``{"x", "y"}``, the ``#NORTH=`` point on the horizon),
    /// ``software``, ``other`` (further header lines, verbatim). The same dict
    /// :func:`read_hdr` returns and :func:`write_hdr` takes.
    #[getter]
    fn header<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        meta_dict(py, &self.meta)
    }

    /// The tone-mapped preview (ACES, automatic exposure keyed on the sky), uint8 array of
    /// shape (height, width, 3), sRGB; None unless ``preview=True``.
    #[getter]
    fn preview<'py>(slf: &Bound<'py, Self>) -> PyResult<Option<Bound<'py, PyArray3<u8>>>> {
        match &slf.get().preview {
            // SAFETY: as for `radiance`.
            Some(p) => Ok(Some(unsafe {
                crate::arrays::view(p, slf.clone().into_any())?
            })),
            None => Ok(None),
        }
    }

    /// The equirectangular (lat-long) map, float32 (height, 2·height, 3): east at the centre,
    /// north at a quarter of the width, the zenith along the top row; None unless
    /// ``equirect=`` was given.
    #[getter]
    fn equirect<'py>(slf: &Bound<'py, Self>) -> PyResult<Option<Bound<'py, PyArray3<f32>>>> {
        match &slf.get().equirect {
            // SAFETY: as for `radiance`.
            Some((img, _)) => Ok(Some(unsafe {
                crate::arrays::view(img, slf.clone().into_any())?
            })),
            None => Ok(None),
        }
    }

    /// The camera profile made by calibrating on this bracket (with the camera's EXIF make,
    /// model, ISO and date), or None when a ``profile`` was given.
    #[getter]
    fn camera_profile(&self) -> Option<CameraProfile> {
        self.camera_profile
            .clone()
            .map(|inner| CameraProfile { inner })
    }

    /// Writes the radiance map by the extension of ``path``: ``.hdr`` (Radiance RGBE, byte for
    /// byte what ``skydome merge -o`` writes from the same frames and options) or ``.exr``
    /// (OpenEXR, half floats unless ``exr_float=True``; switched to float, with a warning, when
    /// values exceed half's range; ``exr_compression`` one of zip, piz, zips, rle, none).
    /// Atomic (a temporary file, then a rename); an existing file is replaced, an input photo
    /// never. The GIL is released while it encodes and writes.
    #[pyo3(signature = (path, *, exr_float=false, exr_compression="zip"))]
    fn save(
        &self,
        py: Python<'_>,
        path: &Bound<'_, PyAny>,
        exr_float: bool,
        exr_compression: &str,
    ) -> PyResult<()> {
        let exr = exr_options(exr_float, exr_compression)?;
        save_radiance(py, path, &self.radiance, &self.meta, exr, &self.inputs)
    }

    /// Writes the equirectangular map (see :meth:`save`); raises ``ValueError`` when the
    /// dome was made without ``equirect=``.
    #[pyo3(signature = (path, *, exr_float=false, exr_compression="zip"))]
    fn save_equirect(
        &self,
        py: Python<'_>,
        path: &Bound<'_, PyAny>,
        exr_float: bool,
        exr_compression: &str,
    ) -> PyResult<()> {
        let exr = exr_options(exr_float, exr_compression)?;
        let Some((img, meta)) = &self.equirect else {
            return Err(value_error(
                "equirect",
                "this dome was made without equirect=; run with equirect=True",
            ));
        };
        save_radiance(py, path, img, meta, exr, &self.inputs)
    }

    fn __repr__(&self) -> String {
        format!(
            "<skydome.Dome {}x{}{}{}>",
            self.radiance.width,
            self.radiance.height,
            match self.meta.sun {
                Some(s) => format!(", sun at ({:.1}, {:.1})", s.pixel.x, s.pixel.y),
                None => String::new(),
            },
            if self.meta.is_absolute() {
                ", absolute"
            } else {
                ""
            }
        )
    }

    /// Pickling: the dome's buffers as bytes, its metadata as dicts (floats exact).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let d = slf.get();
        let f = py.import("skydome._skydome")?.getattr("_dome_from_state")?;
        let image = |img: &HdrImage| {
            let bytes: Vec<u8> = img.data.iter().flat_map(|v| v.to_le_bytes()).collect();
            (img.width, img.height, PyBytes::new(py, &bytes))
        };
        let state = PyDict::new(py);
        state.set_item("radiance", image(&d.radiance))?;
        state.set_item("meta", ser_to_py(py, &d.meta)?)?;
        state.set_item("report", crate::pyvalue::to_py(py, &d.report)?)?;
        state.set_item(
            "preview",
            d.preview
                .as_ref()
                .map(|p| (p.width, p.height, PyBytes::new(py, &p.data))),
        )?;
        match &d.equirect {
            Some((img, m)) => state.set_item("equirect", (image(img), ser_to_py(py, m)?))?,
            None => state.set_item("equirect", py.None())?,
        }
        match &d.camera_profile {
            Some(p) => state.set_item("camera_profile", ser_to_py(py, p)?)?,
            None => state.set_item("camera_profile", py.None())?,
        }
        let inputs: Vec<String> = d
            .inputs
            .iter()
            .map(|p| p.to_string_lossy().to_string())
            .collect();
        state.set_item("inputs", inputs)?;
        Ok((f, PyTuple::new(py, [state])?))
    }
}

type ImageState = (usize, usize, Vec<u8>);

/// Unpickles a dome (used by ``Dome.__reduce__``).
#[pyfunction]
pub fn _dome_from_state(state: &Bound<'_, PyDict>) -> PyResult<Dome> {
    let bad = |what: &str| error(format!("cannot unpickle the dome: bad {what}"));
    let item = |k: &str| -> PyResult<Bound<'_, PyAny>> { state.get_item(k)?.ok_or_else(|| bad(k)) };
    let image = |(w, h, bytes): ImageState| -> PyResult<HdrImage> {
        let data: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        HdrImage::from_vec(w, h, data).ok_or_else(|| bad("image"))
    };
    let meta_of = |o: &Bound<'_, PyAny>| -> PyResult<HdrMeta> {
        serde_json::from_value(crate::pyvalue::from_py("state", o)?).map_err(|_| bad("header"))
    };
    let preview: Option<ImageState> = item("preview")?.extract()?;
    let equirect: Option<(ImageState, Bound<'_, PyAny>)> = item("equirect")?.extract()?;
    let profile = item("camera_profile")?;
    let inputs: Vec<String> = item("inputs")?.extract()?;
    Ok(Dome {
        radiance: image(item("radiance")?.extract()?)?,
        meta: meta_of(&item("meta")?)?,
        report: crate::pyvalue::from_py("state", &item("report")?)?,
        preview: match preview {
            Some((w, h, data)) => {
                Some(RgbImage::from_vec(w, h, data).ok_or_else(|| bad("preview"))?)
            }
            None => None,
        },
        equirect: match equirect {
            Some((img, m)) => Some((image(img)?, meta_of(&m)?)),
            None => None,
        },
        camera_profile: match profile.is_none() {
            true => None,
            false => Some(crate::profile::profile_from_py(&profile)?),
        },
        inputs: inputs.into_iter().map(PathBuf::from).collect(),
    })
}

/// The EXR options of `save`.
fn exr_options(exr_float: bool, compression: &str) -> PyResult<ExrOptions> {
    Ok(ExrOptions {
        pixel_type: match exr_float {
            true => ExrPixelType::Float,
            false => ExrPixelType::Half,
        },
        compression: compression
            .parse()
            .map_err(|e: skydome::UnknownName| value_error("exr_compression", e))?,
    })
}

/// Encodes and writes a radiance map by extension, without the GIL.
pub fn save_radiance(
    py: Python<'_>,
    path: &Bound<'_, PyAny>,
    img: &HdrImage,
    meta: &HdrMeta,
    exr: ExrOptions,
    inputs: &[PathBuf],
) -> PyResult<()> {
    let p = crate::files::path_arg("path", path)?;
    let ext = crate::files::extension(&p);
    let Some(format) = RadianceFormat::from_extension(&ext, exr) else {
        return Err(value_error(
            "path",
            format!(
                "{}: cannot write '.{ext}' radiance files; use .hdr or .exr",
                p.display()
            ),
        ));
    };
    let warnings = py
        .detach(|| -> Result<Vec<String>, String> {
            let name = p.display();
            let e =
                formats::encode_radiance(img, meta, format).map_err(|e| format!("{name}: {e}"))?;
            crate::files::write_atomic(&p, &e.bytes, inputs)?;
            Ok(e.warnings.iter().map(|w| format!("{name}: {w}")).collect())
        })
        .map_err(error)?;
    warn_all(py, &warnings)
}

/// Header metadata as a dict.
pub fn meta_dict<'py>(py: Python<'py>, meta: &HdrMeta) -> PyResult<Bound<'py, PyAny>> {
    ser_to_py(py, meta)
}

/// Runs the whole sky-dome job on a bracket, as ``skydome merge``: decode, lens, response,
/// merge, sky, pictures. Returns a :class:`Dome`.
///
/// frames
///     The bracket, two or more photos of one still scene at different exposures, in any
///     order: paths (str or os.PathLike) of JPEG, PNG or TIFF files, their bytes, or numpy
///     arrays of shape (height, width, 3), uint8 or uint16 camera codes, R, G, B, row 0 at the
///     top. A (n, height, width, 3) array is a stack of n frames.
/// times
///     Exposure times in seconds, one per frame in the order given (e.g. [1/400, 1/100,
///     1/25]); overrides EXIF. Needed for arrays (they carry no EXIF).
/// profile
///     A :class:`CameraProfile`, or the path of a camera.json; without one the bracket
///     calibrates itself (the profile it made is :attr:`Dome.camera_profile`).
/// lens
///     The path of a lens.json from ``skydome lens fit`` (or its contents as a dict).
/// fisheye
///     The photos are fish-eye: detect the image circle (or take ``circle``) and model the lens
///     with ``lens_model`` (default "stereographic"; also equidistant, equisolid, orthographic)
///     and ``fov`` (full field of view across the circle, degrees, default 235).
/// crop
///     Crop to the 180° sky-dome: a square whose inscribed circle is the horizon.
/// sun
///     "auto" (detect the brightest compact blob; the default), "none", "ephemeris" (NREL SPA
///     from the capture time and place), or (x, y), a tapped pixel of the input photos.
/// north
///     Compass azimuth of the phone's top edge, degrees from true north towards east; or
///     "from-sun" (from the observed sun and the ephemeris; needs time and place).
/// time, lat, lon
///     Capture time (ISO 8601 with a UTC offset, or an aware datetime) and place (degrees,
///     north and east positive) for the ephemeris; default from EXIF.
/// illuminance
///     Horizontal illuminance measured beside the camera, lux: makes the radiance absolute
///     (needs a lens).
/// luminance
///     A spot-meter reading (x, y, cd_per_m2[, radius_px]): the luminance of the patch of
///     radius_px (default 3) around pixel (x, y) of the input photos; makes the radiance
///     absolute.
/// weighting
///     Frame weighting of the merge: "noise" (default: inverse variance under a noise model
///     fitted to the bracket or read from the profile), "hat" (Debevec's hat) or "none".
/// exposures
///     "listed" (default): the given or EXIF times as they are; "measured": the exposures
///     measured from the photos, anchored on the listed time of the frame that agrees best
///     (as the command line's ``--exposures``), each frame's listed and measured exposure in
///     ``report["exposures"]`` and a warning naming frames more than 1/3 stop off.
/// preview
///     Also make the tone-mapped preview (:attr:`Dome.preview`).
/// equirect
///     Also make the equirectangular map (needs a lens): True, or its width in pixels.
/// progress
///     A callable ``progress(stage, fraction)``: stage one of "decoding", "lens",
///     "calibrating", "merging", "sky", "pictures", fraction in [0, 1]. Raising in it cancels
///     the run (the exception propagates); so does Ctrl-C (KeyboardInterrupt).
/// circle
///     The fish-eye image circle (cx, cy, r) in pixels, when known (also limits calibration
///     sampling to it).
///
/// Raises :class:`skydome.Error` (a ValueError) with the command line's one-line message when
/// the job fails; TypeError or ValueError naming the argument for a bad argument. Warnings in
/// the report are also issued as Python warnings. The GIL is released while the core runs, so
/// several threads run several jobs at once.
#[pyfunction]
#[pyo3(signature = (frames, times=None, *, profile=None, lens=None, fisheye=false,
    lens_model=None, fov=None, crop=false, sun=None, north=None, time=None, lat=None, lon=None,
    illuminance=None, luminance=None, weighting="noise", exposures="listed", preview=false,
    equirect=None, progress=None, circle=None),
    text_signature = "(frames, times=None, *, profile=None, lens=None, fisheye=False, \
    lens_model=None, fov=None, crop=False, sun='auto', north=None, time=None, lat=None, \
    lon=None, illuminance=None, luminance=None, weighting='noise', exposures='listed', \
    preview=False, equirect=None, progress=None, circle=None)")]
#[allow(clippy::too_many_arguments)]
pub fn run<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    times: Option<&Bound<'py, PyAny>>,
    profile: Option<Bound<'py, PyAny>>,
    lens: Option<Bound<'py, PyAny>>,
    fisheye: bool,
    lens_model: Option<String>,
    fov: Option<f64>,
    crop: bool,
    sun: Option<Bound<'py, PyAny>>,
    north: Option<Bound<'py, PyAny>>,
    time: Option<Bound<'py, PyAny>>,
    lat: Option<f64>,
    lon: Option<f64>,
    illuminance: Option<f64>,
    luminance: Option<Vec<f64>>,
    weighting: &str,
    exposures: &str,
    preview: bool,
    equirect: Option<Bound<'py, PyAny>>,
    progress: Option<Bound<'py, PyAny>>,
    circle: Option<(f64, f64, f64)>,
) -> PyResult<Dome> {
    let built = RunArgs {
        profile,
        lens,
        fisheye,
        lens_model,
        fov,
        circle,
        crop,
        sun,
        north,
        time,
        lat,
        lon,
        illuminance,
        luminance,
        weighting: weighting.to_string(),
        exposures: exposures.to_string(),
        preview,
        equirect,
    }
    .build()?;
    let bracket = frames::extract(frames, times)?;
    let inputs = bracket.paths();
    let mut bridge = Bridge::new(progress::callback_arg(progress)?);
    let options = &built.options;
    let result = py.detach(|| -> Result<pipeline::Dome, Failure> {
        let input = bracket.into_input()?;
        pipeline::run(input, options, &mut |p| bridge.event(p)).map_err(Failure::Pipeline)
    });
    let mut dome = finish(result, &mut bridge)?;
    if let Some(p) = &built.profile_path {
        dome.report.response = format!("profile {}", p.display());
    }
    warn_all(py, &dome.report.warnings)?;
    let report = serde_json::to_value(&dome.report).map_err(|e| error(e.to_string()))?;
    Ok(Dome {
        radiance: dome.radiance,
        meta: dome.meta,
        report,
        preview: dome.preview,
        equirect: dome.equirect,
        camera_profile: dome.camera_profile,
        inputs,
    })
}
