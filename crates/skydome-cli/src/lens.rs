//! `skydome lens detect|fit`: the fish-eye image circle and the lens projection.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use skydome::fisheye::{self, AngleRadius, LensKind, LensProfile};
use skydome::image::Circle;
use skydome::overlay::OverlayMarks;

use crate::io::{self, BracketArgs, Outputs};

/// Arguments of `skydome lens`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: LensCommand,
}

/// `lens` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum LensCommand {
    /// Find the centre and radius of the lens's visible circle in a photo (or bracket).
    Detect(DetectArgs),
    /// Fit the lens projection and write a lens profile (JSON).
    Fit(FitArgs),
}

/// Arguments of `skydome lens detect`.
#[derive(Debug, clap::Args)]
pub struct DetectArgs {
    /// One photo, or a bracket (the best-exposed frame is used).
    #[arg(required = true, num_args = 1..)]
    pub images: Vec<PathBuf>,
    #[command(flatten)]
    pub bracket: BracketArgs,
    /// Draw the visible circle and the 180° horizon (for --model/--fov) on the photo (.png/.jpg).
    #[arg(long, value_name = "FILE")]
    pub overlay: Option<PathBuf>,
    /// Lens projection used to place the 180° horizon on the overlay.
    #[arg(long, value_parser = crate::geometry::parse_kind, default_value = "stereographic")]
    pub model: LensKind,
    /// Field of view of the lens across the visible circle, degrees.
    #[arg(long, default_value_t = 235.0)]
    pub fov: f64,
    /// Also write a lens profile from the circle, --model and --fov.
    #[arg(short, long, value_name = "lens.json")]
    pub output: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `skydome lens fit`.
#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Measured pairs, CSV lines `angle_deg,radius_px` (the seed's transparent-box procedure).
    #[arg(long, value_name = "pairs.csv", conflicts_with = "circle")]
    pub csv: Option<PathBuf>,
    /// Optical centre (CX,CY) for --csv, or the visible circle (CX,CY,R) for a fit from --fov.
    #[arg(long, value_name = "CX,CY[,R]")]
    pub centre: Option<String>,
    /// The visible circle CX,CY,R (e.g. from `lens detect`): the profile comes from --fov and --model.
    #[arg(long, value_parser = crate::calibrate::parse_circle, value_name = "CX,CY,R")]
    pub circle: Option<Circle>,
    /// Full field of view across the visible circle, degrees.
    #[arg(long, default_value_t = 235.0)]
    pub fov: f64,
    /// Projection: auto (best AICc, with --csv), equidistant, equisolid, stereographic,
    /// orthographic or polynomial.
    #[arg(long, default_value = "auto")]
    pub model: String,
    /// Vignetting measurements, CSV lines `angle_deg,relative_value` (1 on the axis): the
    /// fitted fall-off V(θ) goes into the profile and the merge divides it out.
    #[arg(long, value_name = "falloff.csv")]
    pub vignetting: Option<PathBuf>,
    /// Flat-field photos (a uniform target through the lens; repeat the flag for several):
    /// the fall-off V(θ) is measured from them instead of a CSV. Needs --camera to linearise
    /// the codes.
    #[arg(
        long,
        value_name = "photo",
        conflicts_with = "vignetting",
        requires = "camera"
    )]
    pub flat_field: Vec<PathBuf>,
    /// The camera profile (from `skydome calibrate`) that linearises --flat-field photos.
    #[arg(long, value_name = "camera.json")]
    pub camera: Option<PathBuf>,
    /// The lens profile to write.
    #[arg(short, long, value_name = "lens.json")]
    pub output: PathBuf,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
}

/// The top-level entry point for `skydome lens`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    match a.command {
        LensCommand::Detect(d) => detect(d),
        LensCommand::Fit(f) => fit(f, quiet),
    }
}

#[derive(Serialize)]
struct DetectReport {
    circle: Circle,
    residual_px: f64,
    boundary_points: usize,
    candidates: usize,
    horizon: Option<Circle>,
    crop_ratio: Option<f64>,
    written: Vec<String>,
}

fn detect(a: DetectArgs) -> Result<()> {
    for o in [a.overlay.as_ref(), a.output.as_ref()]
        .into_iter()
        .flatten()
    {
        io::check_destination(o, &a.images, a.force)?;
    }
    let input = a.bracket.input(&a.images)?;
    let (fit, photo) = skydome::pipeline::detect_lens_circle(input).map_err(io::hint)?;
    let profile = LensProfile::from_fov(fit.circle, a.fov, a.model).context("lens model")?;
    let horizon = profile
        .radius_at_deg(90.0)
        .ok()
        .map(|r| Circle { r, ..fit.circle });
    let mut out = Outputs::default();
    if let Some(p) = &a.overlay {
        let mut rgb = photo.clone();
        skydome::overlay::draw_overlay(
            &mut rgb,
            &OverlayMarks {
                visible: Some(fit.circle),
                horizon,
                north: None,
                sun: None,
            },
        );
        out.add(p, crate::pictures::encode_rgb8(p, &rgb)?);
    }
    if let Some(p) = &a.output {
        out.add(p, profile.to_json().context("lens profile")?.into_bytes());
    }
    let written = out.commit(&a.images, a.force)?;
    let r = DetectReport {
        circle: fit.circle,
        residual_px: fit.residual_px,
        boundary_points: fit.points,
        candidates: fit.candidates,
        horizon,
        crop_ratio: horizon.map(|h| h.r / fit.circle.r),
        written: written.iter().map(|p| p.display().to_string()).collect(),
    };
    if a.json {
        crate::out(&serde_json::to_string_pretty(&r)?);
    } else {
        crate::out(&format!(
            "circle centre ({:.2}, {:.2}) radius {:.2} px, fit residual {:.2} px RMS over {} of {} boundary points",
            r.circle.cx, r.circle.cy, r.circle.r, r.residual_px, r.boundary_points, r.candidates
        ));
        if let (Some(h), Some(q)) = (r.horizon, r.crop_ratio) {
            crate::out(&format!(
                "180° horizon ({} {:.0}° lens): radius {:.2} px = {:.3} of the visible circle",
                a.model, a.fov, h.r, q
            ));
        }
        for w in &r.written {
            crate::out(&format!("wrote {w}"));
        }
    }
    Ok(())
}

fn read_pairs(p: &PathBuf) -> Result<Vec<AngleRadius>> {
    let name = p.display().to_string();
    let text = std::fs::read_to_string(p).with_context(|| format!("{name}: cannot read"))?;
    fisheye::parse_angle_radius_csv(&text).with_context(|| name)
}

fn parse_centre(s: &str) -> Result<(f64, f64)> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--centre '{s}': expected CX,CY in pixels"))?;
    match v[..] {
        [x, y] | [x, y, _] if x.is_finite() && y.is_finite() => Ok((x, y)),
        _ => bail!("--centre '{s}': expected CX,CY in pixels"),
    }
}

/// The fall-off measured in flat-field photos, linearised with the camera profile.
fn flat_field(
    photos: &[PathBuf],
    camera: &std::path::Path,
    lens: &LensProfile,
) -> Result<Vec<(f64, f64)>> {
    let response = crate::merge::read_profile(camera)?
        .response()
        .with_context(|| camera.display().to_string())?;
    let frames = photos
        .iter()
        .map(|p| {
            // The library's decoding errors name the file.
            let name = p.display().to_string();
            Ok(skydome::bracket::decode(
                &name,
                &io::read(p)?,
                &Default::default(),
            )?)
        })
        .collect::<Result<Vec<_>>>()?;
    let names = photos
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    fisheye::flat_field_falloff(&frames, lens, &response).with_context(|| names)
}

fn fit(a: FitArgs, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, &[], a.force)?;
    let choice = match a.model.as_str() {
        "auto" => None,
        m => Some(crate::geometry::parse_kind(m).map_err(anyhow::Error::msg)?),
    };
    let profile = match (&a.csv, a.circle) {
        (Some(csv), None) => {
            let pairs = read_pairs(csv)?;
            let (cx, cy) = match &a.centre {
                Some(c) => parse_centre(c)?,
                None => bail!("--csv needs --centre CX,CY: the optical centre the radii were measured from"),
            };
            let fit = fisheye::fit_projection(&pairs, choice).with_context(|| csv.display().to_string())?;
            LensProfile::from_fit(cx, cy, a.fov, &fit).context("lens profile")?
        }
        (None, Some(c)) => {
            let kind = choice.unwrap_or(LensKind::Stereographic);
            LensProfile::from_fov(c, a.fov, kind).context("lens profile")?
        }
        _ => bail!("give --csv pairs.csv --centre CX,CY (measured angles), or --circle CX,CY,R with --fov (nominal lens)"),
    };
    let mut profile = profile;
    let falloff = match (&a.vignetting, a.camera.as_deref()) {
        (Some(csv), _) => {
            let pts: Vec<(f64, f64)> = read_pairs(csv)?
                .iter()
                .map(|p| (p.angle_deg, p.radius_px))
                .collect();
            Some((pts, csv.display().to_string()))
        }
        (None, Some(camera)) if !a.flat_field.is_empty() => Some((
            flat_field(&a.flat_field, camera, &profile)?,
            "flat field".into(),
        )),
        _ => None,
    };
    if let Some((pts, source)) = falloff {
        let v = fisheye::Vignetting::fit(&pts).with_context(|| source.clone())?;
        if !quiet && !a.json {
            let [v30, v60, v90] = v.at_30_60_90();
            crate::out(&format!(
                "vignetting: V(30°) = {v30:.3}, V(60°) = {v60:.3}, V(90°) = {v90:.3} (rms {:.4} over {} measurements)",
                v.rms, v.samples
            ));
        }
        profile.vignetting = Some(v);
    }
    let mut out = Outputs::default();
    out.add(
        &a.output,
        profile.to_json().context("lens profile")?.into_bytes(),
    );
    let written = out.commit(&[], a.force)?;
    if a.json {
        crate::out(&profile.to_json()?);
    } else if !quiet {
        for c in &profile.candidates {
            crate::out(&format!(
                "{:<14} rms {:8.3} px  max {:8.3} px  AICc {:10.2}",
                c.projection.kind().name(),
                c.rms_px,
                c.max_px,
                c.aicc
            ));
        }
        let r90 = profile.radius_at_deg(90.0).ok();
        crate::out(&format!(
            "chose {} ({:.0}° lens), circle ({:.2}, {:.2}) r {:.2} px{}",
            profile.projection.kind().name(),
            profile.fov_deg,
            profile.circle.cx,
            profile.circle.cy,
            profile.circle.r,
            r90.map_or(String::new(), |r| format!(
                ", 180° crop radius {r:.2} px = {:.3} of the circle",
                r / profile.circle.r
            ))
        ));
        for w in written {
            crate::out(&format!("wrote {}", w.display()));
        }
    }
    Ok(())
}
