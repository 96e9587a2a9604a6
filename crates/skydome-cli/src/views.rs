//! Pictures of a radiance map: `falsecolor`, `histogram`, `render` (lit spheres).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use skydome::image::Circle;
use skydome::plot::{self, FalseColour};
use skydome::render::{self, SphereScene};
use skydome::tonemap::ToneMap;

use crate::io::{self, Outputs};

/// Arguments of `skydome falsecolor`.
#[derive(Debug, clap::Args)]
pub struct FalsecolorArgs {
    /// A radiance map (.hdr or .exr).
    pub input: PathBuf,
    /// The PNG to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Absolute calibration: cd/m² per unit of the file's luminance (labels the bar in cd/m²).
    /// Default: 179 for a file marked `#UNITS= absolute` (Radiance's luminous efficacy, as
    /// `merge --luminance/--illuminance` writes), else relative units.
    #[arg(long)]
    pub scale: Option<f64>,
    /// Colour-bar range LOW,HIGH in the bar's units (default: 1st–99.9th percentiles).
    #[arg(long, value_name = "LOW,HIGH")]
    pub range: Option<String>,
    /// Only inside this circle (CX,CY,R in pixels).
    #[arg(long, value_parser = crate::calibrate::parse_circle, value_name = "CX,CY,R")]
    pub circle: Option<Circle>,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `skydome histogram`.
#[derive(Debug, clap::Args)]
pub struct HistogramArgs {
    /// A radiance map (.hdr or .exr).
    pub input: PathBuf,
    /// The PNG to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Only inside this circle (CX,CY,R in pixels).
    #[arg(long, value_parser = crate::calibrate::parse_circle, value_name = "CX,CY,R")]
    pub circle: Option<Circle>,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `skydome render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// An equirectangular (lat-long) radiance map as `merge --equirect` writes it
    /// (east at the centre, north at a quarter of the width).
    pub input: PathBuf,
    /// The picture to write (.png or .jpg).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Direction the camera looks, degrees from north towards east.
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0)]
    pub view_azimuth: f64,
    /// Picture width in pixels (height is half).
    #[arg(long, default_value_t = 640)]
    pub width: usize,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

fn write_one(output: &Path, input: &Path, bytes: Vec<u8>, force: bool, quiet: bool) -> Result<()> {
    let mut out = Outputs::default();
    out.add(output, bytes);
    for p in out.commit(&[input.to_path_buf()], force)? {
        if !quiet {
            crate::out(&format!("wrote {}", p.display()));
        }
    }
    Ok(())
}

/// The top-level entry point for `skydome falsecolor`.
pub fn falsecolor(a: FalsecolorArgs, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, std::slice::from_ref(&a.input), a.force)?;
    let range = match &a.range {
        Some(r) => match r
            .split_once(',')
            .map(|(l, h)| (l.trim().parse::<f64>(), h.trim().parse::<f64>()))
        {
            Some((Ok(l), Ok(h))) if l > 0.0 && h > l && h.is_finite() => Some((l, h)),
            _ => bail!("--range '{r}': expected LOW,HIGH with 0 < LOW < HIGH"),
        },
        None => None,
    };
    let file = crate::radiance::read(&a.input)?;
    let absolute = file
        .meta
        .is_absolute()
        .then_some(skydome::image::RADIANCE_EFFICACY);
    let img = file.image;
    let fc = plot::false_colour(
        &img,
        &FalseColour {
            mask: a.circle,
            scale: a.scale.or(absolute),
            range,
            ..FalseColour::default()
        },
    )
    .with_context(|| a.input.display().to_string())?;
    let bytes = crate::pictures::encode_rgb8(&a.output, &fc)?;
    write_one(&a.output, &a.input, bytes, a.force, quiet)
}

/// The top-level entry point for `skydome histogram`.
pub fn histogram(a: HistogramArgs, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, std::slice::from_ref(&a.input), a.force)?;
    if crate::io::extension(&a.output) != "png" {
        bail!("{}: the histogram is written as .png", a.output.display());
    }
    let img = crate::radiance::read(&a.input)?.image;
    let bytes = plot::log_luminance_histogram_png(&img, a.circle.as_ref(), (900, 500))
        .with_context(|| a.input.display().to_string())?;
    write_one(&a.output, &a.input, bytes, a.force, quiet)
}

/// The top-level entry point for `skydome render`.
pub fn render(a: RenderArgs, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, std::slice::from_ref(&a.input), a.force)?;
    let env = crate::radiance::read(&a.input)?.image;
    let scene = SphereScene {
        width: a.width,
        height: a.width / 2,
        view_azimuth_deg: a.view_azimuth,
        ..SphereScene::default()
    };
    let spin = io::spinner(quiet, "rendering");
    let rgb = render::render_spheres(&env, &scene, &ToneMap::default())
        .with_context(|| a.input.display().to_string())?;
    spin.finish_and_clear();
    let bytes = crate::pictures::encode_rgb8(&a.output, &rgb)?;
    write_one(&a.output, &a.input, bytes, a.force, quiet)
}
