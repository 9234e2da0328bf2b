//! The classical reference solvers (f64): segment-fit IK and Newton–Euler ID.

use crate::conv::with_f64_rows;
use crate::errors::IntoPy;
use ikid::body::{BodyModel, MARKER_FRAME_LEN, N_COORDINATES};
use ikid::reference::{inverse_dynamics_rows, inverse_kinematics};
use ikid::status;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(reference_ik, m)?)?;
    m.add_function(wrap_pyfunction!(reference_id, m)?)?;
    m.add_function(wrap_pyfunction!(joint_status, m)?)?;
    Ok(())
}

fn subject(length_scale: f64, mass_scale: f64) -> PyResult<BodyModel> {
    BodyModel::try_scaled(length_scale, mass_scale).py_err()
}

/// Wrist angles `(n, 3)` (rad) of marker frames `(n, 18)` (m) by per-frame least-squares
/// segment fitting on the subject's marker layout. Releases the GIL.
#[pyfunction]
#[pyo3(signature = (markers, length_scale=1.0, mass_scale=1.0))]
fn reference_ik<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    length_scale: f64,
    mass_scale: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let body = subject(length_scale, mass_scale)?;
    with_f64_rows(markers, "markers", MARKER_FRAME_LEN, |values, n| {
        let mut q = vec![0.0; n * N_COORDINATES];
        py.detach(|| inverse_kinematics(&body, values, &mut q)).py_err()?;
        q.into_pyarray(py).reshape([n, N_COORDINATES])
    })
}

/// Joint torques `(n, 3)` (N·m) for joint states `q`, `qd`, `qdd` (each `(n, 3)`, rad-based)
/// with the forearm at `shoulder_flexion` (rad). Releases the GIL.
#[pyfunction]
#[pyo3(signature = (q, qd, qdd, shoulder_flexion=0.0, length_scale=1.0, mass_scale=1.0))]
#[allow(clippy::too_many_arguments)]
fn reference_id<'py>(
    py: Python<'py>,
    q: &Bound<'py, PyAny>,
    qd: &Bound<'py, PyAny>,
    qdd: &Bound<'py, PyAny>,
    shoulder_flexion: f64,
    length_scale: f64,
    mass_scale: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let body = subject(length_scale, mass_scale)?;
    let q = with_f64_rows(q, "q", N_COORDINATES, |v, _| Ok(v.to_vec()))?;
    let qd = with_f64_rows(qd, "qd", N_COORDINATES, |v, _| Ok(v.to_vec()))?;
    let qdd = with_f64_rows(qdd, "qdd", N_COORDINATES, |v, _| Ok(v.to_vec()))?;
    let n = q.len() / N_COORDINATES;
    let mut tau = vec![0.0; q.len()];
    py.detach(|| inverse_dynamics_rows(&body, shoulder_flexion, &q, &qd, &qdd, &mut tau)).py_err()?;
    tau.into_pyarray(py).reshape([n, N_COORDINATES])
}

/// Per row, the `FRAME_STATUS` bits of joint angles `q` `(n, 3)` (rad) read from elsewhere and,
/// given, their torques `tau` `(n, 3)` (N·m) against a subject of `mass_scale`'s limit, each row
/// alone (core `status::joint_status`): `implausible` for an angle far past its range or a
/// torque past the limit, `turned_over` with it for angles that turn the hand over.
#[pyfunction]
#[pyo3(signature = (q, tau=None, mass_scale=1.0))]
fn joint_status<'py>(
    py: Python<'py>,
    q: &Bound<'py, PyAny>,
    tau: Option<&Bound<'py, PyAny>>,
    mass_scale: f64,
) -> PyResult<Bound<'py, PyArray1<u16>>> {
    subject(1.0, mass_scale)?; // refuses a mass scale out of range, as reference_id does
    let limit = status::torque_limit(mass_scale);
    let q = with_f64_rows(q, "q", N_COORDINATES, |v, _| Ok(v.to_vec()))?;
    let tau = tau.map(|t| with_f64_rows(t, "tau", N_COORDINATES, |v, _| Ok(v.to_vec()))).transpose()?;
    if let Some(t) = &tau
        && t.len() != q.len()
    {
        return Err(crate::errors::input(format!(
            "tau: {} rows, q {}: one torque row per joint state",
            t.len() / N_COORDINATES,
            q.len() / N_COORDINATES
        )));
    }
    let row = |v: &[f64], i: usize| -> [f64; N_COORDINATES] { std::array::from_fn(|c| v[N_COORDINATES * i + c]) };
    let bits: Vec<u16> = (0..q.len() / N_COORDINATES)
        .map(|i| status::joint_status(&row(&q, i), tau.as_ref().map(|t| row(t, i)).as_ref(), limit))
        .collect();
    Ok(bits.into_pyarray(py))
}
