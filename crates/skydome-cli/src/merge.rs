//! `skydome merge`: a bracket in, a radiance map (and optionally EXR, preview, maps) out.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;
use skydome::formats::HdrMeta;
use skydome::merge::{self, MergeOptions};
use skydome::response::{self, CameraProfile, Weighting};

use crate::calibrate::CalibArgs;
use crate::geometry::{self, GeometryArgs};
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
    #[command(flatten)]
    pub exr_args: crate::radiance::ExrArgs,
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
    #[command(flatten)]
    pub geometry: GeometryArgs,
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
    geometry: Option<geometry::GeometryReport>,
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
    .chain(a.geometry.outputs())
    .collect();
    a.geometry.check()?;
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

    let lens = match a.geometry.enabled() {
        true => Some(geometry::lens_profile(&a.geometry, &br, a.calib.circle)?),
        false => None,
    };
    // Calibration samples come from inside the lens circle when there is one.
    let circle = a.calib.circle.or(lens.as_ref().map(|l| l.0.circle));
    let mut sampling = None;
    let (resp, response_from) = match (&profile, &a.profile) {
        (Some(p), Some(path)) => (
            p.response().with_context(|| path.display().to_string())?,
            format!("profile {}", path.display()),
        ),
        _ => {
            let spin = io::spinner(quiet, "calibrating");
            let cal = response::calibrate(&br.frames, circle, &a.calib.options())
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
            confidence: a.confidence.is_some(),
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
    let mut meta = HdrMeta {
        capdate,
        gmt,
        ..HdrMeta::default()
    };
    let mut image = merged.radiance;
    let mut geo_report = None;
    let mut equirect = None;
    let mut marks = None;
    if let Some(lens) = lens {
        let orientation = match a.bracket.orientation {
            io::Orientation::Apply => 1,
            io::Orientation::Ignore => br.info.orientation,
        };
        let g = geometry::apply(&a.geometry, &br, lens, image, orientation)?;
        image = g.image;
        meta.sun = g.meta.sun;
        meta.north = g.meta.north;
        meta.view = g.meta.view;
        equirect = g.equirect;
        marks = Some(g.marks);
        if let Some(c) = &g.report.sun_cross_check {
            io::warn(
                quiet || c.angle_deg < 2.0,
                &format!(
                    "detected sun is {:.1}° from the computed one; a compass error of {:+.1}° would explain the azimuth",
                    c.angle_deg, c.compass_error_deg
                ),
            );
        }
        geo_report = Some(g.report);
    }

    let spin = io::spinner(quiet, "encoding");
    let mut outputs = Outputs::default();
    outputs.add(
        &a.output,
        crate::radiance::encode(&a.output, &image, &meta, &a.exr_args)?,
    );
    if let Some(p) = &a.exr {
        outputs.add(p, crate::radiance::encode(p, &image, &meta, &a.exr_args)?);
    }
    if let Some(p) = &a.preview {
        outputs.add(
            p,
            crate::pictures::preview(p, &image, &crate::pictures::default_tonemap(None), false)?,
        );
    }
    if let (Some(p), Some(c)) = (&a.confidence, &merged.confidence) {
        outputs.add(p, crate::pictures::grey_png(p, br.width(), br.height(), c)?);
    }
    if let (Some(p), Some(e)) = (&a.geometry.equirect, &equirect) {
        let m = HdrMeta {
            capdate: meta.capdate.clone(),
            gmt: meta.gmt.clone(),
            ..HdrMeta::default()
        };
        outputs.add(p, crate::radiance::encode(p, e, &m, &a.exr_args)?);
    }
    if let (Some(p), Some(m)) = (&a.geometry.overlay, &marks) {
        outputs.add(p, geometry::overlay_picture(p, &image, m)?);
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
        geometry: geo_report,
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
        if let Some(g) = &summary.geometry {
            crate::out(&format!(
                "lens {} {:.0}°, circle ({:.1}, {:.1}) r {:.1} px; horizon r {:.1} px in the output",
                g.lens.projection.kind(),
                g.lens.fov_deg,
                g.lens.circle.cx,
                g.lens.circle.cy,
                g.lens.circle.r,
                g.horizon.r
            ));
            match (&g.sun, g.sun_source) {
                (Some(s), Some(src)) => crate::out(&format!(
                    "sun ({src}) at ({:.1}, {:.1}){}",
                    s.pixel.x,
                    s.pixel.y,
                    match (s.azimuth_deg, s.elevation_deg) {
                        (Some(az), Some(el)) => format!(", azimuth {az:.2}°, elevation {el:.2}°"),
                        (None, Some(el)) =>
                            format!(", elevation {el:.2}° (give --north for its azimuth)"),
                        _ => String::new(),
                    }
                )),
                _ => crate::out("sun: none"),
            }
            if let Some(n) = g.north {
                crate::out(&format!("north point at ({:.1}, {:.1})", n.x, n.y));
            }
        }
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
