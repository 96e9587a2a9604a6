//! File formats: one module per format, each over `Read`/`Write` (never paths) so the
//! command line and the web app share them.
//!
//! - [`rgbe`]: Radiance RGBE `.hdr` (reader: flat, old-style and new-style RLE, `#?RADIANCE`
//!   and `#?RGBE`; writer: new-style RLE with skydome's header lines).
//! - [`exr`]: OpenEXR RGB half/float with the same metadata as string attributes.
//! - [`picture`]: 8-bit JPEG/PNG and 16-bit PNG display pictures (previews, overlays, maps).

pub mod exr;
pub mod picture;
pub mod rgbe;

/// A pixel position in an output image (origin top-left, `x` right, `y` down, pixel centres at
/// `+0.5`), as written in the seed's `#SUN=-Y y +X x` / `#NORTH=-Y y +X x` header lines.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PixelPoint {
    /// Column in pixels from the left edge.
    pub x: f64,
    /// Row in pixels from the top edge.
    pub y: f64,
}

/// The sun as marked in an output file.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SunMark {
    /// Where the sun's centre is in the image.
    pub pixel: PixelPoint,
    /// Azimuth in degrees from true north towards east (0 = N, 90 = E), when known.
    pub azimuth_deg: Option<f64>,
    /// Elevation above the horizon in degrees, when known.
    pub elevation_deg: Option<f64>,
}

/// Metadata that skydome writes into (and reads back from) `.hdr` and `.exr` files.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HdrMeta {
    /// Radiance's `EXPOSURE=`: stored pixel = radiance × exposure. `None` means 1.
    pub exposure: Option<f64>,
    /// `CAPDATE=` local capture time, formatted `YYYY:MM:DD HH:MM:SS`.
    pub capdate: Option<String>,
    /// `GMT=` capture time in UTC, formatted `YYYY:MM:DD HH:MM:SS`.
    pub gmt: Option<String>,
    /// `VIEW=` Radiance view options for projected domes (e.g. `-vta -vh 180 -vv 180`).
    pub view: Option<String>,
    /// The sun (`#SUN=` line and an azimuth/elevation comment).
    pub sun: Option<SunMark>,
    /// The north point on the horizon circle (`#NORTH=` line).
    pub north: Option<PixelPoint>,
    /// `SOFTWARE=` line; writers fill in `skydome <version>` when `None`.
    pub software: Option<String>,
    /// Any other header lines, verbatim (without the trailing newline).
    pub other: Vec<String>,
}
