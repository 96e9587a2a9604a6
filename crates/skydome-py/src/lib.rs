//! # skydome for Python
//!
//! A PyO3 module (`skydome._skydome`, re-exported by the `skydome` package) over the same
//! entry point as the command line and the phone app, [`skydome::pipeline::run`]. Like them it
//! is a shell: it maps Python arguments onto [`skydome::pipeline::Options`], moves bytes and
//! numpy arrays, shows progress and raises errors; every rule about images is the library's,
//! so `Dome.save("x.hdr")` writes the very bytes `skydome merge … -o x.hdr` writes
//! (`tests/test_cli_equality.py`).
//!
//! Conventions are the library's: pixels origin top-left, `x` right, `y` down, arrays indexed
//! `[row, column, channel]` = `[y, x, (R, G, B)]`; angles in degrees; azimuth from true north
//! towards east; exposure times in seconds; radiance linear, relative units unless a luminance
//! or illuminance reading made it absolute (Radiance's W·sr⁻¹·m⁻²).
//!
//! The GIL is released while the core computes (decoding, calibration, merge, sky, pictures,
//! encoding, file reads and writes), so threads run several jobs at once. Copies of pixel data:
//! a numpy frame is copied once into the core (which frees each frame while it merges); a
//! result array (`Dome.radiance`, `Dome.preview`, `Dome.equirect`) is a read-only view of the
//! core's own buffer, not a copy; `read_hdr` hands over the decoder's buffer; `write_hdr` and
//! `tonemap` copy their input array once.

// The command line's allocator (huge pages for large buffers), shared by path rather than
// copied: a run from Python makes the same few large buffers, and with 4 KiB pages their first
// writes are page faults worth about a quarter of a 6 MP job's CPU time (see the module's doc).
// Rust's allocations in this extension (the core's buffers, and the numpy arrays handed over
// from them, which Rust frees) go through it; Python's and numpy's own memory does not.
#[path = "../../skydome-cli/src/alloc.rs"]
mod alloc;

#[global_allocator]
static ALLOCATOR: alloc::HugePageAlloc = alloc::HugePageAlloc;

mod arrays;
mod dome;
mod errors;
mod files;
mod frames;
mod hdr;
mod options;
mod profile;
mod progress;
mod pyvalue;

use pyo3::prelude::*;

pub use errors::Error;

/// The native part of the `skydome` package (`import skydome` re-exports everything here).
#[pymodule]
fn _skydome(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<Error>())?;
    m.add("__version__", skydome::VERSION)?;
    m.add_class::<dome::Dome>()?;
    m.add_class::<profile::CameraProfile>()?;
    m.add_function(wrap_pyfunction!(dome::run, m)?)?;
    m.add_function(wrap_pyfunction!(profile::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(hdr::read_hdr, m)?)?;
    m.add_function(wrap_pyfunction!(hdr::write_hdr, m)?)?;
    m.add_function(wrap_pyfunction!(hdr::tonemap, m)?)?;
    m.add_function(wrap_pyfunction!(dome::_dome_from_state, m)?)?;
    m.add_function(wrap_pyfunction!(profile::_profile_from_dict, m)?)?;
    Ok(())
}
