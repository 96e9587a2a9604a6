//! `skydome merge`: a bracket in, a radiance map (and optionally EXR, preview, maps) out.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;
use skydome::camera::CameraProfile;
use skydome::exposures::ExposureSource;
use skydome::image::PixelPoint;
use skydome::merge::Weighting;
use skydome::photometry::{Reference, SpotLuminance};
use skydome::pipeline::{
    self, AbsoluteMode, Dome, Options, Products, Report, ResponseSource, SkyOptions,
};

use crate::calibrate::CalibArgs;
use crate::geometry::{GeometryArgs, MapOutputs};
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
    /// Write the camera profile: the response calibrated on this bracket (or the --profile
    /// given) and, when --illuminance, --luminance or --absolute exif made the dome absolute,
    /// the camera's absolute constant, so that every later merge with this profile and EXIF
    /// time, ISO and f-number is absolute without a meter.
    #[arg(long, value_name = "camera.json")]
    pub save_profile: Option<PathBuf>,
    /// Also write an OpenEXR file.
    #[arg(long, value_name = "FILE.exr")]
    pub exr: Option<PathBuf>,
    #[command(flatten)]
    pub exr_args: crate::radiance::ExrArgs,
    /// Also write a tone-mapped preview (.jpg or .png).
    #[arg(long, value_name = "FILE")]
    pub preview: Option<PathBuf>,
    /// Also write the per-pixel standard error of the radiance in stops, from the noise
    /// model: `.exr` writes the float map (per channel; +inf where the bracket did not
    /// measure), `.png`/`.jpg` a false-colour picture with its scale bar (magenta = not
    /// measured). In the input photos' pixels.
    #[arg(long, value_name = "FILE.png|FILE.exr")]
    pub confidence: Option<PathBuf>,
    /// A spot-meter reading that makes the radiance absolute: the luminance in cd/m² of the
    /// patch around pixel X,Y of the input photos (origin top-left).
    #[arg(long, value_name = "X,Y=CD", value_parser = parse_spot)]
    pub luminance: Option<(f64, f64, f64)>,
    /// Radius in pixels of the patch --luminance averages.
    #[arg(long, default_value_t = 3.0, value_name = "PX")]
    pub luminance_radius: f64,
    /// Horizontal illuminance in lux measured beside the camera: makes the radiance absolute
    /// (with --luminance too, the disagreement is reported). Needs a fish-eye lens.
    #[arg(long, value_name = "LUX")]
    pub illuminance: Option<f64>,
    /// Write where frames disagree beyond their noise as a PNG (white = disagree); the
    /// fraction is always reported with it.
    #[arg(long, value_name = "FILE.png")]
    pub consistency: Option<PathBuf>,
    #[command(flatten)]
    pub bracket: BracketArgs,
    #[command(flatten)]
    pub run: PipelineArgs,
    #[command(flatten)]
    pub maps: MapOutputs,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
}

/// The flags that choose how a bracket becomes a dome, shared by `skydome merge` and
/// `skydome batch` (one definition, so both read them alike).
#[derive(Debug, clap::Args)]
pub struct PipelineArgs {
    /// A camera profile from `skydome calibrate`; without one, each bracket
    /// calibrates itself.
    #[arg(long, value_name = "camera.json")]
    pub profile: Option<PathBuf>,
    /// Where the absolute scale comes from without a meter reading: `profile` (the profile's
    /// absolute constant with EXIF time, ISO and f-number, when it has one; default), `exif`
    /// (the reflected-light meter equation, K = 12.5: an estimate within ±30 %, labelled so) or
    /// `none` (relative).
    #[arg(long, default_value = "profile", value_parser = parse_absolute)]
    pub absolute: AbsoluteMode,
    /// Frame weighting: `noise` (default: inverse variance under a camera noise model fitted
    /// to the bracket or read from the profile; 1.04–1.26× the oracle's error where the hat's
    /// is 1.37–2.45×, at 1.1–1.25× the hat's run time), `hat` (Debevec's hat, the earlier default)
    /// or `none` (the seed's unweighted eq. 4).
    #[arg(long, default_value = "noise", value_parser = parse_weighting)]
    pub weighting: Weighting,
    /// Which exposures calibrate and merge: `listed` (EXIF, --times or --times-file, as given;
    /// default), checked against the photos, with a warning naming every frame more than 1/3
    /// stop off; or `measured`: each frame's exposure measured from the photos (the ratio of
    /// neighbouring frames over the pixels well exposed in both, alternating with the curve
    /// fit), anchored on the listed time of the frame that agrees best with the others (said
    /// in the report). For EXIF-rounded times, a mistyped list, or a camera that ignored part
    /// of the bracket (frames of one picture are one exposure; one of each is merged).
    #[arg(long, default_value = "listed", value_parser = parse_exposures)]
    pub exposures: ExposureSource,
    /// The UTC offset (+02:00, -05:00, Z) the camera's clock (EXIF DateTimeOriginal) is read
    /// in, for cameras that write no OffsetTimeOriginal; it overrides EXIF's offset.
    #[arg(long, value_name = "OFFSET", allow_hyphen_values = true)]
    pub time_zone: Option<String>,
    /// Black level of the frames, 8-bit code (e.g. 16 for a film scan): codes at or below
    /// count as black.
    #[arg(long, default_value_t = 0, value_name = "CODE")]
    pub black_level: u8,
    /// Align hand-held frames by translation (median threshold bitmaps) before merging.
    #[arg(long)]
    pub align: bool,
    /// Ghost-aware merge: where frames disagree beyond their noise (moving clouds), keep what
    /// most frames agree on instead of a blend of two scenes.
    #[arg(long)]
    pub ghosts: bool,
    /// The most memory, in MiB, one bracket's photos may take decoded at once: a bracket above
    /// it (frames × width × height × 3 bytes) is read one photo at a time when the job is a
    /// plain crop to the dome (--fisheye --crop; no --align, --ghosts,
    /// tilt, meter reading or EXIF scale), the same bytes for about 1.6× the CPU time. For
    /// small machines and batch nodes; default: no limit (every photo decoded whole).
    #[arg(long, value_name = "MiB")]
    pub memory_budget: Option<u64>,
    #[command(flatten)]
    pub calib: CalibArgs,
    #[command(flatten)]
    pub geometry: GeometryArgs,
}

impl PipelineArgs {
    /// The pipeline options these flags give, with `products` asked for; no meter reading and
    /// no consistency map (the callers add theirs).
    pub fn options(&self, products: Products) -> Result<Options> {
        let response = match &self.profile {
            Some(p) => ResponseSource::Profile(read_profile(p)?),
            None => ResponseSource::Calibrate(self.calib.options()),
        };
        Ok(Options {
            response,
            calibration_circle: self.calib.circle,
            weighting: self.weighting,
            exposures: self.exposures,
            black_level: self.black_level,
            align: self.align,
            consistency: false,
            ghosts: self.ghosts,
            lens: self.geometry.lens_source(self.calib.circle)?,
            // The camera's clock is read in the given zone by the pipeline itself (its report
            // then says the time came from EXIF and the flag).
            sky: SkyOptions {
                time_zone: self.time_zone.clone(),
                ..self.geometry.sky()
            },
            products,
            reference: Reference::default(),
            absolute: self.absolute,
            frame_memory_budget: self.memory_budget.map(|m| m.saturating_mul(1 << 20)),
        })
    }
}

/// Parses a merge weighting name.
fn parse_weighting(s: &str) -> Result<Weighting, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Parses an exposure source name.
fn parse_exposures(s: &str) -> Result<ExposureSource, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Parses an absolute mode name.
pub fn parse_absolute(s: &str) -> Result<AbsoluteMode, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Parses `X,Y=CD`.
fn parse_spot(s: &str) -> Result<(f64, f64, f64), String> {
    let bad = || format!("'{s}': expected X,Y=CD (pixel, then luminance in cd/m²)");
    let (xy, cd) = s.split_once('=').ok_or_else(bad)?;
    let (x, y) = xy.split_once(',').ok_or_else(bad)?;
    let num = |t: &str| t.trim().parse::<f64>().map_err(|_| bad());
    Ok((num(x)?, num(y)?, num(cd)?))
}

/// The `--json` output: the library's report and the files written.
#[derive(Serialize)]
struct Summary<'a> {
    #[serde(flatten)]
    report: &'a Report,
    written: Vec<String>,
}

/// The top-level entry point for `skydome merge`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    let outs: Vec<&PathBuf> = [
        Some(&a.output),
        a.exr.as_ref(),
        a.preview.as_ref(),
        a.confidence.as_ref(),
        a.consistency.as_ref(),
    ]
    .into_iter()
    .flatten()
    .chain(a.maps.outputs())
    .chain(a.save_profile.as_ref())
    .collect();
    // The profile read is an input too: an updated profile goes to a new file.
    let inputs: Vec<PathBuf> = a
        .images
        .iter()
        .chain(a.run.profile.as_ref())
        .cloned()
        .collect();
    for o in &outs {
        io::check_destination(o, &inputs, a.force)?;
    }
    let options = options(&a)?;
    let input = a.bracket.input(&a.images)?;
    let mut bar = io::StageBar::new(quiet);
    let mut dome = pipeline::run(input, &options, &mut |p| bar.show(p)).map_err(io::hint)?;
    bar.finish();
    let writing = std::time::Instant::now();
    if let Some(p) = &a.run.profile {
        dome.report.response = format!("profile {}", p.display());
    }
    for w in &dome.report.warnings {
        io::warn(quiet, w);
    }
    let mut outputs = encode(&a, &dome)?;
    if let Some(p) = &a.save_profile {
        outputs.add(p, profile_to_save(&a, &dome)?.to_json().into_bytes());
    }
    let written = outputs.commit(&inputs, a.force)?;
    bar.timings(&[("writing", writing.elapsed().as_secs_f64())]);
    let written: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    if a.json {
        let s = Summary {
            report: &dome.report,
            written,
        };
        crate::out(&serde_json::to_string_pretty(&s)?);
    } else if !quiet {
        print_summary(&dome.report, &written);
    }
    Ok(())
}

/// The pipeline options for the command line.
fn options(a: &Args) -> Result<Options> {
    let r = &a.run;
    let products = r.geometry.products(
        Products {
            preview: a.preview.is_some(),
            confidence: a.confidence.is_some(),
            consistency: a.consistency.is_some(),
            ..Products::default()
        },
        a.maps.overlay.is_some(),
        a.maps.angular.is_some(),
        a.maps.equirect.is_some(),
    );
    Ok(Options {
        consistency: a.consistency.is_some(),
        reference: Reference {
            luminance: a.luminance.map(|(x, y, cd)| SpotLuminance {
                pixel: PixelPoint { x, y },
                radius_px: a.luminance_radius,
                cd_per_m2: cd,
            }),
            illuminance_lux: a.illuminance,
        },
        ..r.options(products)?
    })
}

/// The profile `--save-profile` writes, or why there is none (before anything is written).
fn profile_to_save(a: &Args, dome: &Dome) -> Result<CameraProfile> {
    let what = a
        .save_profile
        .as_ref()
        .map_or(String::new(), |p| p.display().to_string());
    if let Some(why) = &dome.absolute_constant_refused {
        anyhow::bail!("{what}: cannot store the camera's absolute constant: {why}");
    }
    match &dome.camera_profile {
        Some(p) => Ok(p.clone()),
        None => anyhow::bail!(
            "{what}: with --profile, --save-profile stores a new absolute constant: give --illuminance, --luminance or --absolute exif"
        ),
    }
}

/// Reads and validates a camera profile (JSON).
pub fn read_profile(p: &std::path::Path) -> Result<CameraProfile> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
    let profile = CameraProfile::from_json(&text).with_context(|| p.display().to_string())?;
    profile
        .response()
        .with_context(|| p.display().to_string())?;
    Ok(profile)
}

/// Encodes every requested output.
fn encode(a: &Args, dome: &Dome) -> Result<Outputs> {
    let mut out = Outputs::default();
    let radiance = |p: &PathBuf, img, meta| crate::radiance::encode(p, img, meta, &a.exr_args);
    out.add(&a.output, radiance(&a.output, &dome.radiance, &dome.meta)?);
    if let Some(p) = &a.exr {
        out.add(p, radiance(p, &dome.radiance, &dome.meta)?);
    }
    let maps = [
        (&a.maps.equirect, &dome.equirect),
        (&a.maps.angular, &dome.angular),
    ];
    for (path, map) in maps {
        if let (Some(p), Some((img, meta))) = (path, map) {
            out.add(p, radiance(p, img, meta)?);
        }
    }
    if let (Some(p), Some(sigma)) = (&a.confidence, &dome.standard_error) {
        let is_exr = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if is_exr {
            out.add(
                p,
                radiance(p, sigma, &skydome::formats::HdrMeta::default())?,
            );
        } else if let Some(img) = &dome.confidence {
            out.add(p, crate::pictures::encode_rgb8(p, img)?);
        }
    }
    let pictures = [
        (&a.preview, &dome.preview),
        (&a.consistency, &dome.consistency),
        (&a.maps.overlay, &dome.overlay),
    ];
    for (path, img) in pictures {
        if let (Some(p), Some(img)) = (path, img) {
            out.add(p, crate::pictures::encode_rgb8(p, img)?);
        }
    }
    Ok(out)
}

/// The human-readable summary.
fn print_summary(r: &Report, written: &[String]) {
    let times: Vec<String> = r.frames.iter().map(|f| format_time(f.time_s)).collect();
    let method = r
        .calibration
        .as_ref()
        .map(|m| format!(" ({m} calibration)"))
        .unwrap_or_default();
    crate::out(&format!(
        "merged {} frames ({}) {}x{}, response {}{method}",
        r.frames.len(),
        times.join(", "),
        r.width,
        r.height,
        r.response
    ));
    if let Some(e) = r
        .exposures
        .as_ref()
        .filter(|e| e.source == ExposureSource::Measured)
    {
        crate::out(&format!(
            "exposures measured from the photos, anchored on the listed time of {}",
            e.anchor
        ));
    }
    let c = &r.capture;
    if c.time_utc.is_some() || c.latitude_deg.is_some() {
        crate::out(&format!(
            "time {} (from {}), site {} (from {})",
            c.time_utc.as_deref().unwrap_or("unknown"),
            c.time_from.name(),
            match (c.latitude_deg, c.longitude_deg) {
                (Some(la), Some(lo)) => format!("{la:.5}° N {lo:.5}° E"),
                _ => "unknown".into(),
            },
            c.site_from.name()
        ));
    }
    if let Some(g) = &r.geometry {
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
        if let Some(d) = &g.sun_disc {
            let unit = |u: &'static str| if d.absolute { u } else { " (relative)" };
            crate::out(&format!(
                "sun clipped in every frame: a solar disc of {:.4e}{} put in ({} px), direct normal {:.4e}{}, from {}",
                d.luminance,
                unit(" cd/m²"),
                d.pixels,
                d.direct_normal,
                unit(" lx"),
                d.from.describe()
            ));
        }
        if let Some(f) = g.north_from_sun {
            crate::out(&format!(
                "north from the sun: the phone's top edge pointed at {:.2}°{}",
                f.north_deg,
                f.compass_error_deg.map_or(String::new(), |e| format!(
                    " (the compass was off by {e:+.2}°)"
                ))
            ));
        }
    }
    if let Some(p) = &r.photometry {
        let source = match p.from {
            skydome::photometry::FROM_PROFILE => "the camera profile's constant".to_string(),
            skydome::photometry::FROM_METER_EQUATION => {
                "EXIF by the meter equation (K = 12.5)".to_string()
            }
            reading => format!("the {reading} reading"),
        };
        let mut s = format!("absolute: scaled by {:.6e} from {source}", p.scale);
        if let Some(u) = p.uncertainty_percent {
            s += &format!(" (±{u:.0} %)");
        }
        if let Some(e) = p.horizontal_illuminance_lux {
            s += &format!("; horizontal illuminance {e:.0} lx");
        }
        if let Some(d) = p.disagreement_percent {
            let rebuilt = r
                .geometry
                .as_ref()
                .and_then(|g| g.sun_disc)
                .is_some_and(|d| d.from == skydome::sun_disc::DirectSource::MeasuredIlluminance);
            let when = if rebuilt { " before the sun disc" } else { "" };
            s += &format!("; the illuminance reading disagreed by {d:+.1} %{when}");
        }
        crate::out(&s);
    }
    if let Some(al) = &r.alignment {
        crate::out(&format!(
            "aligned: shifts {:?} px (reference frame {})",
            al.shifts,
            al.reference + 1
        ));
    }
    if let Some(f) = r.inconsistent_fraction {
        crate::out(&format!(
            "frames disagree beyond their noise at {:.2} % of the pixels",
            100.0 * f
        ));
    }
    if let Some(raw) = &r.raw {
        let fw = raw.noise.full_well_electrons();
        let rn = raw.noise.read_noise_electrons();
        crate::out(&format!(
            "RAW: {} demosaic, colour from {}, noise {} ({:.0} e- at white, read noise {:.1} e-, green)",
            raw.demosaic,
            raw.colour.matrix_from,
            if raw.noise.fitted { "fitted on the frames" } else { "assumed" },
            fw[1],
            rn[1]
        ));
    }
    if let Some(e) = &r.standard_error {
        crate::out(&format!(
            "standard error: median {:.3} stops, 90th percentile {:.3}; {:.2} % not measured",
            e.median_stops,
            e.p90_stops,
            100.0 * e.unmeasured_fraction
        ));
    }
    for w in written {
        crate::out(&format!("wrote {w}"));
    }
}

/// Formats a shutter time the way cameras show it (`1/400 s`, `2 s`).
pub fn format_time(t: f64) -> String {
    if t < 1.0 {
        format!("1/{:.0} s", 1.0 / t)
    } else {
        format!("{t} s")
    }
}
