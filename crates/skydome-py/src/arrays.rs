//! numpy in and out.
//!
//! In: an (H, W, 3) `uint8`/`uint16`/`float32` array is copied once into the core's own
//! buffer (the core owns and frees its buffers as it goes). Out: a result image is either a
//! read-only view of a buffer a Python object owns ([`view`]: `Dome.radiance`), or the core's
//! buffer handed to numpy without a copy ([`owned`]: `read_hdr`, `tonemap`).

use numpy::ndarray::ArrayView3;
use numpy::{
    Element, PyArray1, PyArray3, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use skydome::RgbImage;

use crate::errors::{type_error, value_error};

/// A read-only (H, W, 3) numpy view of `img`, kept alive by `owner` (which holds `img` and
/// never changes it).
///
/// # Safety
/// `img` must be owned by `owner` and never be mutated or reallocated while `owner` lives.
pub unsafe fn view<'py, T: Element + Copy>(
    img: &RgbImage<T>,
    owner: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray3<T>>> {
    let v = ArrayView3::from_shape((img.height, img.width, 3), &img.data[..])
        .map_err(|e| value_error("image", e))?;
    // SAFETY: per the caller, `owner` owns the buffer and keeps it unchanged and in place.
    let a = unsafe { PyArray3::borrow_from_array(&v, owner) };
    a.readwrite().make_nonwriteable();
    Ok(a)
}

/// An (H, W, 3) numpy array that takes over `img`'s buffer (no copy).
pub fn owned<T: Element + Copy>(
    py: Python<'_>,
    img: RgbImage<T>,
) -> PyResult<Bound<'_, PyArray3<T>>> {
    let (h, w) = (img.height, img.width);
    PyArray1::from_vec(py, img.data).reshape([h, w, 3])
}

/// The dtype name and shape of `obj` when it is a numpy array.
pub fn describe(obj: &Bound<'_, PyAny>) -> Option<(String, Vec<usize>)> {
    let a = obj.cast::<PyUntypedArray>().ok()?;
    let dtype = a.dtype().str().map(|s| s.to_string()).unwrap_or_default();
    Some((dtype, a.shape().to_vec()))
}

/// Checks that `obj` is an (H, W, 3) numpy array; returns (height, width).
pub fn rgb_shape(arg: &str, obj: &Bound<'_, PyAny>) -> PyResult<(usize, usize)> {
    let a = obj.cast::<PyUntypedArray>().map_err(|_| {
        type_error(
            arg,
            format!("expected a numpy array, got {}", type_name(obj)),
        )
    })?;
    let s = a.shape();
    if s.len() != 3 || s[2] != 3 || s[0] == 0 || s[1] == 0 {
        return Err(value_error(
            arg,
            format!(
                "expected an array of shape (height, width, 3) (RGB, row-major), got shape {}",
                shape_text(s)
            ),
        ));
    }
    Ok((s[0], s[1]))
}

/// The samples of an (H, W, 3) array of `T`, row-major, copied once.
pub fn copy_samples<T: Element + Copy>(arr: &Bound<'_, PyArray3<T>>) -> Vec<T> {
    let r = arr.readonly();
    // `as_slice` also accepts Fortran order, whose memory order is not row-major: only a
    // C-contiguous array is copied as one block.
    match r.as_slice() {
        Ok(s) if arr.is_c_contiguous() => s.to_vec(),
        // A slice, a transposed view, Fortran order: numpy's logical order is row-major.
        _ => r.as_array().iter().copied().collect(),
    }
}

/// True when `obj` is a numpy array of element type `T`.
pub fn is_dtype<T: Element>(obj: &Bound<'_, PyAny>) -> bool {
    obj.cast::<PyUntypedArray>()
        .is_ok_and(|a| a.dtype().is_equiv_to(&numpy::dtype::<T>(obj.py())))
}

/// `(2, 3, 4)` for a shape.
pub fn shape_text(s: &[usize]) -> String {
    let parts: Vec<String> = s.iter().map(|d| d.to_string()).collect();
    match parts.len() {
        1 => format!("({},)", parts[0]),
        _ => format!("({})", parts.join(", ")),
    }
}

/// The Python type name of `obj`, for messages.
pub fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "object".into())
}
