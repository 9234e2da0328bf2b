//! The Python exception hierarchy, mapped from the core's [`ErrorKind`] in one place.
//!
//! `IkidError` is the base; each kind has its class (`InputError`, `ArgumentError`,
//! `ModelFileError`, `ReadError`, and `NotFoundError` for a missing file). Every exception
//! raised from a core error carries the core's classification as attributes — `kind`, `code`
//! (stable), `frame` (or None), `markers` (a list) and `reason` (the message without its
//! `frame N:` prefix) — so no Python code needs to read a message to know what happened.

use ikid::{Error, ErrorKind};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

create_exception!(ikid, IkidError, PyException, "Base class of every error raised by ikid.");
create_exception!(
    ikid,
    ModelFileError,
    IkidError,
    "A model file is corrupt, truncated, or does not fit its model card."
);
create_exception!(
    ikid,
    InputError,
    IkidError,
    "A frame or array is unusable (wrong length, missing marker, jump...); also a ValueError."
);
create_exception!(
    ikid,
    ArgumentError,
    InputError,
    "An argument other than frame data is out of range (a setting, a buffer, a calibration, a time)."
);

/// `ReadError(IkidError, OSError)` and `NotFoundError(ReadError, FileNotFoundError)`: made with
/// `type()`, since an OSError base cannot be given to an existing class.
static READ_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();
static NOT_FOUND_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    let base = py.get_type::<IkidError>();
    // Class-level defaults, for exceptions raised by Python code without a core error.
    for (name, value) in [("kind", py.None()), ("code", py.None()), ("frame", py.None()), ("reason", py.None())] {
        base.setattr(name, value)?;
    }
    base.setattr("markers", PyTuple::empty(py))?;
    m.add("IkidError", &base)?;
    m.add("ModelFileError", py.get_type::<ModelFileError>())?;
    // InputError is also a ValueError, so generic `except ValueError` handlers catch it.
    let input_error = py.get_type::<InputError>();
    input_error.setattr("__bases__", (base.clone(), py.get_type::<PyValueError>()))?;
    m.add("InputError", input_error)?;
    m.add("ArgumentError", py.get_type::<ArgumentError>())?;
    let make = |name: &str, bases: Bound<'_, PyTuple>, doc: &str| -> PyResult<Py<PyType>> {
        let namespace = PyDict::new(py);
        namespace.set_item("__module__", "ikid")?;
        namespace.set_item("__doc__", doc)?;
        let class = py.get_type::<PyType>().call1((name, bases, namespace))?;
        Ok(class.cast_into::<PyType>()?.unbind())
    };
    let read = make(
        "ReadError",
        PyTuple::new(py, [base.as_any(), py.get_type::<PyOSError>().as_any()])?,
        "A file could not be read (not a regular file, too large, no permission); also an OSError.",
    )?;
    let not_found = make(
        "NotFoundError",
        PyTuple::new(py, [read.bind(py).as_any(), py.get_type::<PyFileNotFoundError>().as_any()])?,
        "A file does not exist; also a FileNotFoundError.",
    )?;
    m.add("ReadError", read.bind(py))?;
    m.add("NotFoundError", not_found.bind(py))?;
    let _ = READ_ERROR.set(py, read);
    let _ = NOT_FOUND_ERROR.set(py, not_found);
    Ok(())
}

/// Converts a core error into the exception of its kind, with the core's message and
/// classification attached.
pub fn to_py(err: Error) -> PyErr {
    Python::attach(|py| {
        let message = err.to_string();
        let exception = match err.kind() {
            ErrorKind::Input => InputError::new_err(message),
            ErrorKind::Argument => ArgumentError::new_err(message),
            ErrorKind::ModelFile => ModelFileError::new_err(message),
            ErrorKind::Io => {
                let class = if err.code() == "not_found" { &NOT_FOUND_ERROR } else { &READ_ERROR };
                match class.get(py) {
                    Some(class) => PyErr::from_type(class.bind(py).clone(), message),
                    None => pyo3::exceptions::PyOSError::new_err(message), // before registration
                }
            }
        };
        let value = exception.value(py);
        let attach = || -> PyResult<()> {
            value.setattr("kind", err.kind().name())?;
            value.setattr("code", err.code())?;
            value.setattr("frame", err.frame())?;
            value.setattr("markers", err.markers())?;
            value.setattr("reason", err.message_without_frame())?;
            Ok(())
        };
        // Attributes are an addition to the message; failing to set them loses nothing else.
        let _ = attach();
        exception
    })
}

/// An input error raised by the binding's own argument checks (array shape, dtype, length).
pub fn input(msg: impl Into<String>) -> PyErr {
    InputError::new_err(msg.into())
}

/// `?`-friendly conversion for core results.
pub trait IntoPy<T> {
    fn py_err(self) -> PyResult<T>;
}

impl<T> IntoPy<T> for ikid::Result<T> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}
