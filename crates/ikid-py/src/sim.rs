//! The simulator and the noise models (`ikid-sim`, `ikid::noise`).

use crate::conv::with_f64_rows;
use crate::errors::{IntoPy, input};
use ikid::body::{BodyModel, MARKER_FRAME_LEN};
use ikid::noise;
use ikid_sim::protocol::Protocol;
use ikid_sim::{SimConfig, simulate as run};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SIMULATOR", ikid_sim::SIMULATOR)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(noise_uniform, m)?)?;
    m.add_function(wrap_pyfunction!(noise_gaussian, m)?)?;
    m.add_function(wrap_pyfunction!(noise_drift, m)?)?;
    m.add_function(wrap_pyfunction!(noise_occlusion, m)?)?;
    Ok(())
}

fn sim_err(e: ikid_sim::Error) -> PyErr {
    match e {
        ikid_sim::Error::Core(core) => crate::errors::to_py(core),
        other => input(other.to_string()),
    }
}

fn rows<'py, const W: usize>(py: Python<'py>, v: &[[f64; W]]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    v.concat().into_pyarray(py).reshape([v.len(), W])
}

/// Simulates one trial; returns a dict of arrays (`time`, `q`, `qd`, `qdd`, `tau`,
/// `markers`, `q_ref`). Angles in rad, torques in N·m, markers in m. Releases the GIL.
#[pyfunction]
#[pyo3(signature = (protocol="random", seed=0, duration=10.0, shoulder_flexion=0.0, length_scale=1.0, mass_scale=1.0, dt=0.001, substeps=1, output_every=1, octants=None))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    protocol: &str,
    seed: u64,
    duration: f64,
    shoulder_flexion: f64,
    length_scale: f64,
    mass_scale: f64,
    dt: f64,
    substeps: usize,
    output_every: usize,
    octants: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyDict>> {
    let protocol = Protocol::from_name(protocol, seed, duration, octants.as_deref()).map_err(sim_err)?;
    let config = SimConfig {
        body: BodyModel::try_scaled(length_scale, mass_scale).py_err()?,
        shoulder_flexion,
        dt,
        substeps,
        output_every,
        ..Default::default()
    };
    let trial = py.detach(|| run(&config, &protocol)).map_err(sim_err)?;
    let d = PyDict::new(py);
    d.set_item("time", PyArray1::from_slice(py, &trial.time))?;
    d.set_item("q", rows(py, &trial.q)?)?;
    d.set_item("qd", rows(py, &trial.qd)?)?;
    d.set_item("qdd", rows(py, &trial.qdd)?)?;
    d.set_item("tau", rows(py, &trial.tau)?)?;
    d.set_item("markers", rows(py, &trial.markers)?)?;
    d.set_item("q_ref", rows(py, &trial.q_ref)?)?;
    d.set_item("protocol", &protocol.name)?;
    Ok(d)
}

/// Applies a noise model to a copy of `markers` `(n, 18)` and returns it.
fn with_noise<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    f: impl FnOnce(&mut [f64]) -> ikid::Result<()> + Send,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_f64_rows(markers, "markers", MARKER_FRAME_LEN, |values, n| {
        let mut out = values.to_vec();
        py.detach(|| f(&mut out)).py_err()?;
        out.into_pyarray(py).reshape([n, MARKER_FRAME_LEN])
    })
}

/// The thesis' noise: uniform in ±`fraction` of each coordinate column's range.
#[pyfunction]
fn noise_uniform<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    fraction: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_noise(py, markers, |m| noise::uniform_range(m, fraction, seed))
}

/// Gaussian noise of `sigma` metres on every value.
#[pyfunction]
fn noise_gaussian<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    sigma: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_noise(py, markers, |m| noise::gaussian(m, sigma, seed))
}

/// Slow sinusoidal drift of peak `amplitude` metres per coordinate.
#[pyfunction]
fn noise_drift<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    amplitude: f64,
    rate_hz: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_noise(py, markers, |m| noise::drift(m, amplitude, rate_hz, seed))
}

/// Occlusion bursts: markers set to NaN for `min_s`–`max_s` seconds. Each frame starts a
/// burst on a marker with probability `bursts_per_second / rate_hz`; `markers_affected` lists
/// the marker indices (frame order) that may disappear, all six when empty (the default).
#[pyfunction]
#[pyo3(signature = (markers, bursts_per_second, min_s, max_s, rate_hz, seed, markers_affected=Vec::new()))]
#[pyo3(text_signature = "(markers, bursts_per_second, min_s, max_s, rate_hz, seed, markers_affected=[])")]
#[allow(clippy::too_many_arguments)]
fn noise_occlusion<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    bursts_per_second: f64,
    min_s: f64,
    max_s: f64,
    rate_hz: f64,
    seed: u64,
    markers_affected: Vec<usize>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_noise(py, markers, |m| {
        noise::occlusion(m, bursts_per_second, min_s, max_s, rate_hz, &markers_affected, seed).map(|_| ())
    })
}
