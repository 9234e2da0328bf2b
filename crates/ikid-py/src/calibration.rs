//! `Calibration`: the core's, NumPy in and out.

use crate::conv::{with_f64_rows, with_floats};
use crate::errors::{IntoPy, input};
use ikid::body::{COORDINATES, MARKER_FRAME_LEN};
use nalgebra::Matrix3;
use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyDictMethods};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Calibration>()
}

/// The subject's marker placement: each segment's technical frame (from its markers) in its
/// anatomical frame. Measure it with `Calibration.from_trials`; give it to `Model.stream`.
#[pyclass(module = "ikid", frozen, skip_from_py_object)]
#[derive(Clone)]
pub struct Calibration {
    pub inner: ikid::Calibration,
    report: Option<ikid::calibration::CalibrationReport>,
}

fn matrix<'py>(py: Python<'py>, m: &Matrix3<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows: Vec<f64> = (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect();
    rows.into_pyarray(py).reshape([3, 3])
}

fn read_matrix(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Matrix3<f64>> {
    with_f64_rows(obj, what, 3, |v, n| {
        if n != 3 {
            return Err(input(format!("{what}: expected a 3×3 matrix, got {n} rows")));
        }
        Ok(Matrix3::from_row_slice(v))
    })
}

#[pymethods]
impl Calibration {
    /// Measures the calibration from a static trial in the neutral pose `(n, 18)` and
    /// movements of single coordinates, `{coordinate name: frames (n, 18)}` (at least two
    /// coordinates). Frames must be complete (fill gaps first). Releases the GIL.
    #[staticmethod]
    fn from_trials(py: Python<'_>, static_frames: &Bound<'_, PyAny>, movements: &Bound<'_, PyDict>) -> PyResult<Self> {
        let statics = frames_of(static_frames, "static_frames")?;
        let mut moves: Vec<(usize, Vec<f32>)> = Vec::new();
        for (key, value) in movements.iter() {
            let name: String = key.extract().map_err(|_| input("movements: keys must be coordinate names"))?;
            let j = COORDINATES.iter().position(|c| c.name == name).ok_or_else(|| {
                input(format!(
                    "movements: unknown coordinate {name:?} (known: {})",
                    COORDINATES.map(|c| c.name).join(", ")
                ))
            })?;
            moves.push((j, frames_of(&value, &format!("movements[{name:?}]"))?));
        }
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let (inner, report) = py.detach(|| ikid::Calibration::from_trials(&statics, &refs)).py_err()?;
        Ok(Calibration { inner, report: Some(report) })
    }

    /// The body model's own placement (what an uncalibrated stream assumes).
    #[staticmethod]
    fn body_model() -> Self {
        Calibration { inner: ikid::Calibration::body_model(), report: None }
    }

    /// From its two 3×3 rotation matrices (as `forearm` and `hand` give them).
    #[staticmethod]
    fn from_matrices(forearm: &Bound<'_, PyAny>, hand: &Bound<'_, PyAny>) -> PyResult<Self> {
        let inner =
            ikid::Calibration::from_matrices(read_matrix(forearm, "forearm")?, read_matrix(hand, "hand")?).py_err()?;
        Ok(Calibration { inner, report: None })
    }

    /// `T_f`: the forearm's technical frame in its anatomical frame (3×3).
    #[getter]
    fn forearm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, self.inner.forearm.matrix())
    }

    /// `T_h`: the hand's technical frame in its anatomical frame (3×3).
    #[getter]
    fn hand<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, self.inner.hand.matrix())
    }

    /// What `from_trials` measured: per movement its range (degrees) and the share of it
    /// about one axis; the placement's difference from the body model's (degrees); the
    /// largest skew between measured axes (degrees). `None` for other calibrations.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(r) = &self.report else { return Ok(None) };
        let d = PyDict::new(py);
        let moves = PyDict::new(py);
        for (j, range, purity) in &r.movements {
            let m = PyDict::new(py);
            m.set_item("range_deg", range)?;
            m.set_item("single_axis_share", purity)?;
            moves.set_item(COORDINATES[*j].name, m)?;
        }
        d.set_item("movements", moves)?;
        d.set_item("placement_deg", (r.placement_deg[0], r.placement_deg[1]))?;
        d.set_item("axis_skew_deg", r.axis_skew_deg)?;
        Ok(Some(d))
    }

    /// Markers `(n, 18)` moved to the body model's placement (float32). Frames must be
    /// complete.
    fn apply<'py>(&self, py: Python<'py>, frames: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut values = frames_of(frames, "frames")?;
        let n = values.len() / MARKER_FRAME_LEN;
        py.detach(|| {
            values.chunks_exact_mut(MARKER_FRAME_LEN).enumerate().try_for_each(|(i, f)| {
                ikid::features::FeatureSet::Markers.check_frame(f, i)?;
                self.inner.apply(f, i)
            })
        })
        .py_err()?;
        values.into_pyarray(py).reshape([n, MARKER_FRAME_LEN])
    }

    fn __repr__(&self) -> String {
        let b = ikid::Calibration::body_model();
        format!(
            "Calibration(forearm {:.1}°, hand {:.1}° from the body model's placement)",
            ikid::calibration::angle_deg(&(self.inner.forearm * b.forearm.inverse())),
            ikid::calibration::angle_deg(&(self.inner.hand * b.hand.inverse()))
        )
    }
}

fn frames_of(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f32>> {
    with_floats(obj, what, 2, |values, shape| {
        if shape[1] != MARKER_FRAME_LEN {
            return Err(input(format!("{what}: {} columns, a marker frame has {MARKER_FRAME_LEN}", shape[1])));
        }
        Ok(values.to_vec())
    })
}
