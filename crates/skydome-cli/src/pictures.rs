//! Encoding the pictures the commands write: tone-mapped previews, curve plots, false colour.

use std::path::Path;

use anyhow::{bail, Context, Result};
use skydome::formats::picture::{self, PictureFormat};
use skydome::image::RgbImage;
use skydome::plot;
use skydome::response::Calibration;
use skydome::tonemap::{self, ToneMap};
use skydome::HdrImage;

/// The response-curve figure for `path` (`.png` or `.svg`).
pub fn curve_plot(path: &Path, cal: &Calibration) -> Result<Vec<u8>> {
    let pts: Vec<Vec<(f64, u8)>> = (0..3)
        .map(|c| {
            let (x, y) = cal.plot_points(c);
            x.into_iter().zip(y).map(|(x, y)| (x, y as u8)).collect()
        })
        .collect();
    let samples = [&pts[0][..], &pts[1][..], &pts[2][..]];
    let curves = cal.response.curves();
    let name = path.display();
    match crate::io::extension(path).as_str() {
        "png" => plot::response_curves_png(curves, samples, (1000, 750))
            .with_context(|| name.to_string()),
        "svg" => Ok(plot::response_curves_svg(curves, samples, (800, 600))
            .with_context(|| name.to_string())?
            .into_bytes()),
        e => bail!("{name}: cannot write a plot as '.{e}'; use .png or .svg"),
    }
}

/// Tone-maps `img` and encodes it for `path`: `.jpg`/`.jpeg` (8-bit, quality 92), `.png`
/// (8-bit, or 16-bit when `sixteen`).
pub fn preview(path: &Path, img: &HdrImage, tm: &ToneMap, sixteen: bool) -> Result<Vec<u8>> {
    let name = path.display();
    let ext = crate::io::extension(path);
    if !matches!(ext.as_str(), "jpg" | "jpeg" | "png") {
        bail!("{name}: cannot write a preview as '.{ext}'; use .jpg or .png");
    }
    if sixteen {
        if ext != "png" {
            bail!("{name}: 16-bit output needs a .png file");
        }
        let t = tonemap::tonemap_u16(img, tm).with_context(|| name.to_string())?;
        return plot::encode_png_rgb16(&t).with_context(|| name.to_string());
    }
    let t = tonemap::tonemap_u8(img, tm).with_context(|| name.to_string())?;
    encode_rgb8(path, &t)
}

/// Encodes an 8-bit RGB image as JPEG or PNG by the path's extension.
pub fn encode_rgb8(path: &Path, img: &RgbImage<u8>) -> Result<Vec<u8>> {
    let name = path.display();
    let ext = crate::io::extension(path);
    let Some(format) = PictureFormat::from_extension(&ext) else {
        bail!("{name}: cannot write '.{ext}' images; use .jpg or .png");
    };
    picture::encode_rgb8(img, format).with_context(|| name.to_string())
}
