//! Progress events of [`run`](super::run) and cancellation.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use super::PipelineError;

/// A stage of [`run`](super::run), in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Decoding the photos.
    Decoding,
    /// Finding the lens circle.
    Lens,
    /// Calibrating the response.
    Calibrating,
    /// Merging.
    Merging,
    /// Crop, north, sun, maps.
    Sky,
    /// Tone-mapped pictures.
    Pictures,
}

impl Stage {
    /// Lower-case name for progress displays ("decoding", "calibrating", …).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Decoding => "decoding",
            Stage::Lens => "lens",
            Stage::Calibrating => "calibrating",
            Stage::Merging => "merging",
            Stage::Sky => "sky",
            Stage::Pictures => "pictures",
        }
    }
}

/// A progress event: `fraction` of `stage` done, in `0..=1`. Each stage sends 0 when it starts
/// and 1 when it ends, with steps in between where it has them (one per decoded frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// The stage.
    pub stage: Stage,
    /// Fraction done, `0..=1`.
    pub fraction: f64,
}

/// A progress callback that ignores the events and never cancels.
pub fn no_progress(_: &Progress) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

/// Forwards progress events and turns a cancel into an error.
pub(super) struct Reporter<'a>(pub(super) &'a mut dyn FnMut(&Progress) -> ControlFlow<()>);

impl Reporter<'_> {
    /// Sends `fraction` of `stage`; [`PipelineError::Cancelled`] when the callback says stop.
    pub(super) fn at(&mut self, stage: Stage, fraction: f64) -> Result<(), PipelineError> {
        match (self.0)(&Progress { stage, fraction }) {
            ControlFlow::Continue(()) => Ok(()),
            ControlFlow::Break(()) => Err(PipelineError::Cancelled),
        }
    }
}
