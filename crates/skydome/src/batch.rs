//! A station's archive: frames grouped into captures, captures split into shards, and one table
//! row per capture. Pure data, no files: the `skydome batch` command walks folders, reads bytes,
//! runs [`crate::pipeline::run`] once per capture and writes what this module formats; another
//! shell (a Python binding driving Dask, the web app on a day's photos) reuses the same rules.
//!
//! # Grouping
//! A station writes the frames of every capture into one folder. Frames are grouped by their
//! capture instant (EXIF `DateTimeOriginal` + `SubSecTimeOriginal`, on one clock): sorted in
//! time, a new capture starts where the gap to the previous frame exceeds a threshold
//! ([`group_by_gap`]). The threshold is given (`--group-gap`) or found: the gaps between
//! consecutive frames, each raised to the clock's resolution (1 s without sub-seconds), are
//! sorted and split where one is at least [`AUTO_GAP_RATIO`] times the one below it (the
//! largest such jump); the threshold is the geometric mean of the two. Gaps inside a bracket
//! (a burst, or the longest exposure) and between captures (1–15 minutes) differ by far more
//! than that. Without times, [`group_by_count`] takes `K` frames at a time in name order, and a
//! manifest ([`parse_manifest`], `capture,file,exposure_s`) says it outright.
//!
//! # Sharding
//! [`Shard`] `I/N` takes every `N`-th capture in time order starting at the `I`-th (0-based):
//! deterministic, balanced to within one capture, and the same on every node that lists the same
//! folder. Slurm job arrays and Kubernetes Indexed Jobs give `I` and `N` through the environment.
//!
//! # The table
//! [`CaptureRow`] is one capture's line in `captures.csv` ([`CaptureRow::CSV_HEADER`],
//! [`CaptureRow::csv_line`]), taken from the pipeline's report ([`CaptureRow::from_report`]).
//! Numbers are written in Rust's shortest round-trip form, so a table made by one machine and
//! one joined from shards are byte-identical.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use crate::pipeline::Report;

/// A gap at least this many times the next smaller one separates captures (see the module
/// docs): brackets take seconds, stations capture every 1–15 minutes.
pub const AUTO_GAP_RATIO: f64 = 4.0;

/// Without a clear jump, frames no further apart than this (seconds) are taken as one bracket.
pub const ONE_BRACKET_MAX_GAP_S: f64 = 10.0;

/// Errors of grouping, manifests and shard names; each says what to give instead.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BatchError {
    /// Nothing to group.
    #[error("no frames to group")]
    NoFrames,
    /// The gaps between frames show no jump between brackets and captures.
    #[error("cannot tell captures apart by time: the gaps between frames run from {min_s} s to {max_s} s with no jump of {AUTO_GAP_RATIO}x; give the gap that separates captures (seconds) or the frames per capture")]
    NoGap {
        /// Smallest gap, seconds.
        min_s: f64,
        /// Largest gap, seconds.
        max_s: f64,
    },
    /// A gap or count that cannot be used.
    #[error("{what} = {value} is out of range: {hint}")]
    BadParameter {
        /// The parameter.
        what: &'static str,
        /// Its value.
        value: f64,
        /// What is accepted.
        hint: &'static str,
    },
    /// A manifest line that cannot be read.
    #[error("{file}:{line}: {reason}")]
    Manifest {
        /// The manifest's name.
        file: String,
        /// Line number, 1-based.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A shard that is not `I/N` with `0 ≤ I < N`.
    #[error("shard '{0}': expected I/N with 0 <= I < N (e.g. 0/3)")]
    BadShard(String),
}

/// How frames were grouped, with the gap used, for the "how it grouped" line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Grouping {
    /// Frame indices of every capture, captures and frames in time order.
    pub captures: Vec<Vec<usize>>,
    /// The gap threshold, seconds (`None` when grouped by count or manifest).
    pub gap_s: Option<f64>,
    /// True when the gap was found from the data, false when given.
    pub gap_found: bool,
}

impl Grouping {
    /// One line: captures, frames per capture, the gap used.
    pub fn describe(&self) -> String {
        let n: usize = self.captures.iter().map(Vec::len).sum();
        let mut sizes: Vec<usize> = self.captures.iter().map(Vec::len).collect();
        sizes.sort_unstable();
        sizes.dedup();
        let sizes: Vec<String> = sizes.iter().map(|s| s.to_string()).collect();
        let mut s = format!(
            "{} frames in {} captures ({} frames each)",
            n,
            self.captures.len(),
            sizes.join(" or ")
        );
        if let Some(g) = self.gap_s {
            let how = if self.gap_found { "found" } else { "given" };
            let _ = write!(s, ", a new capture after a gap over {g:.3} s ({how})");
        }
        s
    }
}

/// Groups frames by capture instant (seconds on one clock, one per frame, any order): a new
/// capture starts where the gap to the previous frame exceeds `gap_s`, or the threshold found
/// from the gaps (see the module docs) when `gap_s` is `None`. `resolution_s` is the clock's
/// resolution (1 s for EXIF without sub-seconds): smaller gaps count as that.
pub fn group_by_gap(
    times_s: &[f64],
    gap_s: Option<f64>,
    resolution_s: f64,
) -> Result<Grouping, BatchError> {
    if times_s.is_empty() {
        return Err(BatchError::NoFrames);
    }
    if let Some(g) = gap_s {
        if !(g.is_finite() && g > 0.0) {
            return Err(BatchError::BadParameter {
                what: "group gap (s)",
                value: g,
                hint: "give a positive number of seconds",
            });
        }
    }
    let mut order: Vec<usize> = (0..times_s.len()).collect();
    order.sort_by(|&a, &b| times_s[a].total_cmp(&times_s[b]).then(a.cmp(&b)));
    let res = if resolution_s.is_finite() && resolution_s > 0.0 {
        resolution_s
    } else {
        1.0
    };
    let gaps: Vec<f64> = order
        .windows(2)
        .map(|w| (times_s[w[1]] - times_s[w[0]]).max(res))
        .collect();
    let (threshold, found) = match gap_s {
        Some(g) => (g, false),
        None => (auto_gap(&gaps)?, true),
    };
    let mut captures = vec![vec![order[0]]];
    for (i, g) in gaps.iter().enumerate() {
        if *g > threshold {
            captures.push(Vec::new());
        }
        if let Some(c) = captures.last_mut() {
            c.push(order[i + 1]);
        }
    }
    Ok(Grouping {
        captures,
        gap_s: Some(threshold),
        gap_found: found,
    })
}

/// The gap threshold found from the gaps between consecutive frames (see the module docs).
fn auto_gap(gaps: &[f64]) -> Result<f64, BatchError> {
    let mut sorted = gaps.to_vec();
    sorted.sort_by(f64::total_cmp);
    let (Some(&min), Some(&max)) = (sorted.first(), sorted.last()) else {
        // One frame: one capture, whatever the threshold.
        return Ok(f64::INFINITY);
    };
    let jump = sorted
        .windows(2)
        .map(|w| (w[1] / w[0], w[0], w[1]))
        .filter(|(r, _, _)| *r >= AUTO_GAP_RATIO)
        .max_by(|a, b| a.0.total_cmp(&b.0));
    match jump {
        Some((_, lo, hi)) => Ok((lo * hi).sqrt()),
        None if max <= ONE_BRACKET_MAX_GAP_S => Ok(f64::INFINITY),
        None => Err(BatchError::NoGap {
            min_s: min,
            max_s: max,
        }),
    }
}

/// Groups `n` frames (already in name order) `k` at a time; the last capture holds the rest.
pub fn group_by_count(n: usize, k: usize) -> Result<Grouping, BatchError> {
    if n == 0 {
        return Err(BatchError::NoFrames);
    }
    if k == 0 {
        return Err(BatchError::BadParameter {
            what: "frames per capture",
            value: 0.0,
            hint: "give at least 1",
        });
    }
    Ok(Grouping {
        captures: (0..n)
            .collect::<Vec<_>>()
            .chunks(k)
            .map(<[usize]>::to_vec)
            .collect(),
        gap_s: None,
        gap_found: false,
    })
}

/// One line of a manifest: which capture a file belongs to, and its exposure time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestRow {
    /// The capture's name (any text without a comma; used for grouping and, when no time is
    /// known, as the output's name).
    pub capture: String,
    /// The file, as written (relative paths are relative to the manifest's folder).
    pub file: String,
    /// Exposure time in seconds (`1/250` or `0.004`), or `None` when the column is empty
    /// (then EXIF says it).
    pub exposure_s: Option<f64>,
}

/// Reads a manifest CSV with the header `capture,file,exposure_s` (the third column may be
/// empty; `#` lines and blank lines are skipped). `name` is used in messages.
pub fn parse_manifest(name: &str, text: &str) -> Result<Vec<ManifestRow>, BatchError> {
    let err = |line: usize, reason: String| BatchError::Manifest {
        file: name.to_string(),
        line,
        reason,
    };
    let mut rows = Vec::new();
    let mut header_seen = false;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = line.split(',').map(str::trim).collect();
        if !header_seen {
            header_seen = true;
            if cols
                .first()
                .is_some_and(|c| c.eq_ignore_ascii_case("capture"))
            {
                if cols.len() < 2 || !cols[1].eq_ignore_ascii_case("file") {
                    return Err(err(
                        i + 1,
                        "expected the header capture,file,exposure_s".into(),
                    ));
                }
                continue;
            }
        }
        if !(2..=3).contains(&cols.len()) {
            return Err(err(
                i + 1,
                format!(
                    "expected capture,file,exposure_s (3 columns), found {}",
                    cols.len()
                ),
            ));
        }
        if cols[0].is_empty() || cols[1].is_empty() {
            return Err(err(i + 1, "empty capture or file".into()));
        }
        let exposure_s = match cols.get(2).copied().unwrap_or("") {
            "" => None,
            t => Some(
                crate::bracket::parse_time(cols[1], t).map_err(|e| err(i + 1, e.to_string()))?,
            ),
        };
        rows.push(ManifestRow {
            capture: cols[0].to_string(),
            file: cols[1].to_string(),
            exposure_s,
        });
    }
    if rows.is_empty() {
        return Err(err(
            1,
            "no rows (expected capture,file,exposure_s lines)".into(),
        ));
    }
    Ok(rows)
}

/// The captures of a manifest in order of first appearance: the capture names and, per capture,
/// the indices of its rows.
pub fn group_manifest(rows: &[ManifestRow]) -> (Vec<String>, Grouping) {
    let mut names: Vec<String> = Vec::new();
    let mut captures: Vec<Vec<usize>> = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        match names.iter().position(|n| *n == r.capture) {
            Some(c) => captures[c].push(i),
            None => {
                names.push(r.capture.clone());
                captures.push(vec![i]);
            }
        }
    }
    (
        names,
        Grouping {
            captures,
            gap_s: None,
            gap_found: false,
        },
    )
}

/// One part of a batch split over several machines: capture `i` (0-based, in time order)
/// belongs to shard `i mod count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, `0..count`.
    pub index: usize,
    /// Number of shards (≥ 1).
    pub count: usize,
}

impl Shard {
    /// The whole batch on one machine.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// A shard, checked.
    pub fn new(index: usize, count: usize) -> Result<Shard, BatchError> {
        if count == 0 || index >= count {
            return Err(BatchError::BadShard(format!("{index}/{count}")));
        }
        Ok(Shard { index, count })
    }

    /// True when capture `i` (0-based, in time order) is this shard's.
    pub fn owns(&self, i: usize) -> bool {
        i % self.count == self.index
    }

    /// The shard's file-name part, `shard-I-of-N`.
    pub fn tag(&self) -> String {
        format!("shard-{}-of-{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = BatchError;

    /// Parses `I/N`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || BatchError::BadShard(s.to_string());
        let (i, n) = s.trim().split_once('/').ok_or_else(bad)?;
        let i = i.trim().parse().map_err(|_| bad())?;
        let n = n.trim().parse().map_err(|_| bad())?;
        Shard::new(i, n).map_err(|_| bad())
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// A capture's name for its output files from its instant: `YYYYMMDDTHHMMSSZ` in UTC (ASCII, no
/// colons, sorts in time order), or `YYYYMMDDTHHMMSS-local` when only the local clock is known.
pub fn capture_name(t: time::PrimitiveDateTime, utc: bool) -> String {
    format!(
        "{:04}{:02}{:02}T{:02}{:02}{:02}{}",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second(),
        if utc { "Z" } else { "-local" }
    )
}

/// Makes names unique in order: the second `X` becomes `X_2`, the third `X_3`.
pub fn unique_names(names: &mut [String]) {
    let mut seen: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for n in names.iter_mut() {
        let k = seen.entry(n.clone()).or_insert(0);
        *k += 1;
        if *k > 1 {
            *n = format!("{n}_{k}");
        }
    }
}

/// FNV-1a (64 bit) of `bytes` as 16 hex digits: the fingerprint of a batch's options (their
/// JSON), stable across platforms and versions of Rust, unlike `std`'s hasher.
pub fn fingerprint(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// One capture's line in `captures.csv`. Empty values are `None`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CaptureRow {
    /// The capture's name (also the stem of its output files).
    pub capture: String,
    /// Capture instant in UTC, ISO 8601 (`2026-06-21T10:00:00Z`), when the offset is known.
    pub capture_time_utc: Option<String>,
    /// Number of frames.
    pub frames: usize,
    /// Exposure times, seconds, shortest first (as the pipeline sorted them; file order when the
    /// capture failed before).
    pub exposure_times_s: Vec<f64>,
    /// `ok`, or `failed: <one-line reason>`.
    pub status: String,
    /// The pipeline's warnings.
    pub warnings: Vec<String>,
    /// How the sun was found (`detected`, `ephemeris`, `tap`), or none.
    pub sun_source: Option<String>,
    /// Sun azimuth, degrees from true north towards east: the computed (ephemeris) sun when
    /// time and site are known, else the sun found in the image (needs north).
    pub sun_azimuth_deg: Option<f64>,
    /// Sun elevation above the horizon, degrees, as [`CaptureRow::sun_azimuth_deg`].
    pub sun_elevation_deg: Option<f64>,
    /// Angle between the observed and the computed sun, degrees, when both exist.
    pub sun_ephemeris_angle_deg: Option<f64>,
    /// Horizontal illuminance of the dome (lux when absolute, else relative units).
    pub horizontal_illuminance: Option<f64>,
    /// `lux` or `relative`.
    pub illuminance_unit: Option<String>,
    /// The reconstructed sun's direct normal illuminance, when the sun was rebuilt.
    pub sun_direct_normal: Option<f64>,
    /// The dome's diffuse horizontal illuminance (without the rebuilt sun), when rebuilt.
    pub sun_diffuse_horizontal: Option<f64>,
    /// Fraction of the input pixels clipped even in the shortest exposure.
    pub clipped_fraction: Option<f64>,
    /// Fraction of the tested pixels where frames disagree beyond their noise (ghosts), when
    /// tested.
    pub ghost_fraction: Option<f64>,
    /// The dome's file, relative to the batch's output folder.
    pub output: Option<String>,
    /// Fingerprint of the options ([`fingerprint`]).
    pub options_hash: String,
}

impl CaptureRow {
    /// The CSV header line (no newline).
    pub const CSV_HEADER: &'static str = "capture,capture_time_utc,frames,exposure_times_s,status,warnings,sun_source,sun_azimuth_deg,sun_elevation_deg,sun_ephemeris_angle_deg,horizontal_illuminance,illuminance_unit,sun_direct_normal,sun_diffuse_horizontal,clipped_fraction,ghost_fraction,output,options_hash";

    /// Fills the measured columns from the pipeline's report of this capture. `input_pixels`
    /// is width × height of one input frame (the clipped count is over the whole frame).
    pub fn fill_from_report(&mut self, r: &Report, input_pixels: usize) {
        self.frames = r.frames.len();
        self.exposure_times_s = r.frames.iter().map(|f| f.time_s).collect();
        self.warnings = r.warnings.clone();
        self.clipped_fraction =
            (input_pixels > 0).then(|| r.clipped_high_pixels as f64 / input_pixels as f64);
        self.ghost_fraction = r.inconsistent_fraction;
        let absolute = r.photometry.is_some();
        if let Some(g) = &r.geometry {
            self.sun_source = g.sun_source.map(|s| s.to_string());
            // The sun's true place when time and site are known; else where it was found.
            let (az, el) = match (&g.sun_ephemeris, &g.sun) {
                (Some(e), _) => (Some(e.azimuth_deg), Some(e.elevation_deg)),
                (None, Some(s)) => (s.azimuth_deg, s.elevation_deg),
                (None, None) => (None, None),
            };
            self.sun_azimuth_deg = az;
            self.sun_elevation_deg = el;
            self.sun_ephemeris_angle_deg = g.sun_cross_check.map(|c| c.angle_deg);
            self.horizontal_illuminance = Some(g.horizontal_illuminance);
            self.illuminance_unit = Some(if absolute { "lux" } else { "relative" }.into());
            if let Some(d) = &g.sun_disc {
                self.sun_direct_normal = Some(d.direct_normal);
                self.sun_diffuse_horizontal = Some(d.diffuse_horizontal);
            }
        }
    }

    /// True when the status is `ok`.
    pub fn is_ok(&self) -> bool {
        self.status == "ok"
    }

    /// The row as one CSV line (no newline), fields in [`CaptureRow::CSV_HEADER`]'s order.
    /// Lists are joined with `;` (numbers) and ` | ` (warnings); fields holding a comma, a quote
    /// or a line break are quoted.
    pub fn csv_line(&self) -> String {
        let num = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
        let text = |v: &Option<String>| v.clone().unwrap_or_default();
        let times: Vec<String> = self.exposure_times_s.iter().map(f64::to_string).collect();
        let fields = [
            self.capture.clone(),
            text(&self.capture_time_utc),
            self.frames.to_string(),
            times.join(";"),
            self.status.clone(),
            self.warnings.join(" | "),
            text(&self.sun_source),
            num(self.sun_azimuth_deg),
            num(self.sun_elevation_deg),
            num(self.sun_ephemeris_angle_deg),
            num(self.horizontal_illuminance),
            text(&self.illuminance_unit),
            num(self.sun_direct_normal),
            num(self.sun_diffuse_horizontal),
            num(self.clipped_fraction),
            num(self.ghost_fraction),
            text(&self.output),
            self.options_hash.clone(),
        ];
        fields
            .iter()
            .map(|f| csv_field(f))
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// Quotes a CSV field when it needs it (RFC 4180); line breaks become spaces.
fn csv_field(s: &str) -> String {
    let s = s.replace(['\n', '\r'], " ");
    if s.contains([',', '"']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s
    }
}

/// The whole `captures.csv` for `rows` (in the order given), header first, `\n` line ends.
pub fn csv_table(rows: &[CaptureRow]) -> String {
    let mut s = String::with_capacity(256 * (rows.len() + 1));
    s.push_str(CaptureRow::CSV_HEADER);
    s.push('\n');
    for r in rows {
        s.push_str(&r.csv_line());
        s.push('\n');
    }
    s
}

/// The day plot's points ([`crate::plot::day_png`]) for `rows`, and whether the illuminance is
/// absolute (lux in every processed row). Time is in hours UTC from midnight of the first timed
/// capture's day; rows without a UTC time are left out.
pub fn day_points(rows: &[CaptureRow]) -> (Vec<crate::plot::DayPoint>, bool) {
    use crate::plot::{DayPoint, DayState};
    let timed: Vec<(&CaptureRow, time::OffsetDateTime)> = rows
        .iter()
        .filter_map(|r| {
            let t = crate::bracket::parse_iso8601(r.capture_time_utc.as_deref()?)?;
            Some((r, t))
        })
        .collect();
    let Some(day) = timed.iter().map(|(_, t)| t.date()).min() else {
        return (Vec::new(), false);
    };
    let midnight = day.midnight().assume_utc();
    let points = timed
        .iter()
        .map(|(r, t)| DayPoint {
            hour_utc: (*t - midnight).as_seconds_f64() / 3600.0,
            illuminance: r.horizontal_illuminance,
            sun_elevation_deg: r.sun_elevation_deg,
            state: if !r.is_ok() {
                DayState::Failed
            } else if r.sun_source.is_none() {
                DayState::SunHidden
            } else {
                DayState::Ok
            },
        })
        .collect();
    let processed: Vec<&CaptureRow> = rows.iter().filter(|r| r.is_ok()).collect();
    let absolute = !processed.is_empty()
        && processed
            .iter()
            .all(|r| r.illuminance_unit.as_deref() == Some("lux"));
    (points, absolute)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A station's day: 3-frame brackets (0, 1, 2 s apart) every 60 s, frames shuffled.
    fn station(captures: usize) -> Vec<f64> {
        let mut t = Vec::new();
        for c in 0..captures {
            for f in 0..3 {
                t.push(1_000.0 + 60.0 * c as f64 + f as f64);
            }
        }
        t.reverse();
        t.swap(0, 4);
        t
    }

    #[test]
    fn gap_is_found_between_bracket_and_capture_intervals() {
        let t = station(5);
        let g = group_by_gap(&t, None, 1.0).unwrap();
        assert_eq!(g.captures.len(), 5);
        assert!(g.captures.iter().all(|c| c.len() == 3));
        // Geometric mean of the 1 s gaps inside brackets and the 58 s gaps between them.
        assert!((g.gap_s.unwrap() - 58f64.sqrt()).abs() < 1e-12);
        assert!(g.gap_found);
        for c in &g.captures {
            let ts: Vec<f64> = c.iter().map(|&i| t[i]).collect();
            assert!(ts.windows(2).all(|w| w[1] - w[0] == 1.0), "{ts:?}");
        }
        assert_eq!(
            g.describe(),
            "15 frames in 5 captures (3 frames each), a new capture after a gap over 7.616 s (found)"
        );
    }

    #[test]
    fn burst_frames_with_equal_seconds_group_at_the_clock_resolution() {
        // Whole-second EXIF: frames of a burst share a second; captures 5 minutes apart.
        let t = [0.0, 0.0, 1.0, 300.0, 300.0, 300.0, 600.0, 601.0, 601.0];
        let g = group_by_gap(&t, None, 1.0).unwrap();
        assert_eq!(
            g.captures,
            vec![vec![0, 1, 2], vec![3, 4, 5], vec![6, 7, 8]]
        );
    }

    #[test]
    fn given_gap_is_used_and_irregular_intervals_still_split() {
        let t = [0.0, 1.0, 2.0, 62.0, 63.0, 64.0, 960.0, 961.0];
        let g = group_by_gap(&t, Some(30.0), 1.0).unwrap();
        assert_eq!(g.captures, vec![vec![0, 1, 2], vec![3, 4, 5], vec![6, 7]]);
        assert!(!g.gap_found);
        let auto = group_by_gap(&t, None, 1.0).unwrap();
        assert_eq!(auto.captures, g.captures);
    }

    #[test]
    fn one_bracket_and_ambiguous_gaps() {
        assert_eq!(
            group_by_gap(&[5.0, 3.0, 4.0], None, 1.0).unwrap().captures,
            vec![vec![1, 2, 0]]
        );
        // Gaps of 20, 30, 40 s: neither one bracket nor a clear split.
        let e = group_by_gap(&[0.0, 20.0, 50.0, 90.0], None, 1.0).unwrap_err();
        assert!(matches!(e, BatchError::NoGap { .. }), "{e}");
        assert!(group_by_gap(&[], None, 1.0).is_err());
        assert!(group_by_gap(&[1.0], Some(-1.0), 1.0).is_err());
    }

    #[test]
    fn count_grouping_keeps_the_rest_in_the_last_capture() {
        let g = group_by_count(7, 3).unwrap();
        assert_eq!(g.captures, vec![vec![0, 1, 2], vec![3, 4, 5], vec![6]]);
        assert!(group_by_count(3, 0).is_err());
    }

    #[test]
    fn manifest_reads_fractions_and_empty_times_and_names_bad_lines() {
        let m = "capture,file,exposure_s\n# a comment\nA,a1.jpg,1/400\nA,a2.jpg,0.01\nB,b1.jpg,\n";
        let rows = parse_manifest("m.csv", m).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].exposure_s, Some(1.0 / 400.0));
        assert_eq!(rows[2].exposure_s, None);
        let (names, g) = group_manifest(&rows);
        assert_eq!(names, vec!["A", "B"]);
        assert_eq!(g.captures, vec![vec![0, 1], vec![2]]);
        let e = parse_manifest("m.csv", "capture,file,exposure_s\nA,a.jpg,fast\n").unwrap_err();
        assert!(e.to_string().starts_with("m.csv:2: "), "{e}");
        assert!(parse_manifest("m.csv", "A\n").is_err());
    }

    #[test]
    fn shards_partition_captures_round_robin() {
        let shards: Vec<Shard> = (0..3).map(|i| format!("{i}/3").parse().unwrap()).collect();
        for i in 0..10 {
            assert_eq!(shards.iter().filter(|s| s.owns(i)).count(), 1);
        }
        assert_eq!((0..10).filter(|&i| shards[1].owns(i)).count(), 3);
        assert!("3/3".parse::<Shard>().is_err());
        assert!("1/0".parse::<Shard>().is_err());
        assert!("x".parse::<Shard>().is_err());
        assert_eq!(shards[2].tag(), "shard-2-of-3");
    }

    #[test]
    fn names_sort_in_time_and_repeat_with_suffixes() {
        let t = time::macros::datetime!(2026-06-21 09:05:07);
        assert_eq!(capture_name(t, true), "20260621T090507Z");
        assert_eq!(capture_name(t, false), "20260621T090507-local");
        let mut n = vec!["a".to_string(), "b".into(), "a".into(), "a".into()];
        unique_names(&mut n);
        assert_eq!(n, vec!["a", "b", "a_2", "a_3"]);
    }

    #[test]
    fn fingerprint_is_fnv1a() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(fingerprint(b""), "cbf29ce484222325");
        assert_eq!(fingerprint(b"a"), "af63dc4c8601ec8c");
    }

    #[test]
    fn csv_quotes_what_needs_it() {
        let r = CaptureRow {
            capture: "c1".into(),
            frames: 2,
            exposure_times_s: vec![0.001, 0.25],
            status: "failed: a.jpg: cannot decode: \"bad\", truncated".into(),
            warnings: vec!["w1".into(), "w2".into()],
            options_hash: "00ff".into(),
            ..CaptureRow::default()
        };
        assert_eq!(
            r.csv_line(),
            "c1,,2,0.001;0.25,\"failed: a.jpg: cannot decode: \"\"bad\"\", truncated\",w1 | w2,,,,,,,,,,,,00ff"
        );
        assert_eq!(
            CaptureRow::CSV_HEADER.split(',').count(),
            // 17 separators and the one comma inside the quoted status.
            r.csv_line().matches(',').count()
        );
    }
}
