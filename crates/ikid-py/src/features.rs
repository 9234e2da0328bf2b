//! Feature sets: the same computation training and inference use.

use crate::conv::with_floats;
use crate::errors::{IntoPy, input};
use ikid::FeatureSet;
use ikid::features::FEATURE_SETS;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FEATURE_SETS", FEATURE_SETS.map(FeatureSet::name).to_vec())?;
    m.add_function(wrap_pyfunction!(feature_set_info, m)?)?;
    m.add_function(wrap_pyfunction!(compute_features, m)?)?;
    m.add_function(wrap_pyfunction!(fill_gaps, m)?)?;
    Ok(())
}

/// Sizes and names of a feature set: `frame_len`, `feature_len`, `frame_names`, `feature_names`.
#[pyfunction]
fn feature_set_info<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyDict>> {
    let set = feature_set(name)?;
    let d = PyDict::new(py);
    d.set_item("name", set.name())?;
    d.set_item("frame_kind", set.frame_kind().name())?;
    d.set_item("frame_len", set.frame_len())?;
    d.set_item("feature_len", set.feature_len())?;
    d.set_item("frame_names", set.frame_names())?;
    d.set_item("feature_names", set.feature_names())?;
    Ok(d)
}

/// Features of every frame: `frames` is `(n, frame_len)`, the result `(n, feature_len)` float32.
#[pyfunction]
fn compute_features<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    feature_set: &str,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let set = self::feature_set(feature_set)?;
    with_floats(frames, "frames", 2, |values, shape| {
        if shape[1] != set.frame_len() {
            return Err(input(format!(
                "frames: {} columns, feature set {:?} takes {}",
                shape[1],
                set.name(),
                set.frame_len()
            )));
        }
        let mut out = vec![0f32; shape[0] * set.feature_len()];
        py.detach(|| set.compute_rows(values, &mut out)).py_err()?;
        out.into_pyarray(py).reshape([shape[0], set.feature_len()])
    })
}

/// Filled frames `(n, 18)` and the mask of markers filled per frame `(n,)`.
type FilledFrames<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<u8>>);

/// Runs a fresh gap filler (what a `"fill"` stream does) over a recording `(n, 18)`: the
/// filled frames (float32) and per frame the bit mask of markers filled (uint8, bit `i` =
/// marker `i`). A frame it cannot fill raises (`unfillable="raise"`) or stays missing with
/// mask 0 (`unfillable="keep"`). `rate_hz`: the frames' rate (the filler's time constants are
/// in seconds).
#[pyfunction]
#[pyo3(signature = (frames, unfillable = "raise", rate_hz = 1000.0))]
fn fill_gaps<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    unfillable: &str,
    rate_hz: f64,
) -> PyResult<FilledFrames<'py>> {
    let keep = match unfillable {
        "raise" => false,
        "keep" => true,
        other => return Err(input(format!("unfillable: {other:?} is not \"raise\" or \"keep\""))),
    };
    with_floats(frames, "frames", 2, |values, shape| {
        if shape[1] != ikid::body::MARKER_FRAME_LEN {
            return Err(input(format!(
                "frames: {} columns, marker frames have {}",
                shape[1],
                ikid::body::MARKER_FRAME_LEN
            )));
        }
        let (filled, masks) = py.detach(|| ikid::gaps::fill_gaps(values, keep, rate_hz)).py_err()?;
        Ok((filled.into_pyarray(py).reshape([shape[0], shape[1]])?, masks.into_pyarray(py)))
    })
}

/// A feature set named by the caller: an unknown name is the caller's input error here (in a
/// model file it is a model-file error).
fn feature_set(name: &str) -> PyResult<FeatureSet> {
    FeatureSet::from_name(name).map_err(|e| input(e.to_string()))
}
