//! The body model's names and ranges, read from the core (never restated in Python).

use crate::conv::with_f64_rows;
use crate::errors::{IntoPy, input};
use ikid::body::{BodyModel, COORDINATES, GRAVITY, MARKERS, SegmentParams, VIRTUAL_LINK};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let coords: Vec<(&str, &str, (f64, f64))> = COORDINATES.iter().map(|c| (c.name, c.positive, c.range)).collect();
    m.add("COORDINATES", coords)?;
    let markers: Vec<(&str, &str, &str)> =
        MARKERS.iter().map(|mk| (mk.name, mk.segment.name(), mk.description)).collect();
    m.add("MARKERS", markers)?;
    m.add_function(wrap_pyfunction!(forward_markers, m)?)?;
    m.add_function(wrap_pyfunction!(body_model, m)?)?;
    m.add_function(wrap_pyfunction!(check_marker_units, m)?)?;
    m.add_function(wrap_pyfunction!(hand_from_one_marker, m)?)?;
    m.add_function(wrap_pyfunction!(one_marker_hand_landmarks, m)?)?;
    m.add_function(wrap_pyfunction!(learn_cluster_shape, m)?)?;
    m.add_function(wrap_pyfunction!(fit_cluster, m)?)?;
    m.add_function(wrap_pyfunction!(points_in_technical_frame, m)?)?;
    m.add_function(wrap_pyfunction!(points_from_technical_frame, m)?)?;
    m.add_function(wrap_pyfunction!(lab_turn, m)?)?;
    m.add_function(wrap_pyfunction!(lab_up_axis, m)?)?;
    m.add("MAX_CLUSTER_FIT_RESIDUAL_M", ikid::cluster::MAX_FIT_RESIDUAL_M)?;
    m.add("CLUSTER_SPREAD_FLOOR_M", ikid::cluster::SPREAD_FLOOR_M)?;
    m.add("MIN_NEUTRAL_FRAMES", ikid::calibration::MIN_NEUTRAL_FRAMES)?;
    let hp = ikid::body::HAND_POINT;
    m.add("HAND_POINT", (hp.name, hp.segment.name(), hp.description))?;
    m.add("ONE_HAND_MARKER_UNDETERMINED", COORDINATES[ikid::body::ONE_HAND_MARKER_UNDETERMINED].name)?;
    m.add("MARKER_SPAN_M", ikid::body::MARKER_SPAN_M)?;
    m.add("LENGTH_SCALE_RANGE", ikid::body::LENGTH_SCALE_RANGE)?;
    m.add("MASS_SCALE_RANGE", ikid::body::MASS_SCALE_RANGE)?;
    Ok(())
}

/// The unit vector of the lab axis `name` names as up (`"z"`, `"+Z"`, `"-y"`…): the core's
/// grammar (`body::up_axis`), an `InputError` for anything else.
#[pyfunction]
fn lab_up_axis(name: &str) -> PyResult<[f64; 3]> {
    ikid::body::up_axis(name).py_err()
}

/// The rotation `(3, 3)` taking a lab whose up direction is `up` (an axis such as `"+z"`, or
/// three numbers) into ikid's (+Y up): `p_ikid = R @ p_lab`, the turn the tracker and streams
/// make with their `up` setting (the core's `body::lab_turn`; the identity for +Y).
#[pyfunction]
fn lab_turn<'py>(py: Python<'py>, up: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let up = crate::tracker::lab_up(up)?;
    let turn = ikid::body::lab_turn(up).py_err()?.unwrap_or_else(nalgebra::Rotation3::identity);
    let m = turn.matrix();
    let rows: Vec<f64> = (0..3).flat_map(|i| (0..3).map(move |j| m[(i, j)])).collect();
    rows.into_pyarray(py).reshape([3, 3])
}

/// Refuses a recording `(n, 18)` (metres) whose markers spread over a distance no forearm and
/// hand span (median over its frames; `MARKER_SPAN_M`): `InputError` naming the likely cause
/// ("are the units mm?"). Returns None for a plausible one.
#[pyfunction]
fn check_marker_units(frames: &Bound<'_, PyAny>) -> PyResult<()> {
    with_f64_rows(frames, "frames", ikid::body::MARKER_FRAME_LEN, |v, _| ikid::body::check_recording_span(v).py_err())
}

/// Six-marker frames `(n, 18)` from the forearm's three markers and one hand marker `(n, 12)`
/// (RSP, USP, FAP, HND; metres): the hand's three markers virtual, without a roll of their own
/// (the core's `body::hand_from_one_marker`; `left` for a left arm).
#[pyfunction]
#[pyo3(signature = (frames, left=false))]
fn hand_from_one_marker<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    left: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_f64_rows(frames, "frames", ikid::body::ONE_HAND_MARKER_FRAME_LEN, |v, n| {
        let six = ikid::body::hand_from_one_marker(v, left).py_err()?;
        six.into_pyarray(py).reshape([n, ikid::body::MARKER_FRAME_LEN])
    })
}

/// The hand landmarks `(n, 6)` (second, fifth metacarpal head) a one-marker hand stands for,
/// from `(n, 12)` frames as `hand_from_one_marker` takes them (the core's
/// `body::one_marker_hand_landmarks`).
#[pyfunction]
fn one_marker_hand_landmarks<'py>(py: Python<'py>, frames: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_f64_rows(frames, "frames", ikid::body::ONE_HAND_MARKER_FRAME_LEN, |v, n| {
        let points = ikid::body::one_marker_hand_landmarks(v).py_err()?;
        points.into_pyarray(py).reshape([n, 6])
    })
}

/// The rigid shape `(k, 5)` of a cluster of `n_markers` (three or more) from frames
/// `(n, 3·n_markers)` (metres, NaN = missing): each marker's place `x, y, z`, its spread and
/// its weight (the core's `cluster::ClusterShape::learn`).
#[pyfunction]
fn learn_cluster_shape<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    n_markers: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_f64_rows(frames, "frames", 3 * n_markers, |v, _| {
        let shape = ikid::cluster::ClusterShape::learn(v, n_markers).py_err()?;
        let points = shape.points();
        let rows: Vec<f64> = (0..n_markers)
            .flat_map(|m| [points[3 * m], points[3 * m + 1], points[3 * m + 2], shape.spread()[m], shape.weight()[m]])
            .collect();
        rows.into_pyarray(py).reshape([n_markers, 5])
    })
}

/// A cluster's shape `(k, 5)` (as `learn_cluster_shape` gives it) fitted to each frame
/// `(n, 3k)`: `(placed (n, 3k), left_out (k,) frames each marker was seen but left out of the
/// fit, undetermined frames)` (the core's `cluster::ClusterShape::fit`).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn fit_cluster<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    shape: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Vec<usize>, usize)> {
    let shape = with_f64_rows(shape, "shape", 5, |v, _| {
        let points: Vec<f64> = v.chunks_exact(5).flat_map(|r| r[..3].to_vec()).collect();
        let spread: Vec<f64> = v.chunks_exact(5).map(|r| r[3]).collect();
        let weight: Vec<f64> = v.chunks_exact(5).map(|r| r[4]).collect();
        ikid::cluster::ClusterShape::from_points(&points, &spread, &weight).py_err()
    })?;
    let k = shape.len();
    with_f64_rows(frames, "frames", 3 * k, |v, n| {
        let fit = shape.fit(v).py_err()?;
        Ok((fit.placed.into_pyarray(py).reshape([n, 3 * k])?, fit.left_out, fit.undetermined))
    })
}

/// Points `(n, 3k)` expressed in the technical frame of three markers `(n, 9)` of the same
/// frames (the core's `cluster::points_in_technical_frame`): `(n, 3k)`, NaN where undefined.
#[pyfunction]
fn points_in_technical_frame<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    n_points: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_f64_rows(markers, "markers", 9, |m, n| {
        with_f64_rows(points, "points", 3 * n_points, |p, _| {
            let local = ikid::cluster::points_in_technical_frame(m, p).py_err()?;
            local.into_pyarray(py).reshape([n, 3 * n_points])
        })
    })
}

/// Points fixed in the technical frame of three markers (`local`, `(k, 3)`) in the lab for
/// each frame of the markers `(n, 9)` (the core's `cluster::points_from_technical_frame`).
#[pyfunction]
fn points_from_technical_frame<'py>(
    py: Python<'py>,
    markers: &Bound<'py, PyAny>,
    local: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    with_f64_rows(markers, "markers", 9, |m, n| {
        with_f64_rows(local, "local", 3, |l, k| {
            let lab = ikid::cluster::points_from_technical_frame(m, l).py_err()?;
            lab.into_pyarray(py).reshape([n, 3 * k])
        })
    })
}

/// A subject scaled from the default, each marker moved by `marker_shift` `(6, 3)` (metres,
/// in its segment's frame): the core's [`BodyModel::subject`].
pub(crate) fn subject(
    length_scale: f64,
    mass_scale: f64,
    marker_shift: Option<&Bound<'_, PyAny>>,
) -> PyResult<BodyModel> {
    match marker_shift {
        None => BodyModel::subject(length_scale, mass_scale, None).py_err(),
        Some(shift) => with_f64_rows(shift, "marker_shift", 3, |v, _| {
            BodyModel::subject(length_scale, mass_scale, Some(v)).py_err()
        }),
    }
}

fn segment_dict<'py>(py: Python<'py>, s: &SegmentParams) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("length", s.length)?;
    d.set_item("mass", s.mass)?;
    d.set_item("com", s.com.to_vec())?;
    d.set_item("inertia", s.inertia.to_vec())?;
    Ok(d)
}

/// Everything a model file for another tool (OpenSim `.osim`, biorbd `.bioMod`) needs, for a
/// subject scaled by `length_scale`/`mass_scale`, markers moved by `marker_shift`, the forearm
/// at `shoulder_flexion` (rad). SI units; frames as documented in the core's `body` module.
///
/// Keys: `gravity`; `coordinates` (name, positive, axis in the previous link's frame, range);
/// `segments` (`forearm`, `hand`: length, mass, com, principal inertia about the com along the
/// segment axes); `virtual_link` (the tiny links between the wrist's joints); `forearm_pose`
/// (`rotation` 3×3 rows, `translation`: the forearm frame in the lab, origin at the wrist
/// centre); `markers` (name, segment, description, offset in the segment's frame);
/// `upper_arm_length`, `shoulder`, `length_scale`, `mass_scale`, `shoulder_flexion`.
#[pyfunction]
#[pyo3(signature = (length_scale=1.0, mass_scale=1.0, shoulder_flexion=0.0, marker_shift=None))]
fn body_model<'py>(
    py: Python<'py>,
    length_scale: f64,
    mass_scale: f64,
    shoulder_flexion: f64,
    marker_shift: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if !shoulder_flexion.is_finite() {
        return Err(input(format!("shoulder_flexion: is {shoulder_flexion}")));
    }
    let body = subject(length_scale, mass_scale, marker_shift)?;
    let d = PyDict::new(py);
    d.set_item("gravity", GRAVITY.to_vec())?;
    let coords = PyList::empty(py);
    for c in COORDINATES.iter() {
        let cd = PyDict::new(py);
        cd.set_item("name", c.name)?;
        cd.set_item("positive", c.positive)?;
        cd.set_item("axis", c.axis.to_vec())?;
        cd.set_item("range", vec![c.range.0, c.range.1])?;
        coords.append(cd)?;
    }
    d.set_item("coordinates", coords)?;
    let segments = PyDict::new(py);
    segments.set_item("forearm", segment_dict(py, &body.forearm)?)?;
    segments.set_item("hand", segment_dict(py, &body.hand)?)?;
    d.set_item("segments", segments)?;
    d.set_item("virtual_link", segment_dict(py, &VIRTUAL_LINK)?)?;
    let pose = body.forearm_pose(shoulder_flexion);
    let r = pose.rotation.to_rotation_matrix();
    let rows: Vec<Vec<f64>> = (0..3).map(|i| (0..3).map(|j| r[(i, j)]).collect()).collect();
    let pd = PyDict::new(py);
    pd.set_item("rotation", rows)?;
    pd.set_item("translation", pose.translation.vector.iter().copied().collect::<Vec<f64>>())?;
    d.set_item("forearm_pose", pd)?;
    let markers = PyList::empty(py);
    for (mk, offset) in MARKERS.iter().zip(body.marker_offsets.iter()) {
        let md = PyDict::new(py);
        md.set_item("name", mk.name)?;
        md.set_item("segment", mk.segment.name())?;
        md.set_item("description", mk.description)?;
        md.set_item("offset", offset.to_vec())?;
        markers.append(md)?;
    }
    d.set_item("markers", markers)?;
    d.set_item("upper_arm_length", body.upper_arm_length)?;
    d.set_item("shoulder", body.shoulder.to_vec())?;
    d.set_item("length_scale", length_scale)?;
    d.set_item("mass_scale", mass_scale)?;
    d.set_item("shoulder_flexion", shoulder_flexion)?;
    Ok(d)
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
    let body = subject(length_scale, mass_scale, marker_shift)?;
    with_f64_rows(q, "q", COORDINATES.len(), |values, n| {
        let frames = body.marker_frames(values, shoulder_flexion).py_err()?;
        frames.into_pyarray(py).reshape([n, ikid::body::MARKER_FRAME_LEN])
    })
}
