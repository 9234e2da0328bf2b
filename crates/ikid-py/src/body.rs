//! The body model's names and ranges, read from the core (never restated in Python).

use crate::conv::with_f64_rows;
use crate::errors::IntoPy;
use ikid::body::{BodyModel, COORDINATES, MARKERS};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use pyo3::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let coords: Vec<(&str, &str, (f64, f64))> = COORDINATES.iter().map(|c| (c.name, c.positive, c.range)).collect();
    m.add("COORDINATES", coords)?;
    let markers: Vec<(&str, &str, &str)> = MARKERS.iter().map(|mk| (mk.name, mk.segment.name(), mk.description)).collect();
    m.add("MARKERS", markers)?;
    m.add_function(wrap_pyfunction!(forward_markers, m)?)?;
    Ok(())
}

/// Marker frames `(n, 18)` (metres, lab frame) of the body model at wrist angles `q`
/// `(n, 3)` (radians) and a shoulder flexion (radians), for a subject scaled from the
/// default by `length_scale` and `mass_scale`.
#[pyfunction]
#[pyo3(signature = (q, shoulder_flexion=0.0, length_scale=1.0, mass_scale=1.0))]
fn forward_markers<'py>(
    py: Python<'py>,
    q: &Bound<'py, PyAny>,
    shoulder_flexion: f64,
    length_scale: f64,
    mass_scale: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let body = BodyModel::try_scaled(length_scale, mass_scale).py_err()?;
    with_f64_rows(q, "q", COORDINATES.len(), |values, n| {
        let frames = body.marker_frames(values, shoulder_flexion).py_err()?;
        frames.into_pyarray(py).reshape([n, ikid::body::MARKER_FRAME_LEN])
    })
}
