//! Exposure times given by the user: one time, a `--times` list, or a list file matched to the frames.

use super::BracketError;

/// Parses one exposure time in seconds: `1/400`, `0.0025`, `2`, `1/2.5`. `file` names the source
/// for the error message. Refuses zero, negatives, NaN/infinity and times above 24 hours.
pub fn parse_time(file: &str, text: &str) -> Result<f64, BracketError> {
    let bad = || BracketError::BadTime {
        file: file.to_string(),
        value: text.to_string(),
    };
    let t = text.trim();
    let v = match t.split_once('/') {
        Some((n, d)) => {
            let n: f64 = n.trim().parse().map_err(|_| bad())?;
            let d: f64 = d.trim().parse().map_err(|_| bad())?;
            n / d
        }
        None => t.parse().map_err(|_| bad())?,
    };
    if v.is_finite() && v > 0.0 && v <= 86_400.0 {
        Ok(v)
    } else {
        Err(bad())
    }
}

/// Parses a comma-separated `--times` list (e.g. `1/400,1/100,1/25`).
pub fn parse_times(text: &str) -> Result<Vec<f64>, BracketError> {
    text.split(',')
        .map(|t| parse_time("exposure times", t))
        .collect()
}

/// Parses a list file: one `FILE TIME` pair per line, or `FILE TIME 1/TIME` (the common
/// three-column form, whose third column is the reciprocal of the time, e.g.
/// `DSC_0094.png 0.00390625 256`). Columns are separated by whitespace; `#` starts a comment (a
/// header line such as `# Filename exposure 1/shutter_speed`); blank lines are ignored.
/// `list_name` is used in error messages.
///
/// A third column must agree with 1/TIME within the rounding of its last written digit, or
/// within 1/10 stop (7 %, which covers nominal shutter speeds written beside exact times, such as
/// 60 for 1/64 s); otherwise the line is refused, naming it. Returns the pairs in file order;
/// file names are as written ([`times_from_list`] matches them to frames).
pub fn parse_list_file(list_name: &str, text: &str) -> Result<Vec<(String, f64)>, BracketError> {
    Ok(list_entries(list_name, text)?
        .into_iter()
        .map(|e| (e.file, e.time_s))
        .collect())
}

/// The exposure times of `frames` (file names or paths, as the caller names its frames), in
/// that order, in seconds, from the list file `text` ([`parse_list_file`]'s format) called
/// `list_name` in messages.
///
/// A frame matches the lines that name its full path as given; when none does, the lines whose
/// base name (after the last `/` or `\`) is the frame's. Lines naming no frame are ignored, so
/// one list can serve several subsets of a bracket. A frame that no line names, or that two
/// matching lines give different times, is refused with an error naming it.
pub fn times_from_list<S: AsRef<str>>(
    list_name: &str,
    text: &str,
    frames: &[S],
) -> Result<Vec<f64>, BracketError> {
    let entries = list_entries(list_name, text)?;
    frames
        .iter()
        .map(|f| time_of(list_name, &entries, f.as_ref()))
        .collect()
}

/// One line of a list file.
struct ListEntry {
    /// Line number (1-based).
    line: usize,
    /// The file name as written.
    file: String,
    /// Exposure time in seconds.
    time_s: f64,
}

fn list_entries(list_name: &str, text: &str) -> Result<Vec<ListEntry>, BracketError> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at = format!("{list_name} line {}", n + 1);
        let columns: Vec<&str> = line.split_whitespace().collect();
        let (file, time, inverse) = match columns[..] {
            [file, time] => (file, time, None),
            [file, time, inverse] => (file, time, Some(inverse)),
            _ => {
                return Err(BracketError::BadTime {
                    file: at,
                    value: line.to_string(),
                })
            }
        };
        let time_s = parse_time(&at, time)?;
        if let Some(inverse) = inverse {
            inverse_agrees(list_name, n + 1, time, time_s, inverse)?;
        }
        out.push(ListEntry {
            line: n + 1,
            file: file.to_string(),
            time_s,
        });
    }
    Ok(out)
}

/// Checks a list line's third column against 1/time (see [`parse_list_file`]).
fn inverse_agrees(
    list_name: &str,
    line: usize,
    time: &str,
    time_s: f64,
    inverse: &str,
) -> Result<(), BracketError> {
    let expected = 1.0 / time_s;
    let mismatch = || BracketError::InverseTimeMismatch {
        list: list_name.to_string(),
        line,
        time: time.to_string(),
        inverse: inverse.to_string(),
        expected: format!("{:.4}", expected)
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string(),
    };
    let v: f64 = inverse.parse().map_err(|_| mismatch())?;
    // Half a unit of the last digit written: 0.5 for `256`, 0.05 for `2.5`.
    let rounding = match inverse.split_once('.') {
        _ if inverse.contains(['e', 'E']) => 0.0,
        Some((_, digits)) => 0.5 * 10f64.powi(-(digits.len() as i32)),
        None => 0.5,
    };
    let within_rounding = (v - expected).abs() <= rounding + 1e-9 * expected;
    let within_tenth_stop = v > 0.0 && (v * time_s).log2().abs() <= 0.1;
    match v.is_finite() && (within_rounding || within_tenth_stop) {
        true => Ok(()),
        false => Err(mismatch()),
    }
}

/// The time of one frame: the lines naming its full path, else those naming its base name.
fn time_of(list_name: &str, entries: &[ListEntry], frame: &str) -> Result<f64, BracketError> {
    let base = base_name(frame);
    let exact: Vec<&ListEntry> = entries.iter().filter(|e| e.file == frame).collect();
    let matches = match exact.is_empty() {
        false => exact,
        true => entries
            .iter()
            .filter(|e| base_name(&e.file) == base)
            .collect(),
    };
    let Some(first) = matches.first() else {
        return Err(BracketError::NotListed {
            file: frame.to_string(),
            list: list_name.to_string(),
            base: base.to_string(),
        });
    };
    match matches.iter().find(|e| e.time_s != first.time_s) {
        Some(other) => Err(BracketError::ListedTwice {
            file: frame.to_string(),
            list: list_name.to_string(),
            line: first.line,
            other_line: other.line,
        }),
        None => Ok(first.time_s),
    }
}

/// The part of a path after its last `/` or `\` (either separator, whichever system wrote the
/// list).
fn base_name(path: &str) -> &str {
    path.rsplit(['/', '\\']).next().unwrap_or(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_match_by_full_path_then_base_name() {
        let list = "# a comment\nshots/a.jpg 1/100\nb.jpg 0.04  # trailing comment\nc.jpg 1/25\n";
        let t = times_from_list("t.txt", list, &["shots/a.jpg", "/home/me/shots/b.jpg"]).unwrap();
        assert_eq!(t, [0.01, 0.04]);
        // By base name from another directory, and with Windows separators in the list.
        let t = times_from_list("t.txt", "C:\\shots\\a.jpg 2\n", &["other/a.jpg"]).unwrap();
        assert_eq!(t, [2.0]);
        // A full-path line wins over a base-name line.
        let list = "x/a.jpg 1/100\ny/a.jpg 1/25\n";
        assert_eq!(
            times_from_list("t.txt", list, &["y/a.jpg"]).unwrap(),
            [0.04]
        );
    }

    #[test]
    fn unlisted_and_ambiguous_frames_are_named() {
        let e = times_from_list("t.txt", "a.jpg 1/100\n", &["a.jpg", "dir/b.jpg"]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "dir/b.jpg: not listed in t.txt; add a line 'b.jpg TIME'"
        );
        let list = "x/a.jpg 1/100\ny/a.jpg 1/25\n";
        let e = times_from_list("t.txt", list, &["z/a.jpg"]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "z/a.jpg: listed twice in t.txt with different times (lines 1 and 2); keep one"
        );
        // The same time twice is no ambiguity.
        let list = "x/a.jpg 1/100\ny/a.jpg 0.01\n";
        assert_eq!(times_from_list("t.txt", list, &["a.jpg"]).unwrap(), [0.01]);
    }

    #[test]
    fn three_column_lines_check_the_reciprocal() {
        let list = "# Filename exposure 1/shutter_speed\na.png 1 1\nb.png 0.0009765625 1024 \nc.png 0.333 3\nd.png 0.015625 60\n";
        let t = times_from_list("l.txt", list, &["a.png", "b.png", "c.png", "d.png"]).unwrap();
        assert_eq!(t, [1.0, 0.0009765625, 0.333, 0.015625]);
        let e = parse_list_file("l.txt", "a.png 1 1\nb.png 0.5 4\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "l.txt line 2: third column 4 is not 1/time for time 0.5 s (1/time = 2); correct one of them or drop the third column"
        );
        assert!(parse_list_file("l.txt", "a.png 0.01 100 7\n").is_err());
        assert!(parse_list_file("l.txt", "a.png 0.01 fast\n").is_err());
    }
}
