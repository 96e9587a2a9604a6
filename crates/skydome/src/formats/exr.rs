//! OpenEXR writer and reader for RGB radiance maps (see issue #2).
