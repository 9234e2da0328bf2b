//! NumPy ⇄ Rust conversion: float32/float64 arrays (any layout) or sequences in, f32 slices out.

use crate::errors::input;
use numpy::{AllowTypeChange, PyArray1, PyArrayLike2, PyArrayDescrMethods, PyArrayLikeDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// Calls `f` with the values of `obj` as contiguous f32 (C order) and its shape.
///
/// Accepts float32/float64 ndarrays of any strides, or nested sequences of numbers. A
/// contiguous float32 array is read in place; anything else is converted (copied) first.
/// Refuses other dtypes (int, bool, complex, object) and other ranks than `ndim` with a
/// message naming `what`.
pub fn with_floats<R>(obj: &Bound<'_, PyAny>, what: &str, ndim: usize, f: impl FnOnce(&[f32], &[usize]) -> PyResult<R>) -> PyResult<R> {
    if let Ok(arr) = obj.cast::<PyUntypedArray>() {
        let dtype = arr.dtype();
        if dtype.kind() != b'f' || !(dtype.itemsize() == 4 || dtype.itemsize() == 8) {
            return Err(input(format!("{what}: dtype {} is not supported; pass float32 or float64", dtype.str()?)));
        }
    }
    let like: PyArrayLikeDyn<'_, f32, AllowTypeChange> = obj
        .extract()
        .map_err(|e| input(format!("{what}: expected a float array or a sequence of numbers ({e})")))?;
    let shape = like.shape().to_vec();
    if shape.len() != ndim {
        return Err(input(format!("{what}: expected a {ndim}-D array, got shape {shape:?}")));
    }
    // `as_slice` also accepts Fortran order (memory order ≠ logical order): require C order.
    match like.as_slice() {
        Ok(values) if like.is_c_contiguous() => f(values, &shape),
        _ => f(&like.as_array().iter().copied().collect::<Vec<f32>>(), &shape),
    }
}

/// One frame: the zero-copy fast path for a contiguous 1-D float32 array, else [`with_floats`].
pub fn with_frame<R>(obj: &Bound<'_, PyAny>, f: impl FnOnce(&[f32]) -> PyResult<R>) -> PyResult<R> {
    if let Ok(arr) = obj.cast::<PyArray1<f32>>()
        && let Ok(ro) = arr.try_readonly()
        && let Ok(values) = ro.as_slice()
    {
        return f(values);
    }
    with_floats(obj, "frame", 1, |values, _| f(values))
}

/// Calls `f` with an `(n, cols)` array of numbers as f64 values (C order) and `n`; for
/// quantities kept in f64 (angles, simulation inputs), unlike network inputs.
pub fn with_f64_rows<R>(obj: &Bound<'_, PyAny>, what: &str, cols: usize, f: impl FnOnce(&[f64], usize) -> PyResult<R>) -> PyResult<R> {
    let arr: PyArrayLike2<'_, f64, AllowTypeChange> =
        obj.extract().map_err(|e| input(format!("{what}: expected an (n, {cols}) float array ({e})")))?;
    let shape = arr.shape().to_vec();
    if shape[1] != cols {
        return Err(input(format!("{what}: expected shape (n, {cols}), got {shape:?}")));
    }
    let values: Vec<f64> = arr.as_array().iter().copied().collect();
    f(&values, shape[0])
}
