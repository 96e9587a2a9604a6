//! `skydome.Error` and the mapping of the library's errors onto it.
//!
//! A failed job raises `skydome.Error` (a `ValueError`) whose message is the command line's
//! one line without its `error: ` prefix: the library's message, naming the file (or
//! `frames[i]` for bytes and arrays) and the problem, and where the command line adds the flag
//! that fixes it, the keyword argument instead (`--times` becomes `times=`). Bad arguments
//! (a wrong type, shape or value of an argument, found before the core runs) raise `TypeError`
//! or `ValueError` naming the argument.

use pyo3::create_exception;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::PyErr;
use skydome::bracket::BracketError;
use skydome::pipeline::PipelineError;

create_exception!(
    skydome,
    Error,
    PyValueError,
    "A skydome job failed: unreadable or inconsistent photos, a failed calibration, a lens or sun \
     that cannot be found, an unwritable file. The message is one line, naming the file \
     (or `frames[i]`) and what to do, as the command line's `error:` line."
);

/// `skydome.Error` with `message`.
pub fn error(message: impl Into<String>) -> PyErr {
    Error::new_err(message.into())
}

/// `TypeError` naming argument `arg`.
pub fn type_error(arg: &str, what: impl std::fmt::Display) -> PyErr {
    PyTypeError::new_err(format!("{arg}: {what}"))
}

/// `ValueError` naming argument `arg`.
pub fn value_error(arg: &str, what: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{arg}: {what}"))
}

/// The library's error as the command line words it, with the keyword argument that fixes it
/// where the command line names its flag (see `skydome-cli/src/io.rs`, `hint`).
pub fn pipeline_message(e: &PipelineError) -> String {
    let extra = match e {
        PipelineError::Bracket(BracketError::MissingExposure { .. }) => {
            " with times=[1/400, 1/100, ...] (seconds, one per frame, in the order given)"
        }
        PipelineError::Bracket(BracketError::DarkerWhenLonger { .. }) => {
            " (the EXIF times, or times= in the order of the frames)"
        }
        PipelineError::Bracket(BracketError::OrientationMismatch { .. }) => {
            " (give the frames as arrays in the orientation wanted)"
        }
        PipelineError::CircleNotFound { .. } => " with circle=(cx, cy, r)",
        PipelineError::NoEphemeris => " (time=, lat=, lon=)",
        PipelineError::NeedsLens(_) => " (lens='lens.json' or fisheye=True)",
        _ => "",
    };
    one_line(&format!("{e}{extra}"))
}

/// A message on one line, as the command line prints it.
pub fn one_line(s: &str) -> String {
    s.replace('\n', " ")
}

/// `skydome.Error` for a library error.
pub fn pipeline_error(e: &PipelineError) -> PyErr {
    error(pipeline_message(e))
}
