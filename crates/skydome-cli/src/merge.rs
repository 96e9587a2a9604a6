//! `skydome merge`: a bracket in, a radiance map (and optionally EXR, preview, maps) out.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;
use skydome::formats::HdrMeta;
use skydome::merge::{self, MergeOptions};
use skydome::response::{self, CameraProfile, Weighting};

use crate::calibrate::CalibArgs;
use crate::io::{self, BracketArgs, Outputs};

/// Arguments of `skydome merge`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The bracket: 2 or more photos of one still scene at different exposures.
    #[arg(required = true, num_args = 1..)]
    pub images: Vec<PathBuf>,
    /// The radiance map to write (.hdr Radiance RGBE, or .exr).
    #[arg(short, long)]
    pub output: PathBuf,
    /// A camera profile from `skydome calibrate`; without one, the bracket calibrates itself.
    #[arg(long, value_name = "camera.json")]
    pub profile: Option<PathBuf>,
    /// Also write an OpenEXR file.
    #[arg(long, value_name = "FILE.exr")]
    pub exr: Option<PathBuf>,
    /// Write EXR channels as 32-bit float instead of half.
    #[arg(long)]
    pub exr_float: bool,
    /// Also write a tone-mapped preview (.jpg or .png).
    #[arg(long, value_name = "FILE")]
    pub preview: Option<PathBuf>,
    /// Also write the per-pixel confidence as a grey PNG (black = no frame well exposed).
    #[arg(long, value_name = "FILE.png")]
    pub confidence: Option<PathBuf>,
    /// Frame weighting: `hat` (robust, default) or `none` (the seed's unweighted eq. 4).
    #[arg(long, value_enum, default_value_t = WeightingArg::Hat)]
    pub weighting: WeightingArg,
    #[command(flatten)]
    pub bracket: BracketArgs,
    #[command(flatten)]
    pub calib: CalibArgs,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
}

/// Merge weighting on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WeightingArg {
    /// Hat weight, zero at 0 and 255; clipped pixels keep the shortest exposure.
    Hat,
    /// Unweighted mean (the seed's eq. 4).
    None,
}

#[derive(Serialize)]
struct Summary {
    width: usize,
    height: usize,
    frames: Vec<FrameSummary>,
    response: String,
    sampling: Option<skydome::sampling::SampleReport>,
    clipped_high_pixels: usize,
    clipped_low_pixels: usize,
    meta: HdrMeta,
    written: Vec<String>,
}

#[derive(Serialize)]
struct FrameSummary {
    file: String,
    time_s: f64,
    iso: Option<f64>,
    f_number: Option<f64>,
    relative_exposure: f64,
}

/// The top-level entry point for `skydome merge`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    let outs: Vec<&PathBuf> = [
        Some(&a.output),
        a.exr.as_ref(),
        a.preview.as_ref(),
        a.confidence.as_ref(),
    ]
    .into_iter()
    .flatten()
    .collect();
    for o in &outs {
        io::check_destination(o, &a.images, a.force)?;
    }
    let profile = match &a.profile {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("{}: cannot read", p.display()))?;
            Some(CameraProfile::from_json(&text).with_context(|| p.display().to_string())?)
        }
        None => None,
    };
    let br = io::load_bracket(&a.images, &a.bracket, quiet)?;

    let mut sampling = None;
    let (resp, response_from) = match &profile {
        Some(p) => (
            p.response().with_context(|| {
                format!(
                    "{}",
                    a.profile
                        .as_ref()
                        .map_or(String::new(), |p| p.display().to_string())
                )
            })?,
            format!(
                "profile {}",
                a.profile
                    .as_ref()
                    .map_or(String::new(), |p| p.display().to_string())
            ),
        ),
        None => {
            let spin = io::spinner(quiet, "calibrating");
            let cal = response::calibrate(&br.frames, a.calib.circle, &a.calib.options())
                .context("calibration failed")?;
            spin.finish_and_clear();
            sampling = Some(cal.report().clone());
            (cal.response, "calibrated on this bracket".to_string())
        }
    };

    let spin = io::spinner(quiet, "merging");
    let merged = merge::merge(
        &br.frames,
        &resp,
        &MergeOptions {
            weighting: match a.weighting {
                WeightingArg::Hat => Weighting::Hat,
                WeightingArg::None => Weighting::None,
            },
            confidence: true,
            clipped_mask: false,
        },
    )
    .context("merge failed")?;
    spin.finish_and_clear();
    if merged.clipped_high > 0 {
        io::warn(
            quiet,
            &format!(
                "{} pixels are clipped even in the shortest exposure; their radiance is a lower bound",
                merged.clipped_high
            ),
        );
    }

    let (capdate, gmt) = br.info.header_times();
    let meta = HdrMeta {
        capdate,
        gmt,
        ..HdrMeta::default()
    };
    let image = merged.radiance;

    let spin = io::spinner(quiet, "encoding");
    let mut outputs = Outputs::default();
    outputs.add(
        &a.output,
        crate::radiance::encode(&a.output, &image, &meta, a.exr_float)?,
    );
    if let Some(p) = &a.exr {
        outputs.add(p, crate::radiance::encode(p, &image, &meta, a.exr_float)?);
    }
    if let Some(p) = &a.preview {
        outputs.add(
            p,
            crate::pictures::preview(p, &image, &crate::pictures::default_tonemap(None), false)?,
        );
    }
    if let (Some(p), Some(c)) = (&a.confidence, &merged.confidence) {
        outputs.add(
            p,
            crate::pictures::grey_png(p, image.width, image.height, c)?,
        );
    }
    spin.finish_and_clear();
    let written = outputs.commit(&a.images, a.force)?;

    let summary = Summary {
        width: image.width,
        height: image.height,
        frames: br
            .frames
            .iter()
            .map(|f| FrameSummary {
                file: f.name.clone(),
                time_s: f.exposure.time_s,
                iso: f.exposure.iso,
                f_number: f.exposure.f_number,
                relative_exposure: f.exposure.relative(),
            })
            .collect(),
        response: response_from,
        sampling,
        clipped_high_pixels: merged.clipped_high,
        clipped_low_pixels: merged.clipped_low,
        meta,
        written: written.iter().map(|p| p.display().to_string()).collect(),
    };
    if a.json {
        crate::out(&serde_json::to_string_pretty(&summary)?);
    } else if !quiet {
        let times: Vec<String> = summary
            .frames
            .iter()
            .map(|f| format_time(f.time_s))
            .collect();
        crate::out(&format!(
            "merged {} frames ({}) {}x{}, response {}",
            summary.frames.len(),
            times.join(", "),
            summary.width,
            summary.height,
            summary.response
        ));
        for w in &summary.written {
            crate::out(&format!("wrote {w}"));
        }
    }
    Ok(())
}

/// Formats a shutter time the way cameras show it (`1/400 s`, `2 s`).
pub fn format_time(t: f64) -> String {
    if t < 1.0 {
        format!("1/{:.0} s", 1.0 / t)
    } else {
        format!("{t} s")
    }
}
