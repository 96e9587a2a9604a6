//! Reading and writing files: whole reads naming the file in errors, and atomic writes
//! (a temporary file beside the target, then a rename) so a failed write leaves no partial
//! file and an existing file is replaced whole or not at all.

use std::io::Write;
use std::path::{Path, PathBuf};

use pyo3::prelude::*;

use crate::errors::type_error;

/// A path argument: `str` or `os.PathLike` (not bytes, not other objects).
pub fn path_arg(arg: &str, obj: &Bound<'_, PyAny>) -> PyResult<PathBuf> {
    if obj.is_instance_of::<pyo3::types::PyString>() || obj.hasattr("__fspath__")? {
        return obj
            .extract::<PathBuf>()
            .map_err(|_| type_error(arg, "expected a path (str or os.PathLike)"));
    }
    Err(type_error(
        arg,
        format!(
            "expected a path (str or os.PathLike), got {}",
            obj.get_type().name()?
        ),
    ))
}

/// Reads a whole file; the error names it, as the command line's `<file>: cannot read`.
pub fn read(p: &Path) -> Result<Vec<u8>, String> {
    std::fs::read(p).map_err(|e| format!("{}: cannot read: {e}", p.display()))
}

/// The lower-cased extension of a path.
pub fn extension(p: &Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Writes `bytes` to `p` atomically. Refuses a directory, a missing folder, and any of
/// `inputs` (a job's photos are never overwritten). An existing file is replaced, as numpy's
/// and OpenCV's writers do.
pub fn write_atomic(p: &Path, bytes: &[u8], inputs: &[PathBuf]) -> Result<(), String> {
    let name = p.display();
    if inputs.iter().any(|i| same_file(i, p)) {
        return Err(format!("{name}: refusing to overwrite an input file"));
    }
    if p.is_dir() {
        return Err(format!("{name}: is a directory; give a file name"));
    }
    let dir = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(format!("{name}: folder {} does not exist", dir.display()));
    }
    let mut tmp = tempfile::Builder::new()
        .prefix(".skydome-")
        .suffix(".tmp")
        .tempfile_in(&dir)
        .map_err(|e| format!("{name}: cannot create a file in {}: {e}", dir.display()))?;
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
        .map_err(|e| format!("{name}: cannot write: {e}"))?;
    tmp.persist(p)
        .map_err(|e| format!("{name}: cannot rename into place: {}", e.error))?;
    Ok(())
}
