//! `skydome batch`: a station's archive — frames grouped into captures, each capture one run of
//! `skydome::pipeline::run`, one table row per capture, resumable, split into shards for Slurm
//! job arrays and Kubernetes Indexed Jobs.
//!
//! The rules that are not about files (grouping, shards, the table, the plot) are the library's
//! (`skydome::batch`), so another shell groups and tabulates the same way. This module lists
//! folders, reads bytes, keeps the resumption records and writes files.
//!
//! # Files in OUT
//! - `<capture>.hdr` (and `<capture>.jpg` with `--preview`, `<capture>_latlong.hdr` with
//!   `--equirect`), `<capture>` being the capture's UTC time `YYYYMMDDTHHMMSSZ`;
//! - `captures.csv`, `captures.jsonl` (each line the row and the capture's full report);
//! - `.skydome-batch/<capture>.json`: one record per finished capture (its row, report, input
//!   sizes and the options' fingerprint), written atomically after the capture's outputs. A run
//!   started again skips every capture whose record matches its inputs and options, so a killed
//!   run resumes where it stopped and a run with other options redoes everything;
//! - with shards, `parts/shard-I-of-N.jsonl`, joined by `skydome batch --collect OUT`.
//!
//! Exit codes: 0 every capture processed, 3 the table is written but some captures failed, 1 the
//! batch itself failed (unreadable input, no captures, a shard missing when collecting).

use std::collections::BTreeMap;
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};
use skydome::batch::{self, CaptureRow, Grouping, ManifestRow, Shard};
use skydome::bracket::{self, DecodeOptions, OrientationPolicy};
use skydome::pipeline::{self, EncodedFrame, Frames, Input, Options, Products};

use crate::io;
use crate::merge::PipelineArgs;

/// Arguments of `skydome batch`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folders of photos (JPEG, PNG, TIFF; frames of every capture mixed), photos, or manifest
    /// CSVs (`capture,file,exposure_s`, for cameras without EXIF).
    #[arg(num_args = 0.., required_unless_present = "collect")]
    pub inputs: Vec<PathBuf>,
    /// The output folder (created when missing): one dome per capture, captures.csv.
    #[arg(short, long, value_name = "OUT", required_unless_present = "collect")]
    pub output: Option<PathBuf>,
    /// Join the shards' parts in OUT into OUT/captures.csv and captures.jsonl.
    #[arg(long, value_name = "OUT", conflicts_with_all = ["inputs", "output"])]
    pub collect: Option<PathBuf>,
    /// A new capture starts where frames are more than this many seconds apart (default: found
    /// from the gaps between frames, and said).
    #[arg(long, value_name = "SECONDS", conflicts_with = "frames_per_capture")]
    pub group_gap: Option<f64>,
    /// Group K frames at a time in file-name order instead of by EXIF time.
    #[arg(long, value_name = "K")]
    pub frames_per_capture: Option<usize>,
    /// Also write each capture's tone-mapped preview (<capture>.jpg).
    #[arg(long)]
    pub preview: bool,
    /// Also write each capture's equirectangular map (<capture>_latlong.hdr; needs a lens).
    #[arg(long)]
    pub equirect: bool,
    /// Draw the day: illuminance and sun elevation against time, failed and sun-less captures
    /// marked (.png or .svg; a bare name goes into OUT).
    #[arg(long, value_name = "day.png")]
    pub plot: Option<PathBuf>,
    /// Captures processed at once (default: the number of cores); memory grows with it.
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// Process only shard I of N (0-based; capture i belongs to shard i mod N). Default: from
    /// SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT, or JOB_COMPLETION_INDEX with --shards.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    pub shard: Option<Shard>,
    /// Number of shards when the index comes from Kubernetes' JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "N")]
    pub shards: Option<usize>,
    /// EXIF orientation: apply or ignore.
    #[arg(long, default_value = "apply", value_parser = parse_orientation)]
    pub orientation: OrientationPolicy,
    /// Refuse images with more pixels than this.
    #[arg(long, default_value_t = DecodeOptions::default().max_pixels, value_name = "PIXELS")]
    pub max_pixels: u64,
    /// How each capture becomes a dome (the same flags as `skydome merge`).
    #[command(flatten)]
    pub run: PipelineArgs,
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    s.parse().map_err(|e: batch::BatchError| e.to_string())
}

fn parse_orientation(s: &str) -> Result<OrientationPolicy, String> {
    s.parse().map_err(|e: skydome::UnknownName| e.to_string())
}

/// The batch finished and wrote its table, but some captures failed: exit code 3.
#[derive(Debug)]
pub struct SomeFailed {
    /// Failed captures.
    pub failed: usize,
    /// All captures of this run.
    pub total: usize,
    /// The table that says which.
    pub table: String,
}

impl std::fmt::Display for SomeFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} of {} captures failed (see the status column)",
            self.table, self.failed, self.total
        )
    }
}

impl std::error::Error for SomeFailed {}

/// Where the resumption records live inside OUT.
const STATE_DIR: &str = ".skydome-batch";
/// Where shards put their parts of the table inside OUT.
const PARTS_DIR: &str = "parts";
/// Extensions taken from folders.
const PHOTO_EXTENSIONS: [&str; 5] = ["jpg", "jpeg", "png", "tif", "tiff"];
/// Bytes read from the head of a JPEG to find its EXIF (the APP1 segment is at most 64 KiB and
/// comes first); other formats are read whole.
const EXIF_HEAD_BYTES: usize = 128 * 1024;

/// One capture to process.
#[derive(Debug, Clone)]
struct Capture {
    name: String,
    files: Vec<PathBuf>,
    /// Exposure times from a manifest, one per file.
    times: Option<Vec<f64>>,
    /// Local clock of the first frame.
    local: Option<time::PrimitiveDateTime>,
    /// The capture's UTC instant, when the offset is known (EXIF or --time-zone).
    utc: Option<time::OffsetDateTime>,
    /// A reason the capture cannot be processed, found while grouping.
    problem: Option<String>,
}

/// A finished capture's record in `OUT/.skydome-batch/`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Record {
    options_hash: String,
    inputs: Vec<Stamp>,
    outputs: Vec<String>,
    row: CaptureRow,
    report: Option<serde_json::Value>,
}

/// An input file as it was when processed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Stamp {
    file: String,
    bytes: u64,
    modified_ns: u128,
}

/// One line of `captures.jsonl` (and of a shard's part, with its position in the batch).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Line {
    #[serde(skip_serializing_if = "Option::is_none", default)]
    seq: Option<usize>,
    #[serde(flatten)]
    row: CaptureRow,
    report: Option<serde_json::Value>,
}

/// The top-level entry point for `skydome batch`.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    if let Some(out) = &a.collect {
        return collect(out, a.plot.as_deref(), quiet);
    }
    let out = a
        .output
        .clone()
        .ok_or_else(|| anyhow!("give the output folder with -o OUT"))?;
    if a.run.geometry.time.is_some() {
        bail!("--time: a batch takes each capture's time from EXIF; give --time-zone for cameras that do not write the UTC offset");
    }
    let shard = shard(&a)?;
    let tz = match &a.run.time_zone {
        Some(s) => Some(bracket::parse_utc_offset(s).ok_or_else(|| {
            anyhow!("--time-zone '{s}': expected a UTC offset such as +02:00, -05:00 or Z")
        })?),
        None => None,
    };
    let options = options(&a)?;
    let fingerprint = fingerprint(&a, &options)?;
    let (captures, grouping) = plan(&a, tz)?;
    if !quiet {
        crate::out(&format!("grouped: {}", grouping));
    }
    std::fs::create_dir_all(out.join(STATE_DIR))
        .with_context(|| format!("{}: cannot create the output folder", out.display()))?;
    let mine: Vec<usize> = (0..captures.len()).filter(|&i| shard.owns(i)).collect();
    let jobs = a
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let ctx = Ctx {
        out: &out,
        options: &options,
        fingerprint: &fingerprint,
        orientation: a.orientation,
        max_pixels: a.max_pixels,
    };
    let records = process(&ctx, &captures, &mine, jobs, quiet)?;
    let lines: Vec<Line> = mine
        .iter()
        .zip(records)
        .map(|(&i, r)| Line {
            seq: Some(i),
            row: r.row,
            report: r.report,
        })
        .collect();
    let failed = lines.iter().filter(|l| !l.row.is_ok()).count();
    if shard.count > 1 {
        std::fs::create_dir_all(out.join(PARTS_DIR))
            .with_context(|| format!("{}: cannot create {PARTS_DIR}/", out.display()))?;
        let part = out.join(PARTS_DIR).join(format!("{}.jsonl", shard.tag()));
        let mut text = String::new();
        for l in &lines {
            text += &serde_json::to_string(l)?;
            text.push('\n');
        }
        io::write_atomic(&part, text.as_bytes())?;
        if !quiet {
            crate::out(&format!(
                "shard {shard}: {} captures ({failed} failed); wrote {}; join the shards with: skydome batch --collect {}",
                lines.len(),
                part.display(),
                out.display()
            ));
        }
        if failed > 0 {
            return Err(SomeFailed {
                failed,
                total: lines.len(),
                table: part.display().to_string(),
            }
            .into());
        }
        return Ok(());
    }
    finish(&out, lines, a.plot.as_deref(), quiet)
}

/// Writes the table (and the plot) from the lines of every capture, in batch order.
fn finish(out: &Path, lines: Vec<Line>, plot: Option<&Path>, quiet: bool) -> Result<()> {
    let rows: Vec<CaptureRow> = lines.iter().map(|l| l.row.clone()).collect();
    let csv = out.join("captures.csv");
    io::write_atomic(&csv, batch::csv_table(&rows).as_bytes())?;
    let mut jsonl = String::new();
    for l in lines {
        let l = Line { seq: None, ..l };
        jsonl += &serde_json::to_string(&l)?;
        jsonl.push('\n');
    }
    let jpath = out.join("captures.jsonl");
    io::write_atomic(&jpath, jsonl.as_bytes())?;
    let mut written = vec![csv.clone(), jpath];
    if let Some(p) = plot {
        let p = if p.parent().is_some_and(|d| !d.as_os_str().is_empty()) {
            p.to_path_buf()
        } else {
            out.join(p)
        };
        write_plot(&p, &rows)?;
        written.push(p);
    }
    let failed = rows.iter().filter(|r| !r.is_ok()).count();
    if !quiet {
        crate::out(&format!(
            "{} captures: {} ok, {failed} failed",
            rows.len(),
            rows.len() - failed
        ));
        for w in &written {
            crate::out(&format!("wrote {}", w.display()));
        }
    }
    if failed > 0 {
        return Err(SomeFailed {
            failed,
            total: rows.len(),
            table: csv.display().to_string(),
        }
        .into());
    }
    Ok(())
}

/// Draws the day plot into `p` (.png or .svg).
fn write_plot(p: &Path, rows: &[CaptureRow]) -> Result<()> {
    let (points, absolute) = batch::day_points(rows);
    let name = p.display().to_string();
    let bytes = match io::extension(p).as_str() {
        "png" => skydome::plot::day_png(&points, absolute, (1400, 900)).context(name)?,
        "svg" => skydome::plot::day_svg(&points, absolute, (1400, 900))
            .context(name)?
            .into_bytes(),
        e => bail!("{name}: cannot draw '.{e}'; use .png or .svg"),
    };
    io::write_atomic(p, &bytes)
}

/// `skydome batch --collect OUT`: joins `OUT/parts/shard-I-of-N.jsonl` into the table a
/// one-machine run writes.
fn collect(out: &Path, plot: Option<&Path>, quiet: bool) -> Result<()> {
    let dir = out.join(PARTS_DIR);
    let entries = std::fs::read_dir(&dir).with_context(|| {
        format!(
            "{}: cannot read (no shard has finished here)",
            dir.display()
        )
    })?;
    let mut parts: BTreeMap<usize, (usize, PathBuf)> = BTreeMap::new();
    let mut count = None;
    for e in entries {
        let p = e
            .with_context(|| format!("{}: cannot list", dir.display()))?
            .path();
        let Some(stem) = p
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_suffix(".jsonl"))
        else {
            continue;
        };
        let Some((i, n)) = stem
            .strip_prefix("shard-")
            .and_then(|s| s.split_once("-of-"))
            .and_then(|(i, n)| Some((i.parse::<usize>().ok()?, n.parse::<usize>().ok()?)))
        else {
            continue;
        };
        if *count.get_or_insert(n) != n {
            bail!(
                "{}: parts of runs with different shard counts ({} and {n}); remove the stale ones",
                dir.display(),
                count.unwrap_or(0)
            );
        }
        parts.insert(i, (n, p));
    }
    let n = count.ok_or_else(|| anyhow!("{}: no shard-I-of-N.jsonl parts", dir.display()))?;
    let missing: Vec<String> = (0..n)
        .filter(|i| !parts.contains_key(i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}: shard(s) {} of {n} have not finished; run them, then collect again",
            dir.display(),
            missing.join(", ")
        );
    }
    let mut lines = Vec::new();
    for (_, p) in parts.values() {
        let text =
            std::fs::read_to_string(p).with_context(|| format!("{}: cannot read", p.display()))?;
        for (k, l) in text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
        {
            let line: Line = serde_json::from_str(l)
                .with_context(|| format!("{}:{}: not a batch line", p.display(), k + 1))?;
            lines.push(line);
        }
    }
    lines.sort_by_key(|l| l.seq);
    if let Some(w) = lines.windows(2).find(|w| w[0].seq == w[1].seq) {
        bail!(
            "{}: capture {} appears in two parts; remove stale parts and rerun that shard",
            dir.display(),
            w[0].row.capture
        );
    }
    let hashes: std::collections::BTreeSet<&str> =
        lines.iter().map(|l| l.row.options_hash.as_str()).collect();
    if hashes.len() > 1 {
        bail!(
            "{}: the shards ran with different options (fingerprints {}); rerun them with the same options",
            dir.display(),
            hashes.into_iter().collect::<Vec<_>>().join(", ")
        );
    }
    finish(out, lines, plot, quiet)
}

/// The shard from --shard, else Slurm's or Kubernetes' environment.
fn shard(a: &Args) -> Result<Shard> {
    if let Some(s) = a.shard {
        return Ok(s);
    }
    let env = |k: &str| std::env::var(k).ok().filter(|v| !v.trim().is_empty());
    let num = |k: &str, v: String| -> Result<usize> {
        v.trim()
            .parse()
            .map_err(|_| anyhow!("{k}='{v}': expected a whole number"))
    };
    if let Some(id) = env("SLURM_ARRAY_TASK_ID") {
        let id = num("SLURM_ARRAY_TASK_ID", id)?;
        let count = env("SLURM_ARRAY_TASK_COUNT").ok_or_else(|| {
            anyhow!(
                "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not; give --shard I/N"
            )
        })?;
        let count = num("SLURM_ARRAY_TASK_COUNT", count)?;
        // Arrays need not start at 0 (--array=1-3): the index counts from the array's minimum.
        let min = match env("SLURM_ARRAY_TASK_MIN") {
            Some(m) => num("SLURM_ARRAY_TASK_MIN", m)?,
            None => 0,
        };
        return Shard::new(id.saturating_sub(min), count).map_err(|_| {
            anyhow!("SLURM_ARRAY_TASK_ID={id} (from {min}) with SLURM_ARRAY_TASK_COUNT={count}: use a contiguous array such as --array=0-{}", count.saturating_sub(1))
        });
    }
    if let Some(i) = env("JOB_COMPLETION_INDEX") {
        let i = num("JOB_COMPLETION_INDEX", i)?;
        let n = a.shards.ok_or_else(|| {
            anyhow!("JOB_COMPLETION_INDEX is set: give --shards N (the Job's completions)")
        })?;
        return Shard::new(i, n)
            .map_err(|e| anyhow!("JOB_COMPLETION_INDEX={i}, --shards {n}: {e}"));
    }
    if a.shards.is_some() {
        bail!("--shards N needs JOB_COMPLETION_INDEX (a Kubernetes Indexed Job); elsewhere give --shard I/N");
    }
    Ok(Shard::ALL)
}

/// The pipeline options (`skydome merge`'s, from the same flags); the per-capture time is
/// added in [`process_one`].
fn options(a: &Args) -> Result<Options> {
    let products = a.run.geometry.products(
        Products {
            preview: a.preview,
            ..Products::default()
        },
        false,
        false,
        a.equirect,
    );
    a.run.options(products)
}

/// The options' fingerprint: everything that changes an output byte (not the memory budget,
/// which changes only how the photos are read: shards on nodes of different sizes agree).
fn fingerprint(a: &Args, o: &Options) -> Result<String> {
    let o = Options {
        frame_memory_budget: None,
        ..o.clone()
    };
    let all = serde_json::json!({
        "skydome": skydome::VERSION,
        "options": o,
        "time_zone": a.run.time_zone,
        "orientation": a.orientation.name(),
        "max_pixels": a.max_pixels,
    });
    Ok(batch::fingerprint(serde_json::to_string(&all)?.as_bytes()))
}

/// Lists the inputs and groups them into captures, in time order.
fn plan(a: &Args, tz: Option<time::UtcOffset>) -> Result<(Vec<Capture>, String)> {
    let mut files = Vec::new();
    let mut manifests = Vec::new();
    for p in &a.inputs {
        if p.is_dir() {
            let mut in_dir = Vec::new();
            for e in
                std::fs::read_dir(p).with_context(|| format!("{}: cannot read", p.display()))?
            {
                let f = e
                    .with_context(|| format!("{}: cannot list", p.display()))?
                    .path();
                if f.is_file() && PHOTO_EXTENSIONS.contains(&io::extension(&f).as_str()) {
                    in_dir.push(f);
                }
            }
            in_dir.sort();
            files.extend(in_dir);
        } else if io::extension(p) == "csv" {
            manifests.push(p.clone());
        } else if p.is_file() {
            files.push(p.clone());
        } else {
            bail!("{}: no such file or folder", p.display());
        }
    }
    let mut captures = Vec::new();
    let mut said = Vec::new();
    for m in &manifests {
        let (c, s) = from_manifest(m, tz)?;
        captures.extend(c);
        said.push(s);
    }
    if !files.is_empty() {
        let (c, s) = from_files(&files, a, tz)?;
        captures.extend(c);
        said.push(s);
    }
    if captures.is_empty() {
        bail!("no photos found in the inputs (looked for .jpg, .jpeg, .png, .tif, .tiff)");
    }
    // Time order (UTC, else the local clock), then name; names unique.
    captures.sort_by(|x, y| {
        // Untimed captures last.
        let key = |c: &Capture| {
            let t = c
                .utc
                .map(|t| t.unix_timestamp_nanos())
                .or(c.local.map(|t| t.assume_utc().unix_timestamp_nanos()));
            (t.is_none(), t)
        };
        key(x).cmp(&key(y)).then_with(|| x.name.cmp(&y.name))
    });
    let mut names: Vec<String> = captures.iter().map(|c| c.name.clone()).collect();
    batch::unique_names(&mut names);
    for (c, n) in captures.iter_mut().zip(names) {
        c.name = n;
    }
    Ok((captures, said.join("; ")))
}

/// Reads the head of a file for its EXIF.
fn metadata(p: &Path) -> Result<bracket::FileMetadata> {
    let mut f = std::fs::File::open(p).with_context(|| format!("{}: cannot read", p.display()))?;
    let mut head = Vec::new();
    let jpeg = matches!(io::extension(p).as_str(), "jpg" | "jpeg");
    if jpeg {
        f.take(EXIF_HEAD_BYTES as u64).read_to_end(&mut head)
    } else {
        f.read_to_end(&mut head)
    }
    .with_context(|| format!("{}: cannot read", p.display()))?;
    Ok(bracket::read_metadata(&head))
}

/// The UTC instant of a frame: --time-zone, else EXIF's offset.
fn utc_of(
    m: &bracket::FileMetadata,
    tz: Option<time::UtcOffset>,
) -> (
    Option<time::PrimitiveDateTime>,
    Option<time::OffsetDateTime>,
) {
    let local = m.local_time();
    let offset = tz.or_else(|| {
        m.info
            .utc_offset
            .as_deref()
            .and_then(bracket::parse_utc_offset)
    });
    (local, local.zip(offset).map(|(l, o)| l.assume_offset(o)))
}

fn name_for(
    local: Option<time::PrimitiveDateTime>,
    utc: Option<time::OffsetDateTime>,
) -> Option<String> {
    match (utc, local) {
        (Some(u), _) => {
            let u = u.to_offset(time::UtcOffset::UTC);
            Some(batch::capture_name(
                time::PrimitiveDateTime::new(u.date(), u.time()),
                true,
            ))
        }
        (None, Some(l)) => Some(batch::capture_name(l, false)),
        (None, None) => None,
    }
}

/// Captures from photos: by EXIF time, or K at a time.
fn from_files(
    files: &[PathBuf],
    a: &Args,
    tz: Option<time::UtcOffset>,
) -> Result<(Vec<Capture>, String)> {
    let meta = files
        .iter()
        .map(|f| metadata(f))
        .collect::<Result<Vec<_>>>()?;
    let clocks: Vec<_> = meta.iter().map(|m| utc_of(m, tz)).collect();
    let make = |idx: &[usize], problem: Option<String>| {
        let (local, utc) = clocks[idx[0]];
        let stem = files[idx[0]]
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        Capture {
            name: name_for(local, utc).unwrap_or(stem),
            files: idx.iter().map(|&i| files[i].clone()).collect(),
            times: None,
            local,
            utc,
            problem,
        }
    };
    if let Some(k) = a.frames_per_capture {
        let g = batch::group_by_count(files.len(), k)?;
        let caps = g.captures.iter().map(|c| make(c, None)).collect();
        return Ok((caps, g.describe() + ", in file-name order"));
    }
    // One clock for grouping: UTC when known, else the local clock read as UTC.
    let secs: Vec<Option<f64>> = clocks
        .iter()
        .map(|(l, u)| {
            u.map(|u| u.unix_timestamp_nanos() as f64 / 1e9)
                .or(l.map(|l| l.assume_utc().unix_timestamp_nanos() as f64 / 1e9))
        })
        .collect();
    let timed: Vec<usize> = (0..files.len()).filter(|&i| secs[i].is_some()).collect();
    let untimed: Vec<usize> = (0..files.len()).filter(|&i| secs[i].is_none()).collect();
    let mut caps = Vec::new();
    let mut said = String::new();
    if !timed.is_empty() {
        let t: Vec<f64> = timed.iter().map(|&i| secs[i].unwrap_or(0.0)).collect();
        let subsec = timed
            .iter()
            .all(|&i| meta[i].info.subsec_original.is_some());
        let g: Grouping = batch::group_by_gap(&t, a.group_gap, if subsec { 0.01 } else { 1.0 })
            .map_err(|e| anyhow!("{e} (--group-gap SECONDS or --frames-per-capture K)"))?;
        said = g.describe();
        for c in &g.captures {
            let idx: Vec<usize> = c.iter().map(|&j| timed[j]).collect();
            caps.push(make(&idx, None));
        }
    }
    for &i in &untimed {
        caps.push(make(
            &[i],
            Some(format!(
                "{}: no capture time (EXIF DateTimeOriginal) to group it by; give --frames-per-capture K or a manifest (capture,file,exposure_s)",
                files[i].display()
            )),
        ));
    }
    if !untimed.is_empty() {
        said += &format!(
            "{}{} frames without a capture time (failed rows)",
            if said.is_empty() { "" } else { "; " },
            untimed.len()
        );
    }
    Ok((caps, said))
}

/// Captures from a manifest CSV (paths relative to its folder).
fn from_manifest(m: &Path, tz: Option<time::UtcOffset>) -> Result<(Vec<Capture>, String)> {
    let name = m.display().to_string();
    let text = std::fs::read_to_string(m).with_context(|| format!("{name}: cannot read"))?;
    let rows: Vec<ManifestRow> = batch::parse_manifest(&name, &text)?;
    let base = m.parent().map(Path::to_path_buf).unwrap_or_default();
    let (names, g) = batch::group_manifest(&rows);
    let mut caps = Vec::new();
    for (cname, idx) in names.iter().zip(&g.captures) {
        let files: Vec<PathBuf> = idx.iter().map(|&i| base.join(&rows[i].file)).collect();
        let times: Vec<Option<f64>> = idx.iter().map(|&i| rows[i].exposure_s).collect();
        let problem = if times.iter().any(Option::is_some) && times.iter().any(Option::is_none) {
            Some(format!(
                "{name}: capture {cname} gives exposure times for some files only; give all or none"
            ))
        } else {
            None
        };
        let meta = files
            .first()
            .and_then(|f| metadata(f).ok())
            .unwrap_or_default();
        let (local, utc) = utc_of(&meta, tz);
        let safe: String = cname
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        caps.push(Capture {
            name: name_for(local, utc).unwrap_or(safe),
            files,
            times: times.iter().copied().collect(),
            local,
            utc,
            problem,
        });
    }
    let said = format!(
        "{name}: {} rows in {} captures (manifest)",
        rows.len(),
        caps.len()
    );
    Ok((caps, said))
}

/// What every capture shares.
struct Ctx<'a> {
    out: &'a Path,
    options: &'a Options,
    fingerprint: &'a str,
    orientation: OrientationPolicy,
    max_pixels: u64,
}

/// Runs the shard's captures on `jobs` workers (each one capture at a time, the pipeline's own
/// threads shared), skipping those already recorded. Returns the records in `mine`'s order.
fn process(
    ctx: &Ctx,
    captures: &[Capture],
    mine: &[usize],
    jobs: usize,
    quiet: bool,
) -> Result<Vec<Record>> {
    let mut records: Vec<Option<Record>> = vec![None; mine.len()];
    let mut todo = Vec::new();
    for (k, &i) in mine.iter().enumerate() {
        match reusable(ctx, &captures[i]) {
            Some(r) => records[k] = Some(r),
            None => todo.push(k),
        }
    }
    let reused = mine.len() - todo.len();
    let bar = bar(quiet, todo.len() as u64);
    if !quiet && reused > 0 {
        crate::out(&format!(
            "resuming: {reused} of {} captures already done with these options",
            mine.len()
        ));
    }
    let next = AtomicUsize::new(0);
    let failed = AtomicUsize::new(0);
    let done = Mutex::new(Vec::new());
    let error = Mutex::new(None);
    std::thread::scope(|s| {
        for _ in 0..jobs.min(todo.len()) {
            s.spawn(|| loop {
                let n = next.fetch_add(1, Ordering::SeqCst);
                let Some(&k) = todo.get(n) else { break };
                let cap = &captures[mine[k]];
                match process_one(ctx, cap) {
                    Ok(r) => {
                        if !r.row.is_ok() {
                            failed.fetch_add(1, Ordering::SeqCst);
                        }
                        if let Ok(mut d) = done.lock() {
                            d.push((k, r));
                        }
                    }
                    Err(e) => {
                        // Writing into OUT failed: every later capture would fail the same way.
                        if let Ok(mut slot) = error.lock() {
                            slot.get_or_insert(e);
                        }
                        next.store(todo.len(), Ordering::SeqCst);
                    }
                }
                let f = failed.load(Ordering::SeqCst);
                bar.inc(1);
                let pos = bar.position() as usize;
                bar.set_message(format!(
                    "ok {}, failed {f}, remaining {}",
                    pos.saturating_sub(f),
                    todo.len().saturating_sub(pos)
                ));
            });
        }
    });
    bar.finish_and_clear();
    if let Some(e) = error.into_inner().ok().flatten() {
        return Err(e);
    }
    for (k, r) in done.into_inner().map_err(|_| anyhow!("a worker failed"))? {
        records[k] = Some(r);
    }
    records
        .into_iter()
        .zip(mine)
        .map(|(r, &i)| r.ok_or_else(|| anyhow!("capture {} was not processed", captures[i].name)))
        .collect()
}

fn bar(quiet: bool, len: u64) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "captures [{bar:30}] {pos}/{len} {msg} {elapsed} ETA {eta}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(format!("ok 0, failed 0, remaining {len}"));
    bar
}

fn record_path(out: &Path, name: &str) -> PathBuf {
    out.join(STATE_DIR).join(format!("{name}.json"))
}

/// Stamps of the capture's inputs (size and modification time).
fn stamps(c: &Capture) -> Vec<Stamp> {
    c.files
        .iter()
        .map(|f| {
            let m = std::fs::metadata(f).ok();
            Stamp {
                file: f.display().to_string(),
                bytes: m.as_ref().map_or(0, |m| m.len()),
                modified_ns: m
                    .and_then(|m| m.modified().ok())
                    .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                    .map_or(0, |d| d.as_nanos()),
            }
        })
        .collect()
}

/// The capture's record when it finished with these options and inputs and its outputs are
/// still there.
fn reusable(ctx: &Ctx, c: &Capture) -> Option<Record> {
    let text = std::fs::read_to_string(record_path(ctx.out, &c.name)).ok()?;
    let r: Record = serde_json::from_str(&text).ok()?;
    let same = r.options_hash == ctx.fingerprint
        && r.inputs == stamps(c)
        && r.outputs.iter().all(|o| ctx.out.join(o).is_file());
    same.then_some(r)
}

/// Processes one capture: its outputs, then its record. A capture that cannot be processed
/// gives a failed row; only a failure to write into OUT is an error.
fn process_one(ctx: &Ctx, c: &Capture) -> Result<Record> {
    let mut row = CaptureRow {
        capture: c.name.clone(),
        capture_time_utc: c.utc.map(skydome::bracket::format_iso8601_utc),
        frames: c.files.len(),
        exposure_times_s: c.times.clone().unwrap_or_default(),
        options_hash: ctx.fingerprint.to_string(),
        ..CaptureRow::default()
    };
    let stamps = stamps(c);
    let result = match &c.problem {
        Some(p) => Err(p.clone()),
        None => {
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| merge(ctx, c)));
            match run {
                Ok(r) => r,
                Err(_) => Err(
                    "internal error (a bug in skydome; please report it with this capture's files)"
                        .into(),
                ),
            }
        }
    };
    let (outputs, report) = match result {
        Ok((dome, pixels)) => {
            let files = write_outputs(ctx, c, &dome)?;
            row.status = "ok".into();
            row.fill_from_report(&dome.report, pixels);
            row.output = files.first().cloned();
            (files, Some(serde_json::to_value(&dome.report)?))
        }
        Err(reason) => {
            row.status = format!("failed: {}", reason.replace(['\n', '\r'], " "));
            (Vec::new(), None)
        }
    };
    let rec = Record {
        options_hash: ctx.fingerprint.to_string(),
        inputs: stamps,
        outputs,
        row,
        report,
    };
    io::write_atomic(
        &record_path(ctx.out, &c.name),
        serde_json::to_string(&rec)?.as_bytes(),
    )?;
    Ok(rec)
}

/// Reads the capture's frames and runs the pipeline; the error is the failed row's reason.
/// Also returns the pixel count of one input frame (the clipped fraction's denominator).
fn merge(ctx: &Ctx, c: &Capture) -> std::result::Result<(pipeline::Dome, usize), String> {
    let frames = c
        .files
        .iter()
        .map(|p| {
            Ok(EncodedFrame {
                name: p.display().to_string(),
                bytes: io::read(p)?,
            })
        })
        .collect::<Result<Vec<_>>>()
        .map_err(|e| format!("{e:#}"))?;
    let pixels = frames
        .first()
        .and_then(|f| {
            image::ImageReader::new(std::io::Cursor::new(&f.bytes))
                .with_guessed_format()
                .ok()?
                .into_dimensions()
                .ok()
        })
        .map_or(0, |(w, h)| w as usize * h as usize);
    let input = Input {
        frames: Frames::Encoded(frames),
        times: c.times.clone(),
        orientation: ctx.orientation,
        decode: DecodeOptions {
            max_pixels: ctx.max_pixels,
        },
    };
    let dome = pipeline::run(input, ctx.options, &mut pipeline::no_progress)
        .map_err(|e| format!("{:#}", io::hint(e)))?;
    Ok((dome, pixels))
}

/// Writes the capture's files atomically into OUT; returns their names relative to OUT, the
/// dome first.
fn write_outputs(ctx: &Ctx, c: &Capture, dome: &pipeline::Dome) -> Result<Vec<String>> {
    let mut files = Vec::new();
    let mut put = |name: String, bytes: Vec<u8>| -> Result<()> {
        io::write_atomic(&ctx.out.join(&name), &bytes)?;
        files.push(name);
        Ok(())
    };
    let hdr = format!("{}.hdr", c.name);
    let exr = crate::radiance::ExrArgs::default();
    put(
        hdr.clone(),
        crate::radiance::encode(&ctx.out.join(&hdr), &dome.radiance, &dome.meta, &exr)?,
    )?;
    if let Some(img) = &dome.preview {
        let name = format!("{}.jpg", c.name);
        put(
            name.clone(),
            crate::pictures::encode_rgb8(&ctx.out.join(&name), img)?,
        )?;
    }
    if let Some((img, meta)) = &dome.equirect {
        let name = format!("{}_latlong.hdr", c.name);
        put(
            name.clone(),
            crate::radiance::encode(&ctx.out.join(&name), img, meta, &exr)?,
        )?;
    }
    Ok(files)
}
