//! `skydome calibrate`: recover the camera response from a bracket and save a camera profile.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde::Serialize;
use skydome::camera::CameraProfile;
use skydome::image::Circle;
use skydome::response::{self, CalibrateOptions, Fit, Solver};
use skydome::sampling::{SampleOptions, GRID_METHOD_SAMPLES};

use crate::io::{self, BracketArgs, Outputs};

/// `--grid`'s default.
const GRID_DEFAULT: usize = 10;
/// `--code-bands`' default.
const CODE_BANDS_DEFAULT: usize = 16;

/// How calibration samples and the solve are chosen (shared by `calibrate` and `merge`).
#[derive(Debug, Clone, clap::Args)]
pub struct CalibArgs {
    /// Number of sample pixels N (default 100; 2000 with --method noise or covering, and so with
    /// the default --method auto from 5 frames; raised automatically so that N·(frames−1) ≥ 255
    /// unless --method seed).
    #[arg(long)]
    pub samples: Option<usize>,
    /// Grid size G: with --method seed or --stratify 0, samples are drawn in G×G cells over the
    /// usable area.
    #[arg(long, default_value_t = GRID_DEFAULT)]
    pub grid: usize,
    /// Seed of the sample selection (same seed, same samples).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Code bands: split codes into N bands and add samples to every band the grid left with
    /// too few observations, so both ends of the curve rest on data (0 = off).
    #[arg(long, default_value_t = CODE_BANDS_DEFAULT, value_name = "N")]
    pub code_bands: usize,
    /// Stratified draw: candidates in N bands of the middle frame's code, taken from every band
    /// in turn (default 0 = the grid draw; 32 with --method noise).
    #[arg(long, value_name = "N")]
    pub stratify: Option<usize>,
    /// How the curve is fitted: `hat` is Debevec & Malik's hat weight (default); `noise`
    /// reweights every observation by the noise its code shows and drops outliers (moved
    /// pixels; the default of --method noise).
    #[arg(long, value_parser = parse_fit)]
    pub fit: Option<Fit>,
    /// Smoothness weight λ of the second-derivative term (default 30; 100 with --method noise).
    #[arg(long)]
    pub lambda: Option<f64>,
    /// Move the hat weight's ends in by this many codes: codes within it of 0 and 255 get no
    /// weight (default 0, the seed's hat; 2.55 is colour-hdri's). Not with --method seed.
    #[arg(long, value_name = "CODES")]
    pub hat_margin: Option<f64>,
    /// `auto` (default) is `covering` for brackets of 5 frames or more and `joined` for fewer
    /// (the best at each count on synthetic brackets with a known truth, level with `robust` on
    /// real sub-brackets, see docs/accuracy.md); given --samples, --stratify, --fit, --lambda, --hat-margin, --grid or
    /// --code-bands it is `robust` at every count, those options applied, and so it is with
    /// `merge --exposures measured` (measuring alternates with the fit).
    /// `robust` rejects clipped, edge and non-monotonic samples and raises N; `noise` is robust
    /// with 2000 samples stratified over the middle frame's codes and the noise-weighted fit
    /// (λ 100); `covering` is the noise-weighted fit on 2000 samples spread over 16 code bands of
    /// every frame and channel, codes from 1 counted (λ 150; closest to the oracle, see
    /// docs/accuracy.md); `joined` is the covering curve with the `robust` curve's toe (its
    /// slopes below code 128, blended up to 192; the `robust` curve alone where the covering
    /// fit fails); `colour-hdri` is colour-hdri's Debevec calibration (1000 histogram samples,
    /// Grossberg & Nayar: no alignment needed, but noisy frames bend the curve — see
    /// docs/accuracy.md; λ 30, its hat); `seed` is the original method exactly (random pixels
    /// per cell, no rejection).
    #[arg(long, value_enum, default_value_t = Method::Auto)]
    pub method: Method,
    /// On a bracket whose mean step is at least 2.5 EV, remove the curve's error that repeats
    /// with the step (invisible to frames that far apart) and fit the merge's noise model from
    /// code 24 up (see docs/accuracy.md, "Twelfth round"). The covering calibration does it by
    /// default (so `auto` from 5 frames); this asks for it with any method.
    #[arg(long, conflicts_with = "no_step_periodic")]
    pub step_periodic: bool,
    /// Never apply the step-periodic correction (the calibration before it became the
    /// covering calibration's default).
    #[arg(long)]
    pub no_step_periodic: bool,
    /// Least-squares solver: `schur` (fast, default) or `svd` (the seed's dense SVD, slow).
    #[arg(long, default_value = "schur", value_parser = parse_solver)]
    pub solver: Solver,
    /// Sample only inside this circle (centre x, centre y, radius; pixels, origin top-left).
    #[arg(long, value_parser = parse_circle, value_name = "CX,CY,R")]
    pub circle: Option<Circle>,
}

/// Sampling method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// `covering` for brackets of 5 frames or more, `joined` for fewer (the default).
    Auto,
    /// Rejection of useless samples and automatic N.
    Robust,
    /// Robust, stratified, 2000 samples, the noise-weighted fit.
    Noise,
    /// Robust, covering every code band of every frame, 2000 samples, the noise-weighted fit.
    Covering,
    /// The covering curve with the robust method's toe below code 128, blended up to 192.
    Joined,
    /// colour-hdri's calibration: histogram samples, λ 30, its hat.
    ColourHdri,
    /// The seed's method exactly.
    Seed,
}

fn parse_fit(s: &str) -> Result<Fit, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

fn parse_solver(s: &str) -> Result<Solver, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Parses `cx,cy,r` in pixels.
pub fn parse_circle(s: &str) -> Result<Circle, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected CX,CY,R in pixels, e.g. 1224,1224,1100"))?;
    match v[..] {
        [cx, cy, r] if v.iter().all(|x| x.is_finite()) && r > 0.0 => Ok(Circle { cx, cy, r }),
        _ => Err(format!("'{s}': expected CX,CY,R with a positive radius")),
    }
}

impl CalibArgs {
    /// Library options for these arguments.
    pub fn options(&self) -> CalibrateOptions {
        let robust = |base: CalibrateOptions| CalibrateOptions {
            sampling: SampleOptions {
                samples: self.samples.unwrap_or(base.sampling.samples),
                grid: self.grid,
                seed: self.seed,
                code_bands: self.code_bands,
                stratify: self.stratify.unwrap_or(base.sampling.stratify),
                ..base.sampling.clone()
            },
            lambda: self.lambda.unwrap_or(base.lambda),
            solver: self.solver,
            fit: self.fit.unwrap_or(base.fit),
            hat_margin: self.hat_margin.unwrap_or(base.hat_margin),
            ..base
        };
        let mut o = match self.method {
            Method::Auto => {
                let tuned = self.samples.is_some()
                    || self.stratify.is_some()
                    || self.fit.is_some()
                    || self.lambda.is_some()
                    || self.hat_margin.is_some()
                    || self.grid != GRID_DEFAULT
                    || self.code_bands != CODE_BANDS_DEFAULT;
                let mut o = robust(CalibrateOptions::default());
                if tuned {
                    // Options of the robust method's knobs: the robust method, as asked.
                    o.covering_from = None;
                }
                o
            }
            Method::Robust => robust(CalibrateOptions::robust()),
            Method::Noise => robust(CalibrateOptions::noise_fit()),
            Method::Covering => robust(CalibrateOptions::covering()),
            Method::Joined => robust(CalibrateOptions::joined()),
            Method::ColourHdri => {
                let base = CalibrateOptions::colour_hdri();
                CalibrateOptions {
                    sampling: SampleOptions {
                        samples: self.samples.unwrap_or(base.sampling.samples),
                        ..base.sampling.clone()
                    },
                    lambda: self.lambda.unwrap_or(base.lambda),
                    solver: self.solver,
                    hat_margin: self.hat_margin.unwrap_or(base.hat_margin),
                    ..base
                }
            }
            Method::Seed => CalibrateOptions::seed_method(
                self.samples.unwrap_or(GRID_METHOD_SAMPLES),
                self.grid,
                self.seed,
                self.lambda.unwrap_or(response::SEED_LAMBDA),
                self.solver,
            ),
        };
        if self.step_periodic || self.no_step_periodic {
            o.step_periodic = Some(self.step_periodic);
        }
        o
    }
}

/// Arguments of `skydome calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The bracket: 2 or more photos of one still scene at different exposures.
    #[arg(required = true, num_args = 1..)]
    pub images: Vec<PathBuf>,
    /// The camera profile to write (JSON).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub bracket: BracketArgs,
    #[command(flatten)]
    pub calib: CalibArgs,
    /// The response is known to be linear (e.g. RAW-derived TIFF): write a linear profile.
    #[arg(long)]
    pub linear: bool,
    /// Align hand-held frames by translation (median threshold bitmaps, as `merge --align`)
    /// before sampling, so calibration samples see one scene point in every frame.
    #[arg(long)]
    pub align: bool,
    /// Also solve K times with seeds seed..seed+K−1 and report the spread of g per code.
    #[arg(long, value_name = "K")]
    pub repeat: Option<usize>,
    /// The seed's §9.2 experiment: also calibrate with each of these sample counts (no automatic
    /// raise), 5 seeds each, and print how the seed-to-seed spread of g falls with N.
    #[arg(long, value_name = "N1,N2,...", value_delimiter = ',')]
    pub sweep: Vec<usize>,
    /// Plot the curves with their sample points (.png or .svg).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
}

#[derive(Serialize)]
struct Report<'a> {
    profile: String,
    /// The calibration used, as `--method` names it, `auto` resolved for the frame count
    /// (absent with `--linear`).
    #[serde(skip_serializing_if = "Option::is_none")]
    calibration: Option<String>,
    sampling: Option<&'a skydome::sampling::SampleReport>,
    monotonic_fixes: Option<[usize; 3]>,
    alignment: Option<skydome::align::Alignment>,
    stability: Option<response::Stability>,
    sweep: Vec<SweepRow>,
    /// The noise model fitted to the bracket and stored in the profile.
    noise: Option<skydome::noise::NoiseEstimate>,
    written: Vec<String>,
}

#[derive(Serialize)]
struct SweepRow {
    samples: usize,
    used: f64,
    rms_spread: f64,
    max_spread: f64,
}

/// The top-level entry point for `skydome calibrate`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    io::check_destination(&a.output, &a.images, a.force)?;
    let mut br = io::load_bracket(&a.images, &a.bracket, quiet)?;
    // The alignment `merge --align` runs, from the library: the same shifts on the same frames.
    let alignment = a.align.then(|| {
        skydome::align::align_bracket(&mut br.frames, &skydome::align::AlignOptions::default())
    });
    let opts = a.calib.options();
    let mut outputs = Outputs::default();
    let mut report = Report {
        profile: a.output.display().to_string(),
        calibration: None,
        sampling: None,
        monotonic_fixes: None,
        alignment,
        stability: None,
        sweep: Vec::new(),
        noise: None,
        written: Vec::new(),
    };
    let spin = io::spinner(quiet, "calibrating");
    let calibration;
    // The step-periodic correction applied (a wide-step bracket: by default from 5 frames, or
    // asked for with `--step-periodic`): the stored noise model is then fitted from code 24 up,
    // as the merge after it would fit it.
    let mut wide_step = false;
    let mut profile = if a.linear {
        CameraProfile::linear()
    } else {
        calibration =
            response::calibrate(&br.frames, a.calib.circle, &opts).context("calibration failed")?;
        wide_step = calibration.wide_step;
        report.sampling = Some(calibration.report());
        report.calibration = Some(opts.for_frames(br.frames.len()).method_name());
        if let Some(w) = calibration.report().relaxed_warning() {
            io::warn(quiet, &w);
        }
        if let Some(w) = calibration.report().shortfall_warning() {
            io::warn(quiet, &w);
        }
        if let Some(w) = calibration.report().range_warning() {
            io::warn(quiet, &w);
        }
        report.monotonic_fixes = Some(calibration.monotonic_fixes);
        if let Some(k) = a.repeat {
            let s = response::stability(&br.frames, a.calib.circle, &opts, k)
                .context("calibration stability")?;
            if !s.stable {
                io::warn(
                    quiet,
                    &format!(
                        "the response is unstable: its spread between seeds is {:.3} (ln units, RMS), above {:.3}; use more samples or check the bracket",
                        s.rms_spread, s.threshold
                    ),
                );
            }
            report.stability = Some(s);
        }
        if !a.sweep.is_empty() {
            let rows =
                response::sample_count_experiment(&br.frames, a.calib.circle, &opts, &a.sweep, 5)
                    .context("sample-count experiment")?;
            report.sweep = rows
                .iter()
                .map(|r| SweepRow {
                    samples: r.samples,
                    used: r.used,
                    rms_spread: r.stability.rms_spread,
                    max_spread: r.stability.max_spread,
                })
                .collect();
        }
        if let Some(p) = &a.plot {
            outputs.add(p, crate::pictures::curve_plot(p, &calibration)?);
        }
        CameraProfile::from_calibration(&calibration)
    };
    // The noise model a merge with this profile uses instead of fitting its own (black level
    // 0: a merge with `--black-level` still uses it). Stored with what came from the prior.
    report.noise = Some(
        profile
            .estimate_noise(&br.frames, 0, wide_step)
            .context("noise model")?,
    );
    spin.finish_and_clear();
    skydome::pipeline::describe_camera(&mut profile, &br);
    outputs.add(&a.output, profile.to_json().into_bytes());
    let written = outputs.commit(&a.images, a.force)?;
    report.written = written.iter().map(|p| p.display().to_string()).collect();
    if a.json {
        crate::out(&serde_json::to_string_pretty(&report)?);
    } else if !quiet {
        print_report(&report);
    }
    Ok(())
}

fn print_report(r: &Report) {
    if let Some(m) = &r.calibration {
        crate::out(&format!("calibration: {m}"));
    }
    if let Some(s) = r.sampling {
        let raised = if s.target > s.requested {
            format!(" (raised from {} so that N·(frames−1) ≥ 255)", s.requested)
        } else {
            String::new()
        };
        if s.histogram {
            crate::out(&format!(
                "samples: {} matched by rank in the frames' histograms (Grossberg & Nayar; no pixel positions, nothing rejected)",
                s.used
            ));
        } else {
            crate::out(&format!(
                "samples: {} used of target {}{raised}; rejected {} clipped, {} edge, {} non-monotonic; grid {}x{}, seed {}",
                s.used, s.target, s.rejected_clipped, s.rejected_edge, s.rejected_non_monotonic, s.grid, s.grid, s.seed
            ));
        }
        let cr = s.code_range;
        crate::out(&format!(
            "codes constrained by data: R {}..{}, G {}..{}, B {}..{} ({} samples added to fill code bands); outside them the curve is extrapolated",
            cr[0][0], cr[0][1], cr[1][0], cr[1][1], cr[2][0], cr[2][1], s.band_samples
        ));
    }
    if let Some(n) = &r.noise {
        let g = n.gains();
        let stored = if n.from_prior == skydome::noise::FromPrior::ALL {
            "not stored: nothing measurable, a merge fits its own".to_string()
        } else if n.fitted {
            "fitted, stored in the profile".to_string()
        } else {
            format!("stored, {} from the prior", n.from_prior.names())
        };
        crate::out(&format!(
            "noise model: {:.0} / {:.0} / {:.0} e- at code 128 (R/G/B), read noise {:.1} e-; {stored}",
            g[0], g[1], g[2], n.model.channels[1].read_noise
        ));
    }
    if let Some(al) = &r.alignment {
        crate::out(&format!(
            "aligned: shifts {:?} px (reference frame {})",
            al.shifts,
            al.reference + 1
        ));
    }
    if let Some(f) = r.monotonic_fixes {
        if f.iter().any(|&n| n > 0) {
            crate::out(&format!(
                "made non-decreasing: {} / {} / {} codes (R/G/B) had no support",
                f[0], f[1], f[2]
            ));
        }
    }
    if let Some(s) = &r.stability {
        crate::out(&format!(
            "stability over {} seeds: RMS spread {:.4}, max {:.4} (ln units) — {}",
            s.seeds.len(),
            s.rms_spread,
            s.max_spread,
            if s.stable { "stable" } else { "UNSTABLE" }
        ));
    }
    if !r.sweep.is_empty() {
        crate::out("samples  used   RMS spread of g (ln)  max spread");
        for s in &r.sweep {
            crate::out(&format!(
                "{:>7} {:>6.0} {:>21.4} {:>11.4}",
                s.samples, s.used, s.rms_spread, s.max_spread
            ));
        }
    }
    for w in &r.written {
        crate::out(&format!("wrote {w}"));
    }
}
