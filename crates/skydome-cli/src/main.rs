//! The `skydome` command line: a thin dispatcher over the `skydome` library.
//!
//! Each subcommand lives in its own module with one top-level entry point that turns arguments
//! into library calls and file writes; no algorithm lives here.
//!
//! Exit codes: 0 success, 1 a failed run (one line `error: <file>: <what>` on stderr),
//! 2 a usage error (reported by clap), 3 a batch that wrote its table but had failed captures.

mod alloc;
mod batch;
mod calibrate;
mod compare;
mod demo;

mod geometry;
mod info;
mod io;
mod lens;
mod merge;
mod pictures;
mod radiance;
mod reproject;
mod serve;
mod synth;
mod tonemap;
mod views;

use std::process::ExitCode;

#[global_allocator]
static ALLOCATOR: alloc::HugePageAlloc = alloc::HugePageAlloc;

use clap::{Parser, Subcommand};

/// Calibrated HDR radiance maps of the sky-dome from bracketed fish-eye photos.
#[derive(Debug, Parser)]
#[command(name = "skydome", version, about, propagate_version = true)]
struct Cli {
    /// No progress bars or warnings on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run: the size of the largest variant (merge's many options) does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
enum Command {
    /// Recover the camera response curve from a bracket and save a camera profile (JSON).
    Calibrate(calibrate::Args),
    /// Merge a bracket into a radiance map (.hdr, optionally .exr and a preview).
    Merge(merge::Args),
    /// A station's archive: group frames into captures, merge each, one table (captures.csv);
    /// resumable, sharded on Slurm job arrays and Kubernetes Indexed Jobs.
    Batch(batch::Args),
    /// Tone-map a radiance map to an 8-bit JPEG/PNG (or 16-bit PNG).
    Tonemap(tonemap::Args),
    /// Print a radiance file's header, size and statistics.
    Info(info::Args),
    /// Compare two radiance maps after fitting one global scale.
    Compare(compare::Args),
    /// Find the fish-eye image circle, fit the lens projection, write lens profiles.
    Lens(lens::Args),
    /// Reproject a fish-eye dome to an equirectangular, angular, mirror-ball or fish-eye map.
    Reproject(reproject::Args),
    /// A false-colour luminance map with a logarithmic colour bar (PNG).
    Falsecolor(views::FalsecolorArgs),
    /// A histogram of log2 luminance with the dynamic range in stops (PNG).
    Histogram(views::HistogramArgs),
    /// A diffuse and a mirror sphere lit by an equirectangular dome (PNG/JPEG).
    Render(views::RenderArgs),
    /// Run the whole pipeline on the small fish-eye bracket bundled with skydome.
    Demo(demo::Args),
    /// Write a synthetic fish-eye bracket with known radiance and response (ground truth).
    Synth(synth::Args),
    /// Serve the built phone web app over HTTP (development; localhost is a secure context).
    Serve(serve::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<batch::SomeFailed>().is_some() => {
            eprintln!("error: {e}");
            ExitCode::from(3)
        }
        Err(e) => {
            // `{:#}` joins the context chain on one line: "error: sky.jpg: cannot decode: …".
            let msg = format!("{e:#}").replace('\n', " ");
            eprintln!("error: {msg}");
            ExitCode::from(1)
        }
    }
}

/// Parses a full command line (with the program name first) and runs it; `demo` uses this to
/// run the same commands a user would type.
pub fn run_args(args: &[&str]) -> anyhow::Result<()> {
    dispatch(Cli::try_parse_from(args)?)
}

fn dispatch(cli: Cli) -> anyhow::Result<()> {
    let quiet = cli.quiet;
    match cli.command {
        Command::Calibrate(a) => calibrate::run(a, quiet),
        Command::Merge(a) => merge::run(a, quiet),
        Command::Batch(a) => batch::run(a, quiet),
        Command::Tonemap(a) => tonemap::run(a, quiet),
        Command::Info(a) => info::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Synth(a) => synth::run(a, quiet),
        Command::Lens(a) => lens::run(a, quiet),
        Command::Reproject(a) => reproject::run(a, quiet),
        Command::Falsecolor(a) => views::falsecolor(a, quiet),
        Command::Histogram(a) => views::histogram(a, quiet),
        Command::Render(a) => views::render(a, quiet),
        Command::Demo(a) => demo::run(a, quiet),
        Command::Serve(a) => serve::run(a, quiet),
    }
}

/// Prints `s` and a newline on stdout; a closed pipe (`skydome info … | head`) ends quietly.
pub fn out(s: &str) {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    if writeln!(o, "{s}").is_err() {
        std::process::exit(0);
    }
}
