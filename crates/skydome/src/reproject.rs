//! reproject (in progress).
