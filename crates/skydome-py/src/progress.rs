//! Progress and cancellation while the core runs without the GIL.
//!
//! At each of the pipeline's progress events (between frames and between stages) the GIL is
//! taken back briefly: the user's `progress(stage, fraction)` is called, and pending signals
//! are checked (`PyErr_CheckSignals`), so Ctrl-C raises `KeyboardInterrupt` out of a long run
//! within one stage. An exception raised by the callback cancels the run the same way and
//! propagates unchanged.

use std::ops::ControlFlow;

use pyo3::prelude::*;
use skydome::pipeline::Progress;

/// Forwards progress events to Python and remembers why the run was cancelled.
pub struct Bridge {
    callback: Option<Py<PyAny>>,
    /// The exception that cancelled the run (KeyboardInterrupt, or the callback's own).
    pub raised: Option<PyErr>,
}

impl Bridge {
    /// A bridge to `callback` (`None`: signals are still checked).
    pub fn new(callback: Option<Py<PyAny>>) -> Self {
        Self {
            callback,
            raised: None,
        }
    }

    /// Handles one event; called without the GIL.
    pub fn event(&mut self, p: &Progress) -> ControlFlow<()> {
        self.stage(p.stage.name(), p.fraction)
    }

    /// Reports `fraction` of the stage named `stage`; called without the GIL.
    pub fn stage(&mut self, stage: &str, fraction: f64) -> ControlFlow<()> {
        let result = Python::attach(|py| -> PyResult<()> {
            if let Some(cb) = &self.callback {
                cb.call1(py, (stage, fraction))?;
            }
            py.check_signals()
        });
        match result {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.raised = Some(e);
                ControlFlow::Break(())
            }
        }
    }
}

/// Checks that `progress` is callable (or None).
pub fn callback_arg(progress: Option<Bound<'_, PyAny>>) -> PyResult<Option<Py<PyAny>>> {
    match progress {
        None => Ok(None),
        Some(p) if p.is_none() => Ok(None),
        Some(p) if p.is_callable() => Ok(Some(p.unbind())),
        Some(p) => Err(crate::errors::type_error(
            "progress",
            format!(
                "expected a callable progress(stage: str, fraction: float), got {}",
                crate::arrays::type_name(&p)
            ),
        )),
    }
}
