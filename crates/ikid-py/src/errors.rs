//! The Python exception hierarchy, mapped from the core's error enum in one place.

use ikid::Error;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;

create_exception!(ikid, IkidError, PyException, "Base class of every error raised by ikid.");
create_exception!(ikid, ModelFileError, IkidError, "A model file is corrupt, truncated, or does not fit its model card (a missing file raises FileNotFoundError).");
create_exception!(ikid, InputError, IkidError, "An input (frame, array, argument) is malformed; also a ValueError.");

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("IkidError", py.get_type::<IkidError>())?;
    m.add("ModelFileError", py.get_type::<ModelFileError>())?;
    // InputError is also a ValueError, so generic `except ValueError` handlers catch it.
    let input_error = py.get_type::<InputError>();
    let bases = (py.get_type::<IkidError>(), py.get_type::<PyValueError>());
    input_error.setattr("__bases__", bases)?;
    m.add("InputError", input_error)?;
    Ok(())
}

/// Converts a core error into the matching Python exception, keeping the core's message.
pub fn to_py(err: Error) -> PyErr {
    let msg = err.to_string();
    match err {
        Error::FrameLength { .. }
        | Error::NonFiniteInput { .. }
        | Error::NonFiniteOutput { .. }
        | Error::DegenerateSegment { .. }
        | Error::MissingMarkers { .. }
        | Error::OutlierMarker { .. }
        | Error::BadArgument { .. } => {
            InputError::new_err(msg)
        }
        Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            pyo3::exceptions::PyFileNotFoundError::new_err(msg)
        }
        _ => ModelFileError::new_err(msg),
    }
}

/// An input error raised by the binding's own argument checks.
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
