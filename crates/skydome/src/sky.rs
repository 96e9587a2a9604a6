//! sky (in progress).
