//! Reading and writing radiance maps by file extension (`.hdr` Radiance RGBE, `.exr` OpenEXR);
//! the formats' rules (signatures, `EXPOSURE=`, the half-float fallback) are the library's.

use std::path::Path;

use anyhow::{bail, Context, Result};
use skydome::formats::exr::{ExrCompression, ExrOptions, ExrPixelType};
use skydome::formats::{self, HdrMeta, RadianceFile, RadianceFormat};
use skydome::HdrImage;

/// How `.exr` outputs are written.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ExrArgs {
    /// Write EXR channels as 32-bit float instead of half.
    #[arg(long)]
    pub exr_float: bool,
    /// EXR compression (all lossless): zip (OpenEXR's default), piz (smaller and faster for
    /// photographs), zips, rle, none.
    #[arg(long, default_value = "zip", value_parser = parse_compression)]
    pub exr_compression: ExrCompression,
}

fn parse_compression(s: &str) -> Result<ExrCompression, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

impl ExrArgs {
    /// The library's EXR options.
    pub fn options(&self) -> ExrOptions {
        ExrOptions {
            pixel_type: match self.exr_float {
                true => ExrPixelType::Float,
                false => ExrPixelType::Half,
            },
            compression: self.exr_compression,
        }
    }
}

/// Reads a `.hdr` or `.exr` file (recognised by its first bytes, not its name); values are
/// radiance (divided by the file's `EXPOSURE`).
pub fn read(path: &Path) -> Result<RadianceFile> {
    let bytes = crate::io::read(path)?;
    formats::read_radiance(&bytes).with_context(|| path.display().to_string())
}

/// Encodes a radiance map for `path` by its extension: `.hdr` (RGBE) or `.exr` (half float
/// unless `--exr-float`; the library switches to float, with a warning, when values exceed
/// half's range).
pub fn encode(path: &Path, image: &HdrImage, meta: &HdrMeta, opts: &ExrArgs) -> Result<Vec<u8>> {
    let name = path.display();
    let ext = crate::io::extension(path);
    let Some(format) = RadianceFormat::from_extension(&ext, opts.options()) else {
        bail!("{name}: cannot write '.{ext}' radiance files; use .hdr or .exr");
    };
    let e = formats::encode_radiance(image, meta, format).with_context(|| name.to_string())?;
    for w in &e.warnings {
        crate::io::warn(false, &format!("{name}: {w}"));
    }
    Ok(e.bytes)
}
