//! Reading and writing radiance maps by file extension (`.hdr` Radiance RGBE, `.exr` OpenEXR).

use std::path::Path;

use anyhow::{bail, Context, Result};
use skydome::formats::{exr, rgbe, HdrMeta};
use skydome::HdrImage;

/// How `.exr` outputs are written.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ExrArgs {
    /// Write EXR channels as 32-bit float instead of half.
    #[arg(long)]
    pub exr_float: bool,
    /// EXR compression (all lossless): zip (OpenEXR's default), piz (smaller and faster for
    /// photographs), zips, rle, none.
    #[arg(long, value_enum, default_value_t = CompressionArg::Zip)]
    pub exr_compression: CompressionArg,
}

/// `--exr-compression` values.
#[derive(clap::ValueEnum, Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum CompressionArg {
    /// No compression.
    None,
    /// Run-length.
    Rle,
    /// Deflate, one line per block.
    Zips,
    /// Deflate, 16 lines per block.
    #[default]
    Zip,
    /// Wavelet.
    Piz,
}

impl From<CompressionArg> for exr::ExrCompression {
    fn from(c: CompressionArg) -> Self {
        match c {
            CompressionArg::None => exr::ExrCompression::None,
            CompressionArg::Rle => exr::ExrCompression::Rle,
            CompressionArg::Zips => exr::ExrCompression::Zips,
            CompressionArg::Zip => exr::ExrCompression::Zip,
            CompressionArg::Piz => exr::ExrCompression::Piz,
        }
    }
}

/// A radiance map read from disk.
pub struct Radiance {
    /// Pixels as radiance: stored values divided by the file's `EXPOSURE`.
    pub image: HdrImage,
    /// Metadata from the header.
    pub meta: HdrMeta,
    /// Header lines (`.hdr`) or `name = value` attributes (`.exr`).
    pub header: Vec<String>,
    /// "Radiance RGBE" or "OpenEXR".
    pub format: &'static str,
}

/// Reads a `.hdr` or `.exr` file (recognised by its first bytes, not its name).
pub fn read(path: &Path) -> Result<Radiance> {
    let name = path.display();
    let bytes = crate::io::read(path)?;
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        let f = exr::read_exr(&bytes, &exr::Limits::default()).with_context(|| name.to_string())?;
        let mut image = f.image;
        unexpose(&mut image, f.meta.exposure);
        return Ok(Radiance {
            image,
            header: f
                .text_attributes
                .iter()
                .map(|(k, v)| format!("{k} = {v}"))
                .collect(),
            meta: f.meta,
            format: "OpenEXR",
        });
    }
    if bytes.starts_with(b"#?") {
        let f = rgbe::decode_rgbe(&bytes, &rgbe::Limits::default())
            .with_context(|| name.to_string())?;
        let mut image = f.image;
        unexpose(&mut image, f.header.meta.exposure);
        return Ok(Radiance {
            image,
            meta: f.header.meta,
            header: f.header.lines,
            format: "Radiance RGBE",
        });
    }
    bail!("{name}: not a Radiance .hdr or OpenEXR file (unrecognised first bytes)")
}

/// Radiance's rule: stored pixel = radiance × EXPOSURE.
fn unexpose(image: &mut HdrImage, exposure: Option<f64>) {
    if let Some(e) = exposure.filter(|e| e.is_finite() && *e > 0.0 && *e != 1.0) {
        let k = (1.0 / e) as f32;
        image.data.iter_mut().for_each(|v| *v *= k);
    }
}

/// Largest finite half-float value.
const HALF_MAX: f32 = 65504.0;

/// Encodes a radiance map for `path` by its extension: `.hdr` (RGBE) or `.exr` (half float
/// unless `--exr-float`, or unless the values exceed half's range: then 32-bit float, with a
/// warning, because half would turn them into infinity).
pub fn encode(path: &Path, image: &HdrImage, meta: &HdrMeta, opts: &ExrArgs) -> Result<Vec<u8>> {
    let name = path.display();
    match crate::io::extension(path).as_str() {
        "hdr" | "pic" | "rgbe" => rgbe::encode_rgbe(image, meta).with_context(|| name.to_string()),
        "exr" => {
            let max = image
                .data
                .iter()
                .copied()
                .filter(|v| v.is_finite())
                .fold(0.0f32, f32::max);
            let float = opts.exr_float || max > HALF_MAX;
            if float && max > HALF_MAX {
                crate::io::warn(
                    false,
                    &format!("{name}: values up to {max:.3e} exceed half-float range; writing 32-bit float channels"),
                );
            }
            let o = exr::ExrOptions {
                pixel_type: if float {
                    exr::ExrPixelType::Float
                } else {
                    exr::ExrPixelType::Half
                },
                compression: opts.exr_compression.into(),
            };
            exr::encode_exr(image, meta, o).with_context(|| name.to_string())
        }
        e => bail!("{name}: cannot write '.{e}' radiance files; use .hdr or .exr"),
    }
}
