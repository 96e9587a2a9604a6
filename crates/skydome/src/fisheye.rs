//! fisheye (in progress).
