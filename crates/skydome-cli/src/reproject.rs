//! `skydome reproject IN.hdr --to equirect|angular|mirrorball|fisheye`: maps renderers use.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use skydome::fisheye::{self, LensKind, LensProfile};
use skydome::pipeline;
use skydome::reproject::{self, Ground, MapProjection, ReprojectOptions};
use skydome::sky::{DevicePose, ImageOrientation, SkyGeometry};

use crate::io::{self, Outputs};

/// Arguments of `skydome reproject`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A fish-eye radiance map (.hdr or .exr), e.g. from `skydome merge`.
    pub input: PathBuf,
    /// The map to write (.hdr or .exr).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Target map.
    #[arg(long, value_enum, default_value_t = Target::Equirect)]
    pub to: Target,
    /// The lens profile of the input. For a dome written by `merge --crop`, use `--dome` instead.
    #[arg(long, value_name = "lens.json")]
    pub lens: Option<PathBuf>,
    /// The input is a 180° dome from `merge --crop`: its circle is the horizon; give its model.
    #[arg(long, value_parser = crate::geometry::parse_kind, value_name = "MODEL")]
    pub dome: Option<LensKind>,
    /// Compass azimuth of the phone's top edge, degrees (as given to merge).
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0)]
    pub north: f64,
    /// How the phone lay.
    #[arg(long, default_value = "screen-down", value_parser = crate::geometry::parse_pose)]
    pub device_pose: DevicePose,
    /// Output width (equirect) or side (other maps) in pixels.
    #[arg(long, default_value_t = 1024)]
    pub size: usize,
    /// Azimuth at the centre of the map, degrees (90 = east: Blender's +X east, +Y north).
    #[arg(long, allow_hyphen_values = true, default_value_t = 90.0)]
    pub centre_azimuth: f64,
    #[command(flatten)]
    pub exr: crate::radiance::ExrArgs,
    /// Lower hemisphere: black, mirror, or a constant R,G,B radiance.
    #[arg(long, default_value = "black", value_parser = crate::geometry::parse_ground)]
    pub ground: Ground,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

/// Target maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Target {
    /// Equirectangular lat-long, 2:1.
    Equirect,
    /// Angular map (light probe).
    Angular,
    /// Mirror ball.
    Mirrorball,
    /// Upward equidistant 180° fish-eye, north up, east left.
    Fisheye,
}

/// The top-level entry point for `skydome reproject`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, std::slice::from_ref(&a.input), a.force)?;
    let r = crate::radiance::read(&a.input)?;
    let lens = lens(&a, &r.image)?;
    let geom = SkyGeometry::new(&lens, a.north, a.device_pose, ImageOrientation::Normal)
        .context("sky geometry")?;
    let target = target(&a);
    let spin = io::spinner(quiet, "reprojecting");
    let map = reproject::reproject(
        &r.image,
        &geom,
        &target,
        &ReprojectOptions {
            ground: a.ground,
            ..ReprojectOptions::default()
        },
    )
    .with_context(|| a.input.display().to_string())?;
    spin.finish_and_clear();
    let e_in = reproject::horizontal_irradiance_fisheye(&r.image, &geom);
    let mut meta = pipeline::equirect_meta(&r.meta);
    if let MapProjection::Fisheye { model, fov_deg, .. } = target {
        meta.view = fisheye::radiance_view(model, fov_deg);
    }
    let mut out = Outputs::default();
    out.add(
        &a.output,
        crate::radiance::encode(&a.output, &map, &meta, &a.exr)?,
    );
    for p in out.commit(std::slice::from_ref(&a.input), a.force)? {
        if !quiet {
            let lum = |e: [f64; 3]| 0.2126 * e[0] + 0.7152 * e[1] + 0.0722 * e[2];
            let extra = if a.to == Target::Equirect {
                let e_out = reproject::horizontal_irradiance_equirect(&map);
                format!(
                    "; horizontal irradiance {:.4e} in, {:.4e} out ({:+.2} %)",
                    lum(e_in),
                    lum(e_out),
                    100.0 * (lum(e_out) / lum(e_in) - 1.0)
                )
            } else {
                String::new()
            };
            crate::out(&format!(
                "wrote {} ({}x{}){extra}",
                p.display(),
                map.width,
                map.height
            ));
        }
    }
    Ok(())
}

/// The input's lens: a profile file, or a 180° dome whose horizon is inscribed in the image.
fn lens(a: &Args, img: &skydome::HdrImage) -> Result<LensProfile> {
    Ok(match (&a.lens, a.dome) {
        (Some(p), None) => crate::geometry::read_lens(p)?,
        (None, Some(kind)) => {
            // A cropped dome is square with the horizon circle inscribed.
            let c = skydome::image::Circle {
                cx: img.width as f64 / 2.0,
                cy: img.height as f64 / 2.0,
                r: img.width.min(img.height) as f64 / 2.0,
            };
            LensProfile::from_fov(c, 180.0, kind).context("dome lens")?
        }
        _ => bail!("give either --lens lens.json (an uncropped photo) or --dome MODEL (a 180° dome from merge --crop)"),
    })
}

/// The output map.
fn target(a: &Args) -> MapProjection {
    match a.to {
        Target::Equirect => MapProjection::Equirect {
            width: a.size,
            centre_azimuth_deg: a.centre_azimuth,
        },
        Target::Angular => MapProjection::Angular {
            size: a.size,
            centre_azimuth_deg: a.centre_azimuth,
        },
        Target::Mirrorball => MapProjection::MirrorBall {
            size: a.size,
            centre_azimuth_deg: a.centre_azimuth,
        },
        Target::Fisheye => MapProjection::Fisheye {
            size: a.size,
            model: LensKind::Equidistant,
            fov_deg: 180.0,
        },
    }
}
