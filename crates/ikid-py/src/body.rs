//! The body model's names and ranges, read from the core (never restated in Python).

use crate::conv::with_f64_rows;
use crate::errors::{IntoPy, input};
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
/// default by `length_scale` and `mass_scale`, with each marker moved by `marker_shift`
/// `(6, 3)` (metres, in its segment's frame; a lab's placement differing from the model's).
#[pyfunction]
#[pyo3(signature = (q, shoulder_flexion=0.0, length_scale=1.0, mass_scale=1.0, marker_shift=None))]
fn forward_markers<'py>(
    py: Python<'py>,
    q: &Bound<'py, PyAny>,
    shoulder_flexion: f64,
    length_scale: f64,
    mass_scale: f64,
    marker_shift: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let mut body = BodyModel::try_scaled(length_scale, mass_scale).py_err()?;
    if let Some(shift) = marker_shift {
        with_f64_rows(shift, "marker_shift", 3, |v, n| {
            if n != body.marker_offsets.len() || v.iter().any(|x| !x.is_finite()) {
                return Err(input(format!("marker_shift: expected {} finite rows of 3 (metres), got {n} rows", body.marker_offsets.len())));
            }
            for (o, s) in body.marker_offsets.iter_mut().zip(v.chunks_exact(3)) {
                for k in 0..3 {
                    o[k] += s[k];
                }
            }
            Ok(())
        })?;
    }
    with_f64_rows(q, "q", COORDINATES.len(), |values, n| {
        let frames = body.marker_frames(values, shoulder_flexion).py_err()?;
        frames.into_pyarray(py).reshape([n, ikid::body::MARKER_FRAME_LEN])
    })
}
