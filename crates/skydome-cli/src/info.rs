//! `skydome info FILE`: header, size and statistics of a radiance map.

use std::path::PathBuf;

use anyhow::Result;
use serde::Serialize;
use skydome::image::luminance;

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
    /// log2(p99.9 / p0.1) of positive luminance, in stops (robust to single pixels).
    dynamic_range_stops_robust: Option<f64>,
}

/// The top-level entry point for `skydome info`.
pub fn run(a: Args) -> Result<()> {
    let r = crate::radiance::read(&a.file)?;
    let img = &r.image;
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    let mut sum = [0f64; 3];
    let mut invalid = 0;
    let mut lum = Vec::with_capacity(img.pixel_count());
    let mut zero = 0;
    for p in img.pixels() {
        if p.iter().any(|v| !v.is_finite() || *v < 0.0) {
            invalid += 1;
            continue;
        }
        for c in 0..3 {
            min[c] = min[c].min(p[c]);
            max[c] = max[c].max(p[c]);
            sum[c] += f64::from(p[c]);
        }
        let l = luminance(p);
        if l > 0.0 {
            lum.push(l);
        } else {
            zero += 1;
        }
    }
    let valid = (img.pixel_count() - invalid).max(1) as f64;
    lum.sort_unstable_by(f32::total_cmp);
    let q = |f: f64| lum[((lum.len() - 1) as f64 * f).round() as usize];
    let (dr, dr_robust) = if lum.is_empty() {
        (None, None)
    } else {
        (
            Some(f64::from(q(1.0) / q(0.0)).log2()),
            Some(f64::from(q(0.999) / q(0.001)).log2()),
        )
    };
    let info = Info {
        file: a.file.display().to_string(),
        format: r.format,
        width: img.width,
        height: img.height,
        header: r.header,
        meta: r.meta,
        min,
        max,
        mean: sum.map(|s| s / valid),
        invalid_pixels: invalid,
        zero_pixels: zero,
        dynamic_range_stops: dr,
        dynamic_range_stops_robust: dr_robust,
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
    if invalid > 0 {
        s += &format!("{invalid} pixels are NaN, infinite or negative\n");
    }
    crate::out(s.trim_end());
    Ok(())
}
