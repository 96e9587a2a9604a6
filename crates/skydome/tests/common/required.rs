//! The one guard for tests that need something from outside the repository: the real photo
//! sets in `../shared/data`, or an outside reader (a Python with OpenCV and OpenImageIO, or
//! pyradiance's Radiance binaries). Shared by every test crate of the workspace, each of which
//! includes this file by path (`#[path = "…/skydome/tests/common/required.rs"] mod required;`).
//!
//! When the thing is missing, the guard prints `skipping <test>: <why>` to the terminal (even
//! under `cargo test`'s output capture) and returns `None`, and the test returns early. In CI
//! a skip is a failure: `SKYDOME_REQUIRE_SHARED_DATA=1` for the photo sets,
//! `SKYDOME_REQUIRE_INDEPENDENT_READERS=1` for the outside readers. `SKYDOME_PYTHON` names the
//! Python (default `python3`).
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The switch that turns a missing `../shared/data` into a failure.
pub const REQUIRE_SHARED_DATA: &str = "SKYDOME_REQUIRE_SHARED_DATA";
/// The switch that turns a missing outside reader into a failure.
pub const REQUIRE_READERS: &str = "SKYDOME_REQUIRE_INDEPENDENT_READERS";

/// The running test's name (libtest names each test's thread after it), or the caller's
/// file and line when the test runs on the main thread.
#[track_caller]
pub fn test_name() -> String {
    match std::thread::current().name() {
        Some(n) if n != "main" => n.to_owned(),
        _ => std::panic::Location::caller().to_string(),
    }
}

/// Reports that the running test skips (some of) its checks because `why`: a failure when the
/// environment variable `switch` is `1`, otherwise `skipping <test>: <why>` on standard error,
/// written past libtest's capture so a plain `cargo test` shows it.
#[track_caller]
pub fn skip(switch: &str, why: &str) {
    let test = test_name();
    assert!(
        std::env::var(switch).as_deref() != Ok("1"),
        "{test}: {why}, but {switch}=1"
    );
    let _ = writeln!(std::io::stderr(), "skipping {test}: {why}");
}

/// `../shared/data/<sub>` (`sub = ""`: the data folder itself) beside the repository, or
/// `None` after reporting the skip (see [`skip`]).
#[track_caller]
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let d = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(sub);
    if d.is_dir() {
        return Some(d);
    }
    skip(
        REQUIRE_SHARED_DATA,
        &format!("{} not found (the real photo sets)", d.display()),
    );
    None
}

/// The Python to run outside readers with: `$SKYDOME_PYTHON`, default `python3`.
pub fn python() -> String {
    std::env::var("SKYDOME_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// The Python that can `import cv2, OpenImageIO` (the independent readers of
/// `scripts/independent_readers.py`), or `None` after reporting the skip.
#[track_caller]
pub fn independent_readers() -> Option<String> {
    let py = python();
    let ok = Command::new(&py)
        .args(["-c", "import cv2, OpenImageIO"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    skip(
        REQUIRE_READERS,
        &format!(
            "`{py}` cannot import cv2 and OpenImageIO \
             (pip install -r scripts/requirements.txt, or set SKYDOME_PYTHON)"
        ),
    );
    None
}

/// pyradiance's `bin` and `lib` folders (Radiance's own binaries: `gendaylit`, `rpict`,
/// `evalglare` …), found through [`python`], or `None` after reporting the skip.
#[track_caller]
pub fn radiance_tools() -> Option<(PathBuf, PathBuf)> {
    let py = python();
    let out = Command::new(&py)
        .args([
            "-c",
            "import os, pyradiance; print(os.path.dirname(pyradiance.__file__))",
        ])
        .output()
        .ok()
        .filter(|o| o.status.success());
    if let Some(o) = out {
        let dir = PathBuf::from(String::from_utf8_lossy(&o.stdout).trim());
        return Some((dir.join("bin"), dir.join("lib")));
    }
    skip(
        REQUIRE_READERS,
        &format!(
            "`{py}` lacks pyradiance (pip install -r scripts/requirements.txt, \
             or set SKYDOME_PYTHON)"
        ),
    );
    None
}

/// The switch that turns a missing real RAW bracket into a failure.
pub const REQUIRE_RAW_BRACKET: &str = "SKYDOME_REQUIRE_RAW_BRACKET";

/// The folder of the real RAW bracket (HDRMerge's `sample1.dng`–`sample3.dng`, fetched from
/// Debian by `scripts/fetch-raw-bracket.sh`): `$SKYDOME_RAW_BRACKET_DIR`, default
/// `target/raw-bracket-hdrmerge` in the workspace, or `None` after reporting the skip (a
/// failure when `SKYDOME_REQUIRE_RAW_BRACKET=1`).
#[track_caller]
pub fn raw_bracket() -> Option<PathBuf> {
    let d = std::env::var_os("SKYDOME_RAW_BRACKET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/raw-bracket-hdrmerge")
        });
    if ["sample1.dng", "sample2.dng", "sample3.dng"]
        .iter()
        .all(|f| d.join(f).is_file())
    {
        return Some(d);
    }
    skip(
        REQUIRE_RAW_BRACKET,
        &format!(
            "{} lacks the real RAW bracket (run scripts/fetch-raw-bracket.sh)",
            d.display()
        ),
    );
    None
}
