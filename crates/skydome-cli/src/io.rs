//! File-system edge of the command line: reading inputs, loading a bracket, atomic writes.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use skydome::bracket::{self, Bracket, DecodeOptions, OrientationPolicy};
use skydome::pipeline::{self, EncodedFrame, Frames, Input, PipelineError};

/// Where exposure times come from, as given on the command line.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct BracketArgs {
    /// Exposure times in seconds, in the order of the files (e.g. 1/400,1/100,1/25); overrides EXIF.
    #[arg(long, value_name = "T1,T2,...")]
    pub times: Option<String>,
    /// A list file with one 'FILE TIME' (or 'FILE TIME 1/TIME') line per file, matched by path,
    /// else by file name; '#' starts a comment. Overrides EXIF.
    #[arg(long, value_name = "LIST")]
    pub times_file: Option<PathBuf>,
    /// EXIF orientation: `apply` it (all frames must agree) or `ignore` it (stored pixel order).
    #[arg(long, default_value = "apply", value_parser = parse_orientation)]
    pub orientation: OrientationPolicy,
    /// Refuse images with more pixels than this (decompression-bomb guard).
    #[arg(long, default_value_t = DecodeOptions::default().max_pixels, value_name = "PIXELS")]
    pub max_pixels: u64,
}

impl BracketArgs {
    /// The library's bracket input for `files`: their bytes, the exposure overrides, the
    /// orientation policy and the pixel limit.
    pub fn input(&self, files: &[PathBuf]) -> Result<Input> {
        let times = match (&self.times, &self.times_file) {
            (Some(_), Some(_)) => bail!("give either --times or --times-file, not both"),
            (Some(t), None) => {
                let t = bracket::parse_times(t).map_err(|e| hint(e.into()))?;
                if t.len() != files.len() {
                    bail!(
                        "--times has {} values but {} files were given; give one time per file, in file order",
                        t.len(),
                        files.len()
                    );
                }
                Some(t)
            }
            (None, Some(list)) => Some(times_from_list(list, files)?),
            (None, None) => None,
        };
        let frames = files
            .iter()
            .map(|p| {
                Ok(EncodedFrame {
                    name: p.display().to_string(),
                    bytes: read(p)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Input {
            frames: Frames::Encoded(frames),
            times,
            orientation: self.orientation,
            decode: DecodeOptions {
                max_pixels: self.max_pixels,
            },
        })
    }
}

/// Parses `apply` or `ignore` for `--orientation`.
fn parse_orientation(s: &str) -> Result<OrientationPolicy, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// Reads, decodes and validates the bracket named on the command line.
pub fn load_bracket(files: &[PathBuf], args: &BracketArgs, quiet: bool) -> Result<Bracket> {
    let input = args.input(files)?;
    let mut bar = StageBar::new(quiet);
    let br = pipeline::load_bracket(input, &mut |p| bar.show(p)).map_err(hint)?;
    bar.finish();
    for w in &br.warnings {
        warn(quiet, w);
    }
    Ok(br)
}

/// The library's error with this command line's flags added where the library says what to
/// do in neutral words.
pub fn hint(e: PipelineError) -> anyhow::Error {
    use bracket::BracketError as B;
    let extra = match &e {
        PipelineError::Bracket(B::MissingExposure { .. }) => {
            " with --times 1/400,1/100,... (in file order) or --times-file LIST (lines 'FILE TIME')"
        }
        PipelineError::Bracket(B::TooLarge { .. }) => "; raise it with --max-pixels",
        PipelineError::Bracket(B::DarkerWhenLonger { .. }) => {
            " (the EXIF times, or --times / --times-file in file order)"
        }
        PipelineError::Bracket(B::OrientationMismatch { .. }) => " (use --orientation ignore)",
        PipelineError::Bracket(B::IdenticalPixels { .. }) => " (--exposures measured)",
        PipelineError::CircleNotFound { .. } => " with --circle CX,CY,R",
        PipelineError::NoEphemeris => " (--time, --lat, --lon)",
        PipelineError::NeedsLens(_) => " (--lens lens.json or --fisheye)",
        PipelineError::AbsoluteExif(_) => {
            "; give a meter reading (--illuminance, --luminance) or leave out --absolute exif"
        }
        _ => "",
    };
    anyhow!("{e}{extra}")
}

/// One progress bar on stderr driven by the pipeline's stage events (hidden when quiet or
/// when stderr is not a terminal). With `SKYDOME_TIMINGS=1` in the environment it also times
/// each stage (from its first event to the next stage's) and [`StageBar::timings`] prints them
/// on stderr, quiet or not: the native side of `web-tests/measure.mjs`'s stage table.
pub struct StageBar {
    bar: ProgressBar,
    stage: Option<pipeline::Stage>,
    /// Seconds spent in each stage so far, in order, when timing.
    timings: Option<Vec<(&'static str, f64)>>,
    since: std::time::Instant,
}

impl StageBar {
    /// A bar, hidden when `quiet`.
    pub fn new(quiet: bool) -> Self {
        let bar = progress(quiet, 100, "");
        let timings = std::env::var_os("SKYDOME_TIMINGS")
            .is_some_and(|v| !v.is_empty() && v != "0")
            .then(Vec::new);
        Self {
            bar,
            stage: None,
            timings,
            since: std::time::Instant::now(),
        }
    }

    /// Shows an event; never cancels (Ctrl-C ends the process).
    pub fn show(&mut self, p: &pipeline::Progress) -> std::ops::ControlFlow<()> {
        if self.stage != Some(p.stage) {
            self.lap();
            self.stage = Some(p.stage);
            self.bar.set_message(p.stage.name());
        }
        self.bar
            .set_position((p.fraction.clamp(0.0, 1.0) * 100.0) as u64);
        std::ops::ControlFlow::Continue(())
    }

    /// Ends the current stage's lap (when timing) and starts the next one.
    fn lap(&mut self) {
        let now = std::time::Instant::now();
        if let (Some(t), Some(stage)) = (self.timings.as_mut(), self.stage) {
            let s = now.duration_since(self.since).as_secs_f64();
            match t.iter_mut().find(|(n, _)| *n == stage.name()) {
                Some((_, sum)) => *sum += s,
                None => t.push((stage.name(), s)),
            }
        }
        self.since = now;
    }

    /// Removes the bar and ends the last stage's lap.
    pub fn finish(&mut self) {
        self.lap();
        self.stage = None;
        self.bar.finish_and_clear();
    }

    /// Prints the stage times and `extra` (name, seconds) on stderr as one line
    /// (`timings: decoding 0.123 s, lens 0.045 s, …`) when `SKYDOME_TIMINGS` is set.
    pub fn timings(&self, extra: &[(&str, f64)]) {
        if let Some(t) = &self.timings {
            let parts: Vec<String> = t
                .iter()
                .map(|(n, s)| (*n, *s))
                .chain(extra.iter().copied())
                .map(|(n, s)| format!("{n} {s:.3} s"))
                .collect();
            eprintln!("timings: {}", parts.join(", "));
        }
    }
}

fn times_from_list(list: &Path, files: &[PathBuf]) -> Result<Vec<f64>> {
    let name = list.display().to_string();
    let text = std::fs::read_to_string(list).with_context(|| format!("{name}: cannot read"))?;
    let files: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    Ok(bracket::times_from_list(&name, &text, &files)?)
}

/// Prints a one-line warning on stderr unless quiet.
pub fn warn(quiet: bool, msg: &str) {
    if !quiet {
        eprintln!("warning: {msg}");
    }
}

/// A progress bar on stderr (hidden when quiet or when stderr is not a terminal).
pub fn progress(quiet: bool, len: u64, what: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg:>10} [{bar:30}] {pos}/{len} {elapsed}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}

/// A spinner for a stage of unknown length.
pub fn spinner(quiet: bool, what: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new_spinner();
    bar.set_message(what.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}

/// A set of output files written together: every destination is checked before any is written,
/// each is written to a temporary file in its target folder and renamed into place, so a failed
/// run leaves no partial file and never touches an input.
#[derive(Debug, Default)]
pub struct Outputs {
    files: Vec<(PathBuf, Vec<u8>)>,
}

impl Outputs {
    /// Queues `bytes` for `path`.
    pub fn add(&mut self, path: &Path, bytes: Vec<u8>) {
        self.files.push((path.to_path_buf(), bytes));
    }

    /// Checks every destination, then writes them all atomically. `inputs` are never
    /// overwritten; existing outputs only with `force`. Returns the paths written.
    pub fn commit(self, inputs: &[PathBuf], force: bool) -> Result<Vec<PathBuf>> {
        for (i, (p, _)) in self.files.iter().enumerate() {
            check_destination(p, inputs, force)?;
            if self.files[..i].iter().any(|(q, _)| same_file(p, q)) {
                bail!("{}: named twice as an output", p.display());
            }
        }
        let mut written = Vec::new();
        for (p, bytes) in self.files {
            write_atomic(&p, &bytes)?;
            written.push(p);
        }
        Ok(written)
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Refuses to write over an input, or over an existing file without `force`, or into a
/// folder that does not exist.
pub fn check_destination(p: &Path, inputs: &[PathBuf], force: bool) -> Result<()> {
    let name = p.display();
    if inputs.iter().any(|i| same_file(i, p)) {
        bail!("{name}: refusing to overwrite an input file");
    }
    if p.is_dir() {
        bail!("{name}: is a directory; give a file name");
    }
    if p.exists() && !force {
        bail!("{name}: already exists; use --force to replace it");
    }
    let dir = parent_dir(p);
    if !dir.is_dir() {
        bail!("{name}: folder {} does not exist", dir.display());
    }
    Ok(())
}

fn parent_dir(p: &Path) -> PathBuf {
    match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Writes `bytes` to a temporary file beside `p`, then renames it over `p`.
pub fn write_atomic(p: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let name = p.display();
    let dir = parent_dir(p);
    let mut tmp = tempfile::Builder::new()
        .prefix(".skydome-")
        .suffix(".tmp")
        .tempfile_in(&dir)
        .with_context(|| format!("{name}: cannot create a file in {}", dir.display()))?;
    // Temporary files are created private (0600); a finished output gets the usual 0644.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = tmp
            .as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644));
    }
    tmp.write_all(bytes)
        .and_then(|_| tmp.as_file().sync_all())
        .with_context(|| format!("{name}: cannot write"))?;
    tmp.persist(p)
        .map_err(|e| anyhow!("{name}: cannot rename into place: {}", e.error))?;
    Ok(())
}

/// Reads a whole file, naming it in the error.
pub fn read(p: &Path) -> Result<Vec<u8>> {
    std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))
}

/// The lower-cased extension of a path.
pub fn extension(p: &Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}
