//! tonemap (in progress).
