//! The `frames` argument: paths, encoded bytes or numpy arrays, turned into the pipeline's
//! [`Input`].
//!
//! Paths are read by the core with the GIL released (their names, as given, appear in
//! messages, as on the command line). Bytes are copied once. Arrays (H, W, 3) of `uint8` or
//! `uint16` are copied once into the core's frame buffers; they carry no EXIF, so they need
//! `times` and are named `frames[i]` in messages.

use std::path::PathBuf;

use numpy::PyArray3;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyMemoryView, PyString};
use skydome::bracket::{self, DecodeOptions, DecodedFrame, Pixels};
use skydome::pipeline::{EncodedFrame, Frames, Input, PipelineError};

use crate::arrays;
use crate::errors::{type_error, value_error};

/// One frame as given.
pub enum FrameIn {
    /// A file to read.
    Path(PathBuf),
    /// Encoded bytes (JPEG, PNG, TIFF), named `frames[i]`.
    Bytes(EncodedFrame),
    /// Pixels from a numpy array.
    Array(Box<DecodedFrame>),
}

/// The frames and times of a job, extracted from Python while holding the GIL.
pub struct Bracket {
    /// The frames, in the order given.
    pub frames: Vec<FrameIn>,
    /// Exposure times, seconds, in the order of `frames`.
    pub times: Option<Vec<f64>>,
}

impl Bracket {
    /// The paths among the frames (never overwritten by the job's outputs).
    pub fn paths(&self) -> Vec<PathBuf> {
        self.frames
            .iter()
            .filter_map(|f| match f {
                FrameIn::Path(p) => Some(p.clone()),
                _ => None,
            })
            .collect()
    }

    /// The pipeline's input: files are read here (call it with the GIL released). With any
    /// array among the frames, the encoded ones are decoded here too, by the pipeline's own
    /// decoder, so that all frames reach the core decoded.
    pub fn into_input(self) -> Result<Input, Failure> {
        let any_array = self.frames.iter().any(|f| matches!(f, FrameIn::Array(_)));
        let encoded = |f: FrameIn| -> Result<Result<EncodedFrame, DecodedFrame>, Failure> {
            Ok(match f {
                FrameIn::Path(p) => Ok(EncodedFrame {
                    name: p.display().to_string(),
                    bytes: crate::files::read(&p).map_err(Failure::Message)?,
                }),
                FrameIn::Bytes(e) => Ok(e),
                FrameIn::Array(d) => Err(*d),
            })
        };
        let frames = if any_array {
            let mut decoded = Vec::with_capacity(self.frames.len());
            for f in self.frames {
                decoded.push(match encoded(f)? {
                    Ok(e) => bracket::decode(&e.name, &e.bytes, &DecodeOptions::default())
                        .map_err(|err| Failure::Pipeline(err.into()))?,
                    Err(d) => d,
                });
            }
            Frames::Decoded(decoded)
        } else {
            let mut out = Vec::with_capacity(self.frames.len());
            for f in self.frames {
                if let Ok(e) = encoded(f)? {
                    out.push(e);
                }
            }
            Frames::Encoded(out)
        };
        Ok(Input {
            times: self.times,
            ..Input::new(frames)
        })
    }
}

/// Why a job failed before or inside the core.
pub enum Failure {
    /// A message for `skydome.Error` (a file that cannot be read or written).
    Message(String),
    /// The library's error.
    Pipeline(PipelineError),
}

impl Failure {
    /// The Python exception.
    pub fn into_py(self) -> PyErr {
        match self {
            Failure::Message(m) => crate::errors::error(m),
            Failure::Pipeline(e) => crate::errors::pipeline_error(&e),
        }
    }
}

/// Extracts `frames` and `times`.
pub fn extract(frames: &Bound<'_, PyAny>, times: Option<&Bound<'_, PyAny>>) -> PyResult<Bracket> {
    if frames.is_instance_of::<PyString>()
        || frames.is_instance_of::<PyBytes>()
        || frames.hasattr("__fspath__")?
    {
        return Err(type_error(
            "frames",
            "expected a list of frames (paths, bytes or numpy arrays), got a single one",
        ));
    }
    let items: Vec<Bound<'_, PyAny>> = if let Some((_, shape)) = arrays::describe(frames) {
        // A stack of frames, (N, H, W, 3).
        if shape.len() != 4 {
            return Err(value_error(
                "frames",
                format!(
                    "a single array must be a stack of shape (n, height, width, 3), got shape {}; pass a list of (height, width, 3) arrays",
                    arrays::shape_text(&shape)
                ),
            ));
        }
        frames.try_iter()?.collect::<PyResult<_>>()?
    } else {
        frames
            .try_iter()
            .map_err(|_| {
                type_error(
                    "frames",
                    format!(
                        "expected a list of paths, bytes or numpy arrays, got {}",
                        arrays::type_name(frames)
                    ),
                )
            })?
            .collect::<PyResult<_>>()?
    };
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        out.push(frame(i, item)?);
    }
    let times = match times {
        None => None,
        Some(t) if t.is_none() => None,
        Some(t) => Some(times_arg(t)?),
    };
    if times.is_none() {
        if let Some(i) = out.iter().position(|f| matches!(f, FrameIn::Array(_))) {
            return Err(value_error(
                "times",
                format!(
                    "frames[{i}] is a numpy array, which carries no exposure time; give times=[t0, t1, ...] in seconds, one per frame, in the order given"
                ),
            ));
        }
    }
    Ok(Bracket { frames: out, times })
}

/// `times`: a sequence of positive seconds (validated by the core, which names a bad one).
fn times_arg(t: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    if t.is_instance_of::<PyString>() {
        return Err(type_error(
            "times",
            "expected a list of exposure times in seconds (numbers, e.g. [1/400, 1/100, 1/25]), got a string",
        ));
    }
    let items = t.try_iter().map_err(|_| {
        type_error(
            "times",
            format!(
                "expected a list of exposure times in seconds, got {}",
                arrays::type_name(t)
            ),
        )
    })?;
    items
        .enumerate()
        .map(|(i, x)| {
            let x = x?;
            x.extract::<f64>().map_err(|_| {
                type_error(
                    &format!("times[{i}]"),
                    format!(
                        "expected a number of seconds, got {}",
                        arrays::type_name(&x)
                    ),
                )
            })
        })
        .collect()
}

/// One frame: a path, bytes, or an (H, W, 3) uint8/uint16 array.
fn frame(i: usize, obj: &Bound<'_, PyAny>) -> PyResult<FrameIn> {
    let arg = format!("frames[{i}]");
    if obj.is_instance_of::<PyString>() || obj.hasattr("__fspath__")? {
        return Ok(FrameIn::Path(crate::files::path_arg(&arg, obj)?));
    }
    if obj.is_instance_of::<PyBytes>()
        || obj.is_instance_of::<PyByteArray>()
        || obj.is_instance_of::<PyMemoryView>()
    {
        let bytes: Vec<u8> = if let Ok(b) = obj.cast::<PyBytes>() {
            b.as_bytes().to_vec()
        } else if let Ok(b) = obj.cast::<PyByteArray>() {
            b.to_vec()
        } else {
            // A memoryview: through bytes (its buffer may be strided).
            let b = obj.py().get_type::<PyBytes>().call1((obj,))?;
            b.cast::<PyBytes>()?.as_bytes().to_vec()
        };
        return Ok(FrameIn::Bytes(EncodedFrame { name: arg, bytes }));
    }
    if let Some((dtype, _)) = arrays::describe(obj) {
        let (height, width) = arrays::rgb_shape(&arg, obj)?;
        let pixels = if arrays::is_dtype::<u8>(obj) {
            Pixels::U8(arrays::copy_samples(obj.cast::<PyArray3<u8>>()?))
        } else if arrays::is_dtype::<u16>(obj) {
            Pixels::U16(arrays::copy_samples(obj.cast::<PyArray3<u16>>()?))
        } else {
            return Err(type_error(
                &arg,
                format!(
                    "expected a uint8 or uint16 array (camera codes), got dtype {dtype}; convert with .astype(numpy.uint8) or .astype(numpy.uint16) if the values are codes"
                ),
            ));
        };
        return Ok(FrameIn::Array(Box::new(DecodedFrame::new(
            &arg, width, height, pixels,
        ))));
    }
    Err(type_error(
        &arg,
        format!(
            "expected a path (str or os.PathLike), bytes, or a numpy array of shape (height, width, 3), got {}",
            arrays::type_name(obj)
        ),
    ))
}
