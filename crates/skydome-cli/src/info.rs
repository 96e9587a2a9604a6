//! `skydome info FILE`: header, size and statistics of a radiance map.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;
use skydome::tonemap::radiance_stats;

/// Arguments of `skydome info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A Radiance .hdr or OpenEXR .exr file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
struct Info {
    file: String,
    format: &'static str,
    width: usize,
    height: usize,
    header: Vec<String>,
    meta: skydome::formats::HdrMeta,
    /// Per-channel minimum, maximum and mean of the radiance (after EXPOSURE).
    min: [f32; 3],
    max: [f32; 3],
    mean: [f64; 3],
    /// Pixels with a non-finite or negative value.
    invalid_pixels: usize,
    /// Pixels with zero luminance.
    zero_pixels: usize,
    /// log2(max / min) of positive luminance, in stops.
    dynamic_range_stops: Option<f64>,
    /// log2(p99.9 / p0.1) of positive luminance, in stops (robust to single pixels; percentiles
    /// resolved to 1/32 stop).
    dynamic_range_stops_robust: Option<f64>,
    /// True when the header marks the values absolute (`#UNITS= absolute`, Radiance's
    /// W·sr⁻¹·m⁻²).
    absolute: bool,
    /// Luminance `179 × (0.265 R + 0.670 G + 0.065 B)` of the pixels, cd/m² when `absolute`.
    luminance: Option<skydome::photometry::LuminanceSummary>,
    /// For an upward fish-eye (`VIEW=` with `-vd 0 0 1`): the horizontal illuminance of the
    /// hemisphere, lux when `absolute` (what `evalglare -V` reports).
    horizontal_illuminance: Option<f64>,
}

/// The top-level entry point for `skydome info`.
pub fn run(a: Args) -> Result<()> {
    let r = crate::radiance::read(&a.file)?;
    let img = &r.image;
    // One parallel pass in the library: the same statistics the tone mapper exposes with.
    let st = radiance_stats(img).with_context(|| a.file.display().to_string())?;
    let (min, max) = (st.min, st.max);
    let lum = &st.luminance;
    let (dr, dr_robust) = if lum.count == 0 {
        (None, None)
    } else {
        (
            Some(lum.dynamic_range_stops()),
            Some(lum.robust_range_stops(0.1, 99.9)),
        )
    };
    let invalid = st.invalid_pixels as usize;
    let absolute = r.meta.is_absolute();
    let luminance = skydome::photometry::luminance_summary(img);
    let horizontal_illuminance = r
        .meta
        .view
        .as_deref()
        .and_then(|v| skydome::sky::SkyGeometry::from_radiance_view(v, img.width, img.height))
        .map(|g| {
            skydome::image::radiance_luminance(skydome::reproject::horizontal_irradiance_fisheye(
                img, &g,
            ))
        });
    let info = Info {
        file: a.file.display().to_string(),
        format: r.format,
        width: img.width,
        height: img.height,
        header: r.header,
        meta: r.meta,
        min,
        max,
        mean: st.mean,
        invalid_pixels: invalid,
        zero_pixels: lum.zero_count as usize,
        dynamic_range_stops: dr,
        dynamic_range_stops_robust: dr_robust,
        absolute,
        luminance,
        horizontal_illuminance,
    };
    if a.json {
        crate::out(&serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    let mut s = format!(
        "{}: {} {}x{}\n",
        info.file, info.format, info.width, info.height
    );
    for h in &info.header {
        s += &format!("  {h}\n");
    }
    s += &format!(
        "min  {:.6e} {:.6e} {:.6e}\nmax  {:.6e} {:.6e} {:.6e}\nmean {:.6e} {:.6e} {:.6e}\n",
        min[0], min[1], min[2], max[0], max[1], max[2], info.mean[0], info.mean[1], info.mean[2]
    );
    match (dr, dr_robust) {
        (Some(d), Some(r)) => {
            s += &format!("dynamic range {d:.1} stops (robust, 0.1–99.9 %: {r:.1} stops)\n")
        }
        _ => s += "dynamic range: no pixel with positive luminance\n",
    }
    if let Some(l) = &info.luminance {
        let unit = if absolute { "cd/m²" } else { "relative" };
        s += &format!(
            "luminance ({unit}): median {:.4e}, p99 {:.4e}, max {:.4e}, mean {:.4e}\n",
            l.median, l.p99, l.max, l.mean
        );
    }
    if let Some(e) = info.horizontal_illuminance {
        let unit = if absolute { "lx" } else { "(relative)" };
        s += &format!("horizontal illuminance of the upward view: {e:.4e} {unit}\n");
    }
    if invalid > 0 {
        s += &format!("{invalid} pixels are NaN, infinite or negative\n");
    }
    crate::out(s.trim_end());
    Ok(())
}
