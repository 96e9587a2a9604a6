//! Radiance RGBE `.hdr` reader and writer (see issue #2).
