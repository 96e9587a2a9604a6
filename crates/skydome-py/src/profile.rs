//! `skydome.CameraProfile` and `skydome.calibrate`.

use std::path::Path;

use numpy::PyArray2;
use pyo3::prelude::*;
use skydome::image::Circle;
use skydome::pipeline;
use skydome::response::{self, CalibrateOptions};
use skydome::sampling::SampleOptions;

use crate::errors::{error, pipeline_error, value_error};
use crate::frames::{self, Failure};
use crate::progress::{self, Bridge};

/// A camera's response curves (and noise model), made once per device by
/// :func:`skydome.calibrate` or ``skydome calibrate``, and given to :func:`skydome.run` as
/// ``profile=``. The same JSON as the command line's ``camera.json``: ``version`` (1),
/// ``linear``, ``g`` (three lists of 256 natural-log values g(Z) = ln E + ln Δt for
/// Z = 0..255, red, green, blue, g(128) = 0, non-decreasing), ``lambda``, ``weighting``,
/// ``samples``, ``seed``, ``make``, ``model``, ``iso``, ``date``.
#[pyclass(frozen, module = "skydome", eq)]
#[derive(Clone, PartialEq)]
pub struct CameraProfile {
    pub inner: skydome::camera::CameraProfile,
}

#[pymethods]
impl CameraProfile {
    /// Reads and validates a camera profile (JSON) written by :meth:`save` or
    /// ``skydome calibrate``. Raises :class:`skydome.Error` naming the file when it cannot be
    /// read or is not a valid profile.
    #[staticmethod]
    #[pyo3(signature = (path))]
    fn load(path: &Bound<'_, PyAny>) -> PyResult<Self> {
        let p = crate::files::path_arg("path", path)?;
        Ok(Self {
            inner: read_profile(&p)?,
        })
    }

    /// Parses and validates a profile from its JSON text.
    #[staticmethod]
    #[pyo3(signature = (text))]
    fn from_json(text: &str) -> PyResult<Self> {
        let inner =
            skydome::camera::CameraProfile::from_json(text).map_err(|e| error(e.to_string()))?;
        Ok(Self { inner })
    }

    /// Writes the profile as JSON (the command line's ``camera.json``), atomically: a
    /// temporary file beside ``path``, then a rename.
    #[pyo3(signature = (path))]
    fn save(&self, py: Python<'_>, path: &Bound<'_, PyAny>) -> PyResult<()> {
        let p = crate::files::path_arg("path", path)?;
        let json = self.inner.to_json();
        py.detach(|| crate::files::write_atomic(&p, json.as_bytes(), &[]))
            .map_err(error)
    }

    /// The profile as JSON text (what :meth:`save` writes).
    fn to_json(&self) -> String {
        self.inner.to_json()
    }

    /// The profile as a dict (the JSON's fields, floats exact).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::pyvalue::ser_to_py(py, &self.inner)
    }

    /// The response curves, float64 array of shape (3, 256): row c is g_c(Z) = ln E + ln Δt
    /// for codes Z = 0..255 of channel c (red, green, blue), natural log.
    #[getter]
    fn g<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self.inner.g.to_vec();
        PyArray2::from_vec2(py, &rows).map_err(|e| value_error("g", e))
    }

    /// True for a known-linear response (RAW-derived data).
    #[getter]
    fn linear(&self) -> bool {
        self.inner.linear
    }

    /// Camera make from EXIF, when known.
    #[getter]
    fn make(&self) -> Option<String> {
        self.inner.make.clone()
    }

    /// Camera model from EXIF, when known.
    #[getter]
    fn model(&self) -> Option<String> {
        self.inner.model.clone()
    }

    /// ISO speed of the calibration bracket, when known.
    #[getter]
    fn iso(&self) -> Option<f64> {
        self.inner.iso
    }

    /// Capture date of the calibration bracket (EXIF), when known.
    #[getter]
    fn date(&self) -> Option<String> {
        self.inner.date.clone()
    }

    /// Smoothness weight λ the curves were solved with.
    #[getter]
    fn lambda_(&self) -> f64 {
        self.inner.lambda
    }

    /// Number of sample pixels used.
    #[getter]
    fn samples(&self) -> usize {
        self.inner.samples
    }

    /// Seed of the sample selection.
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed
    }

    fn __repr__(&self) -> String {
        let who = match (&self.inner.make, &self.inner.model) {
            (Some(a), Some(b)) => format!("{a} {b}"),
            (Some(a), None) | (None, Some(a)) => a.clone(),
            (None, None) => "unknown camera".into(),
        };
        format!(
            "<skydome.CameraProfile {who}{}, {} samples, seed {}>",
            if self.inner.linear { ", linear" } else { "" },
            self.inner.samples,
            self.inner.seed
        )
    }

    /// Pickling: the profile as a dict (exact floats).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyAny>,))> {
        let py = slf.py();
        let f = py
            .import("skydome._skydome")?
            .getattr("_profile_from_dict")?;
        Ok((f, (crate::pyvalue::ser_to_py(py, &slf.get().inner)?,)))
    }
}

/// Unpickles a profile (used by ``CameraProfile.__reduce__``).
#[pyfunction]
pub fn _profile_from_dict(d: &Bound<'_, PyAny>) -> PyResult<CameraProfile> {
    Ok(CameraProfile {
        inner: profile_from_py(d)?,
    })
}

/// A profile from its dict (exact floats), validated.
pub fn profile_from_py(d: &Bound<'_, PyAny>) -> PyResult<skydome::camera::CameraProfile> {
    let v = crate::pyvalue::from_py("profile", d)?;
    let p: skydome::camera::CameraProfile =
        serde_json::from_value(v).map_err(|e| value_error("profile", e))?;
    p.response().map_err(|e| value_error("profile", e))?;
    Ok(p)
}

/// Reads and validates a camera profile, naming the file as the command line does.
pub fn read_profile(p: &Path) -> PyResult<skydome::camera::CameraProfile> {
    let text = std::fs::read_to_string(p)
        .map_err(|e| error(format!("{}: cannot read: {e}", p.display())))?;
    let name = p.display();
    let profile = skydome::camera::CameraProfile::from_json(&text)
        .map_err(|e| error(format!("{name}: {e}")))?;
    profile
        .response()
        .map_err(|e| error(format!("{name}: {e}")))?;
    Ok(profile)
}

/// `json.dumps(obj)`.
pub fn json_dumps(obj: &Bound<'_, PyAny>) -> PyResult<String> {
    obj.py()
        .import("json")?
        .call_method1("dumps", (obj,))?
        .extract()
}

/// Calibrates the camera's response on a bracket (Debevec–Malik), as ``skydome calibrate``.
///
/// ``frames`` and ``times`` are as for :func:`skydome.run`. Options, named and defaulted as
/// the command line's: ``samples`` (N, raised so that N·(frames−1) ≥ 255 unless
/// ``method="seed"``), ``grid`` (G: samples drawn in G×G cells), ``seed``, ``code_bands``,
/// ``lambda_`` (smoothness weight λ), ``method`` (``"auto"``: ``"covering"`` for brackets of
/// five frames or more and ``"joined"`` for fewer, as the command line's default; ``"robust"``;
/// ``"covering"``; ``"joined"``; ``"seed"``, the original method exactly), ``solver`` (``"schur"`` or ``"svd"``), ``circle`` ((cx, cy, r) in pixels:
/// sample only inside the fish-eye circle), ``linear`` (known-linear data: a linear profile).
/// Calibration warnings are issued as Python warnings. The GIL is released while it computes.
///
/// Returns a :class:`CameraProfile` carrying the camera's EXIF make, model, ISO and date.
#[pyfunction]
#[pyo3(signature = (frames, times=None, *, samples=None, grid=10, seed=0, code_bands=16,
    lambda_=None, method="auto", solver="schur", circle=None, linear=false, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    py: Python<'_>,
    frames: &Bound<'_, PyAny>,
    times: Option<&Bound<'_, PyAny>>,
    samples: Option<usize>,
    grid: usize,
    seed: u64,
    code_bands: usize,
    lambda_: Option<f64>,
    method: &str,
    solver: &str,
    circle: Option<(f64, f64, f64)>,
    linear: bool,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<CameraProfile> {
    let solver: response::Solver = solver
        .parse()
        .map_err(|e: skydome::UnknownName| value_error("solver", e))?;
    let method = method.trim().to_ascii_lowercase();
    let opts = match method.as_str() {
        "auto" | "robust" => {
            // As the command line's `--method auto`: given a knob of the robust method, the
            // robust method at every frame count, that knob applied.
            let tuned = samples.is_some()
                || lambda_.is_some()
                || grid != SampleOptions::default().grid
                || code_bands != SampleOptions::default().code_bands;
            let base = if method == "auto" && !tuned {
                CalibrateOptions::default()
            } else {
                CalibrateOptions::robust()
            };
            CalibrateOptions {
                sampling: SampleOptions {
                    samples: samples.unwrap_or(skydome::sampling::GRID_METHOD_SAMPLES),
                    grid,
                    seed,
                    code_bands,
                    ..SampleOptions::default()
                },
                lambda: lambda_.unwrap_or(response::SEED_LAMBDA),
                solver,
                ..base
            }
        }
        "covering" | "joined" => {
            let mut o = match method.as_str() {
                "joined" => CalibrateOptions::joined(),
                _ => CalibrateOptions::covering(),
            };
            o.sampling.seed = seed;
            if let Some(n) = samples {
                o.sampling.samples = n;
            }
            o.lambda = lambda_.unwrap_or(o.lambda);
            o.solver = solver;
            o
        }
        "seed" => CalibrateOptions {
            sampling: SampleOptions::seed_method(
                samples.unwrap_or(skydome::sampling::GRID_METHOD_SAMPLES),
                grid,
                seed,
            ),
            lambda: lambda_.unwrap_or(response::SEED_LAMBDA),
            solver,
            ..CalibrateOptions::robust()
        },
        _ => {
            return Err(value_error(
                "method",
                format!("'{method}': expected 'auto', 'robust', 'covering', 'joined' or 'seed'"),
            ))
        }
    };
    let circle = match circle {
        Some((cx, cy, r)) if cx.is_finite() && cy.is_finite() && r.is_finite() && r > 0.0 => {
            Some(Circle { cx, cy, r })
        }
        Some(_) => {
            return Err(value_error(
                "circle",
                "expected (cx, cy, r) in pixels with a positive radius",
            ))
        }
        None => None,
    };
    let bracket = frames::extract(frames, times)?;
    let mut bridge = Bridge::new(progress::callback_arg(progress)?);
    let result = py.detach(|| -> Result<_, Failure> {
        let input = bracket.into_input()?;
        let br =
            pipeline::load_bracket(input, &mut |p| bridge.event(p)).map_err(Failure::Pipeline)?;
        if bridge.stage("calibrating", 0.0).is_break() {
            return Err(Failure::Pipeline(pipeline::PipelineError::Cancelled));
        }
        let (mut profile, warnings, wide_step) = if linear {
            (skydome::camera::CameraProfile::linear(), Vec::new(), false)
        } else {
            let cal = response::calibrate(&br.frames, circle, &opts)
                .map_err(|e| Failure::Message(format!("calibration failed: {e}")))?;
            let r = cal.report();
            let warnings: Vec<String> = [
                r.relaxed_warning(),
                r.shortfall_warning(),
                r.range_warning(),
            ]
            .into_iter()
            .flatten()
            .collect();
            (
                skydome::camera::CameraProfile::from_calibration(&cal),
                warnings,
                cal.wide_step,
            )
        };
        // The noise model merges with this profile use instead of fitting their own, as
        // `skydome calibrate` stores it.
        profile
            .estimate_noise(&br.frames, 0, wide_step)
            .map_err(|e| Failure::Message(format!("noise model: {e}")))?;
        pipeline::describe_camera(&mut profile, &br);
        let mut all = br.warnings.clone();
        all.extend(warnings);
        if bridge.stage("calibrating", 1.0).is_break() {
            return Err(Failure::Pipeline(pipeline::PipelineError::Cancelled));
        }
        Ok((profile, all))
    });
    let (inner, warnings) = finish(result, &mut bridge)?;
    warn_all(py, &warnings)?;
    Ok(CameraProfile { inner })
}

/// The result of a job, or its exception: the one that cancelled it (KeyboardInterrupt or the
/// progress callback's), else `skydome.Error`.
pub fn finish<T>(result: Result<T, Failure>, bridge: &mut Bridge) -> PyResult<T> {
    match result {
        Ok(v) => Ok(v),
        Err(f) => match bridge.raised.take() {
            Some(e) => Err(e),
            None => Err(match f {
                Failure::Pipeline(e) => pipeline_error(&e),
                f => f.into_py(),
            }),
        },
    }
}

/// Issues each message as a `UserWarning` (what the command line prints as `warning: …`).
pub fn warn_all(py: Python<'_>, warnings: &[String]) -> PyResult<()> {
    if warnings.is_empty() {
        return Ok(());
    }
    let w = py.import("warnings")?;
    for m in warnings {
        w.call_method1(
            "warn",
            (
                m.as_str(),
                py.get_type::<pyo3::exceptions::PyUserWarning>(),
                2,
            ),
        )?;
    }
    Ok(())
}
