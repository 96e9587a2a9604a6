//! `skydome tonemap IN.hdr -o OUT.jpg`: a displayable picture of a radiance map.

use std::path::PathBuf;

use anyhow::Result;
use skydome::tonemap::{ExposureMode, Operator, ToneMap};

use crate::io::{self, Outputs};

/// Arguments of `skydome tonemap`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A Radiance .hdr or OpenEXR .exr file.
    pub input: PathBuf,
    /// The picture to write (.jpg or .png).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Operator: aces (default), reinhard, drago, linear, minmax (the seed's).
    #[arg(long, default_value = "aces", value_parser = parse_op)]
    pub op: Operator,
    /// Exposure in stops instead of the automatic one (a radiance of 2^-EV maps to 1).
    #[arg(long, allow_hyphen_values = true)]
    pub exposure: Option<f64>,
    /// Key (target display value of the log-average luminance) for automatic exposure.
    #[arg(long, default_value_t = 0.18)]
    pub key: f64,
    /// Percentile of luminance used as the white point (reinhard) or Lmax (drago).
    #[arg(long, default_value_t = 99.5)]
    pub white_percentile: f64,
    /// Drago's bias.
    #[arg(long, default_value_t = 0.85)]
    pub bias: f64,
    /// Black outside this circle (CX,CY,R in pixels).
    #[arg(long, value_parser = crate::calibrate::parse_circle, value_name = "CX,CY,R")]
    pub circle: Option<skydome::image::Circle>,
    /// Expose for the whole frame, not for the sky inside a detected fish-eye image circle.
    #[arg(long)]
    pub whole_frame: bool,
    /// Write a 16-bit PNG.
    #[arg(long)]
    pub sixteen: bool,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

fn parse_op(s: &str) -> Result<Operator, String> {
    s.parse::<Operator>().map_err(|e| e.to_string())
}

/// The top-level entry point for `skydome tonemap`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, std::slice::from_ref(&a.input), a.force)?;
    let r = crate::radiance::read(&a.input)?;
    let tm = ToneMap {
        operator: a.op,
        exposure: a.exposure.map_or(ExposureMode::Auto, ExposureMode::Ev),
        key: a.key,
        white_percentile: a.white_percentile,
        drago_bias: a.bias,
        mask: a.circle,
        auto_mask: !a.whole_frame,
        ..ToneMap::default()
    };
    let mut out = Outputs::default();
    out.add(
        &a.output,
        crate::pictures::preview(&a.output, &r.image, &tm, a.sixteen)?,
    );
    for p in out.commit(std::slice::from_ref(&a.input), a.force)? {
        if !quiet {
            crate::out(&format!("wrote {}", p.display()));
        }
    }
    Ok(())
}
