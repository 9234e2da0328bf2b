//! NumPy ⇄ Rust conversion, one dtype policy for every array argument: float32 or float64
//! ndarrays of any layout, or (nested) sequences of numbers; nothing else (no ints, bools,
//! complex, bytes or strings — those raise `InputError` naming the argument).

use crate::errors::input;
use numpy::{PyArray1, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyString};

/// Longest frame converted on the stack by [`with_frame`] (no allocation per push).
const MAX_STACK_FRAME: usize = 64;

/// `obj` as a float ndarray: itself if it is one (dtype checked), else `numpy.asarray` of a
/// sequence of numbers.
fn as_float_array<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    if obj.is_instance_of::<PyBytes>() || obj.is_instance_of::<PyByteArray>() || obj.is_instance_of::<PyString>() {
        return Err(input(format!(
            "{what}: expected a float array or a sequence of numbers, got {}",
            obj.get_type().name()?
        )));
    }
    let arr = match obj.cast::<PyUntypedArray>() {
        Ok(arr) => arr.clone(),
        Err(_) => {
            let np = obj.py().import("numpy")?;
            let converted = np
                .call_method1("asarray", (obj, "float64"))
                .map_err(|e| input(format!("{what}: expected a float array or a sequence of numbers ({e})")))?;
            converted.cast_into::<PyUntypedArray>().map_err(|e| input(format!("{what}: {e}")))?
        }
    };
    let dtype = arr.dtype();
    if dtype.kind() != b'f' || !(dtype.itemsize() == 4 || dtype.itemsize() == 8) {
        return Err(input(format!("{what}: dtype {} is not supported; pass float32 or float64", dtype.str()?)));
    }
    Ok(arr)
}

fn check_rank(what: &str, shape: &[usize], ndim: usize) -> PyResult<()> {
    if shape.len() != ndim {
        let expected = if ndim == 1 { "a 1-D array (one frame)".to_string() } else { format!("a {ndim}-D array") };
        return Err(input(format!("{what}: expected {expected}, got shape {shape:?}")));
    }
    Ok(())
}

/// Calls `f` with the values of `obj` as contiguous f32 in C order, and its shape. A
/// C-contiguous float32 array is read in place; anything else is converted.
pub fn with_floats<R>(
    obj: &Bound<'_, PyAny>,
    what: &str,
    ndim: usize,
    f: impl FnOnce(&[f32], &[usize]) -> PyResult<R>,
) -> PyResult<R> {
    let arr = as_float_array(obj, what)?;
    let shape = arr.shape().to_vec();
    check_rank(what, &shape, ndim)?;
    if let Ok(a) = arr.cast::<PyArrayDyn<f32>>() {
        let ro = a.try_readonly()?;
        return match ro.as_slice() {
            Ok(values) if a.is_c_contiguous() => f(values, &shape),
            _ => f(&ro.as_array().iter().copied().collect::<Vec<f32>>(), &shape),
        };
    }
    let a = arr.cast::<PyArrayDyn<f64>>().map_err(|e| input(format!("{what}: {e}")))?;
    let ro = a.try_readonly()?;
    let values: Vec<f32> = ro.as_array().iter().map(|&v| v as f32).collect();
    f(&values, &shape)
}

/// One frame: contiguous 1-D float32 is borrowed, float64 converted on the stack (so a
/// push allocates nothing either way); anything else goes through [`with_floats`].
pub fn with_frame<R>(obj: &Bound<'_, PyAny>, f: impl FnOnce(&[f32]) -> PyResult<R>) -> PyResult<R> {
    if let Ok(arr) = obj.cast::<PyArray1<f32>>()
        && let Ok(ro) = arr.try_readonly()
        && let Ok(values) = ro.as_slice()
    {
        return f(values);
    }
    if let Ok(arr) = obj.cast::<PyArray1<f64>>()
        && let Ok(ro) = arr.try_readonly()
        && let Ok(values) = ro.as_slice()
        && values.len() <= MAX_STACK_FRAME
    {
        let mut buf = [0f32; MAX_STACK_FRAME];
        for (b, v) in buf.iter_mut().zip(values) {
            *b = *v as f32;
        }
        return f(&buf[..values.len()]);
    }
    with_floats(obj, "frame", 1, |values, _| f(values))
}

/// One frame as f64 for the f64 solvers: contiguous 1-D float64 is borrowed, float32 widened
/// on the stack (no allocation per push either way); anything else goes through conversion.
pub fn with_frame_f64<R>(obj: &Bound<'_, PyAny>, f: impl FnOnce(&[f64]) -> PyResult<R>) -> PyResult<R> {
    if let Ok(arr) = obj.cast::<PyArray1<f64>>()
        && let Ok(ro) = arr.try_readonly()
        && let Ok(values) = ro.as_slice()
    {
        return f(values);
    }
    if let Ok(arr) = obj.cast::<PyArray1<f32>>()
        && let Ok(ro) = arr.try_readonly()
        && let Ok(values) = ro.as_slice()
        && values.len() <= MAX_STACK_FRAME
    {
        let mut buf = [0f64; MAX_STACK_FRAME];
        for (b, v) in buf.iter_mut().zip(values) {
            *b = *v as f64;
        }
        return f(&buf[..values.len()]);
    }
    let arr = as_float_array(obj, "frame")?;
    check_rank("frame", arr.shape(), 1)?;
    let values: Vec<f64> = if let Ok(a) = arr.cast::<PyArrayDyn<f64>>() {
        a.try_readonly()?.as_array().iter().copied().collect()
    } else {
        let a = arr.cast::<PyArrayDyn<f32>>().map_err(|e| input(format!("frame: {e}")))?;
        a.try_readonly()?.as_array().iter().map(|&v| v as f64).collect()
    };
    f(&values)
}

/// Calls `f` with an `(n, cols)` float array as f64 values (C order) and `n`; for quantities
/// kept in f64 (angles, markers for the reference solvers and the simulator).
pub fn with_f64_rows<R>(
    obj: &Bound<'_, PyAny>,
    what: &str,
    cols: usize,
    f: impl FnOnce(&[f64], usize) -> PyResult<R>,
) -> PyResult<R> {
    let arr = as_float_array(obj, what)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 || shape[1] != cols {
        return Err(input(format!("{what}: expected shape (n, {cols}), got {shape:?}")));
    }
    let values: Vec<f64> = if let Ok(a) = arr.cast::<PyArrayDyn<f64>>() {
        a.try_readonly()?.as_array().iter().copied().collect()
    } else {
        let a = arr.cast::<PyArrayDyn<f32>>().map_err(|e| input(format!("{what}: {e}")))?;
        a.try_readonly()?.as_array().iter().map(|&v| v as f64).collect()
    };
    f(&values, shape[0])
}

/// An argument that is not a number: an `ArgumentError` naming it and what was given (pyo3's
/// own TypeError names neither what the number is nor the value).
pub fn number_arg(value: &Bound<'_, PyAny>, what: &str, expected: &str) -> PyResult<f64> {
    if value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(crate::errors::ArgumentError::new_err(format!("{what}: is a bool, expected {expected}")));
    }
    value.extract::<f64>().map_err(|_| {
        let given = value.repr().map_or_else(|_| "?".into(), |r| r.to_string());
        crate::errors::ArgumentError::new_err(format!("{what}: expected {expected}, got {given}"))
    })
}

/// A model given as an `ikid.Model` or a name or path `ikid.load` takes (`what` names the
/// argument in errors).
pub fn model_arg<'py>(value: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, crate::model::Model>> {
    object_or_loaded(value, "load", what, "an ikid.Model or a model's name or file")
}

/// A calibration given as an `ikid.Calibration` or the path of its file (`ikid.load_calibration`).
pub fn calibration_arg<'py>(
    value: &Bound<'py, PyAny>,
    what: &str,
) -> PyResult<Bound<'py, crate::calibration::Calibration>> {
    object_or_loaded(value, "load_calibration", what, "an ikid.Calibration or the path of its file")
}

/// `value` as a `T`, a string or path given being loaded first by `ikid.<loader>`; an
/// `ArgumentError` naming `what`, `expected` and the type given otherwise.
fn object_or_loaded<'py, T: pyo3::PyTypeCheck>(
    value: &Bound<'py, PyAny>,
    loader: &str,
    what: &str,
    expected: &str,
) -> PyResult<Bound<'py, T>> {
    let value = if value.is_instance_of::<pyo3::types::PyString>() || is_path(value) {
        value.py().import("ikid")?.call_method1(loader, (value,))?
    } else {
        value.clone()
    };
    value.cast_into::<T>().map_err(|e| {
        let given = e.into_inner().get_type().name().map_or_else(|_| "?".into(), |n| n.to_string());
        crate::errors::ArgumentError::new_err(format!("{what}: expected {expected}, got {given}"))
    })
}

fn is_path(value: &Bound<'_, PyAny>) -> bool {
    value.hasattr("__fspath__").unwrap_or(false)
}
